"""Property-based tests (hypothesis): every input either succeeds with finite, sane results or fails with an
FpmSimError that names the parameter. Few examples, tiny models (2-3 segments, gravity off), derandomised so
CI runs the same examples each time; the whole file runs in seconds."""

from __future__ import annotations

import dataclasses
import math
import re
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fpm_sim.config import default_config
from fpm_sim.config.checks import check_count, check_finite
from fpm_sim.errors import FpmSimError
from fpm_sim.kinematics import Pose
from fpm_sim.linear.mode_filter import ModeFilter
from fpm_sim.linear.solvers import modes_constrained
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import ModelOptions

FAST = settings(
    max_examples=8,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
TINY = ModelOptions(segments=2, axial=False, gravity=False)
BASE = default_config()
HOME = Pose(0.0, 0.0, 0.0)

any_float = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, -1.0, 1e-300, 1e300, math.nan, math.inf, -math.inf]),
)
size_float = st.one_of(
    st.floats(min_value=-1e3, max_value=1e3),
    st.sampled_from([0.0, -0.0, -1.0, 1e-300, math.nan, math.inf, -math.inf]),
)
"""Description values: magnitudes beyond 1e3 (m, kg, ...) overflow inside the section properties
(``thickness_m**3`` raises OverflowError near 1e102: config validation should bound them; reported)."""


def _sane(freq_hz: np.ndarray) -> None:
    assert freq_hz.size > 0
    assert np.all(np.isfinite(freq_hz))
    assert np.all(freq_hz > 0)
    assert np.all(np.diff(freq_hz) >= -1e-9 * freq_hz[1:])  # ascending


def _modes_or_named_error(config_fn, names: str) -> np.ndarray | None:
    """Build and solve; an FpmSimError must name one of ``names`` (regex); fewer modes than asked must be said."""
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            cfg = config_fn()
            res = modes_constrained(build_manipulator(cfg, HOME, TINY), n_modes=3)
    except FpmSimError as e:
        assert re.search(names, str(e), re.IGNORECASE), str(e)
        return None
    if len(res.modes) < 3:  # e.g. every mode overdamped by the stiffness-proportional damping: said, not silent
        assert any("physical modes" in str(w.message) for w in caught)
        if not res.modes:
            return None
    _sane(res.frequencies_hz)
    return res.frequencies_hz


@FAST
@given(value=size_float)
def test_section_thickness_is_valid_or_named(value):
    sec = dataclasses.replace
    _modes_or_named_error(lambda: BASE.replace(section=sec(BASE.section, thickness_m=value)), "thickness|section")


@FAST
@given(young=st.one_of(any_float, st.floats(1e6, 1e13)), density=st.one_of(size_float, st.floats(100, 1e5)))
def test_material_is_valid_or_named(young, density):
    _modes_or_named_error(
        lambda: BASE.replace(material=dataclasses.replace(BASE.material, young_pa=young, density_kg_m3=density)),
        "young|density|material",
    )


@FAST
@given(mass=size_float)
def test_platform_mass_is_valid_or_named(mass):
    def cfg():
        hw = BASE.hardware
        platform = dataclasses.replace(hw.platform, mass_kg=mass)
        return BASE.replace(hardware=dataclasses.replace(hw, platform=platform))

    _modes_or_named_error(cfg, "mass|platform|hardware")


@settings(max_examples=6, deadline=None, derandomize=True)
@given(young=st.floats(min_value=1e9, max_value=1e12))
def test_frequencies_scale_as_the_square_root_of_youngs_modulus(young):
    """Metamorphic truth the solver never sees: gravity off, every spring is proportional to E (bending EI,
    torsion GJ with G = E / 2(1 + nu)) and no mass depends on E, so f(4E) = 2 f(E) to round-off."""
    f = []
    for e in (young, 4.0 * young):
        cfg = BASE.replace(material=dataclasses.replace(BASE.material, young_pa=e))
        f.append(modes_constrained(build_manipulator(cfg, HOME, TINY), n_modes=4).frequencies_hz)
    np.testing.assert_allclose(f[1], 2.0 * f[0], rtol=1e-9)


@FAST
@given(x_mm=st.floats(-400, 400), y_mm=st.floats(-400, 400), phi=st.floats(-1.0, 1.0))
def test_any_pose_is_solved_or_refused_with_a_named_reason(x_mm, y_mm, phi):
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            built = build_manipulator(BASE, Pose.from_mm(x_mm, y_mm, phi), TINY)
            res = modes_constrained(built, n_modes=3)
    except FpmSimError as e:
        assert re.search("pose|unreachable|singular", str(e), re.IGNORECASE), str(e)
        return
    _sane(res.frequencies_hz)


@pytest.fixture(scope="module")
def tiny_home():
    return build_manipulator(BASE, HOME, TINY)


@FAST
@given(n=st.one_of(st.integers(-10, 500), st.floats(allow_nan=True), st.booleans(), st.none()))
def test_n_modes_is_bounded_or_named(tiny_home, n):
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = modes_constrained(tiny_home, n_modes=n)
    except FpmSimError as e:
        assert "n_modes" in str(e)
        return
    assert n is None or 1 <= len(res.modes) <= n
    _sane(res.frequencies_hz)


@FAST
@given(frac=any_float, ratio=any_float, zeta=any_float)
def test_mode_filter_is_valid_or_named(frac, ratio, zeta):
    try:
        ModeFilter(rigid_fraction=frac, max_constraint_ratio=ratio, max_damping_ratio=zeta)
    except FpmSimError as e:
        assert re.search("rigid_fraction|max_constraint_ratio|max_damping_ratio", str(e))
        assert not all(math.isfinite(v) and v >= 0 for v in (frac, ratio, zeta))
        return
    assert all(math.isfinite(v) and v >= 0 for v in (frac, ratio, zeta))


@settings(max_examples=50, deadline=None, derandomize=True)
@given(value=st.one_of(any_float, st.integers(-(10**6), 10**6), st.text(max_size=3), st.none(), st.booleans()))
def test_validation_helpers(value):
    try:
        n = check_count("widgets", value, low=1, high=100)
    except FpmSimError as e:
        assert "widgets" in str(e)
    else:
        assert 1 <= n <= 100
        assert not isinstance(value, (bool, str))
    try:
        arr = check_finite("force_n", value, positive=True)
    except FpmSimError as e:
        assert "force_n" in str(e)
    else:
        assert np.all(np.isfinite(arr))
        assert np.all(arr > 0)


@settings(max_examples=8, deadline=None, derandomize=True)
@given(force=any_float)
def test_rollout_load_is_simulated_or_refused(force):
    from fpm_sim.sim.rollout import RolloutError, constant, rollout

    manip = BASE
    built = build_manipulator(manip, HOME, ModelOptions(segments=2, axial=False))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = rollout(built, manip, duration_s=0.001, ee_wrench=constant(force, 0.0, 0.0))
    except RolloutError as e:
        assert re.search("force|ee_wrench|diverged", str(e)), str(e)
        return
    # a finite load gives a finite motion, within the model's size (else divergence is reported)
    assert np.all(np.isfinite(res.ee_disp))
    assert np.max(np.abs(res.ee_disp[:, :2])) <= built.model.stat.extent
