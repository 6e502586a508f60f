"""Constructed causes of a growing step map (tests/linear/test_growth.py, tests/cli/test_modes_growth.py)."""

from __future__ import annotations

import copy
import dataclasses
from typing import Any

import numpy as np

from fpm_sim.linear import solvers
from fpm_sim.linear.matrices import forward_at, mass_matrix
from fpm_sim.model.spec import BuiltModel


def soften_under_gravity(monkeypatch: Any, shift_w2: float, *, always: bool = False) -> None:
    """The stiffness the constrained eigen-solve sees, softer by ``shift_w2 * M`` when the model has gravity (or
    ``always``): a constructed buckling under gravity's prestress."""
    original = solvers.stiffness_matrix

    def softer(model, data, qpos, eps=1e-7):  # type: ignore[no-untyped-def]
        k = original(model, data, qpos, eps=eps)
        if not (always or np.any(model.opt.gravity != 0.0)):
            return k
        forward_at(model, data, qpos)
        return k - shift_w2 * mass_matrix(model, data)

    monkeypatch.setattr(solvers, "stiffness_matrix", softer)


def with_step(built: BuiltModel, h: float) -> BuiltModel:
    """``built`` with the step ``h`` set on (a copy of) the compiled model, past the compile-time rule, and the
    welds' time constant ``2 h``, as compilation ties it to the step."""
    model = copy.copy(built.model)
    model.opt.timestep = h
    model.eq_solref[:, 0] = 2.0 * h
    return dataclasses.replace(built, model=model)
