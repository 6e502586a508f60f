"""The ``jax`` pose-loop backend and frequency gradients, both in JAX (imported lazily).

``pose_frequencies(config, poses, backend="jax")`` builds the per-pose MuJoCo models on the CPU (as the
``cpu`` backend does), stacks their array fields and linearises and solves all poses in one
``jit``-compiled, ``vmap``-ped JAX computation (:mod:`fpm_sim.batch.jax_linearisation`: MuJoCo's formulas
written in JAX over the model arrays, with one ``lax.scan`` over bodies; not MJX, which is the ``mjx``
backend, :mod:`fpm_sim.batch.mjx_backend`): the same constrained eigenproblem as the ``cpu`` backend
(gravity off, at ``qpos0``, ``K`` from the joint springs, here by ``jax.jacfwd``), so the two agree to
round-off.

:func:`frequency_gradients` returns ``d f_i / d p`` for link thickness, Young's modulus and hardware
masses (:data:`GRADIENT_PARAMETERS`; any name of the form ``hardware.<part>.mass_kg``), by the modal
sensitivity formula on JAX tangents of ``M`` and ``K``.

Process hygiene: importing this module imports neither JAX nor MuJoCo's MJX; JAX's float64 mode is
switched on only inside the backend calls (:func:`x64`), never process-wide; compiled functions are kept in
bounded least-recently-used caches (:class:`CompileCache`); each call's timings are returned in its
result (:class:`TimedPoseFrequencies`), not in a module global.

The names of the release in which this backend was called ``mjx`` (``mjx_pose_frequencies``,
``MjxTimings``) still resolve, with a :class:`DeprecationWarning`, for one release.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import time
import warnings
from collections import OrderedDict
from collections.abc import Callable, Hashable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np

from fpm_sim.batch.pose_loop import (
    IN_PLANE_KINDS,
    STATUS_SINGULAR,
    PoseFrequencies,
    assemble_pose,
    fast_options,
)
from fpm_sim.config import Manipulator, parameter_value, with_parameter
from fpm_sim.errors import FpmSimError, FpmSimWarning
from fpm_sim.kinematics import Pose
from fpm_sim.linear.nullspace import constraint_rank
from fpm_sim.model.options import ModelOptions
from fpm_sim.model.spec import BuiltModel

__all__ = [
    "GRADIENT_PARAMETERS",
    "AssembledPoses",
    "BackendTimings",
    "BatchSolver",
    "CompileCache",
    "FrequencyGradients",
    "TimedPoseFrequencies",
    "assemble_poses",
    "batched_pose_frequencies",
    "check_options",
    "frequencies_from_modes",
    "frequency_gradients",
    "jax_pose_frequencies",
    "pose_frequency_gradients",
    "solve_jax_models",
    "x64",
]

COMPILE_CACHE_SIZE = 8
"""Compiled functions kept per cache (model structure x batch size x mode count); older ones are dropped."""


class CompileCache:
    """Compiled functions by hashable key, at most ``maxsize`` kept (the least recently used is dropped).

    Parameters
    ----------
    maxsize
        Entries kept (>= 1).
    """

    def __init__(self, maxsize: int = COMPILE_CACHE_SIZE) -> None:
        if maxsize < 1:
            raise FpmSimError(f"maxsize must be >= 1, got {maxsize}")
        self.maxsize = maxsize
        self._entries: OrderedDict[Hashable, Any] = OrderedDict()

    def __len__(self) -> int:
        return len(self._entries)

    def clear(self) -> None:
        """Drop every entry."""
        self._entries.clear()

    def get(self, key: Hashable, make: Callable[[], Any]) -> tuple[Any, float]:
        """The entry for ``key`` (made by ``make()`` if absent) and the seconds ``make`` took (0 if cached)."""
        if key in self._entries:
            self._entries.move_to_end(key)
            return self._entries[key], 0.0
        t0 = time.perf_counter()
        value = make()
        elapsed = time.perf_counter() - t0
        self._entries[key] = value
        while len(self._entries) > self.maxsize:
            self._entries.popitem(last=False)
        return value, elapsed


_MODES_CACHE = CompileCache()
_GRADIENTS_CACHE = CompileCache()


@contextlib.contextmanager
def x64() -> Iterator[None]:
    """Context in which JAX computes in float64 (``jax.enable_x64``), restored on exit.

    The backends run inside it, so that a caller's process keeps its own ``jax_enable_x64`` setting.
    With the environment variable ``FPM_SIM_JAX_CACHE_DIR`` set (and no cache directory configured by
    the caller), JAX's persistent compilation cache is used there: measured on the 25 study poses, a
    second process's compile step took 2.5 s instead of 5.2 s (tracing and lowering remain).
    """
    import jax

    cache_dir = os.environ.get("FPM_SIM_JAX_CACHE_DIR")
    # opt-in, never over the caller's own choice; jax's Config stub does not declare its options as attributes
    if cache_dir and not jax.config.jax_compilation_cache_dir:  # type: ignore[attr-defined]
        jax.config.update("jax_compilation_cache_dir", cache_dir)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
    with jax.enable_x64(True):
        yield


@dataclass
class BackendTimings:
    """Wall times (s) of one batched backend call, by stage.

    Attributes
    ----------
    build_s
        Per-pose MuJoCo models and their arrays (CPU, Python).
    compile_s
        XLA compile (0 when the compiled function was cached).
    run_s
        The batched linearisation and eigen-solve.
    poses
        Poses solved (reachable and not singular).
    """

    build_s: float = 0.0
    compile_s: float = 0.0
    run_s: float = 0.0
    poses: int = 0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready copy."""
        return dataclasses.asdict(self)


