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


# --- Timoshenko ---------------------------------------------------------------------------------------

from fpm_sim.beam_theory import (  # noqa: E402
    shear_coefficient_rectangle,
    timoshenko_beam_hz,
    timoshenko_simply_supported_hz,
)

DEEP = dict(length_m=0.15, section=Section(0.030, 0.009), material=Material(200e9, 0.3, 7850))
"""The study's links: 30 mm deep in the plane on a ~150 mm span, where shear matters (~1.5 % on mode 1)."""


def test_cowper_coefficient_of_a_rectangle():
    assert shear_coefficient_rectangle(0.3) == pytest.approx(0.8496, abs=1e-4)
    assert shear_coefficient_rectangle(0.0) == pytest.approx(5.0 / 6.0)


def test_timoshenko_fe_converges_to_the_closed_form():
    # simply supported: the closed form is exact; the FE's error falls as 1/n^2 (measured at 100 elements:
    # 2.1e-6, 2.3e-5, 8.1e-5 on modes 1-3); tolerance about 1.5x the measured value per mode
    ref = [timoshenko_simply_supported_hz(n, **DEEP) for n in (1, 2, 3)]
    fe = timoshenko_beam_hz("pinned-pinned", n_modes=3, elements=100, **DEEP)
    for f, r, tol in zip(fe, ref, (3e-6, 3.5e-5, 1.2e-4)):
        assert f == pytest.approx(r, rel=tol)
    e50 = abs(timoshenko_beam_hz("pinned-pinned", n_modes=1, elements=50, **DEEP)[0] / ref[0] - 1)
    e100 = abs(fe[0] / ref[0] - 1)
    assert 3.5 < e50 / e100 < 4.5


def test_timoshenko_fe_without_corrections_is_euler_bernoulli():
    for bc in ("cantilever", "free-free"):
        fe = timoshenko_beam_hz(bc, n_modes=3, shear=False, rotary_inertia=False, **DEEP)
        assert fe == pytest.approx(euler_bernoulli_hz(bc, n_modes=3, **DEEP), rel=2e-6)


def test_timoshenko_lowers_the_deep_links_first_mode_by_about_1_5_percent():
    eb = euler_bernoulli_hz("cantilever", **DEEP)[0]
    ti = timoshenko_beam_hz("cantilever", n_modes=1, **DEEP)[0]
    assert -0.035 < ti / eb - 1 < -0.01


def test_segment_chain_with_shear_and_rotary_inertia_converges_to_timoshenko():
    import dataclasses

    from fpm_sim.config import default_config
    from fpm_sim.linear.analysis import rig_modes
    from fpm_sim.model.options import ModelOptions

    cfg = default_config()
    rig = dataclasses.replace(
        cfg.rig, length_m=DEEP["length_m"], clamped_length_m=0.0, section=DEEP["section"], material=DEEP["material"]
    )
    cfg = cfg.replace(rig=rig, material=DEEP["material"])
    ref = timoshenko_beam_hz("cantilever", n_modes=1, **DEEP)[0]
    eb = euler_bernoulli_hz("cantilever", **DEEP)[0]
    errs = []
    for n in (12, 24):
        opts = ModelOptions(segments=n, shear=True, rotary_inertia=True, gravity=False, axial=False)
        res = rig_modes(cfg, "cantilever", options=opts, n_modes=4, method="constrained")
        f = min(m.frequency_hz for m in res.modes if m.dominant in ("bend_in", "shear_in"))
        errs.append(f / ref - 1)
    # the chain's discretisation error falls as ~1/n^2 (as for Euler-Bernoulli: +0.16 % at 12 segments)
    assert abs(errs[1]) < 0.003
    assert abs(errs[1]) < abs(errs[0])
    # and the correction it captures is Timoshenko's, not Euler-Bernoulli's
    assert abs(errs[1]) < 0.25 * abs(eb / ref - 1)


def _clamped_link_frequencies(length_m, section, material, *, segments, hub_m, n=3):
    """First bending frequencies (in-plane) of one segment-chain link clamped at its start (no joint)."""
    import mujoco
    import scipy.linalg

    from fpm_sim.linear.matrices import mass_matrix
    from fpm_sim.model.links import add_link
    from fpm_sim.model.parts import LinkSpec
    from fpm_sim.model.passive import dof_stiffness
    from fpm_sim.model.spec import compile_model, new_spec

    spec = new_spec("hub_test", gravity=False)
    build = add_link(
        spec,
        spec.worldbody,
        LinkSpec(
            name="link",
            pos_m=(0.0, 0.0, 0.0),
            angle_rad=0.0,
            length_m=length_m,
            section=section,
            material=material,
            segments=segments,
            axial=False,
            hub_length_m=hub_m,
        ),
    )
    model = compile_model(spec, timestep_s=None)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    inplane = [
        model.jnt_dofadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, j)]
        for j, kind in build.joints
        if kind == "bend_in"
    ]
    k = dof_stiffness(model)[inplane]
    m = mass_matrix(model, data)[np.ix_(inplane, inplane)]
    w2 = scipy.linalg.eigh(np.diag(k), m, eigvals_only=True)[:n]
    return np.sqrt(w2) / (2 * np.pi)


