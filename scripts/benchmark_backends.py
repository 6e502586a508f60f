"""Pose-loop backends compared in one run: cpu sequential, cpu parallel (processes) and mjx (JAX, batched).

For the study's 25 poses and for 400 reachable poses of a dense workspace grid, at the fast path's
resolution (default 6 segments per link, inextensible, gravity off), it times

* ``cpu``, 1 worker: per pose, build the MuJoCo model, ``mj_fullM``, weld Jacobian, scipy eigen-solve;
* ``cpu``, ``--workers`` processes: the same, poses split between processes;
* ``mjx``: build the per-pose models (CPU), then one jit-compiled, vmapped JAX linearisation and eigen-solve
  of all poses. The first call compiles (reported apart); the second call reuses the compiled function
  (steady state);

checks that the backends agree on the first six frequencies, and prints the ratios; then times
:func:`fpm_sim.batch.jax_backend.frequency_gradients` (first call with its compile, second call) against central
differences of the cpu path, and prints their largest relative difference.

Usage: ``python scripts/benchmark_backends.py [--segments 6] [--workers 2] [--n-dense 400]``
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

from fpm_sim.batch.frequencies import pose_frequencies
from fpm_sim.batch.jax_backend import (
    LAST_TIMINGS,
    frequency_gradients,
    parameter_value,
    pose_frequency_gradients,
    with_parameter,
)
from fpm_sim.batch.pose_loop import FAST_SEGMENTS, fast_options
from fpm_sim.config import default_config
from fpm_sim.kinematics import NearSingularityWarning, Pose, inverse_kinematics
from fpm_sim.study.poses import study_poses
from fpm_sim.study.sweep import dense_grid


def reachable_poses(config, n: int) -> list:  # noqa: ANN001
    """``n`` reachable, non-singular poses spread evenly over a 5 mm dense grid (phi = 0)."""
    ok = []
    for p in dense_grid(config, step_mm=5.0):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", NearSingularityWarning)
                inverse_kinematics(config.geometry, p)
        except ValueError:
            continue
        ok.append(p)
    idx = np.linspace(0, len(ok) - 1, n).round().astype(int)
    return [ok[i] for i in idx]


def timed(config, poses, **kwargs):  # noqa: ANN001, ANN003, ANN201
    """``pose_frequencies(config, poses, **kwargs)`` and its wall time (s)."""
    t0 = time.perf_counter()
    out = pose_frequencies(config, poses, **kwargs)
    return out, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--segments", type=int, default=FAST_SEGMENTS)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--n-dense", type=int, default=400)
    ap.add_argument("--modes", type=int, default=6)
    args = ap.parse_args()
    config = default_config()
    opts = fast_options(segments=args.segments)
    sets = {
        "study poses": [p.pose for p in study_poses()],
        f"dense grid ({args.n_dense})": reachable_poses(config, args.n_dense),
    }
    print(f"segments {args.segments}, inextensible, gravity off, {args.modes} modes, cpu workers {args.workers}")
    header = (
        f"{'poses':<18}{'n':>5}{'cpu 1 (s)':>11}{'cpu par (s)':>12}{'mjx build':>11}{'compile':>9}{'run':>8}"
        f"{'mjx 1st':>9}{'mjx 2nd':>9}{'cpu1/mjx2':>10}{'par/mjx2':>9}{'max rel diff':>14}"
    )
    print(header)
    kw = {"n_modes": args.modes, "options": opts}
    # All cpu runs first: the cpu backend's worker processes are forked, and forking after JAX has
    # started its threads risks a deadlock (JAX warns about it).
    cpu = {
        label: (
            timed(config, poses, backend="cpu", workers=1, **kw),
            timed(config, poses, backend="cpu", workers=args.workers, **kw),
        )
        for label, poses in sets.items()
    }
    for label, poses in sets.items():
        (cpu1, t_cpu1), (cpup, t_cpup) = cpu[label]
        mjx1, t_mjx1 = timed(config, poses, backend="mjx", **kw)
        compile_s = LAST_TIMINGS.compile_s
        mjx2, t_mjx2 = timed(config, poses, backend="mjx", **kw)
        build_s, run_s = LAST_TIMINGS.build_s, LAST_TIMINGS.run_s
        ok = np.isfinite(cpu1.frequencies_hz)
        assert np.array_equal(ok, np.isfinite(mjx2.frequencies_hz)), "backends disagree on computed poses"
        diff = np.abs(mjx2.frequencies_hz[ok] / cpu1.frequencies_hz[ok] - 1).max()
        same_par = np.allclose(cpup.frequencies_hz[ok], cpu1.frequencies_hz[ok], rtol=1e-12)
        print(
            f"{label:<18}{len(poses):>5}{t_cpu1:>11.3f}{t_cpup:>12.3f}{build_s:>11.3f}{compile_s:>9.2f}{run_s:>8.3f}"
            f"{t_mjx1:>9.2f}{t_mjx2:>9.3f}{t_cpu1 / t_mjx2:>10.2f}{t_cpup / t_mjx2:>9.2f}{diff:>14.1e}"
            + ("" if same_par else "  (cpu parallel differs!)")
        )
    print(
        "cpu1/mjx2, par/mjx2: steady-state ratios (> 1: mjx faster). 'mjx 1st' includes the compile; "
        "'run' is the batched JAX linearisation + eigen-solve alone (build = per-pose MuJoCo models, CPU)."
    )
    grad_names = ["section.thickness_m", "material.young_pa", "hardware.platform.mass_kg"]
    pose = Pose.from_mm(50.0, -50.0, 0.0)
    times, stages = [], []
    for _ in range(2):
        t0 = time.perf_counter()
        grad = frequency_gradients(config, pose, grad_names, n_modes=args.modes, options=opts)
        times.append(time.perf_counter() - t0)
        stages.append(", ".join(f"{k} {v:.3f} s" for k, v in grad.timings_s.items()))
    t0 = time.perf_counter()
    worst = 0.0
    for k, name in enumerate(grad_names):
        v = parameter_value(config, name)
        h = 1e-4 * v
        up = pose_frequencies(with_parameter(config, name, v + h), [pose], n_modes=args.modes, options=opts)
        down = pose_frequencies(with_parameter(config, name, v - h), [pose], n_modes=args.modes, options=opts)
        fd = (up.frequencies_hz[0] - down.frequencies_hz[0]) / (2 * h)
        worst = max(worst, float(np.abs(grad.gradient[:, k] / fd - 1).max()))
    t_fd = time.perf_counter() - t0
    print(
        f"gradients at (50, -50, 0) mm, {len(grad_names)} parameters: first call {times[0]:.2f} s "
        f"({stages[0]}), second {times[1]:.3f} s ({stages[1]}); cpu central differences {t_fd:.3f} s "
        f"(ratio {t_fd / times[1]:.2f}); max rel diff {worst:.1e}"
    )
    study = sets["study poses"]
    reachable = [p for p, f in zip(study, cpu["study poses"][0][0].frequencies_hz[:, 0]) if np.isfinite(f)]
    times = []
    for _ in range(2):
        t0 = time.perf_counter()
        pose_frequency_gradients(config, reachable, grad_names, n_modes=args.modes, options=opts)
        times.append(time.perf_counter() - t0)
    t0 = time.perf_counter()
    for name in grad_names:
        v = parameter_value(config, name)
        for sign in (1.0, -1.0):
            pose_frequencies(with_parameter(config, name, v * (1 + sign * 1e-4)), reachable, **kw)
    t_fd = time.perf_counter() - t0
    print(
        f"gradients at the {len(reachable)} computable study poses: first call {times[0]:.2f} s, second "
        f"{times[1]:.3f} s; cpu central differences (1 worker) {t_fd:.3f} s (ratio {t_fd / times[1]:.2f})"
    )


if __name__ == "__main__":
    main()
