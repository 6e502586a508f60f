"""Every output of every command is proven creatable before an input is read or anything is computed (issue 32).

Each command runs with one output at a time in ``/proc`` (never creatable) or under a plain file, while every
reader of an input (descriptions, posteriors, CSV files, atlases, FRF files) and MuJoCo's compilation are
tripwires: the run must end with one ``error:`` line naming the option and exit 2 without touching one. A test
also walks the parser, so that a new output option without a case here fails.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import io
import sys
from pathlib import Path

import pytest

from fpm_sim.cli.main import build_parser, main

INPUT_DESTS = {
    "config", "posterior", "poses", "designs", "subsystems", "workspace", "priors", "path_csv", "atlas", "file",
    "files", "model",
}  # fmt: skip
"""Path-typed arguments that are read, not written (every other path-typed argument is an output)."""

VARY = ["--vary", "section.thickness_m=0.01,0.02"]
FREE_HEIGHT = ["--free", "sections.bar.height_m"]
FIVE_BAR = Path(__file__).resolve().parents[2] / "examples" / "architectures" / "five_bar.toml"
# (command, the arguments the parser requires, output option, suffix of the output's name: "" a folder)
OUTPUTS: list[tuple[str, list[str], str, str]] = [
    ("modes", [], "--plot", ".png"),
    ("modes", [], "--animate", ".gif"),
    ("export-mjcf", ["manipulator"], "--out", ".xml"),
    ("reproduce", [], "--out", ""),
    ("sweep", [], "--out", ""),
    ("sweep", ["--config", "{tmp}/imported.toml", "--poses", "{tmp}/joints.csv"], "--out", ""),
    ("rollout", [], "--out", ".csv"),
    ("rollout", [], "--plot", ".png"),
    ("reduce", ["--modes", "3"], "--out", ".npz"),
    ("transient", [], "--out", ""),
    ("move", [], "--out", ".csv"),
    ("move", [], "--plot", ".png"),
    ("frf", [], "--csv", ".csv"),
    ("frf", [], "--plot", ".png"),
    ("impact", [], "--csv", ".csv"),
    ("impact", [], "--uff", ".uff"),
    ("impact", [], "--plot", ".png"),
    ("readability", [], "--markdown", ".md"),
    ("readability", [], "--plot", ".png"),
    ("atlas build", [], "--out", ".npz"),
    ("atlas build", ["--out", "{tmp}/a.npz"], "--plot", ".png"),
    ("atlas query", ["{tmp}/in.npz"], "--out", ".npz"),
    ("design", VARY, "--out", ""),
    ("design", ["--config", str(FIVE_BAR), "--vary", "sections.bar.height_m=0.004"], "--out", ""),
    ("calibrate", ["--priors", "{tmp}/priors.toml", "--measured", "{tmp}/m.csv"], "--out", ""),
    (
        "calibrate",
        ["--config", str(FIVE_BAR), "--priors", "{tmp}/priors.toml", "--measured", "{tmp}/m.csv"],
        "--out",
        "",
    ),
    ("identify", ["--measured", "{tmp}/m.csv"], "--out", ""),
    ("identify", ["--config", str(FIVE_BAR), "--measured", "{tmp}/m.csv", *FREE_HEIGHT], "--out", ""),
    ("ema", ["{tmp}/frf.csv"], "--out", ""),
    ("check", ["{tmp}/req.toml"], "--junit-xml", ".xml"),
    ("check", ["{tmp}/req.toml"], "--plot", ".png"),
    ("plan-tests", [], "--out", ""),
    (
        "import",
        ["{tmp}/m.xml", "--flexible", "arm", "--section", "rect:25x6mm", "--material", "steel"],
        "--out",
        ".toml",
    ),
]
"""One case per output option of every command (checked against the parser)."""

# the readers of every input and the model compiler: none may run before the outputs are proven creatable
TRIPWIRES = {
    "fpm_sim.config.schema": ("load_config", "default_config"),
    "fpm_sim.architecture.reader": ("load_description",),
    "fpm_sim.model.spec": ("compile_model",),
    "fpm_sim.batch.pose_loop": ("read_poses_csv",),
    "fpm_sim.batch.joint_sweep": ("read_joint_poses_csv",),
    "fpm_sim.architecture.imported": ("load_imported",),
    "fpm_sim.designs.study": ("read_designs_csv",),
    "fpm_sim.study.identify.data": ("read_measured_csv", "read_subsystems_csv"),
    "fpm_sim.study.identify.ema": ("read_frfs",),
    "fpm_sim.study.calibrate.priors": ("read_priors",),
    "fpm_sim.study.requirements": ("load_requirements",),
    "fpm_sim.rom.atlas": ("load_atlas",),
    "fpm_sim.sim.trajectory": ("read_path_csv",),
}


class _Tripped(Exception):
    pass


def _import_all() -> None:
    """Import every module of the package (the optional backends and the dm_env wrapper aside, as the result
    contract's walk leaves them)."""
    import pkgutil

    import fpm_sim

    for mod in pkgutil.walk_packages(fpm_sim.__path__, "fpm_sim."):
        if not mod.name.endswith(("jax_backend", "mjx_backend", "dm_env")):
            importlib.import_module(mod.name)


def _output_options() -> set[tuple[str, str]]:
    """``(command, option)`` of every path-typed argument of the parser that is not an input."""
    found: set[tuple[str, str]] = set()

    def walk(parser: argparse.ArgumentParser, words: list[str]) -> None:
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    walk(sub, [*words, name])
            elif action.type is Path and action.dest not in INPUT_DESTS:
                found.add((" ".join(words), action.option_strings[0]))

    walk(build_parser(), [])
    return found


def test_every_output_option_has_a_case():
    cases = {(command, option) for command, _, option, _ in OUTPUTS}
    assert _output_options() <= cases, sorted(_output_options() - cases)


@pytest.fixture
def tripwires(monkeypatch):
    """Replace every input reader and the model compiler, wherever imported, by a function that raises.

    Every module of the package is imported first: a module imported for the first time while the tripwires are in
    place would bind a tripwire by ``from ... import`` and keep it after the test (a later test then trips on it)."""
    _import_all()
    originals = {}
    for module, names in TRIPWIRES.items():
        mod = importlib.import_module(module)
        for name in names:
            originals[id(getattr(mod, name))] = name

    def trip(name: str):
        def tripped(*args, **kwargs):
            raise _Tripped(f"{name} ran before the outputs were checked")

        return tripped

    for mod in [m for n, m in sys.modules.items() if n.startswith("fpm_sim") and m is not None]:
        for attr, value in list(vars(mod).items()):
            if id(value) in originals and not attr.startswith("__"):
                monkeypatch.setattr(mod, attr, trip(originals[id(value)]))
    from fpm_sim.study.posterior import Posterior

    monkeypatch.setattr(Posterior, "from_netcdf", classmethod(lambda cls, *a, **k: trip("from_netcdf")()))


def _run(argv: list[str]) -> tuple[int | str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code: int | str = main(argv)
        except _Tripped as exc:
            code = f"tripped: {exc}"
    return code, out.getvalue() + err.getvalue()


@pytest.mark.parametrize("place", ["proc", "under-a-file"])
@pytest.mark.parametrize(("command", "argv", "option", "suffix"), OUTPUTS, ids=[f"{c[0]} {c[2]}" for c in OUTPUTS])
def test_an_uncreatable_output_is_refused_before_anything_is_read(
    command, argv, option, suffix, place, tmp_path, tripwires
):
    (tmp_path / "afile").write_text("a file in the way of a folder")
    target = "/proc/x/y" if place == "proc" else f"{tmp_path}/afile/y"
    argv = [*command.split(), *(a.replace("{tmp}", str(tmp_path)) for a in argv), option, target + suffix]
    code, text = _run(argv)
    assert "Traceback" not in text, text
    assert code == 2, f"exit {code}: {text}"
    lines = text.strip().splitlines()
    assert len(lines) == 1, text
    assert lines[0].startswith("error: "), text
    assert f"{option}: cannot create {target}" in lines[0], lines[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"]  # nothing written