@dataclass
class TimedPoseFrequencies(PoseFrequencies):
    """:class:`~fpm_sim.batch.pose_loop.PoseFrequencies` with the call's :class:`BackendTimings`."""

    timings: BackendTimings = field(default_factory=BackendTimings)


def check_options(options: ModelOptions, backend: str) -> None:
    """Refuse options the batched backends do not linearise (gravity on, a link model other than segments).

    Raises
    ------
    FpmSimError
        Naming the option and the fix.
    """
    if options.gravity:
        raise FpmSimError(
            f"the {backend} backend linearises at qpos0 with gravity off, like the cpu backend; "
            "use fast_options() or ModelOptions(gravity=False)"
        )
    if options.link_model != "segments":
        raise FpmSimError(
            f"the {backend} backend needs link_model 'segments'", parameter="link_model", value=options.link_model
        )


@dataclass
class AssembledPoses:
    """The per-pose models of a batched backend call (built on the CPU).

    Attributes
    ----------
    poses
        All poses, in order.
    built
        The built model of each pose, ``None`` where unreachable or singular.
    singularity
        Singularity measure of each pose.
    status
        Status of each pose (``ok``, ``near_singular``, ``singular``, ``unreachable``).
    """

    poses: list[Pose]
    built: list[BuiltModel | None]
    singularity: np.ndarray
    status: list[str]

    @property
    def ok(self) -> list[int]:
        """Indices of the poses with a model."""
        return [i for i, b in enumerate(self.built) if b is not None]


def assemble_poses(
    config: Manipulator, poses: Sequence[Pose], options: ModelOptions, *, progress: bool = False, desc: str = "poses"
) -> AssembledPoses:
    """Build the model of every pose (:func:`~fpm_sim.batch.pose_loop.assemble_pose`), sequentially.

    Raises
    ------
    FpmSimError
        If the models are not unstressed at ``qpos0`` (springs at rest), which the batched backends assume.
    """
    poses = list(poses)
    built: list[BuiltModel | None] = []
    sing = np.full(len(poses), math.nan)
    status: list[str] = []
    iterator: Any = poses
    if progress:
        from tqdm.auto import tqdm

        iterator = tqdm(poses, desc=f"{desc} (build)", unit="pose")
    for i, p in enumerate(iterator):
        b, sing[i], st = assemble_pose(config, p, options)
        built.append(b)
        status.append(st)
    if not all(np.array_equal(b.model.qpos0, b.model.qpos_spring) for b in built if b is not None):
        raise FpmSimError("the batched backends need springs at rest at qpos0 (an unstressed assembled pose)")
    return AssembledPoses(poses=poses, built=built, singularity=sing, status=status)


