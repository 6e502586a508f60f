"""Every function of the package fits on a screen, or says why it is long.

A function or method whose body runs over :data:`MAX_BODY_LINES` lines (counted from its ``def`` line
to its last line, both included, so a long signature counts) must give the reason in its docstring, on a line starting
``Long because:`` (e.g. a flat sequence of steps that reads best top to bottom). ARCHITECTURE.md states the rule.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import fpm_sim

MAX_BODY_LINES = 80
"""Longest function body without a stated reason."""

PACKAGE = Path(fpm_sim.__file__).parent



def body_lines(node: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    """Lines from the ``def`` line (decorators excluded) to the function's last line, both included."""
    assert node.end_lineno is not None
    return node.end_lineno - node.lineno + 1


def states_a_reason(node: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    """Whether the docstring has a line starting ``Long because:``."""
    doc = ast.get_docstring(node) or ""
    return any(line.strip().startswith("Long because:") for line in doc.splitlines())


def long_functions(root: Path, *, limit: int = MAX_BODY_LINES, skip: tuple[str, ...] = ()) -> list[str]:
    """``path:line name (n lines)`` of every function under ``root`` longer than ``limit`` without a reason."""
    found = []
    for path in sorted(root.rglob("*.py")):
        rel = f"{root.name}/{path.relative_to(root).as_posix()}"
        if rel.startswith(skip):
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = body_lines(node)
                if n > limit and not states_a_reason(node):
                    found.append(f"{rel}:{node.lineno} {node.name} ({n} lines)")
    return found


def test_functions_fit_or_say_why_they_are_long():
    offenders = long_functions(PACKAGE)
    assert not offenders, (
        f"functions over {MAX_BODY_LINES} lines without a 'Long because:' line in their docstring: "
        + "; ".join(offenders)
    )


@pytest.mark.parametrize(("reason", "flagged"), [("", True), ("\n    Long because: a flat sequence.\n    ", False)])
def test_the_check_sees_a_long_function_and_its_reason(tmp_path, reason, flagged):
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    body = "".join(f"    x{i} = {i}\n" for i in range(MAX_BODY_LINES))
    (pkg / "mod.py").write_text(f'def f():\n    """Doc.{reason}"""\n{body}', encoding="utf-8")
    (pkg / "short.py").write_text('def g():\n    """Doc."""\n    return 1\n', encoding="utf-8")
    assert bool(long_functions(pkg)) is flagged
    assert long_functions(pkg, skip=("pkg/mod.py",)) == []
