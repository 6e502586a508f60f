"""Dotted paths into a described architecture's file (:mod:`fpm_sim.architecture.edit`): an edit is the hand-edited
file, a shared section changes every link using it, the physics of the edit is beam theory's, errors name the path."""

from __future__ import annotations

import tomllib
import warnings
from pathlib import Path

import numpy as np
import pytest

from fpm_sim.architecture import (
    ParameterPathError,
    TaskPose,
    description_value,
    load_description,
    machine_parameter,
    parse_description,
    settable_paths,
    with_description_value,
    with_machine_parameter,
)
from fpm_sim.architecture.three_rrr import description_of_3rrr
from fpm_sim.beam_theory import euler_bernoulli_hz
from fpm_sim.config import Material, Section, default_config, with_parameter
from fpm_sim.config.schema import ConfigError
from fpm_sim.errors import FpmSimError
from fpm_sim.linear.analysis import analyse
from fpm_sim.model.general import build_general
from fpm_sim.model.options import ModelOptions

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "architectures"
FIVE_BAR = EXAMPLES / "five_bar.toml"


def _freqs(desc, pose, options, n=6):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return analyse(build_general(desc, pose, options), "constrained", n).frequencies_hz


def test_a_shared_section_changes_every_link_and_is_the_hand_edited_file():
    """Second route to the same machine: the five-bar's file with its one ``height_m`` line edited by hand. The two
    descriptions are equal (every field that makes the model), so their models are; every link took the height."""
    desc = load_description(FIVE_BAR)
    edited = with_description_value(desc, "sections.bar.height_m", 0.009)
    text = FIVE_BAR.read_text()
    assert text.count("height_m = 0.006") == 1
    by_hand = parse_description(tomllib.loads(text.replace("height_m = 0.006", "height_m = 0.009")))
    assert edited == by_hand
    assert edited != desc
    assert [lk.section.height_m for c in edited.chains for lk in c.links] == [0.009] * 4
    assert edited.provenance["sections.bar.height_m"] == "design study"
    assert edited.provenance["sections.bar.thickness_m"] == "example specification"
    assert edited.source_file == desc.source_file
    assert description_value(edited, "sections.bar.height_m") == 0.009
    assert description_value(desc, "sections.bar.height_m") == 0.006  # the original is left as it was


def test_a_link_by_chain_and_name_is_the_reader_s_indexed_path_and_changes_that_link_only():
    desc = load_description(FIVE_BAR)
    assert description_value(desc, "chains.left.proximal.length_m") == 0.18
    assert description_value(desc, "chains[0].path[1].length_m") == 0.18
    edited = with_description_value(desc, "chains.right.distal.length_m", 0.23)
    assert [lk.length_m for c in edited.chains for lk in c.links] == [0.18, 0.22, 0.18, 0.23]
    assert edited.provenance["chains[1].path[3].length_m"] == "design study"
    lump = with_description_value(desc, "lumps.elbow.inertia_kg_m2[2]", 3e-5)
    assert lump.chains[0].path[2].lump.inertia_kg_m2 == (2e-5, 2e-5, 3e-5)  # every joint carrying "elbow"
    assert lump.chains[1].path[2].lump.inertia_kg_m2 == (2e-5, 2e-5, 3e-5)


def test_every_settable_path_reads_and_setting_it_to_itself_changes_nothing():
    desc = load_description(FIVE_BAR)
    paths = settable_paths(desc)
    assert {"sections.bar.height_m", "materials.steel.young_pa", "chains.left.proximal.length_m"} <= set(paths)
    for path in paths:
        assert with_description_value(desc, path, description_value(desc, path)) == desc, path


_CANTILEVER = """
name = "cantilever"
kind = "spatial"
task = ["x", "y", "z"]
[materials.steel]
young_pa = 200e9
poisson = 0.3
density_kg_m3 = 7850.0
[sections.s]
shape = "rect"
thickness_m = 0.025
height_m = 0.006
[end_effector]
attachments_m = { tip = [0.0, 0.0, 0.0] }
[[chains]]
name = "beam"
path = [
  { joint = "root", type = "revolute", axis = [0, 0, 1], actuated = true },
  { link = "beam", length_m = 0.5, section = "s", material = "steel" },
  { joint = "tip", type = "fixed", at = "tip" },
]
"""


def test_editing_the_height_moves_the_out_of_plane_frequency_as_beam_theory_says():
    """A link clamped at a locked joint, its section's height edited from 6 to 9 mm: its out-of-plane f1 is
    Euler-Bernoulli's at each height to the resolution policy's promise (0.41 / n^2), and the ratio is exactly
    h2 / h1 (E I_out / (rho A) grows as h^2: the discretisation error, the same relative one at both heights,
    cancels; measured 3e-10, the finite-difference stiffness' round-off), while the in-plane f1 (I_in / A = t^2 / 12)
    does not move."""
    desc = parse_description(tomllib.loads(_CANTILEVER))
    options = ModelOptions(gravity=False, segments=12, axial=False)
    mat = Material(200e9, 0.3, 7850.0)
    out_of_plane, in_plane = [], []
    for h in (0.006, 0.009):
        f = _freqs(with_description_value(desc, "sections.s.height_m", h), TaskPose(0.5, 0.0, 0.0), options, n=2)
        truth = euler_bernoulli_hz("cantilever", length_m=0.5, section=Section(0.025, h), material=mat, plane="out")
        assert abs(f[0] / truth[0] - 1) < 0.41 / 12**2, (h, f, truth)
        out_of_plane.append(f[0])
        in_plane.append(f[1])
    assert out_of_plane[1] / out_of_plane[0] == pytest.approx(1.5, rel=1e-7)
    assert in_plane[1] == pytest.approx(in_plane[0], rel=1e-7)


