"""The public entry points, one per capability (re-exported lazily by :mod:`fpm_sim`)."""

from __future__ import annotations

from fpm_sim.linear.analysis import manipulator_modes, rig_modes

__all__ = ["manipulator_modes", "rig_modes"]
