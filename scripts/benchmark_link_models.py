"""Time per manipulator pose for each link model at its default resolution, as ratios to ``segments``.

One pose = build + static equilibrium + ``mjd_transitionFD`` linearisation + eigen-decomposition
(``modes_transition_fd``). Each model is timed ``--repeat`` times, the minimum is kept (the machine is
shared). Run: ``nice python scripts/benchmark_link_models.py``.
"""

from __future__ import annotations

import argparse
import time
import warnings

from fpm_sim.config import default_config
from fpm_sim.kinematics import Pose
from fpm_sim.linear.modal import modes_transition_fd
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import ModelOptions
from fpm_sim.model.parts import DEFAULT_RESOLUTION


def time_pose(link_model: str, pose: Pose) -> tuple[float, int, float]:
    """Wall time (s), nv and first frequency (Hz) of one pose."""
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # flex's SectionWarning / DampingWarning (docs/link_models.md)
        built = build_manipulator(default_config(), pose, ModelOptions(link_model=link_model))
        f1 = modes_transition_fd(built, n_modes=1).frequencies_hz[0]
    return time.perf_counter() - t0, built.model.nv, f1


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeat", type=int, default=3)
    args = p.parse_args()
    pose = Pose.from_mm(0.0, 0.0, 0.0)
    rows = {}
    for lm in ("segments", "cable", "flex"):
        runs = [time_pose(lm, pose) for _ in range(args.repeat)]
        rows[lm] = (min(r[0] for r in runs), runs[0][1], runs[0][2])
    base = rows["segments"][0]
    print(f"{'model':>9} {'n':>3} {'nv':>4} {'f1 (Hz)':>8} {'s/pose':>7} {'ratio':>6}")
    for lm, (t, nv, f1) in rows.items():
        print(f"{lm:>9} {DEFAULT_RESOLUTION[lm]:>3} {nv:>4} {f1:>8.2f} {t:>7.2f} {t / base:>6.2f}")


if __name__ == "__main__":
    main()
