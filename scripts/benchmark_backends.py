"""Pose-loop backends compared in one run: cpu (sequential and processes), jax and mjx (both batched).

For the study's 25 poses and for 400 reachable poses of a dense workspace grid, at the fast path's
resolution (default 6 segments per link, inextensible, gravity off), it times

* ``cpu``, 1 worker: per pose, build the MuJoCo model, ``mj_fullM``, weld Jacobian, SciPy eigen-solve;
* ``cpu``, ``--workers`` processes: the same, poses split between processes;
* ``jax``: build the per-pose models (CPU), then one jit-compiled, vmapped JAX linearisation (MuJoCo's
  formulas written in JAX, one ``lax.scan`` over bodies) and eigen-solve of all poses;
* ``mjx``: build the per-pose models, ``mjx.put_model`` each, stack, then one jit-compiled ``vmap`` of MJX's
  ``fwd_position`` (mass matrix, weld rows) and ``jax.jacfwd`` of its smooth forces, and the same eigen-solve.

For the batched backends the first call compiles (reported apart: ``result.timings``) and the second call
reuses the compiled function (steady state). It checks that the backends agree on the first six
frequencies and prints the ratios. With ``--gradients`` it also times
:func:`fpm_sim.batch.jax_backend.frequency_gradients` against central differences of the cpu path.

Usage: ``python scripts/benchmark_backends.py [--quick] [--segments 6] [--workers 2] [--n-dense 400]``
(``--quick``: the 25 study poses only, 3 segments per link: about a minute and a half).
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

from fpm_sim.batch.frequencies import pose_frequencies
from fpm_sim.batch.jax_backend import frequency_gradients, parameter_value, pose_frequency_gradients, with_parameter
from fpm_sim.batch.pose_loop import FAST_SEGMENTS, fast_options
from fpm_sim.config import default_config
from fpm_sim.kinematics import NearSingularityWarning, Pose, inverse_kinematics
from fpm_sim.study.poses import study_poses
from fpm_sim.study.sweep import dense_grid

BATCHED = ("jax", "mjx")


def reachable_poses(config, n: int) -> list:
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


def timed(config, poses, **kwargs):
    """``pose_frequencies(config, poses, **kwargs)`` and its wall time (s)."""
    t0 = time.perf_counter()
    out = pose_frequencies(config, poses, **kwargs)
    return out, time.perf_counter() - t0


def gradient_lines(config, opts, study, cpu_study, n_modes: int) -> None:
    """Time the JAX frequency gradients against central differences of the cpu path; print two lines."""
    kw = {"n_modes": n_modes, "options": opts}
    grad_names = ["section.thickness_m", "material.young_pa", "hardware.platform.mass_kg"]
    pose = Pose.from_mm(50.0, -50.0, 0.0)
    times, stages = [], []
    for _ in range(2):
        t0 = time.perf_counter()
        grad = frequency_gradients(config, pose, grad_names, n_modes=n_modes, options=opts)
        times.append(time.perf_counter() - t0)
        stages.append(", ".join(f"{k} {v:.3f} s" for k, v in grad.timings_s.items()))
    t0 = time.perf_counter()
    worst = 0.0
    for k, name in enumerate(grad_names):
        v = parameter_value(config, name)
        h = 1e-4 * v
        up = pose_frequencies(with_parameter(config, name, v + h), [pose], **kw)
        down = pose_frequencies(with_parameter(config, name, v - h), [pose], **kw)
        fd = (up.frequencies_hz[0] - down.frequencies_hz[0]) / (2 * h)
        worst = max(worst, float(np.abs(grad.gradient[:, k] / fd - 1).max()))
    t_fd = time.perf_counter() - t0
    print(
        f"gradients at (50, -50, 0) mm, {len(grad_names)} parameters: first call {times[0]:.2f} s "
        f"({stages[0]}), second {times[1]:.3f} s ({stages[1]}); cpu central differences {t_fd:.3f} s "
        f"(ratio {t_fd / times[1]:.2f}); max rel diff {worst:.1e}"
    )
    reachable = [p for p, f in zip(study, cpu_study.frequencies_hz[:, 0]) if np.isfinite(f)]
    times = []
    for _ in range(2):
        t0 = time.perf_counter()
        pose_frequency_gradients(config, reachable, grad_names, n_modes=n_modes, options=opts)
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--segments", type=int, default=None, help=f"per link (default {FAST_SEGMENTS}; 3 with --quick)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--n-dense", type=int, default=400)
    ap.add_argument("--modes", type=int, default=6)
    ap.add_argument("--quick", action="store_true", help="the 25 study poses only, 3 segments per link")
    ap.add_argument("--backends", default="jax,mjx", help="batched backends to time (comma-separated)")
    ap.add_argument("--gradients", action="store_true", help="also time the JAX frequency gradients")
    args = ap.parse_args()
    segments = args.segments or (3 if args.quick else FAST_SEGMENTS)
    batched = [b for b in args.backends.split(",") if b]
    for b in batched:
        if b not in BATCHED:
            ap.error(f"--backends: {b!r} is not one of {', '.join(BATCHED)}")
    config = default_config()
    opts = fast_options(segments=segments)
    sets = {"study poses": [p.pose for p in study_poses()]}
    if not args.quick:
        sets[f"dense grid ({args.n_dense})"] = reachable_poses(config, args.n_dense)
    print(f"segments {segments}, inextensible, gravity off, {args.modes} modes, cpu workers {args.workers}")
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
    header = (
        f"{'poses':<18}{'n':>5}{'backend':>8}{'build':>8}{'compile':>9}{'run':>8}{'1st (s)':>9}{'steady':>9}"
        f"{'cpu1/this':>10}{'par/this':>9}{'max rel diff vs cpu':>21}"
    )
    print(header)
    for label, poses in sets.items():
        (cpu1, t_cpu1), (cpup, t_cpup) = cpu[label]
        ok = np.isfinite(cpu1.frequencies_hz)
        same_par = np.allclose(cpup.frequencies_hz[ok], cpu1.frequencies_hz[ok], rtol=1e-12)
        print(
            f"{label:<18}{len(poses):>5}{'cpu 1':>8}{'':>8}{'':>9}{'':>8}{'':>9}{t_cpu1:>9.3f}{1.0:>10.2f}"
            f"{t_cpup / t_cpu1:>9.2f}{0.0:>21.1e}"
        )
        print(
            f"{label:<18}{len(poses):>5}{'cpu ' + str(args.workers):>8}{'':>8}{'':>9}{'':>8}{'':>9}{t_cpup:>9.3f}"
            f"{t_cpu1 / t_cpup:>10.2f}{1.0:>9.2f}{0.0:>21.1e}" + ("" if same_par else "  (cpu parallel differs!)")
        )
        for backend in batched:
            first, t_first = timed(config, poses, backend=backend, **kw)
            steady, t_steady = timed(config, poses, backend=backend, **kw)
            assert np.array_equal(ok, np.isfinite(steady.frequencies_hz)), f"{backend}: computed poses differ"
            diff = np.abs(steady.frequencies_hz[ok] / cpu1.frequencies_hz[ok] - 1).max()
            tm = steady.timings
            print(
                f"{label:<18}{len(poses):>5}{backend:>8}{tm.build_s:>8.3f}{first.timings.compile_s:>9.2f}"
                f"{tm.run_s:>8.3f}{t_first:>9.2f}{t_steady:>9.3f}{t_cpu1 / t_steady:>10.2f}"
                f"{t_cpup / t_steady:>9.2f}{diff:>21.1e}"
            )
    print(
        "steady: second call (compiled function cached); cpu1/this, par/this: steady-state time ratios "
        "(> 1: this backend faster). build: per-pose MuJoCo models (+ mjx.put_model and stacking for mjx), "
        "run: the one batched linearisation + eigen-solve; '1st' includes the compile."
    )
    if args.gradients:
        gradient_lines(config, opts, sets["study poses"], cpu["study poses"][0][0], args.modes)


if __name__ == "__main__":
    main()
