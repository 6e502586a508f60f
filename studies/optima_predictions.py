"""Predicted f1 of several identified descriptions at the study's six withheld poses, and their spread.

    python studies/optima_predictions.py out/identify_study out/id_hub2_s0 out/id_rand_s1 ...

Each argument is an ``fpm-sim identify`` output folder (its ``config.toml`` and ``identify.json``). Competing
optima that fit the data about equally well can predict unmeasured poses very differently; this prints, per
withheld pose (the study's reading ``x+``, 12 segments as ``fpm-sim reproduce``), every description's f1 and
the median absolute deviation from the ensemble's median: where it is small the data pin the prediction down,
where it is large they do not. It reads no measurement at those poses (the project does not have them)."""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path

import numpy as np

from fpm_sim.batch.frequencies import pose_frequencies
from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.config import load_config
from fpm_sim.kinematics import NearSingularityWarning
from fpm_sim.study.poses import parse_reading, study_poses
from fpm_sim.study.tables import withheld_cells


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folders", nargs="+", type=Path, help="fpm-sim identify output folders")
    ap.add_argument("--segments", type=int, default=12)
    args = ap.parse_args()
    for f in args.folders:
        if not (f / "config.toml").is_file() or not (f / "identify.json").is_file():
            print(f"error: {f} is not an fpm-sim identify output folder (config.toml, identify.json)", file=sys.stderr)
            return 2
    cells = set(withheld_cells())
    sp = [p for p in study_poses(parse_reading("x+")) if (p.row_mm, p.col_mm) in cells]
    print("description".ljust(28) + "cost " + "".join(f"{f'({p.row_mm:g},{p.col_mm:g})':>12}" for p in sp))
    rows = []
    for f in args.folders:
        cost = json.loads((f / "identify.json").read_text())["result"]["cost"]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NearSingularityWarning)
            pf = pose_frequencies(
                load_config(f / "config.toml"),
                [p.pose for p in sp],
                n_modes=1,
                options=fast_options(segments=args.segments),
            )
        rows.append(pf.frequencies_hz[:, 0])
        print(f"{str(f)[-27:]:<28}{cost:4.0f} " + "".join(f"{v:12.1f}" for v in rows[-1]))
    a = np.array(rows)
    med = np.median(a, axis=0)
    print(
        "median |deviation| from the median, %".ljust(33)
        + "".join(f"{v:12.1f}" for v in 100 * np.median(np.abs(a / med - 1), axis=0))
    )
    print("max / min - 1, %".ljust(33) + "".join(f"{v:12.0f}" for v in 100 * (a.max(0) / a.min(0) - 1)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
