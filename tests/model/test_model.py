import pytest

from fpm_sim.model.options import ModelOptions, TimestepError
from fpm_sim.model.parts import LinkModelError
from fpm_sim.model.rigs import RigSetup, build_rig
from fpm_sim.model.spec import TIMESTEP_SAFETY, highest_frequency_rad_s


def test_automatic_timestep_follows_the_stiffest_spring(steel_bar):
    b = build_rig(RigSetup("cantilever"), steel_bar, ModelOptions(segments=8))
    w = highest_frequency_rad_s(b.model)
    assert b.timestep_s == pytest.approx(TIMESTEP_SAFETY / w, rel=1e-9)
    # refining raises omega_max ~ n^2 (bending) or n (axial) and shrinks the step
    b2 = build_rig(RigSetup("cantilever"), steel_bar, ModelOptions(segments=16))
    assert b2.timestep_s < b.timestep_s


def test_unstable_timestep_is_refused(steel_bar):
    with pytest.raises(TimestepError, match="timestep_s"):
        build_rig(RigSetup("cantilever"), steel_bar, ModelOptions(segments=8, timestep_s=1e-4))


@pytest.mark.parametrize(
    ("kw", "match"), [({"link_model": "noodle"}, "unknown link model"), ({"segments": 0}, "segments")]
)
def test_bad_link_options(kw, match):
    with pytest.raises(LinkModelError, match=match):
        ModelOptions(**kw)
