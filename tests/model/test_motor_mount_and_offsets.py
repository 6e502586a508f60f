"""Motor-mount tilt compliance and stacked links (``geometry.distal_offset_m`` / ``platform_offset_m``) against
independent truths: the frequency equations of the spring-hinged cantilever and of the spring-held bar in
torsion, and an exact 3D Euler-Bernoulli frame (numpy, written here) for the static compliance of the stacked
manipulator."""

import dataclasses
import math

import mujoco
import numpy as np
import pytest
import scipy.linalg

from fpm_sim.batch.frequencies import pose_frequencies
from fpm_sim.batch.pose_loop import fast_options, solve_poses
from fpm_sim.beam_theory import spring_held_torsion_hz, spring_hinged_cantilever_hz
from fpm_sim.config import Compliance, Manipulator, Material, Section
from fpm_sim.kinematics import Pose, inverse_kinematics
from fpm_sim.linear.equilibrium import equality_jacobian
from fpm_sim.linear.solvers import modes_constrained
from fpm_sim.model.links import add_link
from fpm_sim.model.manipulator import add_motor_mount, build_manipulator, dof_kinds_of
from fpm_sim.model.options import ModelOptions
from fpm_sim.model.parts import LinkSpec
from fpm_sim.model.passive import dof_stiffness
from fpm_sim.model.spec import BuiltModel, compile_model, new_spec

SECTION = Section(0.02865, 0.0148)  # the default links' section: out-of-plane bending well apart from in-plane
STEEL = Material(200e9, 0.3, 7850.0)
LENGTH_M = 0.25


def _with_compliance(cfg: Manipulator, **changes: float) -> Manipulator:
    return cfg.replace(compliance=dataclasses.replace(cfg.compliance, **changes))


def _stacked(cfg: Manipulator, distal, platform) -> Manipulator:
    return cfg.replace(geometry=dataclasses.replace(cfg.geometry, distal_offset_m=distal, platform_offset_m=platform))


# --------------------------------------------------------------------------------------------- motor mount


def _mounted_cantilever(k_nm_per_rad: float, segments: int, *, rotary_inertia: bool = False) -> BuiltModel:
    """One link on a motor mount: the manipulator's own mount code (add_motor_mount) on a link fixed to the world."""
    spec = new_spec("motor_mount", gravity=False)
    link = add_link(
        spec,
        spec.worldbody,
        LinkSpec(
            name="link",
            pos_m=(0.0, 0.0, 0.0),
            angle_rad=0.0,
            length_m=LENGTH_M,
            section=SECTION,
            material=STEEL,
            segments=segments,
            axial=False,
            rotary_inertia=rotary_inertia,
        ),
    )
    kinds = dict(link.joints)
    add_motor_mount(link.first, "motor_0", Compliance(motor_mount_tilt_nm_per_rad=k_nm_per_rad), 0.0, kinds)
    model = compile_model(spec, timestep_s=None)
    return BuiltModel(model, spec, "motor_mount", {"link": link.sites}, dof_kinds_of(model, kinds))


def _modes_on(built: BuiltModel, kind: str, mount_joint: str, n: int) -> np.ndarray:
    """The lowest ``n`` modes living (> 99 % of the shape) on the ``kind`` springs and the mount's ``mount_joint``."""
    m = built.model
    names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, m.dof_jntid[i]) for i in range(m.nv)]
    on = np.array([kd == kind or nm == mount_joint for kd, nm in zip(built.dof_kinds, names)])
    res = modes_constrained(built, n_modes=10 * n)
    f = [md.frequency_hz for md in res.modes if np.sum(md.shape[on] ** 2) > 0.99 * np.sum(md.shape**2)]
    assert len(f) >= n
    return np.array(f[:n])


