"""Benchmark: the virtual impact test on the model's own step vs MuJoCo's discrete integrator at larger steps.

The model's own integrator (``implicitfast``) integrates the spring hinges explicitly, so its automatic step is
set by the stiffest spring's highest (discretisation) mode and shrinks as ``1 / segments^2``. The ``discrete``
integrator (the default since issue 21; ``ImpactSetup.timestep_s``, ``fpm-sim impact --implicit-step-s`` set its
step) treats springs and welds implicitly, stable at any step. For each step: wall time of one impact
(``--record-s``), the ratio to the model's own step, and what the EMA (sdypy-EMA LSCF, as ``fpm-sim ema``:
the window's decay and the discrete step's numerical damping removed) reads from each FRF, in-plane
(hammer normal to distal_0 at mid-span) and out-of-plane (along z), against the nearest modal frequency of the
same model (its mode number in brackets), with the damping it reads.

    python scripts/benchmark_impact_timestep.py [--segments 12] [--record-s 0.5] [--steps-s 1e-5 2e-5]
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

import fpm_sim  # noqa: F401  (single-threaded BLAS)
from fpm_sim.batch.frequencies import pose_frequencies
from fpm_sim.config import default_config
from fpm_sim.kinematics import Pose
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import ModelOptions
from fpm_sim.response import LinkPoint
from fpm_sim.rom.reduction import modal_system
from fpm_sim.sim.impact import ImpactSetup, virtual_impact_test
from fpm_sim.study.identify.ema import MeasuredFrf, estimate_modes


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--segments", type=int, default=12)
    ap.add_argument("--record-s", type=float, default=0.5)
    ap.add_argument("--steps-s", type=float, nargs="+", default=[1e-5, 2e-5])
    ap.add_argument("--pose-mm", type=float, nargs=3, default=[0.0, 0.0, 0.2], metavar=("X", "Y", "PHI_RAD"))
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    manip, pose = default_config(), Pose.from_mm(*args.pose_mm)
    opts = ModelOptions(segments=args.segments, axial=False, gravity=False)
    built = build_manipulator(manip, pose, opts)
    system = modal_system(built)
    f_modal = pose_frequencies(manip, [pose], n_modes=8, options=opts).frequencies_hz[0]
    print(
        f"{args.segments} segments, nv {built.model.nv}, model step {built.timestep_s:.3g} s; modal frequencies "
        f"{', '.join(f'{v:.3f}' for v in f_modal[:6])} Hz; record {args.record_s:g} s"
    )
    head = ("integrator", "step (s)", "axis", "wall (s)", "speed-up", "EMA f err", "EMA zeta")
    print(f"{head[0]:<14} " + " ".join(f"{h:>9}" for h in head[1:]))
    base_wall: dict[str, float] = {}
    for h in [None, *args.steps_s]:
        for axis in ("normal", "z"):
            p = LinkPoint("distal_0", 0.5, axis)
            setup = ImpactSetup(
                impact=p,
                accelerometer=p,
                record_s=args.record_s,
                n_impacts=1,
                f_max_hz=400.0,
                timestep_s=h,
                integrator="explicit" if h is None else "discrete",
            )
            t0 = time.perf_counter()
            res = virtual_impact_test(built, setup, system=system)
            wall = time.perf_counter() - t0
            base_wall.setdefault(axis, wall)
            est = estimate_modes(
                MeasuredFrf(res.frf.freq_hz, res.frf.h, axis, None, res.window_tau_s, res.discrete_step_s),
                f_lower_hz=20.0,
                f_upper_hz=400.0,
                n_modes=1,
            )
            k = int(np.argmin(np.abs(f_modal - est.freq_hz[0])))
            print(
                f"{res.parameters['rollout_integrator'].removeprefix('mjINT_'):<14} "
                f"{res.parameters['rollout_timestep_s']:>9.3g} {axis:>6} {wall:>9.2f} {base_wall[axis] / wall:>8.1f}x "
                f"{100 * (est.freq_hz[0] / f_modal[k] - 1):>+9.4f}% ({k + 1}) {est.damping[0]:>9.4f}"
            )


if __name__ == "__main__":
    main()
