"""Pose-loop backends in one run: ``cpu`` (1 and 2 processes), ``jax`` and ``mjx`` (batched) (issues 5, 10).

(Was ``scripts/benchmark_backends.py``.) ``fast_options``: inextensible links, gravity off, 6 modes. The
parameter ``backend`` is the way; ``poses`` is the set: the study's 25 poses at 3 segments per link (the quick
set) or, with ``FPM_SIM_BENCH_FULL=1``, 400 reachable poses of the 5 mm dense grid at 6 segments. ``mjx`` (MJX's
own pipeline) compiles for about three minutes on a CPU, so it runs only with ``FPM_SIM_BENCH_FULL=1``.

- ``time_steady``: the second call, the batched backends' compiled function cached (their first call, in
  ``setup``, compiles); ``track_compile_s``: the first call's compile (``result.timings.compile_s``);
  ``track_max_rel_diff_vs_cpu``: the largest relative difference of the six frequencies against ``cpu``, 1
  process (round-off: the backends solve the same eigenproblem).
- ``Gradients``: ``jax_backend.frequency_gradients`` (d f_i / d p, three parameters, one pose) against central
  differences of the cpu path, once compiled; ``GradientAgreement`` compares the two.

Each benchmark runs in its own process: the cpu backend's workers are forked, and forking after JAX has started
its threads risks a deadlock, so no benchmark here mixes the two in one process before forking.
"""

from __future__ import annotations

import numpy as np

from benchmarks.common import reachable_poses, require_full

BACKENDS = ["cpu 1", "cpu 2", "jax", "mjx"]
POSE_SETS = ["study 25, 3 segments", "dense 400, 6 segments"]
N_MODES = 6
GRADIENT_PARAMETERS = ["section.thickness_m", "material.young_pa", "hardware.platform.mass_kg"]


def _problem(poses: str):
    from fpm_sim.batch.pose_loop import fast_options
    from fpm_sim.config import default_config
    from fpm_sim.study.poses import study_poses

    config = default_config()
    if poses.startswith("study"):
        return config, [p.pose for p in study_poses()], fast_options(segments=3)
    return config, reachable_poses(config, 400), fast_options(segments=6)


def _call(config, poses, opts, backend: str):
    from fpm_sim.batch.frequencies import pose_frequencies

    name, _, workers = backend.partition(" ")
    return pose_frequencies(config, poses, backend=name, workers=int(workers or 1), n_modes=N_MODES, options=opts)


class Backends:
    """One pose set through one backend (both parameters)."""

    params = [POSE_SETS, BACKENDS]
    param_names = ["poses", "backend"]
    number = 1
    repeat = (1, 5, 60.0)
    timeout = 900.0

    def setup(self, poses: str, backend: str) -> None:
        if backend == "mjx" or not poses.startswith("study"):
            require_full()
        self.config, self.poses, self.opts = _problem(poses)
        self.first = _call(self.config, self.poses, self.opts, backend)  # compiles (batched backends)

    def time_steady(self, poses: str, backend: str) -> None:
        _call(self.config, self.poses, self.opts, backend)

    def track_compile_s(self, poses: str, backend: str) -> float:
        timings = getattr(self.first, "timings", None)
        return float(getattr(timings, "compile_s", 0.0) or 0.0)

    track_compile_s.unit = "s"

    def track_max_rel_diff_vs_cpu(self, poses: str, backend: str) -> float:
        """Against a fresh ``cpu 1`` call (for ``cpu 1`` itself: its repeatability, exactly 0)."""
        ref = _call(self.config, self.poses, self.opts, "cpu 1")
        ok = np.isfinite(ref.frequencies_hz)
        if not np.array_equal(ok, np.isfinite(self.first.frequencies_hz)):
            raise AssertionError(f"{backend}: the computed poses differ from cpu's")
        return float(np.abs(self.first.frequencies_hz[ok] / ref.frequencies_hz[ok] - 1.0).max())

    track_max_rel_diff_vs_cpu.unit = "relative"

    def track_build_s(self, poses: str, backend: str) -> float:
        """Of a steady call of a batched backend: building the per-pose models (0 for cpu: not timed apart)."""
        timings = getattr(_call(self.config, self.poses, self.opts, backend), "timings", None)
        return float(getattr(timings, "build_s", 0.0) or 0.0)

    track_build_s.unit = "s"

    def track_run_s(self, poses: str, backend: str) -> float:
        """Of a steady call of a batched backend: the one batched linearisation and eigen-solve."""
        timings = getattr(_call(self.config, self.poses, self.opts, backend), "timings", None)
        return float(getattr(timings, "run_s", 0.0) or 0.0)

    track_run_s.unit = "s"


class Gradients:
    """d f_i / d p, 3 segments, at (50, -50, 0) mm (``frequency_gradients``) or at the computable study poses at
    once (``pose_frequency_gradients``, ``FPM_SIM_BENCH_FULL=1``): JAX (compiled in setup) or central differences
    of the cpu path (1 process)."""

    params = [["one pose", "study poses"], ["jax", "central differences"]]
    param_names = ["poses", "way"]
    number = 1
    repeat = (1, 5, 60.0)
    timeout = 600.0

    def setup(self, poses: str, way: str) -> None:
        from fpm_sim.batch.frequencies import pose_frequencies
        from fpm_sim.batch.pose_loop import fast_options
        from fpm_sim.config import default_config
        from fpm_sim.kinematics import Pose
        from fpm_sim.study.poses import study_poses

        self.config, self.opts = default_config(), fast_options(segments=3)
        if poses == "one pose":
            self.poses = [Pose.from_mm(50.0, -50.0, 0.0)]
        else:
            require_full()
            study = [p.pose for p in study_poses()]
            f1 = pose_frequencies(self.config, study, n_modes=N_MODES, options=self.opts).frequencies_hz[:, 0]
            self.poses = [p for p, f in zip(study, f1) if np.isfinite(f)]
        self.gradient = self._gradient(way)  # the first JAX call compiles

    def _gradient(self, way: str) -> np.ndarray:
        """(poses, modes, parameters)."""
        from fpm_sim.batch import jax_backend
        from fpm_sim.batch.frequencies import pose_frequencies
        from fpm_sim.config import parameter_value, with_parameter

        kw = {"n_modes": N_MODES, "options": self.opts}
        if way == "jax":
            if len(self.poses) == 1:
                res = jax_backend.frequency_gradients(self.config, self.poses[0], GRADIENT_PARAMETERS, **kw)
                return np.asarray(res.gradient)[None]
            res = jax_backend.pose_frequency_gradients(self.config, self.poses, GRADIENT_PARAMETERS, **kw)
            return np.stack([r.gradient for r in res])
        cols = []
        for name in GRADIENT_PARAMETERS:
            v = parameter_value(self.config, name)
            h = 1e-4 * v
            up, down = (
                pose_frequencies(with_parameter(self.config, name, v + s * h), self.poses, **kw)
                for s in (1.0, -1.0)
            )
            cols.append((up.frequencies_hz - down.frequencies_hz) / (2 * h))
        return np.stack(cols, axis=-1)

    def time_gradients(self, poses: str, way: str) -> None:
        self._gradient(way)


class GradientAgreement:
    """The JAX gradients against central differences of the cpu path (relative step 1e-4) at (50, -50, 0) mm."""

    timeout = 600.0

    def track_max_rel_diff_vs_central_differences(self) -> float:
        g = Gradients()
        g.setup("one pose", "jax")
        return float(np.abs(g.gradient / g._gradient("central differences") - 1.0).max())

    track_max_rel_diff_vs_central_differences.unit = "relative"
