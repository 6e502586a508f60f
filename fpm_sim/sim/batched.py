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
from fpm_sim.model.spec import BuiltModel
from fpm_sim.sim.rollout import RolloutMachine, end_effector_coordinates, end_effector_site_id
from fpm_sim.sim.stepping import (
    DEFAULT_INTEGRATOR,
    Stepping,
    SteppingError,
    apply_stepping,
    choose_stepping,
    reraise_as,
)

__all__ = ["BatchedRolloutError", "BatchedRollouts", "batched_rollouts"]


_UNIT = {"x": "m", "y": "m", "z": "m", "phi": "rad"}
_LOAD = {"x": "fx_n", "y": "fy_n", "z": "fz_n", "phi": "mz_nm"}


class BatchedRolloutError(FpmSimError):
    """Bad batched-rollout input (named in the message) or a diverging rollout."""


class BatchedRollouts:
    """The result of :func:`batched_rollouts` as a :class:`fpm_sim.results.Result` (``fs.batched_rollouts``).

    ``dataset`` is the :class:`xarray.Dataset` (:meth:`to_xarray`): ``wrench`` (rollout, load) and ``ee_disp``
    (rollout, time, axis), the stepping and the timing in its attributes.
    """

    def __init__(self, dataset: Any) -> None:
        self.dataset = dataset

    def to_xarray(self) -> Any:
        """The :class:`xarray.Dataset` (``to_netcdf`` writes it)."""
        return self.dataset

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: per rollout the wrench, the final and peak end-effector displacement; stepping, timing,
        resolution."""
        from fpm_sim.model.options import resolution_of_parameters

        ds = self.dataset
        disp = np.asarray(ds["ee_disp"].values)
        axes = [f"{c}_{'rad' if c == 'phi' else 'm'}" for c in ds["axis"].values]
        parameters = json.loads(ds.attrs["parameters"])
        return {
            "rollouts": [
                {
                    "wrench": dict(zip([str(x) for x in ds["load"].values], map(float, w))),
                    "final_disp": dict(zip(axes, map(float, d[-1]))),
                    "peak_abs_disp": dict(zip(axes, map(float, np.abs(d).max(axis=0)))),
                }
                for w, d in zip(np.asarray(ds["wrench"].values), disp)
            ],
            "duration_s": float(ds["time"].values[-1]),
            "n_samples": int(disp.shape[1]),
            "n_steps_per_rollout": int(ds.attrs["n_steps_per_rollout"]),
            "threads": int(ds.attrs["threads"]),
            "wall_s": float(ds.attrs["wall_s"]),
            "stepping": json.loads(ds.attrs["stepping"]),
            "pose": json.loads(ds.attrs["pose"]),
            "parameters": parameters,
            "resolution": resolution_of_parameters(parameters),
        }

    def table(self) -> str:
        """One row per rollout: wrench (N, N, N m), final and peak in-plane displacement (um), final rotation."""
        d = self.to_dict()
        heads = {"fx_n": "F_x (N)", "fy_n": "F_y (N)", "fz_n": "F_z (N)", "mz_nm": "M_z (N m)"}
        loads = [str(x) for x in self.dataset["load"].values]
        axes = [str(x) for x in self.dataset["axis"].values]
        lines = [
            f"{len(d['rollouts'])} rollouts of {d['duration_s']:.4g} s in {d['threads']} thread(s), "
            f"wall {d['wall_s']:.2f} s",
            " ".join(f"{heads[x]:>10}" for x in loads)
            + "".join(f" {'final ' + c + (' (urad)' if c == 'phi' else ' (um)'):>17}" for c in axes)
            + f" {'peak |xy| (um)':>15}",
        ]
        disp = np.asarray(self.dataset["ee_disp"].values)
        for r, dd in zip(d["rollouts"], disp):
            w, f = r["wrench"], list(r["final_disp"].values())
            peak = float(np.linalg.norm(dd[:, :2], axis=1).max())
            lines.append(
                " ".join(f"{w[x]:10.3g}" for x in loads)
                + "".join(f" {v * 1e6:17.4g}" for v in f)
                + f" {peak * 1e6:15.4g}"
            )
        st = d["stepping"]
        lines.append(f"integrator {st['integrator']}, step {st['step_s']:.3g} s, band {st['band_hz']:.4g} Hz")
        return "\n".join(lines)

    def plot(self, ax: Any = None) -> Any:
        """In-plane end-effector displacement magnitude over time, one line per rollout; the ``Figure``."""
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(figsize=(7, 4))
        ds = self.dataset
        t_ms = np.asarray(ds["time"].values) * 1e3
        for w, d in zip(np.asarray(ds["wrench"].values), np.asarray(ds["ee_disp"].values)):
            label = ", ".join(f"{n} {v:g}" for n, v in zip(ds["load"].values, w))
            ax.plot(t_ms, np.linalg.norm(d[:, :2], axis=1) * 1e6, lw=1, label=label)
        ax.set_xlabel("t (ms)")
        ax.set_ylabel("|end-effector displacement| (um)")
        ax.set_title(f"{ds.sizes['rollout']} batched rollouts from the static equilibrium", fontsize=9)
        ax.legend(fontsize=8)
        ax.figure.tight_layout()
        return ax.figure


def batched_rollouts(
    built: BuiltModel,
    manip: Manipulator | RolloutMachine,
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

    ``manip`` is the description ``built`` was made from (recorded in the attributes), or a described
    architecture's :class:`fpm_sim.sim.rollout.RolloutMachine` (then each row is a load along its coordinates: a
    force (N) per translational one, a moment about z (N m) for ``phi``); ``integrator``, ``band_hz``, ``f1_hz``:
    :func:`fpm_sim.sim.stepping.choose_stepping`.
    """
    from mujoco import rollout as mj_rollout

    coords = manip.coordinates if isinstance(manip, RolloutMachine) else ("x", "y", "phi")
    w = _checked_inputs(wrenches, threads, duration_s, output_step_s, coords)
    q0 = static_equilibrium(built.model, mujoco.MjData(built.model))
    try:
        stepping = choose_stepping(
            built, integrator=integrator, band_hz=band_hz, divides_s=output_step_s, f1_hz=f1_hz, qpos=q0
        )
    except SteppingError as e:
        raise reraise_as(BatchedRolloutError, e) from None
    model = apply_stepping(built, stepping).model
    h = float(model.opt.timestep)
    n_sub = max(1, round(output_step_s / h))
    n_out = round(duration_s / (n_sub * h))
    control = _control(model, w, coords)
    data = mujoco.MjData(model)
    data.qpos[:] = q0
    mujoco.mj_forward(model, data)
    ee0 = end_effector_coordinates(model, data, coords)
    spec = int(mujoco.mjtState.mjSTATE_FULLPHYSICS)
    nstate = mujoco.mj_stateSize(model, spec)
    s0 = np.empty(nstate)
    mujoco.mj_getState(model, data, s0, spec)
    n = w.shape[0]
    state = np.tile(s0, (n, 1))
    datas = [mujoco.MjData(model) for _ in range(threads)]
    disp = np.zeros((n, n_out + 1, len(coords)))
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
            disp[i, k] = end_effector_coordinates(model, probe, coords) - ee0
        if not np.all(np.isfinite(state)) or np.abs(disp[:, k, :2]).max() > model.stat.extent:
            raise BatchedRolloutError(
                f"a rollout diverged by t = {k * n_sub * h:.4g} s",
                hint="reduce the loads (wrenches) or the band (band_hz)",
            )
    wall = time.perf_counter() - start
    t = np.arange(n_out + 1) * n_sub * h
    return _dataset(w, disp, t, stepping, threads=threads, wall_s=wall, n_steps=n_out * n_sub, built=built, manip=manip)