@pytest.mark.parametrize("ratio", [0.3, 3.0, 30.0])
def test_motor_mount_spring_matches_the_spring_hinged_cantilever(ratio):
    ei = STEEL.young_pa * SECTION.i_outofplane_m4
    k = ratio * ei / LENGTH_M  # K = k L / (E I)
    truth = spring_hinged_cantilever_hz(
        length_m=LENGTH_M, section=SECTION, material=STEEL, root_stiffness_nm_per_rad=k, n_modes=3
    )
    clamped = spring_hinged_cantilever_hz(
        length_m=LENGTH_M, section=SECTION, material=STEEL, root_stiffness_nm_per_rad=math.inf, n_modes=3
    )
    assert truth[0] < 0.95 * clamped[0]  # the spring matters at these stiffnesses (K = 30: -6 %; K = 0.3: -74 %)
    err = {n: _modes_on(_mounted_cantilever(k, n), "bend_out", "motor_0_mount_tilty", 3) / truth - 1 for n in (12, 24)}
    # 2e-3: the chain's discretisation error at 24 segments (measured <= 1.7e-3, mode 3 at K = 30; 4e-4 at K = 3)
    assert np.all(np.abs(err[24]) < 2e-3), err
    # and it converges to the spring-hinged beam: halving the pieces divides the error by 3.9-4.0 (second order),
    # 2.5 for mode 3 at K = 0.3 (pre-asymptotic there; 3.6 from 24 to 48 segments)
    assert np.all(np.abs(err[12]) / np.abs(err[24]) > 2.0), err


@pytest.mark.parametrize("ratio", [0.3, 3.0, 30.0])
def test_motor_mount_twist_spring_matches_the_spring_held_bar_in_torsion(ratio):
    gj = STEEL.shear_pa * SECTION.torsion_constant_m4
    k = ratio * gj / LENGTH_M  # K = k L / (G J)
    kw = dict(length_m=LENGTH_M, section=SECTION, material=STEEL, n_modes=2)
    truth = spring_held_torsion_hz(root_stiffness_nm_per_rad=k, **kw)
    assert truth[0] < 0.97 * spring_held_torsion_hz(root_stiffness_nm_per_rad=math.inf, **kw)[0]  # K = 30: -3 %
    # rotary_inertia: the pieces carry the section's polar inertia A (t^2 + h^2) / 12 (without it MuJoCo's
    # triangle inequality caps the twist inertia, see fpm_sim.model.parts.box_part)
    err = {
        n: _modes_on(_mounted_cantilever(k, n, rotary_inertia=True), "twist", "motor_0_mount_tiltx", 2) / truth - 1
        for n in (12, 24)
    }
    # 1.5e-3: the chain's discretisation error at 24 segments (measured <= 1.32e-3, mode 2 at K = 30)
    assert np.all(np.abs(err[24]) < 1.5e-3), err
    assert np.all(np.abs(err[12]) / np.abs(err[24]) > 3.9), err  # second order: measured 4.0


def test_motor_mount_adds_two_tilt_springs_per_motor(default_manip):
    pose = Pose(0.0, 0.0, 0.0)
    built = build_manipulator(
        _with_compliance(default_manip, motor_mount_tilt_nm_per_rad=1e4), pose, ModelOptions(segments=2)
    )
    assert built.dof_kinds.count("tilt") == 6
    m = built.model
    for i in range(3):
        for ax, axis in (("x", [1, 0, 0]), ("y", [0, 1, 0])):
            j = m.joint(f"motor_{i}_mount_tilt{ax}")
            assert m.body(j.bodyid[0]).name == f"proximal_{i}_b0"  # at the proximal link's root
            assert np.array_equal(j.axis, axis)
            assert j.stiffness[0] == 1e4
    rigid = build_manipulator(default_manip, pose, ModelOptions(segments=2))
    assert "tilt" not in rigid.dof_kinds  # inf (the default) adds nothing


POSES = [Pose(0.0, 0.0, 0.0), Pose.from_mm(30.0, -20.0, 0.1)]