def frequencies_from_modes(
    assembled: AssembledPoses,
    w2: np.ndarray,
    shapes: np.ndarray,
    k_diag: np.ndarray,
    sv_ratio: np.ndarray,
    *,
    n_modes: int,
    timings: BackendTimings,
) -> TimedPoseFrequencies:
    """The pose-loop result from the batched eigen-solve of the poses ``assembled.ok`` (in that order).

    ``w2`` ``(B, n)`` eigenvalues (rad^2/s^2), ``shapes`` ``(B, nv, n)`` full-space M-normalised modes,
    ``k_diag`` ``(B, nv)`` spring stiffness per dof (strain energy of the mode character), ``sv_ratio``
    ``(B,)`` smallest-to-largest singular value of the weld Jacobian (unscaled; kept for diagnostics). A pose
    whose weld Jacobian is rank-deficient in consistent units (:func:`fpm_sim.linear.nullspace.constraint_rank`)
    is reported ``singular`` with NaN frequencies and a warning.
    """
    poses, status = assembled.poses, list(assembled.status)
    ok = assembled.ok
    freq = np.full((len(poses), n_modes), np.nan)
    frac = np.full((len(poses), n_modes), np.nan)
    n = w2.shape[1] if len(ok) else 0
    if ok:
        first = assembled.built[ok[0]]
        assert first is not None
        inplane = np.array([kind in IN_PLANE_KINDS for kind in first.dof_kinds])
        for r, i in enumerate(ok):
            built_i = assembled.built[i]
            assert built_i is not None
            rank_data = mujoco.MjData(built_i.model)
            mujoco.mj_forward(built_i.model, rank_data)
            rank = constraint_rank(built_i.model, rank_data, warn=False)  # the one rank decision (consistent units)
            if rank.deficient:
                warnings.warn(
                    f"pose {poses[i]}: weld Jacobian is rank-deficient in consistent units (scaled singular value "
                    f"ratio {rank.ratio:.1e}); reported singular",
                    FpmSimWarning,
                    stacklevel=3,
                )
                status[i] = STATUS_SINGULAR
                continue
            freq[i, :n] = np.sqrt(np.maximum(w2[r], 0.0)) / (2 * np.pi)
            energy = k_diag[r][:, None] * shapes[r] ** 2
            tot = energy.sum(axis=0)
            frac[i, :n] = np.where(tot > 0, energy[inplane].sum(axis=0) / np.where(tot > 0, tot, 1.0), np.nan)
    return TimedPoseFrequencies(
        poses=poses,
        frequencies_hz=freq,
        in_plane=frac,
        singularity=assembled.singularity,
        status=status,
        timings=timings,
    )


def _compiled_modes(structure: Any, params: dict[str, np.ndarray], n_modes: int) -> tuple[Any, float]:
    """The compiled batched solve for this structure/batch shape, and its compile time (0 if cached)."""
    import jax

    from fpm_sim.batch import jax_linearisation as jl

    batch = next(iter(params.values())).shape[0]

    def make() -> Any:
        def fn(p: dict[str, Any]) -> Any:
            return jl.batched_modes(structure, p, n_modes=n_modes, geometric=False)

        return jax.jit(fn).lower(params).compile()

    return _MODES_CACHE.get((structure.key(), batch, n_modes), make)


def jax_pose_frequencies(
    config: Manipulator,
    poses: Sequence[Pose],
    *,
    n_modes: int = 3,
    options: ModelOptions | None = None,
    workers: int = 1,
    progress: bool = False,
    desc: str = "poses",
) -> TimedPoseFrequencies:
    """Lowest ``n_modes`` frequencies (Hz) at each pose, all poses in one batched JAX computation.

    Same arguments and result as :func:`fpm_sim.batch.frequencies.pose_frequencies`, plus the call's
    :class:`BackendTimings` (``result.timings``). ``workers`` is ignored: the per-pose models are built in
    this process (building them is most of the cost, but forking worker processes after JAX has started
    its threads risks deadlocks, and ``forkserver`` or ``spawn`` workers re-import the caller's main
    module), and the solve of all poses is one vectorised JAX computation. The compiled function is kept
    per model structure, batch size and ``n_modes`` (at most :data:`COMPILE_CACHE_SIZE`). A pose whose weld
    Jacobian is rank-deficient in consistent units (:func:`fpm_sim.linear.nullspace.constraint_rank`, the one rank
    decision of the package) is reported ``singular`` with NaN frequencies and a warning.

    Raises
    ------
    FpmSimError
        ``options.gravity`` is on (the backend linearises the unstressed model at ``qpos0``), the link
        model is not ``segments``, or the poses' models differ in structure.
    """
    del workers
    return batched_pose_frequencies(
        config,
        poses,
        backend="jax",
        solve=solve_jax_models,
        n_modes=n_modes,
        options=options,
        progress=progress,
        desc=desc,
    )


