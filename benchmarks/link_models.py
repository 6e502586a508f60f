"""Time per manipulator pose for each link model at its default resolution (issue 3).

(Was ``scripts/benchmark_link_models.py``.) One pose = build + static equilibrium + ``mjd_transitionFD`` linearisation
+ eigen-decomposition (``modes_transition_fd``), the symmetric manipulator (``benchmarks.common.SYMMETRIC_CONFIG``) at
(0, 0, 0); the parameter is the link model, so one run gives the ratios to ``segments``. ``track_f1_hz`` records each
model's first frequency (the flex's lower f1 is the model's, not its discretisation's: docs/link_models.md).

The flex runs only with ``FPM_SIM_BENCH_FULL=1``, and fails there today: at its default resolution (16) the
linearised step map of the symmetric manipulator has growing modes (``UnstableModelError``: 19 modes, the fastest
at 6.6e5 Hz, timestep 7.6e-7 s; measured 2 Dec 2026), where the history measured 2.33 s per pose. Its constrained
eigen-solve works (f1 46.19 Hz without gravity, as the history's 46.19 Hz) but took 239 s against 4.9 s for the
segments on the loaded machine, so it is no stand-in for a quick run. With the flex's bending damping scaled
(main, 0d12151) one growing mode is left: damping ratio -1.9e-6 at 48.9 Hz, still refused.
"""

from __future__ import annotations

import warnings

from benchmarks.common import require_full, symmetric_config, warm_imports


def _pose(link_model: str):
    from fpm_sim.kinematics import Pose
    from fpm_sim.linear.solvers import modes_transition_fd
    from fpm_sim.model.manipulator import build_manipulator
    from fpm_sim.model.options import ModelOptions

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # flex's SectionWarning / DampingWarning (docs/link_models.md)
        built = build_manipulator(symmetric_config(), Pose(0.0, 0.0, 0.0), ModelOptions(link_model=link_model))
        return modes_transition_fd(built, n_modes=1)


class LinkModels:
    """One whole pose per link model at its default resolution (``fpm_sim.model.parts.DEFAULT_RESOLUTION``)."""

    params = [["segments", "cable", "flex"]]
    param_names = ["link_model"]
    number = 1
    repeat = (1, 3, 60.0)  # seconds per pose: a few samples at most
    timeout = 300.0

    def setup(self, link_model: str) -> None:
        if link_model == "flex":
            require_full()
        warm_imports()

    def time_pose(self, link_model: str) -> None:
        _pose(link_model)

    def track_f1_hz(self, link_model: str) -> float:
        return float(_pose(link_model).frequencies_hz[0])

    track_f1_hz.unit = "Hz"
