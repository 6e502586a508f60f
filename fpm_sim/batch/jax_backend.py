"""The ``mjx`` pose-loop backend and frequency gradients, both in JAX (imported lazily).

``pose_frequencies(config, poses, backend="mjx")`` builds the per-pose MuJoCo models on the CPU (as the
``cpu`` backend does), stacks their array fields and linearises and solves all poses in one
``jit``-compiled, ``vmap``-ped JAX computation (:mod:`fpm_sim.batch.jax_linearisation`): the same constrained
eigenproblem as the ``cpu`` backend (gravity off, at ``qpos0``, ``K`` from the joint springs, here by
``jax.jacfwd``), so the two agree to round-off.

:func:`frequency_gradients` returns ``d f_i / d p`` for link thickness, Young's modulus and hardware
masses (:data:`GRADIENT_PARAMETERS`; any name of the form ``hardware.<part>.mass_kg``), by the modal
sensitivity formula on JAX tangents of ``M`` and ``K``.

Importing this module does not import JAX: the backend is registered as a thin wrapper that imports
:mod:`fpm_sim.batch.jax_linearisation` on its first call.
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings
from collections.abc import Sequence
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
from fpm_sim.config import Manipulator
from fpm_sim.errors import FpmSimWarning
from fpm_sim.kinematics import (
    Pose,
)
from fpm_sim.linear.modal import constraint_rank
from fpm_sim.model.options import ModelOptions

__all__ = [
    "MjxTimings",
    "LAST_TIMINGS",
    "mjx_pose_frequencies",
    "FrequencyGradients",
    "GRADIENT_PARAMETERS",
    "frequency_gradients",
    "pose_frequency_gradients",
    "parameter_value",
    "with_parameter",
]

_COMPILED: dict[tuple, Any] = {}


@dataclass
class MjxTimings:
    """Wall times (s) of the last :func:`mjx_pose_frequencies` call, by stage.

    ``build``: per-pose MuJoCo models and their arrays (CPU, Python); ``compile``: XLA compile (0 when the
    compiled function was cached); ``run``: the batched linearisation and eigen-solve; ``poses``: count.
    """

    build_s: float = 0.0
    compile_s: float = 0.0
    run_s: float = 0.0
    poses: int = 0


LAST_TIMINGS = MjxTimings()
"""Timings of the most recent ``mjx`` backend call (the benchmark reads it)."""


def _check_options(options: ModelOptions) -> None:
    if options.gravity:
        raise ValueError(
            "the mjx backend linearises at qpos0 with gravity off, like the cpu backend; "
            "use fast_options() or ModelOptions(gravity=False)"
        )
    if options.link_model != "segments":
        raise ValueError(f"the mjx backend needs link_model='segments', got {options.link_model!r}")


def _compiled_modes(structure: Any, params: dict[str, np.ndarray], n_modes: int) -> tuple[Any, float]:
    """The compiled batched solve for this structure/batch shape, and its compile time (0 if cached)."""
    import jax

    from fpm_sim.batch import jax_linearisation as jl

    batch = next(iter(params.values())).shape[0]
    key = (structure.key(), batch, n_modes)
    if key in _COMPILED:
        return _COMPILED[key], 0.0
    t0 = time.perf_counter()

    def fn(p: dict[str, Any]) -> Any:
        return jl.batched_modes(structure, p, n_modes=n_modes, geometric=False)

    compiled = jax.jit(fn).lower(params).compile()
    _COMPILED[key] = compiled
    return compiled, time.perf_counter() - t0


def mjx_pose_frequencies(
    config: Manipulator,
    poses: Sequence[Pose],
    *,
    n_modes: int = 3,
    options: ModelOptions | None = None,
    workers: int = 1,
    progress: bool = False,
    desc: str = "poses",
) -> PoseFrequencies:
    """Lowest ``n_modes`` frequencies (Hz) at each pose, all poses in one batched JAX computation.

    Same arguments and result as :func:`fpm_sim.batch.pose_loop.pose_frequencies`. ``workers`` is
    ignored: the per-pose models are built in this process (building them is most of the cost, but
    forking worker processes after JAX has started its threads risks deadlocks, and ``forkserver`` or
    ``spawn`` workers re-import the caller's main module), and the solve of all poses is one vectorised
    JAX computation. The compiled function is cached per model structure, batch size and ``n_modes``;
    :data:`LAST_TIMINGS` holds the build / compile / run times. A pose whose weld Jacobian is
    rank-deficient in consistent units (:func:`fpm_sim.linear.modal.constraint_rank`, the one rank decision
    of the package) is reported ``singular`` with NaN frequencies and a warning.

    Raises
    ------
    ValueError
        ``options.gravity`` is on (the backend linearises the unstressed model at ``qpos0``), the link
        model is not ``segments``, or the poses' models differ in structure.
    """
    import jax.numpy as jnp

    from fpm_sim.batch import jax_linearisation as jl

    del workers
    opts = options or fast_options()
    _check_options(opts)
    poses = list(poses)
    t0 = time.perf_counter()
    built: list[Any] = []
    sing = np.full(len(poses), math.nan)
    status: list[str] = []
    iterator: Any = poses
    if progress:
        from tqdm.auto import tqdm

        iterator = tqdm(poses, desc=f"{desc} (build)", unit="pose")
    for i, p in enumerate(iterator):
        b, sing[i], st = assemble_pose(config, p, opts)
        built.append(b)
        status.append(st)
    ok = [i for i, b in enumerate(built) if b is not None]
    freq = np.full((len(poses), n_modes), np.nan)
    frac = np.full((len(poses), n_modes), np.nan)
    timings = MjxTimings(poses=len(ok))
    if ok:
        models = [built[i].model for i in ok]
        structure = jl.structure_of(models[0])
        for i, m in zip(ok[1:], models[1:]):
            if not jl.structure_of(m).same_as(structure):
                raise ValueError(f"pose {poses[i]}: model structure differs from the first pose's")
        if not all(np.array_equal(m.qpos0, m.qpos_spring) for m in models):
            raise ValueError("the mjx backend needs springs at rest at qpos0 (an unstressed assembled pose)")
        params = jl.stack_params([jl.params_of(m) for m in models])
        n = min(n_modes, structure.nv - len(structure.weld_b1) * 6)
        timings.build_s = time.perf_counter() - t0
        fn, timings.compile_s = _compiled_modes(structure, params, n)
        t1 = time.perf_counter()
        w2, x, kdiag, _sv_ratio = (np.asarray(a) for a in fn({k: jnp.asarray(v) for k, v in params.items()}))
        timings.run_s = time.perf_counter() - t1
        inplane = np.array([kind in IN_PLANE_KINDS for kind in built[ok[0]].dof_kinds])
        for r, i in enumerate(ok):
            rank_data = mujoco.MjData(built[i].model)
            mujoco.mj_forward(built[i].model, rank_data)
            rank = constraint_rank(built[i].model, rank_data, warn=False)
            if rank.deficient:
                warnings.warn(
                    f"pose {poses[i]}: weld Jacobian is rank-deficient in consistent units (scaled singular "
                    f"value ratio {rank.ratio:.1e}); reported singular",
                    FpmSimWarning,
                    stacklevel=2,
                )
                status[i] = STATUS_SINGULAR
                continue
            freq[i, :n] = np.sqrt(np.maximum(w2[r], 0.0)) / (2 * np.pi)
            energy = kdiag[r][:, None] * x[r] ** 2
            tot = energy.sum(axis=0)
            frac[i, :n] = np.where(tot > 0, energy[inplane].sum(axis=0) / np.where(tot > 0, tot, 1.0), np.nan)
    else:
        timings.build_s = time.perf_counter() - t0
    LAST_TIMINGS.__dict__.update(dataclasses.asdict(timings))
    return PoseFrequencies(poses=poses, frequencies_hz=freq, in_plane=frac, singularity=sing, status=status)


# --------------------------------------------------------------------------------------------- gradients

GRADIENT_PARAMETERS = (
    "section.thickness_m",
    "material.young_pa",
    "hardware.platform.mass_kg",
)
"""Parameters with gradients; also any ``hardware.<part>.mass_kg`` and ``section.height_m``,
``material.density_kg_m3``, ``material.poisson``."""

_GEOMETRY_FIELDS = ("body_pos", "body_quat", "jnt_pos", "jnt_axis", "qpos0", "qpos_spring", "eq_data")


def parameter_value(config: Manipulator, name: str) -> float:
    """The value (SI) of a dotted parameter name, e.g. ``section.thickness_m``."""
    obj: Any = config
    for part in name.split("."):
        if not hasattr(obj, part):
            raise ValueError(
                f"unknown parameter {name!r}: {part!r} is not a field; use e.g. {', '.join(GRADIENT_PARAMETERS)}"
            )
        obj = getattr(obj, part)
    if not isinstance(obj, (int, float)):
        raise ValueError(f"parameter {name!r} is not a number")
    return float(obj)


def with_parameter(config: Manipulator, name: str, value: float) -> Manipulator:
    """A copy of ``config`` with the dotted parameter ``name`` set to ``value`` (validated)."""
    parameter_value(config, name)
    parts = name.split(".")

    def rebuild(obj: Any, path: list[str]) -> Any:
        if len(path) == 1:
            return dataclasses.replace(obj, **{path[0]: value})
        return dataclasses.replace(obj, **{path[0]: rebuild(getattr(obj, path[0]), path[1:])})

    return rebuild(config, parts).replace()


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
    """``d f_i / d p`` at ``pose`` for the named parameters, on the ``mjx`` backend's model.

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
    ValueError
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
        raise ValueError(f"pose {pose} is {status}: no frequencies to differentiate")
    p0 = jl.params_of(base.model)
    structure = jl.structure_of(base.model)
    tangents: list[dict[str, np.ndarray]] = []
    for name, v in zip(names, values):
        h = rel_step * v
        arrays = []
        for sign in (1.0, -1.0):
            b, _, _ = assemble_pose(with_parameter(config, name, v + sign * h), pose, opts)
            if b is None or not jl.structure_of(b.model).same_as(structure):
                raise ValueError(f"parameter {name!r} changes the model structure at pose {pose}")
            arrays.append(jl.params_of(b.model))
        t = {k: (arrays[0][k] - arrays[1][k]) / (2 * h) for k in jl.PARAM_FIELDS}
        for k in _GEOMETRY_FIELDS:
            scale = max(1.0, float(np.abs(p0[k]).max())) if p0[k].size else 1.0
            if np.abs(t[k]).max(initial=0.0) * h > 1e-12 * scale:
                raise ValueError(f"parameter {name!r} moves the geometry ({k}); not supported by the modal formula")
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
    Every pose must be reachable and not singular (``ValueError`` names the first that is not).
    """
    import jax
    import jax.numpy as jnp

    from fpm_sim.batch import jax_linearisation as jl

    opts = options or fast_options()
    _check_options(opts)
    names = list(parameters)
    poses = list(poses)
    if not names:
        raise ValueError("parameters: give at least one name")
    if not poses:
        raise ValueError("poses: give at least one pose")
    values = np.array([parameter_value(config, n) for n in names])
    for name, v in zip(names, values):
        if not v > 0:
            raise ValueError(f"parameter {name!r} = {v}: gradients need a positive value (relative step)")
    t0 = time.perf_counter()
    per_pose = [_pose_tangents(config, p, names, values, opts, rel_step) for p in poses]
    structure = per_pose[0][1]
    for pose, (_, s, _) in zip(poses[1:], per_pose[1:]):
        if not s.same_as(structure):
            raise ValueError(f"pose {pose}: model structure differs from the first pose's")
    p0 = jl.stack_params([x[0] for x in per_pose])
    tangents = {k: np.stack([x[2][k] for x in per_pose]) for k in jl.PARAM_FIELDS}
    n = min(n_modes, structure.nv - 6 * len(structure.weld_b1))
    t1 = time.perf_counter()
    key = ("gradients", structure.key(), len(poses), len(names), n)
    if key not in _COMPILED:

        def one(p: dict[str, Any], t: dict[str, Any]) -> Any:
            return jl.modal_sensitivity(structure, p, t, n_modes=n, geometric=False)

        _COMPILED[key] = jax.jit(jax.vmap(one))
    f_hz, df = _COMPILED[key](
        {k: jnp.asarray(v) for k, v in p0.items()}, {k: jnp.asarray(v) for k, v in tangents.items()}
    )
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
