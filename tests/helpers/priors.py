"""Priors texts shared by the calibration tests (the form :func:`fpm_sim.study.calibrate.read_priors` reads)."""

from __future__ import annotations

HARDWARE_PRIORS = """
[parameters."hardware.platform.mass_kg"]
dist = "loguniform"
lower = 0.5
upper = 5.0
reason = "assumed: test"
[parameters."hardware.elbow_joint.mass_kg"]
dist = "loguniform"
lower = 0.05
upper = 1.0
reason = "assumed: test"
[parameters."hardware.platform_joint.mass_kg"]
dist = "loguniform"
lower = 0.05
upper = 1.0
reason = "assumed: test"
"""
"""The three hardware masses, log-uniform over what a bench-top machine's can be."""


def height_and_discrepancy_priors(path: str = "section.height_m") -> str:
    """A link height's prior at ``path`` (log-uniform 5-30 mm, bar stock) and the model discrepancy's (0.5-50 %)."""
    return f"""
[parameters."{path}"]
dist = "loguniform"
lower = 0.005
upper = 0.03
reason = "assumed: bar stock"

[likelihood.discrepancy_rel]
dist = "loguniform"
lower = 0.005
upper = 0.5
reason = "assumed: model error"
"""
