"""Moves x designs on the engine: one :func:`fpm_sim.sim.trajectory.simulate_move` per (design, move) task.

Where the models differ (each design is its own MuJoCo model), the threads of ``mujoco.rollout``
(:mod:`fpm_sim.sim.batched`) do not apply: each (design, move) pair is one task of :func:`fpm_sim.batch.engine.
run_chunks` (a local Dask cluster of processes with ``scheduler="local"``, a running cluster by address, or this
process). The result is an :class:`xarray.Dataset` over ``design`` and ``move``: the residual vibration's peak,
settling time and dominant frequency, the modal f1 and the dominant in-plane mode at the end pose, and the peak
tracking error and deflection.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from fpm_sim.batch.engine import EngineOptions, run_chunks
from fpm_sim.config import Manipulator
from fpm_sim.model.options import ModelOptions
from fpm_sim.sim.trajectory import MovePath, simulate_move

__all__ = ["MOVE_SUMMARY_FIELDS", "move_summary", "moves_over_designs"]

MOVE_SUMMARY_FIELDS = (
    "residual_peak_m",
    "settling_time_s",
    "dominant_hz",
    "modal_f1_hz",
    "inplane_mode_hz",
    "peak_tracking_error_m",
    "peak_deflection_m",
    "move_end_s",
)
"""The numbers kept per (design, move) (SI units; ``settling_time_s`` is ``inf`` when not settled)."""


def move_summary(item: tuple[Manipulator, MovePath], **kwargs: Any) -> dict[str, float]:
    """One task: ``simulate_move(design, path, **kwargs)`` reduced to :data:`MOVE_SUMMARY_FIELDS`."""
    manip, path = item
    res = simulate_move(manip, path, **kwargs)
    d = res.to_dict()
    r = res.residual
    return {
        "residual_peak_m": r.peak_m,
        "settling_time_s": r.settling_time_s,
        "dominant_hz": r.dominant_hz,
        "modal_f1_hz": r.modal_f1_hz,
        "inplane_mode_hz": r.inplane_mode_hz,
        "peak_tracking_error_m": d["peak_tracking_error_m"],
        "peak_deflection_m": d["peak_deflection_m"],
        "move_end_s": res.move_end_s,
    }


def moves_over_designs(
    designs: Sequence[Manipulator],
    paths: Sequence[MovePath],
    *,
    settle_s: float = 0.3,
    options: ModelOptions | None = None,
    shaper_kind: str = "none",
    engine: EngineOptions | None = None,
) -> Any:
    """Every move of ``paths`` on every description of ``designs`` (module docstring); an xarray Dataset."""
    import xarray as xr

    items = [(m, p) for m in designs for p in paths]
    kw = {"settle_s": settle_s, "options": options, "shaper_kind": shaper_kind}
    eng = engine or EngineOptions(desc="moves")
    rows = run_chunks(move_summary, items, kwargs=kw, options=eng)
    shape = (len(designs), len(paths))
    data: dict[str, Any] = {
        f: (("design", "move"), np.array([r[f] for r in rows], float).reshape(shape)) for f in MOVE_SUMMARY_FIELDS
    }
    data["design_name"] = (("design",), np.array([m.name for m in designs], dtype=str))
    return xr.Dataset(
        data,
        coords={"design": np.arange(len(designs)), "move": np.arange(len(paths))},
        attrs={"shaper": shaper_kind, "settle_s": settle_s},
    )
