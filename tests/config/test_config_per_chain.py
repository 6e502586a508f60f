"""Per-chain geometry in the description and the TOML writer (round trip with provenance)."""

import dataclasses
import math
import tomllib

import numpy as np
import pytest

from fpm_sim.config import ConfigError, default_config
from fpm_sim.config.schema import config_to_toml, load_config, parse_config
from fpm_sim.kinematics import Pose, inverse_kinematics


def _per_chain(cfg, **fields):
    return cfg.replace(geometry=dataclasses.replace(cfg.geometry, **fields))


def test_toml_round_trip_keeps_values_and_provenance(tmp_path):
    cfg = default_config()
    text = config_to_toml(cfg, header="round trip")
    back = parse_config(tomllib.loads(text), source="x")
    assert back == cfg
    for key, src in cfg.provenance.items():
        assert back.provenance[key] == src


def test_per_chain_lengths_parse_write_and_load(tmp_path):
    cfg = _per_chain(default_config(), proximal_length_m=(0.150, 0.155, 0.16), base_radius_m=(0.15, 0.152, 0.154))
    p = tmp_path / "c.toml"
    p.write_text(config_to_toml(cfg))
    back = load_config(p)
    assert back.geometry.proximal_length_per_chain == (0.150, 0.155, 0.16)
    assert back.geometry.base_radius_per_chain == (0.15, 0.152, 0.154)
    assert isinstance(back.geometry.distal_length_m, float)  # a symmetric field stays a scalar
    assert not back.geometry.is_symmetric_in_lengths()


def test_per_chain_bad_entry_names_its_index():
    cfg = default_config()
    with pytest.raises(ConfigError, match=r"geometry.proximal_length_m\[1\]"):
        _per_chain(cfg, proximal_length_m=(0.15, -0.1, 0.15)).replace()
    import re

    text = re.sub(
        r"proximal_length_m = \{ value = [0-9.e-]+", "proximal_length_m = { value = [0.15, 0.15]", config_to_toml(cfg)
    )
    assert "[0.15, 0.15]" in text
    with pytest.raises(ConfigError, match=r"proximal_length_m.*list of 3"):
        parse_config(tomllib.loads(text))


def test_per_chain_kinematics_closes_every_loop():
    # independent check: each chain's joint distances equal its own link lengths
    l1, l2 = (0.148, 0.152, 0.157), (0.151, 0.16, 0.149)
    cfg = _per_chain(default_config(), proximal_length_m=l1, distal_length_m=l2, platform_radius_m=(0.085, 0.09, 0.088))
    asm = inverse_kinematics(cfg.geometry, Pose.from_mm(20, -10, 0.1), check_singularity=False)
    np.testing.assert_allclose(np.linalg.norm(asm.b - asm.a, axis=1), l1, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(asm.c - asm.b, axis=1), l2, rtol=0, atol=1e-12)
    r = np.linalg.norm(asm.c - np.array([0.020, -0.010]), axis=1)
    np.testing.assert_allclose(r, (0.085, 0.09, 0.088), atol=1e-12)


def test_equal_per_chain_values_give_the_scalar_model():
    from fpm_sim.batch.frequencies import pose_frequencies
    from fpm_sim.batch.pose_loop import fast_options

    cfg = default_config()
    g = cfg.geometry
    tri = _per_chain(cfg, proximal_length_m=(g.proximal_length_m,) * 3, distal_length_m=(g.distal_length_m,) * 3)
    poses = [Pose.from_mm(0, 0, 0.2), Pose.from_mm(50, -50, 0)]
    a = pose_frequencies(cfg, poses, n_modes=3, options=fast_options(segments=3)).frequencies_hz
    b = pose_frequencies(tri, poses, n_modes=3, options=fast_options(segments=3)).frequencies_hz
    np.testing.assert_allclose(a, b, rtol=1e-12)
    assert math.isfinite(a[0, 0])


def test_stacked_offsets_and_motor_mount_round_trip_with_provenance():
    cfg = default_config()
    assert cfg.geometry.distal_offset_per_chain == (0.0, 0.0, 0.0)
    assert math.isinf(cfg.compliance.motor_mount_tilt_nm_per_rad)
    assert cfg.provenance["compliance.motor_mount_tilt_nm_per_rad"].startswith("assumed: rigid")
    assert "offset" not in config_to_toml(cfg)  # coplanar (0) is not written, as hub_length_m
    stacked = _per_chain(cfg, distal_offset_m=0.025, platform_offset_m=(0.01, 0.0, 0.02))
    stacked = stacked.replace(compliance=dataclasses.replace(cfg.compliance, motor_mount_tilt_nm_per_rad=4e4))
    prov = dict(stacked.provenance, **{"geometry.distal_offset_m": "assumed: 25 mm layer"})
    stacked = dataclasses.replace(stacked, provenance=prov)
    back = parse_config(tomllib.loads(config_to_toml(stacked)), source="x")
    assert back == stacked
    assert back.geometry.platform_offset_per_chain == (0.01, 0.0, 0.02)
    assert back.provenance["geometry.distal_offset_m"] == "assumed: 25 mm layer"
    assert back.provenance["geometry.platform_offset_m"] == "unknown"  # the writer's default source
    assert back.compliance.motor_mount_tilt_nm_per_rad == 4e4


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"distal_offset_m": math.nan}, r"^geometry\.distal_offset_m: must be a finite height"),
        ({"platform_offset_m": (0.0, math.inf, 0.0)}, r"geometry\.platform_offset_m\[1\]"),
    ],
)
def test_bad_offsets_name_the_field(change, match):
    with pytest.raises(ConfigError, match=match):
        _per_chain(default_config(), **change)


@pytest.mark.parametrize(("value", "match"), [(0.0, "is 0: that is a free joint"), (-5.0, ">= 0"), (math.nan, ">= 0")])
def test_bad_motor_mount_stiffness_names_the_field(value, match):
    cfg = default_config()
    with pytest.raises(ConfigError, match=r"compliance\.motor_mount_tilt_nm_per_rad.*" + match):
        cfg.replace(compliance=dataclasses.replace(cfg.compliance, motor_mount_tilt_nm_per_rad=value))


def test_offsets_in_a_user_file(tmp_path):
    text = config_to_toml(default_config()).replace(
        "[section]", "distal_offset_m = 0.02\nplatform_offset_m = [0.01, 0.01, 0.015]\n\n[section]", 1
    )
    p = tmp_path / "stacked.toml"
    p.write_text(text)
    g = load_config(p).geometry
    assert g.distal_offset_m == 0.02
    assert g.platform_offset_per_chain == (0.01, 0.01, 0.015)
    with pytest.raises(ConfigError, match=r"geometry\.distal_offset_m.*list of 3"):
        parse_config(tomllib.loads(text.replace("distal_offset_m = 0.02", "distal_offset_m = [0.02]")))
