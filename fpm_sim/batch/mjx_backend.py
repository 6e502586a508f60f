"""The ``mjx`` pose-loop backend: MJX's own pipeline, batched over poses (JAX and MJX imported lazily).

``pose_frequencies(config, poses, backend="mjx")`` builds the per-pose MuJoCo models on the CPU (as the
other backends do), puts each on the device with ``mjx.put_model``, stacks the array leaves of the
resulting ``mjx.Model`` pytrees along a leading pose axis (``jax.tree_util``; the static fields, which
hold the topology, must be equal for all poses) and runs one ``jit``-compiled ``jax.vmap`` over poses of

* ``M``: the joint-space mass matrix from MJX (``mjx.fwd_position``: ``crb``/``factor_m``, then
  ``mjx.full_m``);
* ``J``: the weld rows of MJX's constraint Jacobian (``efc_J``, equality rows first, from
  ``mjx.fwd_position``'s ``make_constraint``);
* ``K = -d(qfrc_smooth)/dq`` at the assembled pose (``qpos0``, zero velocity), by ``jax.jacfwd`` of the
  smooth generalised force that ``mjx.forward`` computes (:func:`smooth_force`: its position, velocity,
  actuation and acceleration stages, without the constraint solve, which ``qfrc_smooth`` does not
  depend on). With gravity off and the springs at rest this is the spring stiffness; the derivative is
  taken in the tangent space, which for hinge and slide joints is ``qpos`` itself (other joints are
  refused);

then the constrained eigenproblem ``Z'KZ x = w^2 Z'MZ x``, ``Z = null(J)``, by the ``jax`` backend's
solver (:func:`fpm_sim.batch.jax_linearisation.reduced_modes`). The three backends (``cpu``, ``jax``,
``mjx``) solve the same discrete eigenproblem and agree to round-off (``tests/batch/test_mjx_pipeline.py``).

Cost: MJX walks the kinematic tree level by level, so its XLA compile grows with the chain depth
(``benchmarks/backends.py``, ``docs/benchmarks.md``); on a CPU the ``jax`` backend compiles faster.
With a GPU, this is the path to measure.

The rigs are refused (:func:`check_mjx_model`): their kinematic tree is one serial chain, and
``jit(mjx.kinematics)`` of the two-link chain rig runs for minutes per call on the CPU (XLA:CPU's code for
a tree level of one body; ``docs/mjx_chain_rig.md``, ``studies/repro_mjx_chain_rig.py``).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import mujoco
import numpy as np

from fpm_sim.batch.jax_backend import (
    BackendTimings,
    CompileCache,
    TimedPoseFrequencies,
    batched_pose_frequencies,
    x64,
)
from fpm_sim.config import Manipulator
from fpm_sim.errors import FpmSimError
from fpm_sim.kinematics import Pose
from fpm_sim.model.options import ModelOptions
from fpm_sim.model.spec import BuiltModel

__all__ = [
    "SERIAL_DOF_LIMIT",
    "MjxModelError",
    "check_mjx_model",
    "import_mjx",
    "mjx_linearisation",
    "mjx_pose_frequencies",
    "serial_dofs",
    "smooth_force",
    "solve_mjx_models",
    "stack_models",
]

_MODES_CACHE = CompileCache()

SERIAL_DOF_LIMIT = 9
"""Most degrees of freedom accepted in the serial part of the kinematic tree (levels holding one body).