def test_every_frequency_of_the_five_bar_grows_as_the_root_of_young_s_modulus():
    """Gravity off, every stiffness (bending, torsion through G = E / 2(1 + nu)) is proportional to E and no mass
    depends on it: four times E is twice every frequency (dimensional analysis; 1e-7 for the finite-difference
    stiffness, measured 1e-10)."""
    desc = load_description(FIVE_BAR)
    options = ModelOptions(gravity=False, segments=3)
    base = _freqs(desc, TaskPose(0.0, 0.25), options)
    stiff = _freqs(with_description_value(desc, "materials.steel.young_pa", 800e9), TaskPose(0.0, 0.25), options)
    np.testing.assert_allclose(stiff / base, 2.0, rtol=1e-7)


@pytest.mark.parametrize(
    ("path", "message", "settable"),
    [
        ("sections.bars.height_m", "no 'bars' under sections", "sections.bar.<thickness_m|height_m>"),
        ("sections.bar.depth_m", "no 'depth_m' under sections.bar", "sections.bar.thickness_m, sections.bar.height_m"),
        ("chains.middle.proximal.length_m", "no 'middle' under chains", "chains.left, chains.right"),
        ("chains.left.proximal.lenght_m", "no 'lenght_m'", "chains.left.proximal.length_m"),
        ("sections.bar", "sections.bar is a table, not a number", "sections.bar.height_m"),
        ("end_effector.lumps[3].mass_kg", "end_effector.lumps is a list of 1", "end_effector.lumps[0..0]"),
        ("speed", "no 'speed' at the top", "materials.<steel>, sections.<bar>"),
    ],
)
def test_an_unknown_path_names_itself_and_what_is_settable_where_it_failed(path, message, settable):
    desc = load_description(FIVE_BAR)
    for call in (lambda: description_value(desc, path), lambda: with_description_value(desc, path, 1.0)):
        with pytest.raises(ParameterPathError) as err:
            call()
        assert err.value.parameter == path
        assert message in err.value.message
        assert settable in (err.value.hint or "")


@pytest.mark.parametrize(
    ("path", "message"),
    [
        ("sections.bar.shape", "is not a number"),
        ("lumps.elbow.inertia_kg_m2", "is a list of 3 numbers"),
        ("check_poses[0].x_mm", "not a design parameter"),
        ("sections..height_m", "cannot read"),
    ],
)
def test_a_path_to_no_number_says_what_it_names(path, message):
    with pytest.raises(ParameterPathError, match=message) as err:
        with_description_value(load_description(FIVE_BAR), path, 1.0)
    assert err.value.parameter == path


def test_a_bad_value_is_the_reader_s_error_naming_the_path():
    """A negative height is what the reader says of a file with one: the same message, naming the same path."""
    desc = load_description(FIVE_BAR)
    with pytest.raises(ConfigError) as by_hand:
        parse_description(tomllib.loads(FIVE_BAR.read_text().replace("height_m = 0.006", "height_m = -0.001")))
    with pytest.raises(ConfigError) as edited:
        with_description_value(desc, "sections.bar.height_m", -0.001)
    assert str(edited.value) == str(by_hand.value) == "sections.bar.height_m: must be > 0, got -0.001"
    with pytest.raises(ConfigError, match=r"^chains.left.proximal.length_m: must be > 0, got -0.1"):
        with_description_value(desc, "chains.left.proximal.length_m", -0.1)
    with pytest.raises(ConfigError, match=r"^lumps.elbow.mass_kg: .*must be >= 0"):
        with_description_value(desc, "lumps.elbow.mass_kg", -1.0)
    with pytest.raises(ConfigError, match=r"^materials.steel.young_pa: must be a finite number, got nan"):
        with_description_value(desc, "materials.steel.young_pa", float("nan"))


def test_a_description_built_in_code_has_no_paths_and_says_how_to_get_them():
    with pytest.raises(ParameterPathError, match="built in code") as err:
        description_value(description_of_3rrr(default_config()), "sections.links.height_m")
    assert "load_description" in (err.value.hint or "")


def test_one_entry_point_for_both_forms():
    """``machine_parameter`` / ``with_machine_parameter`` take the 3RRR's dotted names on its description and paths
    into the file on a described architecture."""
    cfg = default_config()
    assert machine_parameter(cfg, "section.thickness_m") == cfg.section.thickness_m
    assert with_machine_parameter(cfg, "section.thickness_m", 0.02) == with_parameter(cfg, "section.thickness_m", 0.02)
    desc = load_description(EXAMPLES / "three_rrr.toml")
    assert machine_parameter(desc, "sections.links.thickness_m") == cfg.section.thickness_m
    edited = with_machine_parameter(desc, "sections.links.thickness_m", 0.02)
    assert edited.chains[2].links[1].section.thickness_m == 0.02
    with pytest.raises(FpmSimError):
        machine_parameter(cfg, "sections.links.thickness_m")