def test_motor_mount_lowers_out_of_plane_modes_only(previous_default_manip):
    opts = fast_options(segments=8)

    def run(k: float):
        return pose_frequencies(
            _with_compliance(previous_default_manip, motor_mount_tilt_nm_per_rad=k), POSES, n_modes=8, options=opts
        )

    rigid, soft, stiff = run(math.inf), run(1e4), run(1e12)
    for p in range(len(POSES)):
        in_r, in_s = rigid.in_plane[p] > 0.5, soft.in_plane[p] > 0.5
        assert np.all((rigid.in_plane[p] < 1e-9) | (rigid.in_plane[p] > 1 - 1e-9))  # coplanar: pure modes
        n_in = min(in_r.sum(), in_s.sum())
        assert n_in >= 3
        # in-plane modes: the tilt springs are out-of-plane freedoms, decoupled from them in a coplanar model;
        # measured 0 at home and 8.5e-11 at the second pose (round-off)
        np.testing.assert_allclose(soft.frequencies_hz[p][in_s][:n_in], rigid.frequencies_hz[p][in_r][:n_in], rtol=1e-9)
        # out-of-plane modes: softer mounts lower each of them (measured -18 % to -33 % for the first three)
        out_r, out_s = rigid.frequencies_hz[p][~in_r][:3], soft.frequencies_hz[p][~in_s][:3]
        assert np.all(out_s < 0.9 * out_r), (out_s, out_r)
    # a very stiff mount is the rigid one: measured max 1.3e-6 relative on the frozen stop-14 description (7.8e-6
    # on the current default: the round-off depends on the masses), the round-off of 1e12 N m/rad springs
    # beside the links' ~1e3-1e4 N m/rad (the physical change, ~6e-9 at 1e12, is 5.6e-5 at 1e8)
    np.testing.assert_allclose(stiff.frequencies_hz, rigid.frequencies_hz, rtol=5e-6)


# --------------------------------------------------------------------------------------------- stacked links


def test_zero_offsets_are_the_coplanar_model_bit_for_bit(default_manip):
    pose = Pose.from_mm(20.0, -10.0, 0.1)
    ref = build_manipulator(default_manip, pose, ModelOptions(segments=3)).to_xml()
    for zero in (0.0, (0.0, 0.0, 0.0)):
        assert build_manipulator(_stacked(default_manip, zero, zero), pose, ModelOptions(segments=3)).to_xml() == ref


def test_offsets_stack_the_layers_and_keep_the_plane_kinematics(default_manip):
    pose = Pose.from_mm(20.0, -10.0, 0.1)
    dz_d, dz_p = (0.02, 0.03, 0.04), (0.01, 0.0, 0.025)
    flat = build_manipulator(default_manip, pose, ModelOptions(segments=3))
    stacked = build_manipulator(_stacked(default_manip, dz_d, dz_p), pose, ModelOptions(segments=3))
    d0, d1 = mujoco.MjData(flat.model), mujoco.MjData(stacked.model)
    mujoco.mj_forward(flat.model, d0)
    mujoco.mj_forward(stacked.model, d1)
    for i in range(3):
        for link, z in ((f"proximal_{i}", 0.0), (f"distal_{i}", dz_d[i])):
            for s in stacked.links[link]:
                assert np.allclose(d1.site(s).xpos[:2], d0.site(s).xpos[:2], atol=1e-12)
                assert d1.site(s).xpos[2] == pytest.approx(z, abs=1e-12)
        assert d1.site(f"pin_{i}_site").xpos[2] == pytest.approx(dz_d[i] + dz_p[i], abs=1e-12)
    assert np.allclose(d1.site("platform_center").xpos, [pose.x_m, pose.y_m, dz_d[0] + dz_p[0]], atol=1e-12)
    assert np.max(np.abs(d1.efc_pos[: d1.nefc])) < 1e-12  # the loops close at qpos0 with the layers


def _skew(r: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])


