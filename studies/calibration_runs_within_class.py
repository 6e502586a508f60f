"""Where a finished calibration's runs disagree inside one elbow-branch class (issue 31; docs/identification.md, "Twice
as fast, and the class weights in the check"): each run's own weighted draws of the class, from the ``.done`` files
the calibration leaves in its output folder, their weights' effective sample size and the 5/50/95 % points of the
parameters asked for:

    python studies/calibration_runs_within_class.py out/cal_fast --classes 5 2 \\
        --parameters geometry.distal_length_m geometry.platform_radius_m

Class indices are the ``classN`` of the file names (the study's priors: 5 is ``(-1, -1, 1) x3``, 2 is ``(1, 1, -1)
x3``).
"""

from __future__ import annotations

import argparse
import pickle
from pathlib import Path

import numpy as np

from fpm_sim.study.calibrate.problem import study_problem

QS = (0.05, 0.5, 0.95)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out", type=Path, help="a finished calibration's output folder")
    p.add_argument("--classes", type=int, nargs="+", default=[5])
    p.add_argument("--parameters", nargs="+", default=["geometry.distal_length_m", "geometry.platform_radius_m"])
    a = p.parse_args()
    names = study_problem().names
    cols = [names.index(n) for n in a.parameters]
    for k in a.classes:
        for done in sorted(a.out.glob(f"checkpoint.dynesty.class{k}.seed*.done")):
            with done.open("rb") as fh:
                run = pickle.load(fh)
            x, lw = np.asarray(run["samples"]), np.asarray(run["logwt"], float)
            w = np.exp(lw - lw.max())
            w /= w.sum()
            points = "; ".join(
                f"{n} {' / '.join(f'{v:.4g}' for v in np.quantile(x[:, c], QS, weights=w, method='inverted_cdf'))}"
                for n, c in zip(a.parameters, cols)
            )
            print(f"class {k}, {done.name.split('.')[-2]}: weights' ESS {1 / np.sum(w**2):.0f}; {points}")


if __name__ == "__main__":
    main()
