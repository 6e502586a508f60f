"""Render every figure the commands make into one folder, to look at them as a reader would.

    nice python scripts/render_figures.py --out out/figures [--only reproduce,sweep_paper] [--list]

Each step runs one ``fpm-sim`` command in this process (the same code path as the command line) and copies
its figures into ``OUT`` as ``<step>__<file>.png``; at the end it lists every PNG with its size and the seconds
each step took. The commands run at their defaults where that takes seconds; where a default takes minutes the
step says so and uses a smaller setting (in ``STEPS``, column ``why``), so the figures show what the defaults
draw, at a resolution that differs only in the numbers. A step that fails is reported and the others still run
(exit code 1 at the end).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import shutil
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from fpm_sim.cli.main import main as cli_main


@dataclass(frozen=True)
class Step:
    """One command and the figures it writes (relative to its work folder ``{w}``)."""

    name: str
    argv: list[str]
    figures: list[str]
    why: str = "the command's defaults"


def steps() -> list[Step]:
    """The figures of every command (``{w}`` in an argument: the step's work folder)."""
    from importlib import resources

    data = resources.files("fpm_sim.data")
    measured = str(data.joinpath("measured_table4_train.csv"))
    return [
        Step("reproduce", ["reproduce", "--out", "{w}/rep"], ["rep/heatmaps.png", "rep/subsystems.png"]),
        Step(
            "reproduce_5mm",
            ["reproduce", "--thickness-mm", "5", "--fidelity", "fast", "--out", "{w}/rep5"],
            ["rep5/heatmaps.png", "rep5/subsystems.png"],
            "fidelity fast (8 segments): the 5 mm variant, whose figure shows no COMSOL comparison",
        ),
        Step("sweep_paper", ["sweep", "--grid", "paper", "--out", "{w}/sw"], ["sw/sweep_paper.png"]),
        Step("sweep_dense", ["sweep", "--grid", "dense", "--out", "{w}/swd"], ["swd/sweep_dense.png"]),
        Step(
            "design",
            [
                "design",
                "--vary",
                "section.thickness_m=0.005:0.03:6",
                "--vary",
                "hardware.payload.mass_kg=0:1:3",
                "--grid",
                "dense",
                "--step-mm",
                "40",
                "--segments",
                "4",
                "--f-min-hz",
                "40",
                "--out",
                "{w}/design",
            ],
            ["design/design_min_f1.png", "design/design_maps.png", "design/design_tradeoff.png"],
            "the README's design study (18 designs) at --step-mm 40 and 4 segments instead of 10 mm / 12 (18 dense "
            "sweeps, 13 s each measured here: minutes)",
        ),
        Step(
            "modes",
            ["modes", "--x-mm", "50", "--y-mm", "-50", "--n-modes", "3", "--plot", "{w}/modes.png"],
            ["modes.png"],
        ),
        Step(
            "frf",
            ["frf", "--x-mm", "50", "--input-axis", "z", "--csv", "{w}/frf.csv", "--plot", "{w}/frf.png"],
            ["frf.png"],
        ),
        Step(
            "impact",
            ["impact", "--segments", "4", "--record-s", "0.2", "--plot", "{w}/impact.png"],
            ["impact.png"],
            "4 segments instead of the default 12 (40 min of CPU per simulated second at 12, README)",
        ),
        Step("readability", ["readability", "--plot", "{w}/readability.png"], ["readability.png"]),
        Step(
            "atlas",
            ["atlas", "build", "--fidelity", "fast", "--out", "{w}/atlas.npz", "--plot", "{w}/atlas.png"],
            ["atlas.png"],
            "fidelity fast (8 segments) instead of standard (61 s measured here)",
        ),
        Step(
            "rollout",
            [
                "rollout",
                "--thickness-mm",
                "5",
                "--fidelity",
                "fast",
                "--no-axial",
                "--force-x-n",
                "10",
                "--out",
                "{w}/r.csv",
                "--plot",
                "{w}/rollout.png",
            ],
            ["rollout.png"],
            "the README's example (fidelity fast)",
        ),
        Step(
            "transient",
            ["transient", "--study", "--segments", "4", "--out", "{w}/transient"],
            ["transient/transient.png"],
            "4 segments instead of 12 (about 5 min at 12, README)",
        ),
        Step(
            "identify",
            [
                "identify",
                "--measured",
                f"{measured},sigma_pct=2",
                "--reading",
                "x+",
                "--free",
                "hardware",
                "--global",
                "none",
                "--max-nfev",
                "5",
                "--segments",
                "4",
                "--out",
                "{w}/ident",
            ],
            ["ident/measured_vs_predicted.png", "ident/residuals_workspace.png"],
            "a local fit of the hardware masses only (5 evaluations, 4 segments): the figures' form, not the "
            "study's fit",
        ),
    ]


def run_step(step: Step, work: Path, out: Path) -> tuple[float, list[Path], str]:
    """Run ``step`` in ``work``; copy its figures to ``out``. Returns seconds, the copies and an error ('' if ok)."""
    argv = [a.replace("{w}", str(work)) for a in step.argv]
    t0 = time.perf_counter()
    buf = io.StringIO()
    try:
        with contextlib.redirect_stdout(buf):
            rc = cli_main(argv)
    except SystemExit as exc:  # argparse errors
        rc = int(exc.code or 0)
    seconds = time.perf_counter() - t0
    if rc:
        return seconds, [], f"exit code {rc}: {' '.join(argv)}"
    copies, missing = [], []
    for f in step.figures:
        src = work / f
        if not src.is_file():
            missing.append(f)
            continue
        dst = out / f"{step.name}__{src.name}"
        shutil.copyfile(src, dst)
        copies.append(dst)
    return seconds, copies, f"missing {', '.join(missing)}" if missing else ""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("out/figures"), help="folder for the PNGs (default out/figures)")
    ap.add_argument("--only", default="", help="comma-separated step names (default: all)")
    ap.add_argument("--list", action="store_true", help="list the steps and their settings, run nothing")
    args = ap.parse_args()
    todo = steps()
    if args.list:
        for s in todo:
            print(f"{s.name:<15} fpm-sim {' '.join(s.argv)}\n{'':<15} ({s.why})")
        return 0
    if args.only:
        names = set(args.only.split(","))
        unknown = names - {s.name for s in todo}
        if unknown:
            print(f"error: unknown step(s) {', '.join(sorted(unknown))} (--only); see --list", file=sys.stderr)
            return 2
        todo = [s for s in todo if s.name in names]
    args.out.mkdir(parents=True, exist_ok=True)
    failed = 0
    with tempfile.TemporaryDirectory(prefix="fpm_figures_") as tmp:
        for s in todo:
            work = Path(tmp) / s.name
            work.mkdir()
            seconds, copies, error = run_step(s, work, args.out)
            status = "FAILED " + error if error else ", ".join(p.name for p in copies)
            failed += bool(error)
            print(f"{s.name:<15} {seconds:7.1f} s  {status}  [{s.why}]", flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
