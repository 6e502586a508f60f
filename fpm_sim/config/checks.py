"""Checks of the numbers that enter outside the description (forces, counts): each raises
:class:`~fpm_sim.errors.FpmSimError` naming the parameter, its value and the allowed range."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from fpm_sim.errors import FpmSimError

__all__ = [
    "check_count",
    "check_finite",
]


def check_finite(name: str, value: Any, *, positive: bool = False) -> np.ndarray:
    """``value`` as a float array, all finite (and ``> 0`` with ``positive``).

    Raises :class:`FpmSimError` naming ``name`` otherwise."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise FpmSimError("must be a number", parameter=name, value=value) from None
    if not np.all(np.isfinite(arr)):
        raise FpmSimError("must be finite", parameter=name, value=value)
    if positive and not np.all(arr > 0):
        raise FpmSimError("must be positive", parameter=name, value=value)
    return arr


def check_count(name: str, value: Any, *, low: int = 1, high: int | None = None, hint: str = "") -> int:
    """``value`` as an integer in ``[low, high]``, else :class:`FpmSimError` naming ``name`` and the range."""
    ok = isinstance(value, (int, np.integer)) and not isinstance(value, bool)
    if not ok and isinstance(value, float) and math.isfinite(value) and value.is_integer():
        ok, value = True, int(value)
    if not ok or value < low or (high is not None and value > high):
        bound = f"[{low}, {high}]" if high is not None else f">= {low}"
        raise FpmSimError(f"must be an integer {bound}{hint}", parameter=name, value=value)
    return int(value)