import numpy as np  # noqa: E402


def test_rigid_hubs_match_the_beam_with_rigid_ends():
    # a 150 mm link with 20 mm rigid hubs at both ends, clamped at its start: the reference is the
    # Euler-Bernoulli FE of the 110 mm elastic span with the tip hub as a rigid body (beam_theory)
    kw = dict(length_m=0.15, section=Section(0.030, 0.009), material=Material(200e9, 0.3, 7850))
    ref = timoshenko_beam_hz("cantilever", n_modes=2, shear=False, rotary_inertia=False, hub_length_m=0.02, **kw)
    no_hub = euler_bernoulli_hz("cantilever", n_modes=2, **kw)
    e12 = _clamped_link_frequencies(segments=12, hub_m=0.02, n=2, **kw) / ref - 1
    e24 = _clamped_link_frequencies(segments=24, hub_m=0.02, n=2, **kw) / ref - 1
    # the chain's discretisation error, ~1/n^2 as without hubs: measured +0.028 % / +0.091 % (modes 1, 2) at
    # 24 segments, four times that at 12; tolerance 1.5x the measured values
    assert abs(e24[0]) < 4.5e-4
    assert abs(e24[1]) < 1.4e-3
    assert e12 / e24 == pytest.approx([4.0, 4.0], rel=0.05)
    assert ref[0] > 1.3 * no_hub[0]  # hubs matter: the same link flexible joint to joint is far softer


# --- spring-hinged cantilever -------------------------------------------------------------------------

import scipy.linalg  # noqa: E402

from fpm_sim.beam_theory import spring_hinged_cantilever_beta_l, spring_hinged_cantilever_hz  # noqa: E402


def _hermite_cantilever_with_root_spring_beta_l(ratio: float, *, elements: int = 50, n: int = 3) -> np.ndarray:
    """``beta_n L`` of a unit beam (E I = rho A = L = 1) by cubic Hermite finite elements, root deflection fixed,
    root rotation held by a spring ``ratio`` (= k L / E I): an independent numerical truth. 50 elements: its
    discretisation error on beta L is O(h^4), ~2e-7 at mode 3; the round-off of the dense solve grows with the
    spectrum's span (~1/h^4): ~9e-7 on the soft mode 1 at K = 0.1 here, 1e-3 at 400 elements."""
    h = 1.0 / elements
    ke = (
        np.array(
            [
                [12, 6 * h, -12, 6 * h],
                [6 * h, 4 * h * h, -6 * h, 2 * h * h],
                [-12, -6 * h, 12, -6 * h],
                [6 * h, 2 * h * h, -6 * h, 4 * h * h],
            ]
        )
        / h**3
    )
    me = (
        h
        / 420.0
        * np.array(
            [
                [156, 22 * h, 54, -13 * h],
                [22 * h, 4 * h * h, 13 * h, -3 * h * h],
                [54, 13 * h, 156, -22 * h],
                [-13 * h, -3 * h * h, -22 * h, 4 * h * h],
            ]
        )
    )
    size = 2 * (elements + 1)
    k, m = np.zeros((size, size)), np.zeros((size, size))
    for e in range(elements):
        s = slice(2 * e, 2 * e + 4)
        k[s, s] += ke
        m[s, s] += me
    k[1, 1] += ratio
    w2 = scipy.linalg.eigh(k[1:, 1:], m[1:, 1:], eigvals_only=True, subset_by_index=[0, n - 1])
    return np.sqrt(np.sqrt(w2))  # w = (beta L)^2 for the unit beam


@pytest.mark.parametrize("ratio", [0.1, 1.0, 10.0, 100.0])
def test_spring_hinged_roots_match_a_beam_fe(ratio):
    fe = _hermite_cantilever_with_root_spring_beta_l(ratio)
    # 2e-6: the 50-element FE's own error on beta L (measured <= 8.8e-7: round-off, mode 1 at K = 0.1)
    np.testing.assert_allclose(spring_hinged_cantilever_beta_l(ratio, 3), fe, rtol=2e-6)


