"""Modes of described architectures, against independent truths: the 3RRR's own builder, beam theory, refinement,
the machines' symmetries, and the rigid-link limit."""

from __future__ import annotations

import math
import tomllib
import warnings
from pathlib import Path

import numpy as np
import pytest

from fpm_sim.architecture import MobilityError, TaskPose, load_description, parse_description
from fpm_sim.architecture.three_rrr import description_of_3rrr
from fpm_sim.beam_theory import euler_bernoulli_hz
from fpm_sim.config import Material, Section, default_config
from fpm_sim.kinematics import Pose
from fpm_sim.linear.analysis import analyse
from fpm_sim.model.general import build_general
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import ModelOptions

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "architectures"
NO_GRAVITY = ModelOptions(gravity=False, fidelity="fast")


def _pose(p: dict[str, float]) -> TaskPose:
    return TaskPose(p.get("x", 0.0), p.get("y", 0.0), p.get("z", 0.0), p.get("phi", 0.0))


def _freqs(desc, pose, options=NO_GRAVITY, n=8, method="constrained"):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return analyse(build_general(desc, pose, options), method, n).frequencies_hz


@pytest.mark.parametrize("name", ["five_bar", "delta", "three_prr", "serial_arm"])
def test_every_machine_has_modes_at_every_check_pose(name):
    desc = load_description(EXAMPLES / f"{name}.toml")
    for p in desc.check_poses:
        f = _freqs(desc, _pose(p), n=6)
        assert len(f) == 6
        assert np.all(np.diff(f) >= 0)
        assert f[0] > 0.5


def test_the_3rrr_through_the_general_path_has_the_3rrr_builders_frequencies():
    """The study's machine written as a general description and built by the general builder gives the same
    model as the 3RRR's own builder: the same first eight frequencies to round-off of the inverse kinematics
    (1e-11 m in the joint positions) and of the finite-difference stiffness (measured 5e-11 to 3e-10)."""
    cfg = default_config()
    desc = description_of_3rrr(cfg)
    for x_mm, y_mm, phi in [(0.0, 0.0, 0.0), (50.0, -50.0, 0.1), (-40.0, 80.0, -0.2)]:
        native = analyse(build_manipulator(cfg, Pose.from_mm(x_mm, y_mm, phi), NO_GRAVITY), "constrained", 8)
        general = _freqs(desc, TaskPose.from_mm(x_mm, y_mm, 0.0, phi))
        np.testing.assert_allclose(general, native.frequencies_hz, rtol=1e-8)


def _cantilever(section_toml: str, rotation: str) -> str:
    return f"""
name = "oblique cantilever"
kind = "spatial"
task = ["x", "y", "z"]
[materials.steel]
young_pa = 200e9
poisson = 0.3
density_kg_m3 = 7850.0
[sections.s]
{section_toml}
[end_effector]
attachments_m = {{ tip = [0.0, 0.0, 0.0] }}
[[chains]]
name = "beam"
{rotation}
path = [
  {{ joint = "root", type = "revolute", axis = [0, 0, 1], actuated = true }},
  {{ link = "beam", length_m = 0.5, section = "s", material = "steel" }},
  {{ joint = "tip", type = "fixed", at = "tip" }},
]
"""


@pytest.mark.parametrize(
    ("section_toml", "section"),
    [
        ('shape = "tube"\nouter_diameter_m = 0.02\ninner_diameter_m = 0.016', None),
        ('shape = "rect"\nthickness_m = 0.01\nheight_m = 0.025', Section(0.01, 0.025)),
    ],
    ids=["tube", "rect"],
)
def test_an_oblique_link_is_a_beam_theory_cantilever_converging_at_second_order(section_toml, section):
    """A single link clamped at a locked joint, pointing along an oblique 3D direction: its bending frequencies
    in both planes are Euler-Bernoulli's, to the resolution policy's promise (0.41 / n^2 on the first frequency),
    and the error falls by 4 when the segments double (second order)."""
    rotation = "base_rotation_deg = 40.0\nbase_rotation_axis = [1.0, 2.0, 3.0]"
    desc = parse_description(tomllib.loads(_cantilever(section_toml, rotation)))
    mat = Material(200e9, 0.3, 7850.0)
    sec = section if section is not None else desc.chains[0].links[0].section
    truth = np.sort(
        np.concatenate(
            [
                euler_bernoulli_hz("cantilever", length_m=0.5, section=sec, material=mat, plane=p)[:1]
                for p in ("in", "out")
            ]
        )
    )
    tip = np.array(desc.chains[0].base_rotation) @ [0.5, 0.0, 0.0]  # the link straight along its base frame's x
    errors = []
    for n in (12, 24):
        f = _freqs(desc, TaskPose(*tip), ModelOptions(gravity=False, segments=n, axial=False), n=2)
        err = np.abs(f / truth - 1)
        assert np.all(err < 0.41 / n**2), (n, f, truth)
        errors.append(err)
    ratio = errors[0] / errors[1]
    assert np.all((ratio > 3.5) & (ratio < 4.5)), ratio


def test_the_delta_is_three_fold_symmetric_on_its_axis():
    """On the z axis the Delta turns into itself by 120 deg: its modes that are not symmetric come in equal pairs."""
    desc = load_description(EXAMPLES / "delta.toml")
    f = _freqs(desc, TaskPose(0.0, 0.0, -0.3), n=6)
    pairs = [(0, 1), (3, 4)]
    # the finite-difference stiffness (step 1e-7) moves each eigenvalue by ~1e-9 relative; a chain out of place
    # breaks a pair by 1e-4 or more
    for a, b in pairs:  # the two lowest pairs (measured: 65.9, 139.1 Hz at 8 segments)
        assert abs(f[a] / f[b] - 1) < 1e-7, f


