"""The error contract (fpm_sim.errors): library errors name library parameters; the CLI names its options.

- no string literal outside ``fpm_sim/cli/`` names a command-line flag (docstrings and full ``fpm-sim <command>``
  command lines, which document a command, are allowed);
- representative errors carry ``parameter``, ``value`` and, for files, ``file`` and ``row``;
- the one table (``fpm_sim.cli.common.OPTION_NAMES``) maps only to options that exist, and the one error path
  shows the option and the value in its unit;
- every parser refuses abbreviated options.
"""

from __future__ import annotations

import argparse
import ast
import math
import pickle
import re
from pathlib import Path

import pytest

import fpm_sim
from fpm_sim.cli.common import OPTION_NAMES, error_line
from fpm_sim.cli.main import build_parser, main
from fpm_sim.config import default_config
from fpm_sim.config.schema import ConfigError
from fpm_sim.errors import FpmSimError
from fpm_sim.kinematics import PoseValueError, checked_pose_mm
from fpm_sim.model.options import ModelOptions, TimestepError
from fpm_sim.model.parts import LinkModelError

PACKAGE = Path(fpm_sim.__file__).parent
FLAG = re.compile(r"(?<![\w-])--[a-z][a-z0-9-]*")
COMMAND_LINE = re.compile(r"fpm-sim [a-z-]+|python scripts/[a-z_]+\.py")  # a quoted command documents its options


def _docstrings(tree: ast.AST) -> set[int]:
    ids = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                ids.add(id(body[0].value))
        # attribute docstrings: a string expression right after an assignment
        for field in ("body", "orelse"):
            stmts = getattr(node, field, None)
            if isinstance(stmts, list):
                for s in stmts:
                    if isinstance(s, ast.Expr) and isinstance(s.value, ast.Constant):
                        ids.add(id(s.value))
    return ids


