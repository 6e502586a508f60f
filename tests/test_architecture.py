"""The package's shape: no import cycles, no private names imported across modules, cli imported by no one.

The layers themselves are checked by ``lint-imports`` (contract in pyproject.toml); these tests walk the
same import graph (grimp, import-linter's engine) for what a layers contract does not see.
"""

from __future__ import annotations

import ast
from pathlib import Path

import grimp
import pytest

PACKAGE_DIR = Path(__file__).resolve().parents[1] / "fpm_sim"


@pytest.fixture(scope="module")
def graph() -> grimp.ImportGraph:
    return grimp.build_graph("fpm_sim", cache_dir=None)


def test_no_import_cycles_between_modules(graph: grimp.ImportGraph) -> None:
    cycles = []
    for module in sorted(graph.modules):
        for imported in graph.find_modules_directly_imported_by(module):
            if imported != module and graph.chain_exists(importer=imported, imported=module):
                chain = graph.find_shortest_chain(importer=imported, imported=module)
                cycles.append(f"{module} -> {' -> '.join(chain or [])}")
    assert not cycles, "import cycles:\n" + "\n".join(cycles)


def test_nothing_outside_cli_imports_cli(graph: grimp.ImportGraph) -> None:
    offenders = [
        m
        for m in graph.find_downstream_modules("fpm_sim.cli", as_package=True)
        if not m.startswith("fpm_sim.cli")
    ]
    assert not offenders


def _private_imports(path: Path) -> list[str]:
    tree = ast.parse(path.read_text())
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("fpm_sim"):
            out += [f"{path.name}: from {node.module} import {a.name}" for a in node.names if a.name.startswith("_")
                    and not a.name.startswith("__")]
    return out


def test_no_private_name_is_imported_across_modules() -> None:
    found = [hit for p in sorted(PACKAGE_DIR.rglob("*.py")) for hit in _private_imports(p)]
    assert not found, "\n".join(found)