def test_the_three_prr_is_three_fold_symmetric_at_home():
    desc = load_description(EXAMPLES / "three_prr.toml")
    f = _freqs(desc, TaskPose(), n=6)
    assert abs(f[1] / f[2] - 1) < 1e-7, f
    assert abs(f[4] / f[5] - 1) < 1e-7, f


def test_the_five_bar_is_mirror_symmetric_but_for_its_end_effector_s_turn():
    """Mirrored in the y axis (x -> -x) the five-bar is itself but for one thing: its end effector turns with distal
    link 1 (rigid on it), not with link 2. With the end effector's inertia about z removed (to 1e-12: MuJoCo wants
    it positive) the mirror images have the same frequencies; with it, the in-plane modes that turn it differ
    (measured 0.1 %), the others do not."""
    text = (EXAMPLES / "five_bar.toml").read_text()
    assert text.count("inertia_kg_m2 = [1e-4, 1e-4, 1e-4]") == 1
    no_turn = parse_description(
        tomllib.loads(
            text.replace("inertia_kg_m2 = [1e-4, 1e-4, 1e-4]", "inertia_kg_m2 = [1e-4, 1e-4, 1e-12]")
        )
    )
    left, right = _freqs(no_turn, TaskPose(-0.06, 0.3)), _freqs(no_turn, TaskPose(0.06, 0.3))
    # what still turns with the end effector is the pin of link 2's hinge (1e-9 kg m^2, MIN_BODY_MASS_KG's lump):
    # 1e-5 of the 1e-4 removed, so the 1e-3 difference shrinks to ~1e-8 (measured 1.2e-8)
    np.testing.assert_allclose(left, right, rtol=1e-6)
    desc = load_description(EXAMPLES / "five_bar.toml")
    left, right = _freqs(desc, TaskPose(-0.06, 0.3)), _freqs(desc, TaskPose(0.06, 0.3))
    same = np.abs(left / right - 1) < 1e-6
    assert 0 < np.count_nonzero(~same) < len(left)


@pytest.mark.parametrize("name", ["five_bar", "delta", "three_prr"])
def test_rigid_links_leave_no_modes_with_ideal_joints(name):
    """With rigid links, ideal joints and locked actuators a parallel machine is a rigid structure: nothing is left
    to vibrate (its hardware is rigid on the links)."""
    desc = load_description(EXAMPLES / f"{name}.toml")
    built = build_general(desc, _pose(desc.check_poses[0]), ModelOptions(gravity=False, link_model="rigid"))
    for method in ("constrained", "transition_fd"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            assert len(analyse(built, method, 1).frequencies_hz) == 0


def test_the_default_method_agrees_with_the_constrained_solve_on_the_delta():
    """transitionFD and the constrained eigen-solve on the Delta (ball joints, connect and weld closures): equal to
    the step's period error, (w h)^2 / 12 ~ 1e-6 at 150 Hz and h = 3e-7 s; 1e-5 leaves round-off room."""
    desc = load_description(EXAMPLES / "delta.toml")
    built = build_general(desc, TaskPose(0.05, 0.0, -0.32), NO_GRAVITY)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fd, con = analyse(built, "transition_fd", 6), analyse(built, "constrained", 6)
    np.testing.assert_allclose(fd.frequencies_hz, con.frequencies_hz, rtol=1e-5)


def test_a_machine_that_moves_with_its_actuators_locked_is_refused():
    text = (EXAMPLES / "five_bar.toml").read_text()
    text = text.replace(
        '{ joint = "motor", type = "revolute", axis = [0, 0, 1], actuated = true },\n  { link = "proximal", '
        'length_m = 0.180, section = "bar", material = "steel" },\n  { joint = "elbow", type = "revolute", axis '
        '= [0, 0, 1], lump = "elbow", branch_deg = [0, 180] }',
        '{ joint = "motor", type = "revolute", axis = [0, 0, 1] },\n  { link = "proximal", length_m = 0.180, '
        'section = "bar", material = "steel" },\n  { joint = "elbow", type = "revolute", axis = [0, 0, 1], lump = '
        '"elbow", branch_deg = [0, 180] }',
    )
    assert text.count("actuated = true") == 1
    desc = parse_description(tomllib.loads(text))
    with pytest.raises(MobilityError, match=r"keeps 1 degree\(s\) of freedom"):
        build_general(desc, TaskPose(0.0, 0.25), NO_GRAVITY)


def test_frequencies_do_not_depend_on_where_the_machine_stands():
    """Turning the whole five-bar about z (every chain's base) leaves its frequencies: a check of the frames."""
    text = (EXAMPLES / "five_bar.toml").read_text()
    desc = load_description(EXAMPLES / "five_bar.toml")
    base = _freqs(desc, TaskPose(0.0, 0.25))
    ang = math.radians(30.0)
    c, s = math.cos(ang), math.sin(ang)
    turned = text.replace("base_position_m = [-0.080, 0.0, 0.0]", f"base_position_m = [{-0.08 * c}, {-0.08 * s}, 0.0]")
    turned = turned.replace("base_position_m = [0.080, 0.0, 0.0]", f"base_position_m = [{0.08 * c}, {0.08 * s}, 0.0]")
    turned = turned.replace('path = [\n  { joint = "motor"', 'base_rotation_deg = 30.0\npath = [\n  { joint = "motor"')
    assert turned.count("base_rotation_deg = 30.0") == 2
    d2 = parse_description(tomllib.loads(turned))
    x, y = -0.25 * s, 0.25 * c
    np.testing.assert_allclose(_freqs(d2, TaskPose(x, y)), base, rtol=1e-8)
