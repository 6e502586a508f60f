"""Time per manipulator pose for each link model at its default resolution (issue 3).

(Was ``scripts/benchmark_link_models.py``.) One pose = build + static equilibrium + ``mjd_transitionFD``
linearisation + eigen-decomposition (``modes_transition_fd``), default configuration at (0, 0, 0); the parameter
is the link model, so one run gives the ratios to ``segments``. ``track_f1_hz`` records each model's first
frequency (the flex's lower f1 is the model's, not its discretisation's: docs/link_models.md).
"""

from __future__ import annotations

import warnings


def _pose(link_model: str):
    from fpm_sim.config import default_config
    from fpm_sim.kinematics import Pose
    from fpm_sim.linear.modal import modes_transition_fd
    from fpm_sim.model.manipulator import build_manipulator
    from fpm_sim.model.options import ModelOptions

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # flex's SectionWarning / DampingWarning (docs/link_models.md)
        built = build_manipulator(default_config(), Pose(0.0, 0.0, 0.0), ModelOptions(link_model=link_model))
        return modes_transition_fd(built, n_modes=1)


class LinkModels:
    """One whole pose per link model at its default resolution (``fpm_sim.model.parts.DEFAULT_RESOLUTION``)."""

    params = [["segments", "cable", "flex"]]
    param_names = ["link_model"]
    number = 1
    repeat = (1, 3, 60.0)  # seconds per pose: a few samples at most
    timeout = 300.0

    def time_pose(self, link_model: str) -> None:
        _pose(link_model)

    def track_f1_hz(self, link_model: str) -> float:
        return float(_pose(link_model).frequencies_hz[0])

    track_f1_hz.unit = "Hz"
