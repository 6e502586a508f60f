"""The figures and tables of docs/architectures.md: each example machine's first modes at its check poses and its
mode-1 map over the workspace (a horizontal slice for the Delta).

    python scripts/architecture_figures.py --out docs --workers 2

Writes ``docs/figures/architecture_<name>_f1.png`` and ``docs/results/architectures_modes.md``.
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

import fpm_sim as fs
from fpm_sim.linear.solvers import modes_constrained
from fpm_sim.model.general import build_general

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "architectures"
STEPS_MM = {"five_bar": 20.0, "delta": 30.0, "three_prr": 10.0, "serial_arm": 50.0}
BOX_MM = {"three_prr": 150.0}
"""A box (+- mm) for machines whose chains the reach box cannot bound (a prismatic joint on an unbounded rail)."""


def sweep(name: str, workers: int):
    desc = fs.load_description(EXAMPLES / f"{name}.toml")
    opts = fs.ModelOptions(fidelity="fast")
    if name not in BOX_MM:
        return fs.sweep(desc, step_mm=STEPS_MM[name], options=opts, workers=workers)
    from fpm_sim.batch.task_sweep import sweep_task

    half, step = BOX_MM[name], STEPS_MM[name]
    ticks = [k * step for k in range(-int(half / step), int(half / step) + 1)]
    poses = [fs.TaskPose.from_mm(x, y) for y in ticks for x in ticks]
    return sweep_task(desc, poses, options=opts, workers=workers, grid="dense", step_mm=step)


def modes_table(name: str, n_modes: int = 6) -> list[str]:
    desc = fs.load_description(EXAMPLES / f"{name}.toml")
    opts = fs.ModelOptions(gravity=False)  # standard resolution, 12 segments per link; gravity off (the spec)
    cols = [("phi_rad" if c == "phi" else f"{c}_mm") for c in desc.task]
    lines = [f"**{desc.name}** (12 segments per link, gravity off, constrained eigen-solve)", ""]
    lines.append("| " + " | ".join(cols) + " | " + " | ".join(f"f{k} (Hz)" for k in range(1, n_modes + 1)) + " |")
    lines.append("|" + "---|" * (len(cols) + n_modes))
    for p in desc.check_poses:
        pose = fs.TaskPose(p.get("x", 0.0), p.get("y", 0.0), p.get("z", 0.0), p.get("phi", 0.0))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            f = modes_constrained(build_general(desc, pose, opts), n_modes=n_modes).frequencies_hz
        vals = [f"{p[c]:g}" if c == "phi" else f"{p[c] * 1e3:g}" for c in desc.task]
        lines.append("| " + " | ".join(vals) + " | " + " | ".join(f"{v:.2f}" for v in f) + " |")
    return [*lines, ""]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--out", type=Path, default=Path("docs"))
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--sweeps", default=",".join(STEPS_MM), help="the machines whose maps to draw (comma-separated)")
    args = ap.parse_args()
    table = ["# First modes of the example architectures at their check poses", "",
             "Written by `python scripts/architecture_figures.py`; see docs/architectures.md.", ""]
    for name in STEPS_MM:
        table += modes_table(name)
    (args.out / "results" / "architectures_modes.md").write_text("\n".join(table))
    for name in [n for n in args.sweeps.split(",") if n]:
        sw = sweep(name, args.workers)
        sw.write_csv(args.out / "results" / f"architecture_{name}_sweep.csv")
        fig = sw.plot()
        fig.savefig(args.out / "figures" / f"architecture_{name}_f1.png", dpi=100)
        print(name, sw.table(), flush=True)


if __name__ == "__main__":
    main()
