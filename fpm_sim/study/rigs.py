"""The study's subsystem tests on their rigs: our first frequency of each (the cantilevers and the chain
of two links on a hinge described by ``config.rig``).

The rigs are solved by the constrained eigen-solve with gravity off (the free-free rig has no gravity
anyway; for the clamped rigs gravity's prestress is negligible: the links hang in the base plane with
gravity along the motor axes). Used by the reproduction, the identification and the calibration.
"""

from __future__ import annotations

from dataclasses import dataclass

from fpm_sim.config import Manipulator
from fpm_sim.linear.analysis import rig_modes
from fpm_sim.model.options import ModelOptions
from fpm_sim.study.tables import SubsystemTest, subsystem_tests

__all__ = ["SUBSYSTEM_SEGMENTS", "SubsystemResult", "subsystem_frequencies"]

SUBSYSTEM_SEGMENTS = 12
"""Spring locations per link for the subsystem rigs (cantilever mode 1 within +0.2 % of Euler-Bernoulli)."""


@dataclass
class SubsystemResult:
    """One subsystem test with our first frequency (Hz) and its mode's dominant spring kind."""

    test: SubsystemTest
    ours_hz: float
    dominant: str

    @property
    def error_pct(self) -> float:
        return 100.0 * (self.ours_hz / self.test.experimental_hz - 1.0)


def subsystem_frequencies(
    config: Manipulator, *, segments: int = SUBSYSTEM_SEGMENTS, tests: list[SubsystemTest] | None = None
) -> list[SubsystemResult]:
    """Our first frequency of each of the study's subsystem tests (rigs from ``config.rig``).

    Parameters
    ----------
    config
        The description; its ``rig`` table describes the test pieces.
    segments
        Spring locations per link of the rig models.
    tests
        The tests to solve (default: the study's, :func:`fpm_sim.study.tables.subsystem_tests`).
    """
    opts = ModelOptions(segments=segments, gravity=False)
    out = []
    for t in tests or subsystem_tests():
        res = rig_modes(config, t.rig, angle_deg=t.angle_deg, options=opts, n_modes=1, method="constrained")
        m = res.modes[0]
        out.append(SubsystemResult(t, float(m.frequency_hz), m.dominant))
    return out