def _frame_element(p1: np.ndarray, p2: np.ndarray, sec: Section, mat: Material) -> np.ndarray:
    """12 x 12 stiffness (global axes) of a 3D Euler-Bernoulli beam with axial stretch and Saint-Venant torsion;
    the section's height along global z. DOFs: (u, theta) at p1, then at p2."""
    length = float(np.linalg.norm(p2 - p1))
    ex = (p2 - p1) / length
    ez = np.array([0.0, 0.0, 1.0])
    rot = np.vstack([ex, np.cross(ez, ex), ez])
    ea, gj = mat.young_pa * sec.area_m2, mat.shear_pa * sec.torsion_constant_m4
    ei_in, ei_out = mat.young_pa * sec.i_inplane_m4, mat.young_pa * sec.i_outofplane_m4
    k = np.zeros((12, 12))
    k[np.ix_([0, 6], [0, 6])] = ea / length * np.array([[1.0, -1.0], [-1.0, 1.0]])
    k[np.ix_([3, 9], [3, 9])] = gj / length * np.array([[1.0, -1.0], [-1.0, 1.0]])
    h = length
    bend = (
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
    k[np.ix_([1, 5, 7, 11], [1, 5, 7, 11])] = ei_in * bend  # in-plane: v with theta_z
    flip = np.diag([1.0, -1.0, 1.0, -1.0])  # out of plane: w with theta_y = -w'
    k[np.ix_([2, 4, 8, 10], [2, 4, 8, 10])] = ei_out * flip @ bend @ flip
    t = scipy.linalg.block_diag(rot, rot, rot, rot)
    return t.T @ k @ t


def _frame_platform_compliance(cfg: Manipulator, pose: Pose) -> np.ndarray:
    """6 x 6 compliance (translation, rotation) of the platform centre of the 3RRR as an exact beam frame.

    One element per link (exact for loads at the joints); motors clamped; each z-hinge leaves its child's
    rotation about z free and ties the rest; the offsets are rigid pins along z, the platform a rigid body.
    Unknowns: the platform (6), per chain the elbow node of the proximal link (6) and the z-rotations of the
    distal link's two ends (2).
    """
    g = cfg.geometry
    asm = inverse_kinematics(g, pose)
    dz_d, dz_p = g.distal_offset_per_chain, g.platform_offset_per_chain
    n = 6 + 3 * 8
    centre = np.array([pose.x_m, pose.y_m, dz_d[0] + dz_p[0]])
    k = np.zeros((n, n))
    for i in range(3):
        a, b = np.array([*asm.a[i], 0.0]), np.array([*asm.b[i], 0.0])
        b_up, c_up = np.array([*asm.b[i], dz_d[i]]), np.array([*asm.c[i], dz_d[i]])
        j = 6 + 8 * i
        t_a = np.zeros((6, n))  # clamped motor
        t_b = np.zeros((6, n))
        t_b[:, j : j + 6] = np.eye(6)
        t_bu = np.zeros((6, n))  # distal start: rigid pin on the elbow node, own rotation about z
        t_bu[0:3, j : j + 3] = np.eye(3)
        t_bu[0:3, j + 3 : j + 6] = -_skew(b_up - b)
        t_bu[3:5, j + 3 : j + 5] = np.eye(2)
        t_bu[5, j + 6] = 1.0
        t_cu = np.zeros((6, n))  # distal end: rigid with the platform (through the pin), own rotation about z
        t_cu[0:3, 0:3] = np.eye(3)
        t_cu[0:3, 3:6] = -_skew(c_up - centre)
        t_cu[3:5, 3:5] = np.eye(2)
        t_cu[5, j + 7] = 1.0
        for p1, t1, p2, t2 in ((a, t_a, b, t_b), (b_up, t_bu, c_up, t_cu)):
            t = np.vstack([t1, t2])
            k += t.T @ _frame_element(p1, p2, cfg.section, cfg.material) @ t
    return np.linalg.inv(k)[:6, :6]


def _model_platform_compliance(built: BuiltModel) -> np.ndarray:
    """6 x 6 static compliance of the platform centre of the MuJoCo model: the springs' stiffness on the
    null space of the loop closures (unloaded at qpos0, gravity off: no geometric stiffness)."""
    m = built.model
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    basis = scipy.linalg.null_space(equality_jacobian(m, d))
    jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    mujoco.mj_jacSite(m, d, jacp, jacr, m.site("platform_center").id)
    g = np.vstack([jacp, jacr]) @ basis
    return g @ np.linalg.solve(basis.T @ (dof_stiffness(m)[:, None] * basis), g.T)


SCALE = np.diag([1.0, 1.0, 1.0, 0.2, 0.2, 0.2])  # moments per 0.2 m and rotations times 0.2 m: comparable entries


@pytest.mark.parametrize(
    "offsets",
    [(0.0, 0.0), (0.03, 0.02), ((0.02, 0.03, 0.04), (0.01, 0.0, 0.025))],
    ids=["coplanar", "stacked", "per-chain"],
)
def test_stacked_static_compliance_matches_an_exact_beam_frame(default_manip, offsets):
    pose = Pose.from_mm(20.0, -10.0, 0.1)
    cfg = _stacked(default_manip, *offsets)
    truth = SCALE @ _frame_platform_compliance(cfg, pose) @ SCALE
    flat = SCALE @ _frame_platform_compliance(default_manip, pose) @ SCALE
    if offsets[0] != 0.0:
        # the layers matter: the in-plane compliances grow by 8-32 % (torsion and out-of-plane bending of the
        # proximal links under the distal links' forces, lever arm = the offsets); largest entry change measured
        # 18 % (stacked) and 7 % (per-chain) of the largest entry
        assert np.max(np.abs(truth - flat)) > 0.05 * np.max(np.abs(flat))
    err = {}
    for seg in (12, 24):
        built = build_manipulator(cfg, pose, ModelOptions(segments=seg, axial=True, gravity=False))
        got = SCALE @ _model_platform_compliance(built) @ SCALE
        err[seg] = np.max(np.abs(got - truth)) / np.max(np.abs(truth))
    # 5e-4: the spring chain's midpoint-rule error at 24 segments (measured 3.2e-4 in all three cases; a
    # cantilever's tip compliance is off by 1/(4 n^2) = 4.3e-4), second order (measured ratio 4.0)
    assert err[24] < 5e-4, err
    assert err[12] / err[24] > 3.5, err


def test_reposed_stacked_model_equals_the_per_pose_compile(default_manip):
    # The pose loop re-poses one compiled model by body orientations about z; the offsets sit in body positions
    # along z, which re-posing leaves as they are. 1e-9: as tests/batch/test_fast_frequencies.py (bit for bit here).
    cfg = _stacked(_with_compliance(default_manip, motor_mount_tilt_nm_per_rad=3e4), 0.03, (0.0, 0.01, 0.02))
    poses = [Pose(0.0, 0.0, 0.0), Pose.from_mm(-40.0, -30.0, 0.0), Pose.from_mm(30.0, 40.0, 0.15)]
    opts = fast_options(segments=3, axial=True)
    fast = solve_poses(cfg, poses, n_modes=5, options=opts)
    ref = solve_poses(cfg, poses, n_modes=5, options=opts, recompile=True)
    assert fast.status == ref.status == ["ok"] * 3
    np.testing.assert_allclose(fast.frequencies_hz, ref.frequencies_hz, rtol=1e-9)
    np.testing.assert_allclose(fast.in_plane, ref.in_plane, rtol=1e-9, atol=1e-12)
    # stacked layers couple in-plane and out-of-plane motion: the modes are no longer pure
    assert np.any((fast.in_plane > 1e-3) & (fast.in_plane < 1 - 1e-3))


def test_stacked_mounted_model_survives_the_mjcf_export(default_manip):
    cfg = _stacked(_with_compliance(default_manip, motor_mount_tilt_nm_per_rad=2e4), 0.03, (0.0, 0.01, 0.02))
    built = build_manipulator(cfg, Pose.from_mm(20.0, -10.0, 0.1), ModelOptions(segments=2))
    back = mujoco.MjModel.from_xml_string(built.to_xml())
    assert back.nv == built.model.nv
    for name in ("motor_0_mount_tiltx", "motor_2_mount_tilty"):
        assert back.joint(name).stiffness[0] == 2e4
    # the MJCF carries 6 significant digits: 5e-7 on positions below 1 m and on unit quaternions
    np.testing.assert_allclose(back.body_pos, built.model.body_pos, rtol=0, atol=5e-7)
    np.testing.assert_allclose(back.body_quat, built.model.body_quat, rtol=0, atol=5e-7)
    for i, z in enumerate((0.0, 0.01, 0.02)):  # the layer offsets come through exactly
        assert back.body(f"distal_{i}_b0").pos[2] == 0.03
        assert back.body(f"pin_{i}").pos[2] == z
