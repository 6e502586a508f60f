"""Where each elbow-branch class of a finished calibration holds the two rotations (issue 31; docs/identification.md,
"Where the emulator missed, and a better one"): per class its draws and the 5/50/95 % points of the motors' and the
platform's rotations, and the share of the dominant class's draws within 5 deg of the motors' prior bounds.

    python studies/calibration_classes.py out/cal_e500/calibration.pkl
"""

from __future__ import annotations

import pickle
import sys
from pathlib import Path

import numpy as np

from fpm_sim.study.identify.problem import ELBOW_BRANCHES


def main(path: str) -> None:
    with Path(path).open("rb") as fh:
        cal = pickle.load(fh)  # the calibration's own output
    names = list(cal.names)
    base, plat = names.index("geometry.base_rotation_deg"), names.index("geometry.platform_rotation_deg")
    klass = np.rint(cal.draws[:, -1]).astype(int)
    for k in np.unique(klass):
        d = cal.draws[klass == k]
        qb, qp = (np.quantile(d[:, i], [0.05, 0.5, 0.95]) for i in (base, plat))
        print(f"{ELBOW_BRANCHES[k]!s:<14} {len(d):>5} draws; motors' rotation {qb.round(1)} deg, platform's "
              f"{qp.round(1)} deg")  # fmt: skip
    top = np.bincount(klass).argmax()
    rot = cal.draws[klass == top, base]
    print(f"dominant class {ELBOW_BRANCHES[top]}: {np.mean(rot < -55):.0%} of its draws below -55 deg, "
          f"{np.mean(rot > 55):.0%} above 55 deg")  # fmt: skip


if __name__ == "__main__":
    main(sys.argv[1])