def test_spring_hinged_roots_reach_the_clamped_and_pinned_limits():
    np.testing.assert_allclose(spring_hinged_cantilever_beta_l(math.inf, 5), BETA_L["cantilever"], rtol=1e-10)
    # a stiff spring: beta L approaches the clamped roots as 1 / K
    np.testing.assert_allclose(spring_hinged_cantilever_beta_l(1e9, 3), BETA_L["cantilever"][:3], rtol=1e-8)
    soft = spring_hinged_cantilever_beta_l(1e-8, 3)
    assert soft[0] == pytest.approx((3e-8) ** 0.25, rel=1e-6)  # the link swinging rigidly on its spring
    for bl in soft[1:]:  # then the pinned-free roots, tan = tanh (3.9266, 7.0686)
        assert math.tan(bl) - math.tanh(bl) == pytest.approx(0.0, abs=1e-6)
    assert soft[1] == pytest.approx(3.9266023120, rel=1e-8)
    with pytest.raises(ValueError, match="stiffness_ratio"):
        spring_hinged_cantilever_beta_l(0.0)


def test_spring_hinged_hz_uses_the_bending_plane():
    kw = dict(length_m=0.2, section=Section(0.01, 0.02), material=Material(200e9, 0.3, 7850), n_modes=3)
    stiff = spring_hinged_cantilever_hz(root_stiffness_nm_per_rad=math.inf, plane="out", **kw)
    np.testing.assert_allclose(stiff, euler_bernoulli_hz("cantilever", plane="out", **kw), rtol=1e-10)
    ei_out = 200e9 * kw["section"].i_outofplane_m4
    ei_in = 200e9 * kw["section"].i_inplane_m4
    f_out = spring_hinged_cantilever_hz(root_stiffness_nm_per_rad=ei_out / 0.2, plane="out", **kw)  # K = 1
    f_in = spring_hinged_cantilever_hz(root_stiffness_nm_per_rad=ei_in / 0.2, plane="in", **kw)  # K = 1 in plane
    np.testing.assert_allclose(f_out / f_in, 2.0, rtol=1e-10)  # the same root; sqrt(I) doubles out of plane


# --- spring-held bar in torsion -----------------------------------------------------------------------

from fpm_sim.beam_theory import spring_held_torsion_hz, spring_held_torsion_roots  # noqa: E402


def _linear_fe_torsion_roots(ratio: float, *, elements: int = 400, n: int = 3) -> np.ndarray:
    """``alpha_n L`` of a unit shaft (G J = rho I_p = L = 1) by linear elements with consistent inertia, the root
    rotation held by a spring ``ratio`` (= k L / G J): an independent numerical truth (error O(h^2))."""
    h = 1.0 / elements
    size = elements + 1
    k, m = np.zeros((size, size)), np.zeros((size, size))
    for e in range(elements):
        s = slice(e, e + 2)
        k[s, s] += np.array([[1.0, -1.0], [-1.0, 1.0]]) / h
        m[s, s] += h / 6.0 * np.array([[2.0, 1.0], [1.0, 2.0]])
    k[0, 0] += ratio
    w2 = scipy.linalg.eigh(k, m, eigvals_only=True, subset_by_index=[0, n - 1])
    return np.sqrt(w2)  # w = alpha L for the unit shaft


@pytest.mark.parametrize("ratio", [0.1, 1.0, 10.0, 100.0])
def test_spring_held_torsion_roots_match_a_shaft_fe(ratio):
    fe = _linear_fe_torsion_roots(ratio)
    # 2e-5: the 400-element FE's own error, (h alpha L)^2 / 24 relative: measured <= 1.6e-5 (mode 3, K = 100)
    np.testing.assert_allclose(spring_held_torsion_roots(ratio, 3), fe, rtol=2e-5)


def test_spring_held_torsion_limits_and_frequency():
    np.testing.assert_allclose(spring_held_torsion_roots(math.inf, 3), [math.pi / 2, 3 * math.pi / 2, 5 * math.pi / 2])
    np.testing.assert_allclose(spring_held_torsion_roots(1e9, 2), [math.pi / 2, 3 * math.pi / 2], rtol=1e-8)
    soft = spring_held_torsion_roots(1e-8, 3)
    assert soft[0] == pytest.approx(1e-4, rel=1e-6)  # rigid rotation on the spring: alpha L = sqrt(K)
    np.testing.assert_allclose(soft[1:], [math.pi, 2 * math.pi], rtol=1e-7)
    # clamped-free shaft: f1 = sqrt(G J / (rho I_p)) / (4 L)
    sec, mat = Section(0.02, 0.01), Material(200e9, 0.3, 7850)
    c = math.sqrt(mat.shear_pa * sec.torsion_constant_m4 / (mat.density_kg_m3 * sec.area_m2 * (0.02**2 + 0.01**2) / 12))
    f = spring_held_torsion_hz(length_m=0.3, section=sec, material=mat, root_stiffness_nm_per_rad=math.inf, n_modes=1)
    assert f[0] == pytest.approx(c / (4 * 0.3), rel=1e-12)
    with pytest.raises(ValueError, match="stiffness_ratio"):
        spring_held_torsion_roots(-1.0)