def solve_jax_models(
    built: list[BuiltModel], n_modes: int, timings: BackendTimings, t0: float
) -> tuple[np.ndarray, ...]:
    """The ``jax`` backend's :data:`BatchSolver`: every model of ``built`` (one structure) linearised and solved in
    one compiled, ``vmap``-ped call (any described machine's models too, :mod:`fpm_sim.batch.task_sweep`)."""
    import jax.numpy as jnp

    from fpm_sim.batch import jax_linearisation as jl

    models = [b.model for b in built]
    structure = jl.structure_of(models[0])
    for i, m in enumerate(models[1:], start=1):
        if not jl.structure_of(m).same_as(structure):
            raise FpmSimError(f"pose {i} of the computed poses: model structure differs from the first pose's")
    params = jl.stack_params([jl.params_of(m) for m in models])
    n = min(n_modes, structure.nv - len(structure.weld_b1) * 6)
    timings.build_s = time.perf_counter() - t0
    fn, timings.compile_s = _compiled_modes(structure, params, n)
    t1 = time.perf_counter()
    out = tuple(np.asarray(a) for a in fn({k: jnp.asarray(v) for k, v in params.items()}))
    timings.run_s = time.perf_counter() - t1
    return out


BatchSolver = Callable[[list[BuiltModel], int, BackendTimings, float], tuple[np.ndarray, ...]]
"""``solve(built, n_modes, timings, t0) -> (w2, shapes, k_diag, sv_ratio)`` for the computed poses (see
:func:`frequencies_from_modes`); it runs inside :func:`x64` and fills ``timings`` (``build_s`` counted
from ``t0``, ``compile_s``, ``run_s``)."""


def batched_pose_frequencies(
    config: Manipulator,
    poses: Sequence[Pose],
    *,
    backend: str,
    solve: BatchSolver,
    n_modes: int,
    options: ModelOptions | None,
    progress: bool = False,
    desc: str = "poses",
) -> TimedPoseFrequencies:
    """The common frame of the batched backends: check the options, build every pose's model, ``solve``
    the computed poses at once (inside :func:`x64`), and assemble the result.

    Raises
    ------
    FpmSimError
        Options the batched backends do not linearise (:func:`check_options`) or models not at rest.
    """
    opts = options or fast_options()
    check_options(opts, backend)
    t0 = time.perf_counter()
    assembled = assemble_poses(config, poses, opts, progress=progress, desc=desc)
    ok = assembled.ok
    timings = BackendTimings(poses=len(ok))
    if not ok:
        timings.build_s = time.perf_counter() - t0
        empty = np.zeros((0, n_modes))
        return frequencies_from_modes(
            assembled, empty, np.zeros((0, 0, n_modes)), empty, np.zeros(0), n_modes=n_modes, timings=timings
        )
    built = [b for b in assembled.built if b is not None]
    with x64():
        out = solve(built, n_modes, timings, t0)
    return frequencies_from_modes(assembled, *out, n_modes=n_modes, timings=timings)


# --------------------------------------------------------------------------------------------- gradients

GRADIENT_PARAMETERS = (
    "section.thickness_m",
    "material.young_pa",
    "hardware.platform.mass_kg",
)
"""Parameters with gradients; also any ``hardware.<part>.mass_kg`` and ``section.height_m``,
``material.density_kg_m3``, ``material.poisson``."""

_GEOMETRY_FIELDS = ("body_pos", "body_quat", "jnt_pos", "jnt_axis", "qpos0", "qpos_spring", "eq_data")


