"""Truths shared by tests and studies: the tests' reference manipulator and the impact road's hidden truth.

``tests/study/test_identify_uff.py`` (the modal-FRF road) and ``tests/study/test_identify_impact_road.py`` (the
time-domain road) take their start and truth from here, and ``studies/impact_road_scatter.py`` reruns the impact
road's rollouts with the same truth, poses and settings over many noise draws: it imports this module, not a test
module. Importing it imports no test and no ``conftest``.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

from fpm_sim.config import Geometry, LumpedMass, Manipulator, load_config

PREVIOUS_DEFAULT_CONFIG = Path(__file__).resolve().parents[1] / "data" / "previous_default_3rrr.toml"
"""The default as identified in stop 14 (frozen copy; ``tests/conftest.py`` names the same file)."""


REFERENCE_GEOMETRY = Geometry(
    0.1526,
    tuple(math.radians(a) for a in (150.8546, -89.1454, 30.8546)),
    0.1515,
    0.1535,
    0.0874,
    tuple(math.radians(a) for a in (-178.6021, -58.6021, 61.3979)),
    (-1, -1, -1),
)
"""The geometry many tests measured their numbers on (the embedded default before the identify re-run): they are
about kinematics, surrogates and roads, not about whichever geometry the default holds now."""


def reference_config() -> Manipulator:
    """The tests' own manipulator (shared by the modal-FRF and the impact roads): :data:`REFERENCE_GEOMETRY`, away
    from singularities at the roads' poses, on the frozen previous default with a 4.79 kg platform."""
    geo = REFERENCE_GEOMETRY
    cfg = load_config(PREVIOUS_DEFAULT_CONFIG)  # frozen: re-identifying the embedded default must not move it
    plat = LumpedMass(4.79, (4.79e-3, 4.79e-3, 9.58e-3 * (1 - 1e-6)))
    return cfg.replace(geometry=geo, hardware=dataclasses.replace(cfg.hardware, platform=plat))


# ------------------------------------------------------------------------ the impact road (time domain)
SEGMENTS = 3
"""The impact road's model: 3 segments per link without axial springs, the coarsest flexible model (its automatic
timestep is 5 us, so one 0.5 s impact record takes about 4 s of CPU); the fit uses the same."""
POSES_MM = [(0.0, 0.0, 0.2), (-100.0, -50.0, 0.0), (50.0, 100.0, 0.0), (100.0, 100.0, 0.0)]
"""Poses where a driving-point test at mid-span of distal_0 sees the truth's first mode of each kind as its first
FRF peak, that mode at least 25 Hz from any other (screened with the modal FRF). Not every pose is like this: at
(-50, 50, 0) mm the first in-plane mode (34 Hz) rises only 1.8 dB out of the accelerance there, below the EMA's
3 dB prominence, and the first in-plane peak read is the second in-plane mode (159 Hz), 1 Hz from an
out-of-plane one: a lab has to check what the first peak of a test is before labelling it. At (0, 100, 0) mm the
first in-plane mode (40 Hz) rises 5 dB: read, but noise moves it by up to +0.6 % (0.01 m/s^2, 5 seeds)."""
AXES = {"normal": "in_plane", "z": "out_of_plane"}
"""Hammer and accelerometer axis -> the kind of modes that test sees (in the plane, normal to the link / along the
motor axes: the structure is planar, the two families decouple without gravity)."""
TRUTH_SECTION_M = {"thickness_m": 0.0265, "height_m": 0.0162}
"""The hidden truth: the reference description with these links (start: 28.65 mm x 14.80 mm, i.e. -7.5 % and
+9.5 %); the identification starts from the reference and never sees these values."""
NOISE_M_S2 = 0.01
"""Accelerometer noise (m/s^2 rms per 0.1 ms sample; the 20 N tap peaks at ~11 m/s^2): a good accelerometer's floor."""
SIGMA_PCT = 0.2
"""Relative std given to each EMA frequency: the EMA's scatter measured at these settings (in the road test),
in-plane."""
