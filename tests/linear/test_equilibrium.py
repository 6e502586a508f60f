import mujoco
import numpy as np
import pytest

from fpm_sim.config import RigConfig, Section
from fpm_sim.linear.equilibrium import EquilibriumError, static_equilibrium
from fpm_sim.model.options import ModelOptions
from fpm_sim.model.rigs import RigSetup, build_rig


def test_cantilever_sag_matches_beam_theory(steel_bar):
    """Tip deflection of a cantilever under its own weight: w = rho A g L^4 / (8 E I)."""
    bar = RigConfig(0.4, Section(0.01, 0.004), steel_bar.material)  # thin out of plane: visible sag
    built = build_rig(RigSetup("cantilever"), bar, ModelOptions(segments=20))
    m = built.model
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    a0 = np.max(np.abs(d.qacc))
    q = static_equilibrium(m, d)
    d.qpos[:] = q
    mujoco.mj_forward(m, d)
    tip = d.site(built.links["link_0"][-1]).xpos
    sec, mat = bar.section, bar.material
    w = mat.density_kg_m3 * sec.area_m2 * 9.81 * 0.4**4 / (8 * mat.young_pa * sec.i_outofplane_m4)
    # the discretisation's error on a static deflection at n = 20 is ~1/(2n^2) ~ 0.1 %; 1 % covers it
    assert -tip[2] == pytest.approx(w, rel=0.01)
    # equilibrium: the residual acceleration fell by the documented factor (rtol = 1e-5)
    assert np.max(np.abs(d.qacc)) <= 1e-5 * a0


def test_no_gravity_returns_qpos0(steel_bar):
    built = build_rig(RigSetup("cantilever"), steel_bar, ModelOptions(segments=4, gravity=False))
    assert np.array_equal(static_equilibrium(built.model), built.model.qpos0)


def test_floating_model_under_gravity_is_refused(steel_bar):
    built = build_rig(RigSetup("free-free"), steel_bar, ModelOptions(segments=4))
    m = built.model
    m.opt.gravity[:] = [0, 0, -9.81]
    with pytest.raises(EquilibriumError, match="gravity"):
        static_equilibrium(m)


def test_thin_links_closed_loops_converge(default_manip):
    """Regression: 5 mm links, 12 segments, axial springs (KKT condition number 1e14 unscaled)."""
    from fpm_sim.kinematics import Pose
    from fpm_sim.linear.equilibrium import applied_forces
    from fpm_sim.model.manipulator import build_manipulator

    built = build_manipulator(default_manip.with_section(thickness_m=0.005), Pose(0.0, 0.0, 0.0))
    m = built.model
    d = mujoco.MjData(m)
    q = static_equilibrium(m, d)
    f = applied_forces(m, d, q)
    rows = d.efc_type[: d.nefc] == mujoco.mjtConstraint.mjCNSTR_EQUALITY
    assert np.max(np.abs(d.efc_pos[: d.nefc][rows])) < 1e-12  # loops closed
    jac = d.efc_J[: d.nefc * m.nv].reshape(d.nefc, m.nv)[rows]
    lam = np.linalg.lstsq(jac.T, -f, rcond=None)[0]
    # gravity is balanced by springs and loop forces alone (relative imbalance at round-off level)
    assert np.max(np.abs(f + jac.T @ lam)) < 1e-8 * np.max(np.abs(applied_forces(m, d, m.qpos0)))
    assert np.max(np.abs(q)) > 1e-6  # and it did sag