@dataclass
class FrequencyGradients:
    """Frequencies at one pose and their derivatives with respect to model parameters.

    Attributes
    ----------
    pose
        The pose.
    frequencies_hz
        ``(n_modes,)`` lowest frequencies.
    parameters
        Parameter names (dotted, SI units in the name).
    values
        Parameter values (SI).
    gradient
        ``(n_modes, n_params)``: ``d f_i / d p_k`` in Hz per SI unit of ``p_k``.
    """

    pose: Pose
    frequencies_hz: np.ndarray
    parameters: list[str]
    values: np.ndarray
    gradient: np.ndarray
    timings_s: dict[str, float] = field(default_factory=dict)
    """``build``: models at the nominal and perturbed parameters (CPU); ``jax``: compile (first call per
    structure and parameter count) and run."""

    @property
    def relative(self) -> np.ndarray:
        """``(p / f) df/dp``: dimensionless sensitivities (``(n_modes, n_params)``)."""
        return self.gradient * self.values[None, :] / self.frequencies_hz[:, None]

    def to_dict(self) -> dict[str, Any]:
        return {
            "pose": {"x_m": self.pose.x_m, "y_m": self.pose.y_m, "phi_rad": self.pose.phi_rad},
            "frequencies_hz": self.frequencies_hz.tolist(),
            "parameters": list(self.parameters),
            "values": self.values.tolist(),
            "gradient_hz_per_unit": self.gradient.tolist(),
            "relative": self.relative.tolist(),
        }


def frequency_gradients(
    config: Manipulator,
    pose: Pose,
    parameters: Sequence[str] = GRADIENT_PARAMETERS,
    *,
    n_modes: int = 6,
    options: ModelOptions | None = None,
    rel_step: float = 1e-6,
) -> FrequencyGradients:
    """``d f_i / d p`` at ``pose`` for the named parameters, on the ``jax`` backend's model.

    How: the per-pose model arrays (masses, centres of mass, inertia tensors, spring stiffnesses) are
    functions of the parameters through the model builder (``K_bend_in ~ E t^3``, ``K_bend_out ~ E t``,
    ``K_twist ~ G J(t)``, masses ~ ``t``, ...). The builder is MuJoCo's C compiler, which JAX cannot
    trace, so the array tangents ``d(arrays)/dp`` are central differences of the compiled arrays
    (relative step ``rel_step``; the arrays are smooth closed-form functions of ``p``, so the truncation
    error is ~``rel_step^2``: measured, the gradients at 3 segments change by at most 3e-9 relative
    for ``rel_step`` from 1e-4 to 1e-7). From the arrays on everything is exact: ``dM``, ``dK`` are ``jax.jvp``
    tangents of the linearisation and ``d(w^2) = x'(dK - w^2 dM)x`` with M-normalised modes ``x``.

    Exact for distinct eigenvalues; for a (near-)repeated pair only the sum of the pair's derivatives is
    defined. Parameters that move the geometry (body or joint positions, weld data) are refused.

    Raises
    ------
    FpmSimError
        Unknown or non-positive parameter, gravity on, an unreachable/singular pose, or a parameter that
        changes the geometry.
    """
    return pose_frequency_gradients(config, [pose], parameters, n_modes=n_modes, options=options, rel_step=rel_step)[0]


def _pose_tangents(
    config: Manipulator, pose: Pose, names: list[str], values: np.ndarray, opts: ModelOptions, rel_step: float
) -> tuple[dict[str, np.ndarray], Any, dict[str, np.ndarray]]:
    """Nominal arrays, structure and stacked array tangents ``d(arrays)/dp_k`` at one pose."""
    from fpm_sim.batch import jax_linearisation as jl

    base, _, status = assemble_pose(config, pose, opts)
    if base is None:
        raise FpmSimError(f"pose {pose} is {status}: no frequencies to differentiate")
    p0 = jl.params_of(base.model)
    structure = jl.structure_of(base.model)
    tangents: list[dict[str, np.ndarray]] = []
    for name, v in zip(names, values):
        h = rel_step * v
        arrays = []
        for sign in (1.0, -1.0):
            b, _, _ = assemble_pose(with_parameter(config, name, v + sign * h), pose, opts)
            if b is None or not jl.structure_of(b.model).same_as(structure):
                raise FpmSimError(f"parameter {name!r} changes the model structure at pose {pose}")
            arrays.append(jl.params_of(b.model))
        t = {k: (arrays[0][k] - arrays[1][k]) / (2 * h) for k in jl.PARAM_FIELDS}
        for k in _GEOMETRY_FIELDS:
            scale = max(1.0, float(np.abs(p0[k]).max())) if p0[k].size else 1.0
            if np.abs(t[k]).max(initial=0.0) * h > 1e-12 * scale:
                raise FpmSimError(f"parameter {name!r} moves the geometry ({k}); not supported by the modal formula")
            t[k] = np.zeros_like(t[k])
        tangents.append(t)
    return p0, structure, jl.stack_params(tangents)


