"""Batched rollouts of one model: many load cases stepped by MuJoCo's threaded ``mujoco.rollout``.

Where the model is shared (one pose and description, many load cases), the rollouts run in ``mujoco.rollout``'s
C++ thread pool, which steps them without the GIL: each load case is a constant end-effector wrench (``xfrc_applied``
of the platform, as :func:`fpm_sim.sim.rollout.rollout`) switched on at ``t = 0`` from the static equilibrium
under gravity, stepped on the :mod:`fpm_sim.sim.stepping` integrator (discrete at the band's step by default).
The rollouts advance one output step at a time (``nstep`` integrator steps in C per call; the state is handed
back between calls, so memory holds one output step, not the whole trajectory), and the end-effector pose is
read from each state. Where models differ (moves x designs), :func:`fpm_sim.batch.moves.moves_over_designs` runs
one :func:`fpm_sim.sim.trajectory.simulate_move` per task on the Dask engine instead.

Result: an :class:`xarray.Dataset` with one row per rollout (dims ``rollout``, ``time``, ``axis``): the applied
wrench, the end-effector displacement from the equilibrium, and the stepping in its attributes; ``to_netcdf``
writes it.
"""

from __future__ import annotations

import json
import math
import time
from typing import Any

import mujoco
import numpy as np
from numpy.typing import ArrayLike

from fpm_sim.config import Manipulator
from fpm_sim.errors import FpmSimError
from fpm_sim.linear.equilibrium import static_equilibrium
from fpm_sim.model.options import BuiltModel
from fpm_sim.rom.reduction import END_EFFECTOR_SITE
from fpm_sim.sim.rollout import end_effector_pose
from fpm_sim.sim.stepping import DEFAULT_INTEGRATOR, apply_stepping, choose_stepping

__all__ = ["BatchedRolloutError", "batched_rollouts"]


class BatchedRolloutError(FpmSimError):
    """Bad batched-rollout input (named in the message) or a diverging rollout."""


def batched_rollouts(
    built: BuiltModel,
    manip: Manipulator,
    wrenches: ArrayLike,
    *,
    duration_s: float,
    output_step_s: float = 1e-4,
    threads: int = 1,
    integrator: str = DEFAULT_INTEGRATOR,
    band_hz: float | None = None,
    f1_hz: float | None = None,
) -> Any:
    """Constant end-effector wrenches ``(n, 3)`` (``F_x, F_y`` in N, ``M_z`` in N m), one rollout each, in
    ``threads`` threads (module docstring); returns an :class:`xarray.Dataset`.

    ``manip`` is the description ``built`` was made from (recorded in the attributes); ``integrator``,
    ``band_hz``, ``f1_hz``: :func:`fpm_sim.sim.stepping.choose_stepping`.
    """
    import xarray as xr
    from mujoco import rollout as mj_rollout

    w = np.atleast_2d(np.asarray(wrenches, float))
    if w.ndim != 2 or w.shape[1] != 3 or w.shape[0] < 1 or not np.all(np.isfinite(w)):
        raise BatchedRolloutError(f"wrenches must be finite (n, 3) rows F_x, F_y, M_z, got shape {w.shape}")
    if not (isinstance(threads, int) and threads >= 1):
        raise BatchedRolloutError(f"threads (--threads) must be an integer >= 1, got {threads!r}")
    for name, v in (("duration_s", duration_s), ("output_step_s", output_step_s)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise BatchedRolloutError(f"{name} must be a positive finite time, got {v!r}")
    q0 = static_equilibrium(built.model, mujoco.MjData(built.model))
    stepping = choose_stepping(
        built, integrator=integrator, band_hz=band_hz, divides_s=output_step_s, f1_hz=f1_hz, qpos=q0
    )
    model = apply_stepping(built, stepping).model
    h = float(model.opt.timestep)
    n_sub = max(1, round(output_step_s / h))
    n_out = round(duration_s / (n_sub * h))
    sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, END_EFFECTOR_SITE)
    bid = int(model.site_bodyid[sid])
    data = mujoco.MjData(model)
    data.qpos[:] = q0
    mujoco.mj_forward(model, data)
    ee0 = end_effector_pose(model, data)
    spec = int(mujoco.mjtState.mjSTATE_FULLPHYSICS)
    nstate = mujoco.mj_stateSize(model, spec)
    s0 = np.empty(nstate)
    mujoco.mj_getState(model, data, s0, spec)
    n = w.shape[0]
    state = np.tile(s0, (n, 1))
    control = np.zeros((n, 1, 6 * model.nbody))
    control[:, 0, 6 * bid : 6 * bid + 2] = w[:, :2]
    control[:, 0, 6 * bid + 5] = w[:, 2]
    datas = [mujoco.MjData(model) for _ in range(threads)]
    disp = np.zeros((n, n_out + 1, 3))
    out = np.empty((n, n_sub, nstate))
    probe = mujoco.MjData(model)
    start = time.perf_counter()
    for k in range(1, n_out + 1):
        mj_rollout.rollout(
            model,
            datas,
            state,
            control,
            control_spec=int(mujoco.mjtState.mjSTATE_XFRC_APPLIED),
            nstep=n_sub,
            state=out,
            persistent_pool=threads > 1,
        )
        state = out[:, -1, :].copy()
        for i in range(n):
            mujoco.mj_setState(model, probe, state[i], spec)
            mujoco.mj_kinematics(model, probe)
            disp[i, k] = end_effector_pose(model, probe) - ee0
        if not np.all(np.isfinite(state)) or np.abs(disp[:, k, :2]).max() > model.stat.extent:
            raise BatchedRolloutError(
                f"a rollout diverged by t = {k * n_sub * h:.4g} s; reduce the wrenches or the band (--band-hz)"
            )
    wall = time.perf_counter() - start
    t = np.arange(n_out + 1) * n_sub * h
    return xr.Dataset(
        {
            "wrench": (("rollout", "load"), w, {"units": "N, N, N m"}),
            "ee_disp": (("rollout", "time", "axis"), disp, {"units": "m, m, rad"}),
        },
        coords={
            "rollout": np.arange(n),
            "time": ("time", t, {"units": "s"}),
            "axis": ["x", "y", "phi"],
            "load": ["fx_n", "fy_n", "mz_nm"],
        },
        attrs={
            "stepping": json.dumps(stepping.to_dict()),
            "threads": threads,
            "wall_s": wall,
            "n_steps_per_rollout": n_out * n_sub,
            "description": manip.name,
            "parameters": json.dumps({k: v for k, v in built.parameters.items() if k != "pose"}, default=str),
            "pose": json.dumps(built.parameters.get("pose", {}), default=str),
        },
    )