def _control(model: mujoco.MjModel, w: np.ndarray, coords: tuple[str, ...]) -> np.ndarray:
    """The ``xfrc_applied`` control of each rollout: its load on the end effector's body (centre of mass at its
    site, checked), a force along each translational coordinate and a moment about z for ``phi``."""
    sid = end_effector_site_id(model)
    bid = int(model.site_bodyid[sid])
    if not np.allclose(model.body_ipos[bid], model.site_pos[sid], atol=1e-12):
        raise BatchedRolloutError(
            "the end effector's centre of mass is not at its site; wrench application unsupported"
        )
    control = np.zeros((w.shape[0], 1, 6 * model.nbody))
    slots = {"x": 0, "y": 1, "z": 2, "phi": 5}
    for k, c in enumerate(coords):
        control[:, 0, 6 * bid + slots[c]] = w[:, k]
    return control


def _checked_inputs(
    wrenches: ArrayLike, threads: int, duration_s: float, output_step_s: float, coords: tuple[str, ...]
) -> np.ndarray:
    """The wrenches as finite ``(n, len(coords))`` rows; ``threads`` an integer >= 1; both times positive and
    finite (s)."""
    w = np.atleast_2d(np.asarray(wrenches, float))
    if w.ndim != 2 or w.shape[1] != len(coords) or w.shape[0] < 1 or not np.all(np.isfinite(w)):
        names = ", ".join({"x": "F_x", "y": "F_y", "z": "F_z", "phi": "M_z"}[c] for c in coords)
        raise BatchedRolloutError(
            f"must be finite (n, {len(coords)}) rows {names}", parameter="wrenches", value=f"shape {w.shape}"
        )
    if not (isinstance(threads, int) and not isinstance(threads, bool) and threads >= 1):
        raise BatchedRolloutError("must be an integer >= 1", parameter="threads", value=threads)
    for name, v in (("duration_s", duration_s), ("output_step_s", output_step_s)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise BatchedRolloutError("must be a positive finite time", parameter=name, value=v)
    return w


def _dataset(
    w: np.ndarray,
    disp: np.ndarray,
    t: np.ndarray,
    stepping: Stepping,
    *,
    threads: int,
    wall_s: float,
    n_steps: int,
    built: BuiltModel,
    manip: Manipulator | RolloutMachine,
) -> Any:
    """The rollouts as an ``xarray.Dataset``: wrenches, end-effector displacements over time, how they were run."""
    import xarray as xr

    coords = manip.coordinates if isinstance(manip, RolloutMachine) else ("x", "y", "phi")
    return xr.Dataset(
        {
            "wrench": (("rollout", "load"), w, {"units": ", ".join("N m" if c == "phi" else "N" for c in coords)}),
            "ee_disp": (("rollout", "time", "axis"), disp, {"units": ", ".join(_UNIT[c] for c in coords)}),
        },
        coords={
            "rollout": np.arange(w.shape[0]),
            "time": ("time", t, {"units": "s"}),
            "axis": list(coords),
            "load": [_LOAD[c] for c in coords],
        },
        attrs={
            "stepping": json.dumps(stepping.to_dict()),
            "threads": threads,
            "wall_s": wall_s,
            "n_steps_per_rollout": n_steps,
            "description": manip.name if isinstance(manip, Manipulator) else str(built.parameters.get("config")),
            "parameters": json.dumps({k: v for k, v in built.parameters.items() if k != "pose"}, default=str),
            "pose": json.dumps(built.parameters.get("pose", {}), default=str),
        },
    )