MJX's tree scan processes the bodies of one tree level together; where a level holds a single body, XLA:CPU
(jax 0.10.2, its fusion emitters) turns the chain into code whose every call takes seconds to minutes
although it does ~1e4 flops (``docs/mjx_chain_rig.md``). Measured with ``studies/repro_mjx_chain_rig.py``,
3-hinge bodies in series: 9 dofs 10-20 ms per ``mjx.kinematics`` call, 12 dofs 1.4 s, 12 dofs and a
jointless tip 4-5 s; the chain rig at 2 segments (17 dofs) 81-324 s. The same chain twice side by side
(two bodies per level, as the manipulator's three legs) runs in 1-5 ms."""


class MjxModelError(FpmSimError):
    """A model the ``mjx`` backend does not handle (joint types, a known MJX pathology)."""


def import_mjx() -> Any:
    """``mujoco.mjx``, imported with its start-up notice on stdout (``Failed to import warp: ...``, printed
    when the optional Warp GPU backend is absent) kept out of the caller's stdout (e.g. ``--json`` output)."""
    import contextlib
    import io
    import sys

    if "mujoco.mjx" not in sys.modules:
        with contextlib.redirect_stdout(io.StringIO()):
            from mujoco import mjx  # noqa: F401
    return sys.modules["mujoco.mjx"]


def check_mjx_model(built: BuiltModel) -> None:
    """Refuse models the ``mjx`` backend cannot linearise, or that MJX cannot run in reasonable time.

    Raises
    ------
    MjxModelError
        For a kinematic tree whose serial part (levels with one body) holds more than
        :data:`SERIAL_DOF_LIMIT` dofs, as the rigs' single chains do (MJX's compiled kinematics then runs
        for seconds to minutes per call on the CPU; ``docs/mjx_chain_rig.md``), for joints other than
        hinges and slides (the tangent space would differ from ``qpos``), and for models with flexes (not
        in MJX's JAX implementation).
    """
    model = built.model
    if model.nflex:
        raise MjxModelError("the mjx backend does not handle flex links; use link_model='segments'")
    hinge_slide = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
    if model.nq != model.nv or not np.all(np.isin(model.jnt_type, hinge_slide)):
        raise MjxModelError(
            "the mjx backend differentiates in qpos, which is the tangent space only for hinge and slide joints; "
            "this model has ball or free joints (use the cpu path)"
        )
    serial = serial_dofs(model)
    if serial > SERIAL_DOF_LIMIT:
        what = "the chain rig" if built.name == "chain" else f"the {built.name} model"
        raise MjxModelError(
            f"{what} is kept off MJX: its kinematic tree is a serial chain of {serial} dofs (more than "
            f"{SERIAL_DOF_LIMIT}), for which jit(mjx.kinematics) runs for seconds to minutes per call on the CPU "
            "(docs/mjx_chain_rig.md); use the cpu backend"
        )


def serial_dofs(model: mujoco.MjModel) -> int:
    """Degrees of freedom of the bodies that are alone on their level of the kinematic tree."""
    depth = np.zeros(model.nbody, dtype=int)
    for b in range(1, model.nbody):
        depth[b] = depth[model.body_parentid[b]] + 1
    per_level = np.bincount(depth)
    alone = per_level[depth] == 1
    alone[0] = False
    return int(np.asarray(model.body_dofnum)[alone].sum())


def stack_models(models: Sequence[mujoco.MjModel]) -> Any:
    """``mjx.put_model`` of each model, array leaves stacked along a new leading axis (one ``mjx.Model``).

    Call inside :func:`fpm_sim.batch.jax_backend.x64` (float64). The static fields (topology, joint
    types, option flags) must be equal for all models.

    Raises
    ------
    MjxModelError
        If the models differ in structure.
    """
    import jax
    import jax.numpy as jnp

    mjx = import_mjx()

    put = [mjx.put_model(m) for m in models]
    treedef = jax.tree_util.tree_structure(put[0])
    for i, mx in enumerate(put[1:], start=1):
        if jax.tree_util.tree_structure(mx) != treedef:  # type: ignore[operator]  # jaxlib stub: PyTreeDef unresolved
            raise MjxModelError(f"model {i}: its structure (static MJX fields) differs from the first model's")
    return jax.tree_util.tree_map(lambda *leaves: jnp.stack(leaves), *put)


def smooth_force(mx: Any, qpos: Any) -> Any:
    """``qfrc_smooth`` (N m or N per dof) of MJX at ``qpos``, zero velocity, no controls.

    The stages of ``mjx.forward`` before its constraint solve (``fwd_position``, ``fwd_velocity``,
    ``fwd_actuation``, ``fwd_acceleration``): ``qfrc_passive - qfrc_bias + qfrc_actuator + qfrc_applied``.
    """
    mjx = import_mjx()

    d = mjx.make_data(mx).replace(qpos=qpos)
    d = mjx.fwd_position(mx, d)
    d = mjx.fwd_velocity(mx, d)
    d = mjx.fwd_actuation(mx, d)
    d = mjx.fwd_acceleration(mx, d)
    return d.qfrc_smooth


def linearise_one(mx: Any) -> tuple[Any, Any, Any]:
    """``(M, K, J)`` of one ``mjx.Model`` at its ``qpos0`` (traceable; ``vmap`` it over stacked models).

    ``M`` ``(nv, nv)`` from ``mjx.full_m``; ``K = -d(qfrc_smooth)/dq`` ``(nv, nv)`` by ``jax.jacfwd`` of
    :func:`smooth_force`; ``J`` ``(ne, nv)``: the equality rows of MJX's constraint Jacobian (MJX puts
    equality rows first; ``ne`` is static).
    """
    import jax

    mjx = import_mjx()

    d = mjx.fwd_position(mx, mjx.make_data(mx))
    mass = mjx.full_m(mx, d)
    stiff = -jax.jacfwd(lambda q: smooth_force(mx, q))(mx.qpos0)
    impl = d._impl  # MJX keeps the constraint rows in its backend-specific part of Data
    jac = impl.efc_J[: impl.ne]
    return mass, stiff, jac


def mjx_linearisation(built: BuiltModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(M, K, J)`` of one built model at ``qpos0`` through MJX (float64, numpy); see :func:`linearise_one`.

    Raises
    ------
    MjxModelError
        See :func:`check_mjx_model`.
    """
    check_mjx_model(built)
    with x64():
        import jax

        mjx = import_mjx()

        mx = mjx.put_model(built.model)
        out = jax.jit(linearise_one)(mx)
        return tuple(np.asarray(a) for a in out)  # type: ignore[return-value]


def _compiled_modes(stacked: Any, n_modes: int) -> tuple[Any, float]:
    """The compiled batched MJX linearisation and eigen-solve, and its compile time (0 if cached)."""
    import jax
    import jax.numpy as jnp

    from fpm_sim.batch import jax_linearisation as jl

    leaves, treedef = jax.tree_util.tree_flatten(stacked)
    key = (treedef, tuple(leaf.shape for leaf in leaves), n_modes)

    def make() -> Any:
        def one(mx: Any) -> tuple[Any, ...]:
            mass, stiff, jac = linearise_one(mx)
            w2, x, ratio = jl.reduced_modes(mass, stiff, jac, n_modes)
            return w2, x, jnp.diag(stiff), ratio

        return jax.jit(jax.vmap(one)).lower(stacked).compile()

    return _MODES_CACHE.get(key, make)


def mjx_pose_frequencies(
    config: Manipulator,
    poses: Sequence[Pose],
    *,
    n_modes: int = 3,
    options: ModelOptions | None = None,
    workers: int = 1,
    progress: bool = False,
    desc: str = "poses",
) -> TimedPoseFrequencies:
    """Lowest ``n_modes`` frequencies (Hz) at each pose through MJX's pipeline, all poses in one ``vmap``.

    Same arguments and result as :func:`fpm_sim.batch.jax_backend.jax_pose_frequencies` (timings in
    ``result.timings``; ``workers`` is ignored). The compiled function is kept per MJX model structure,
    batch size and ``n_modes`` (a bounded cache).

    Raises
    ------
    FpmSimError
        ``options.gravity`` is on, the link model is not ``segments``, or the poses' models differ in
        structure (:class:`MjxModelError`).
    """
    del workers
    return batched_pose_frequencies(
        config,
        poses,
        backend="mjx",
        solve=solve_mjx_models,
        n_modes=n_modes,
        options=options,
        progress=progress,
        desc=desc,
    )


def solve_mjx_models(
    built: list[BuiltModel], n_modes: int, timings: BackendTimings, t0: float
) -> tuple[np.ndarray, ...]:
    """The ``mjx`` backend's :data:`fpm_sim.batch.jax_backend.BatchSolver`: every model of ``built`` (one structure,
    checked by :func:`check_mjx_model`) through MJX's pipeline in one compiled, ``vmap``-ped call."""
    import jax

    for b in built:
        check_mjx_model(b)
    first = built[0].model
    n = min(n_modes, first.nv - 6 * first.neq)
    stacked = stack_models([b.model for b in built])
    timings.build_s = time.perf_counter() - t0
    fn, timings.compile_s = _compiled_modes(stacked, n)
    t1 = time.perf_counter()
    out = tuple(np.asarray(a) for a in jax.block_until_ready(fn(stacked)))
    timings.run_s = time.perf_counter() - t1
    return out