def _flag_literals(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    skip = _docstrings(tree)
    hits = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in skip:
            for m in FLAG.finditer(node.value):
                if not COMMAND_LINE.search(node.value[: m.start()]):  # `fpm-sim identify --folds K` documents
                    hits.append(f"{path.relative_to(PACKAGE.parent)}:{node.lineno}: {m.group()} in {node.value!r}")
    return hits


def test_no_library_message_names_a_command_line_flag():
    # the command line and the pytest plugin (which declares pytest's own --fpm-* options) may name flags
    files = [
        p
        for p in PACKAGE.rglob("*.py")
        if "cli" not in p.relative_to(PACKAGE).parts and p.name != "pytest_plugin.py"
    ]
    assert len(files) > 50  # the scan sees the package
    hits = [h for p in files for h in _flag_literals(p)]
    assert hits == [], "\n".join(hits)


def test_the_scan_finds_a_flag_in_a_message(tmp_path):
    """The scan above can fail: a message naming a flag is found, a docstring or a command line is not."""
    p = PACKAGE / "_probe_flag_scan.py"
    try:
        p.write_text(
            '"""Use ``--segments`` here."""\n'
            'def f():\n    """--x-mm is fine in a docstring."""\n'
            '    raise ValueError(f"bad {1} (--thickness-mm)")\n'
            'NOTE = "run `fpm-sim identify --folds K`"\n'
        )
        hits = _flag_literals(p)
    finally:
        p.unlink()
    assert len(hits) == 1
    assert "--thickness-mm" in hits[0]


def test_errors_carry_parameter_value_and_hint():
    with pytest.raises(ConfigError) as exc:
        default_config().with_section(thickness_m=0.0)
    assert (exc.value.parameter, exc.value.value) == ("section.thickness_m", 0.0)
    assert str(exc.value) == "section.thickness_m: must be a positive finite number, got 0.0"

    with pytest.raises(LinkModelError) as exc2:
        ModelOptions(link_model="bogus")
    assert exc2.value.parameter == "link_model"
    assert exc2.value.value == "bogus"
    assert "segments" in exc2.value.hint

    with pytest.raises(TimestepError) as exc3:
        ModelOptions(timestep_s=1.0)
    assert exc3.value.parameter == "timestep_s"
    assert exc3.value.value == 1.0

    with pytest.raises(PoseValueError) as exc4:
        checked_pose_mm(0, 0, 30, file="poses.csv", row=4)
    e = exc4.value
    assert (e.parameter, e.value, e.file, e.row) == ("phi_rad", 30.0, "poses.csv", 4)
    assert str(e).startswith("poses.csv: row 4: phi_rad: outside -pi..pi")
    assert checked_pose_mm("10", 20, "-3.1").x_m == pytest.approx(0.01)


def test_plain_message_and_pickling():
    assert str(FpmSimError("a plain message")) == "a plain message"
    assert FpmSimError("x").parameter is None
    assert not FpmSimError("x").has_value
    e = ConfigError("must be > 0", parameter="section.height_m", value=-1.0, hint="in m", file="m.toml", row=3)
    back = pickle.loads(pickle.dumps(e))
    assert type(back) is ConfigError
    assert str(back) == str(e) == "m.toml: row 3: section.height_m: must be > 0, got -1.0; in m"
    assert (back.parameter, back.value, back.hint, back.file, back.row) == (
        "section.height_m",
        -1.0,
        "in m",
        "m.toml",
        3,
    )
    assert not pickle.loads(pickle.dumps(FpmSimError("x", parameter="p"))).has_value


def _options_of_every_command() -> dict[str, set[str]]:
    """``{command: option strings}`` of every (sub)command."""
    out: dict[str, set[str]] = {}

    def walk(p: argparse.ArgumentParser, name: str) -> None:
        out[name] = set(p._option_string_actions)
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                for sub_name, sub in a.choices.items():
                    walk(sub, f"{name} {sub_name}".strip())

    walk(build_parser(), "")
    return out


def test_every_parser_refuses_abbreviations():
    parsers = _options_of_every_command()
    assert len(parsers) > 15

    def walk(p: argparse.ArgumentParser) -> list[argparse.ArgumentParser]:
        subs = [s for a in p._actions if isinstance(a, argparse._SubParsersAction) for s in a.choices.values()]
        return [p] + [q for s in subs for q in walk(s)]

    assert all(p.allow_abbrev is False for p in walk(build_parser()))


@pytest.mark.parametrize(
    ("argv", "option"),
    [
        (["reproduce", "--thickness-m", "0.01"], "--thickness-m"),
        (["modes", "--x-m", "0.05"], "--x-m"),
        (["sweep", "--step", "5"], "--step"),
        (["atlas", "build", "--out", "a.npz", "--mod", "3"], "--mod"),
    ],
)
def test_abbreviated_options_are_refused(argv, option, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: unrecognized arguments: " + option)
    assert list(tmp_path.iterdir()) == []


def test_the_option_table_names_only_existing_options():
    options = _options_of_every_command()
    every = set().union(*options.values())
    for key, (option, factor) in OPTION_NAMES.items():
        command, _, _ = key.rpartition(":")
        # "command:" keys are top-level commands (args.command): all of their sub-commands' options count
        have = set().union(*(v for k, v in options.items() if k.split(" ")[0] == command)) if command else every
        assert all(o in have for o in option.split(", ")), (key, option)
        assert factor in (1.0, 1e3)
        assert (factor == 1.0) == (not option.endswith("-mm") or key.endswith("_mm"))


def test_error_line_shows_the_option_and_the_value_in_its_unit():
    e = ConfigError("must be a positive finite number", parameter="section.thickness_m", value=0.0005)
    assert error_line(e, "rollout", {"--thickness-mm"}) == (
        "error: --thickness-mm: must be a positive finite number, got 0.5 mm"
    )
    # a command without that option (design --vary section.thickness_m=...) keeps the library's name
    assert error_line(e, "design", {"--vary"}).startswith("error: section.thickness_m: ")
    # a value read from a file names the file, not an option
    e.file = "m.toml"
    assert error_line(e, "rollout", {"--thickness-mm"}).startswith("error: m.toml: section.thickness_m: ")
    grid = FpmSimError("must list distinct finite grid values", parameter="x_m", value=[0.01, math.nan])
    assert (
        error_line(grid, "atlas", {"--x-mm"})
        == "error: --x-mm: must list distinct finite grid values, got [10, nan] mm"
    )
    n = FpmSimError("must be >= 1", parameter="n_modes", value=0)
    assert error_line(n, "atlas", {"--modes"}) == "error: --modes: must be >= 1, got 0"
    assert error_line(n, "design", {"--n-modes"}) == "error: --n-modes: must be >= 1, got 0"


@pytest.mark.parametrize(
    ("argv", "line"),
    [
        (["rollout", "--thickness-mm", "0"], "error: --thickness-mm: must be a positive finite number, got 0 mm"),
        (["reproduce", "--thickness-mm", "-3"], "error: --thickness-mm: must be a positive finite number, got -3 mm"),
        (["modes", "--link-model", "foo"], "error: --link-model: unknown link model, got 'foo'; choose one of "),
        (["modes", "--phi-rad", "30"], "error: --phi-rad: outside -pi..pi"),
    ],
)
def test_the_cli_names_its_options(argv, line, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(line)
    assert err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []
