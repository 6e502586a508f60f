import math

import pytest

from fpm_sim.beam_theory import BETA_L, euler_bernoulli_hz
from fpm_sim.config import Material, Section


def test_characteristic_roots_satisfy_their_equations():
    for bl in BETA_L["cantilever"]:
        assert math.cos(bl) + 1.0 / math.cosh(bl) == pytest.approx(0.0, abs=1e-9)
    for bl in BETA_L["free-free"]:
        assert math.cos(bl) - 1.0 / math.cosh(bl) == pytest.approx(0.0, abs=1e-9)


def test_probe_bar_values_from_engine_notes():
    # ENGINE_NOTES: steel 10 x 10 x 228 mm, cantilever 156.9 / 983.0 / 2752 Hz, free-free 998.1 / 2751 / 5394 Hz
    kw = dict(length_m=0.228, section=Section(0.01, 0.01), material=Material(200e9, 0.3, 7850))
    assert euler_bernoulli_hz("cantilever", **kw) == pytest.approx([156.9, 983.0, 2752], rel=1e-3)
    assert euler_bernoulli_hz("free-free", **kw) == pytest.approx([998.1, 2751, 5394], rel=1e-3)


def test_plane_selects_the_second_moment():
    kw = dict(length_m=0.2, section=Section(0.01, 0.02), material=Material(200e9, 0.3, 7850))
    f_in = euler_bernoulli_hz("cantilever", plane="in", **kw)
    f_out = euler_bernoulli_hz("cantilever", plane="out", **kw)
    assert f_out[0] / f_in[0] == pytest.approx(2.0)


def test_unknown_boundary():
    with pytest.raises(ValueError, match="boundary"):
        euler_bernoulli_hz("pinned", length_m=1, section=Section(0.01, 0.01), material=Material(1e9, 0.3, 1000))