def pose_frequency_gradients(
    config: Manipulator,
    poses: Sequence[Pose],
    parameters: Sequence[str] = GRADIENT_PARAMETERS,
    *,
    n_modes: int = 6,
    options: ModelOptions | None = None,
    rel_step: float = 1e-6,
) -> list[FrequencyGradients]:
    """:func:`frequency_gradients` at many poses, all solved in one ``jit``/``vmap`` JAX computation.

    The compiled function is cached per model structure, pose count, parameter count and mode count.
    Every pose must be reachable and not singular (:class:`~fpm_sim.errors.FpmSimError` names the first that is not).
    """
    opts = options or fast_options()
    check_options(opts, "jax")
    names = list(parameters)
    poses = list(poses)
    if not names:
        raise FpmSimError("parameters: give at least one name")
    if not poses:
        raise FpmSimError("poses: give at least one pose")
    values = np.array([parameter_value(config, n, examples=GRADIENT_PARAMETERS) for n in names])
    for name, v in zip(names, values):
        if not v > 0:
            raise FpmSimError(f"parameter {name!r} = {v}: gradients need a positive value (relative step)")
    with x64():
        import jax
        import jax.numpy as jnp

        from fpm_sim.batch import jax_linearisation as jl

        t0 = time.perf_counter()
        per_pose = [_pose_tangents(config, p, names, values, opts, rel_step) for p in poses]
        structure = per_pose[0][1]
        for pose, (_, s, _) in zip(poses[1:], per_pose[1:]):
            if not s.same_as(structure):
                raise FpmSimError(f"pose {pose}: model structure differs from the first pose's")
        p0 = jl.stack_params([x[0] for x in per_pose])
        tangents = {k: np.stack([x[2][k] for x in per_pose]) for k in jl.PARAM_FIELDS}
        n = min(n_modes, structure.nv - 6 * len(structure.weld_b1))
        t1 = time.perf_counter()

        def make() -> Any:
            def one(p: dict[str, Any], t: dict[str, Any]) -> Any:
                return jl.modal_sensitivity(structure, p, t, n_modes=n, geometric=False)

            return jax.jit(jax.vmap(one))

        fn, _ = _GRADIENTS_CACHE.get((structure.key(), len(poses), len(names), n), make)
        f_hz, df = fn({k: jnp.asarray(v) for k, v in p0.items()}, {k: jnp.asarray(v) for k, v in tangents.items()})
        f_hz, df = np.asarray(f_hz), np.asarray(df)
        t2 = time.perf_counter()
    timings = {"build": t1 - t0, "jax": t2 - t1}
    return [
        FrequencyGradients(
            pose=pose,
            frequencies_hz=f_hz[i],
            parameters=names,
            values=values,
            gradient=df[i].T,
            timings_s=timings,
        )
        for i, pose in enumerate(poses)
    ]


# --------------------------------------------------------------------------------------------- old names

_DEPRECATED = {"mjx_pose_frequencies": "jax_pose_frequencies", "MjxTimings": "BackendTimings"}


def __getattr__(name: str) -> Any:
    """The names of the release in which this backend was called ``mjx``, with a DeprecationWarning."""
    if name in _DEPRECATED:
        new = _DEPRECATED[name]
        warnings.warn(
            f"fpm_sim.batch.jax_backend.{name} is deprecated and will be removed in the next release: use {new} "
            "(this backend is now called 'jax'; 'mjx' is MJX's own pipeline, fpm_sim.batch.mjx_backend)",
            DeprecationWarning,
            stacklevel=2,
        )
        return globals()[new]
    if name == "LAST_TIMINGS":
        raise AttributeError(
            "fpm_sim.batch.jax_backend.LAST_TIMINGS was removed (a mutable global): read the timings of a call "
            "from its result, jax_pose_frequencies(...).timings"
        )
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
