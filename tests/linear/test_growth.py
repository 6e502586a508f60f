"""A step map that grows says which cause it is (issue 32): the structure (buckling), the step, or the linearisation.

No configuration of the 3RRR buckles under its own gravity (out of plane, gravity stiffens its near-singular mode:
0.21 -> 0.58 Hz at (-99.4, 50, 0) mm; a heavy payload makes the equilibrium solve fail before any stiffness turns
negative), and compilation refuses the steps at which the springs' step grows: both causes are constructed here,
the buckling by softening the gravity-prestressed stiffness the constrained eigen-solve sees, the step by setting
one beyond the compile-time rule on the compiled model.
"""

from __future__ import annotations

import re
import warnings

import numpy as np
import pytest

from fpm_sim.kinematics import NearSingularityWarning, Pose
from fpm_sim.linear.equilibrium import static_equilibrium
from fpm_sim.linear.solvers import (
    BucklingError,
    CoarseTimestepError,
    growth_error,
    modes_constrained,
    modes_transition_fd,
)
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import ModelOptions
from fpm_sim.model.spec import highest_frequency_rad_s
from tests.helpers.growth import soften_under_gravity, with_step

pytestmark = pytest.mark.filterwarnings("ignore::fpm_sim.kinematics.NearSingularityWarning")

NEAR = Pose(-0.0994, 0.050, 0.0)  # near the parallel singularity of the default (measure 0.0015)


def _build(manip, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NearSingularityWarning)
        return build_manipulator(manip, NEAR, ModelOptions(segments=3, **kw))


def test_buckling_under_gravity_says_so_with_the_singularity_measure_and_f1_without_gravity(
    default_manip, monkeypatch
):
    built = _build(default_manip)
    f1 = modes_constrained(built, n_modes=1).frequencies_hz[0]
    f1_free = modes_constrained(_build(default_manip, gravity=False), n_modes=1).frequencies_hz[0]
    soften_under_gravity(monkeypatch, (2 * np.pi * f1) ** 2 + (2 * np.pi * 0.5) ** 2)
    with pytest.raises(BucklingError) as err:
        raise growth_error(built, static_equilibrium(built.model), ["damping ratio -0.1 at 0.5 Hz"])
    text = str(err.value)
    assert "buckles under gravity's prestress" in text
    assert f"singularity measure {built.parameters['singularity_measure']:.3g}" in text
    assert f"without gravity it is stable with f1 = {f1_free:.3g} Hz" in text
    assert "no timestep_s helps" in text
    assert " or timestep" not in text


def test_an_unstable_structure_without_gravity_is_not_blamed_on_gravity(default_manip, monkeypatch):
    built = _build(default_manip)
    soften_under_gravity(monkeypatch, 1e6, always=True)
    with pytest.raises(BucklingError, match=r"unstable at this pose .* even without gravity") as err:
        raise growth_error(built, static_equilibrium(built.model), ["real growth rate 3 1/s"])
    assert "buckles" not in str(err.value)


def test_a_too_coarse_step_says_so_and_names_a_step_that_works(default_manip):
    built = _build(default_manip)
    coarse = with_step(built, 100.0 / highest_frequency_rad_s(built.model))  # the compile rule stops at 2 / w_max
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(CoarseTimestepError) as err:
            modes_transition_fd(coarse, n_modes=2)
    assert err.value.parameter == "timestep_s"
    text = str(err.value)
    assert f"{coarse.timestep_s:.3g} s is too coarse" in text
    assert "the equilibrium is stable" in text
    works = float(re.search(r"timestep_s=(\S+) s works", text).group(1))
    assert works < coarse.timestep_s
    # it does work: the step map at that step grows nowhere, and gives the constrained f1
    res = modes_transition_fd(with_step(built, works), n_modes=1)
    assert res.frequencies_hz[0] == pytest.approx(modes_constrained(built, n_modes=1).frequencies_hz[0], rel=1e-2)
