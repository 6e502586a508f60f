"""Input shaping on the default machine: the default move (0 -> 30 mm in x in 0.3 s, minimum jerk, 0.3 s of
settling) at the default fidelity, unshaped, ZV and ZVD (designed at the end pose's dominant in-plane mode).

Prints each run's wall time, residual vibration peak, settling time and dominant frequency against the modal f1,
and draws the three residuals into one figure (``docs/figures/move_input_shaping.png`` by default).

    nice -n 10 python scripts/move_shaping.py [--segments 12] [--figure docs/figures/move_input_shaping.png]
"""

from __future__ import annotations

import argparse
import math
import time
import warnings
from pathlib import Path

import numpy as np

import fpm_sim  # noqa: F401  (single-threaded BLAS)
from fpm_sim.config import default_config
from fpm_sim.kinematics import Pose
from fpm_sim.model.options import ModelOptions
from fpm_sim.sim.trajectory import MovePath, simulate_move


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--segments", type=int, default=None, help="default: the standard fidelity (12)")
    ap.add_argument("--figure", type=Path, default=Path("docs/figures/move_input_shaping.png"))
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    opts = ModelOptions(segments=args.segments, axial=False)
    path = MovePath(Pose(0.0, 0.0, 0.0), Pose.from_mm(30.0, 0.0, 0.0), 0.3)
    fig, axes = plt.subplots(2, 1, figsize=(9, 6.5))
    print(
        f"{'shaper':<7} {'wall (s)':>9} {'sim (s)':>8} {'move (ms)':>9} {'peak (mm)':>10} {'settle (ms)':>11} "
        f"{'dominant (Hz)':>13} {'modal f1 (Hz)':>13}"
    )
    peaks = {}
    for kind in ("none", "zv", "zvd"):
        t0 = time.perf_counter()
        res = simulate_move(default_config(), path, options=opts, shaper_kind=kind)
        wall = time.perf_counter() - t0
        r = res.residual
        peaks[kind] = r.peak_m
        settle = f"{r.settling_time_s * 1e3:.0f}" if math.isfinite(r.settling_time_s) else "> record"
        print(
            f"{kind:<7} {wall:>9.1f} {res.t_s[-1]:>8.3f} {res.move_end_s * 1e3:>9.1f} {r.peak_m * 1e3:>10.4f} "
            f"{settle:>11} {r.dominant_hz:>13.2f} {r.modal_f1_hz:>13.2f}"
        )
        err = np.linalg.norm(res.tracking_error[:, :2], axis=1)
        axes[0].plot(res.t_s * 1e3, err * 1e3, lw=1, label=f"{kind} (move ends {res.move_end_s * 1e3:.0f} ms)")
        after = res.t_s >= res.move_end_s
        resid = np.linalg.norm(res.tracking_error[:, :2] - r.final_offset_m, axis=1)
        axes[1].plot(
            (res.t_s[after] - res.move_end_s) * 1e3,
            resid[after] * 1e3,
            lw=1,
            label=f"{kind}: peak {r.peak_m * 1e3:.3f} mm",
        )
    print(
        f"residual peak ratio: ZV / none {peaks['zv'] / peaks['none']:.3f}, "
        f"ZVD / none {peaks['zvd'] / peaks['none']:.3f}"
    )
    print(res.stepping.line() if res.stepping else "")
    axes[0].set_xlabel("t (ms)")
    axes[0].set_ylabel("|pose - command| (mm)")
    axes[0].set_title(
        f"default machine, {opts.segments} segments: 30 mm in 0.3 s (minimum jerk), servos "
        f"{res.parameters['servo_stiffness_nm_per_rad']:g} N m/rad",
        fontsize=9,
    )
    axes[0].legend(fontsize=8)
    axes[1].set_xlabel("time after the move (ms)")
    axes[1].set_ylabel("residual vibration (mm)")
    axes[1].set_yscale("log")
    axes[1].set_title(
        f"residual after the move, shaped for the end pose's in-plane mode ({r.inplane_mode_hz:.2f} Hz)", fontsize=9
    )
    axes[1].legend(fontsize=8)
    fig.tight_layout()
    args.figure.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.figure, dpi=110)
    print(f"wrote {args.figure}")


if __name__ == "__main__":
    main()
