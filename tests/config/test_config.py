import math
import textwrap
import tomllib

import pytest

from fpm_sim.config import ConfigError, default_config, default_config_text, load_config

PROVENANCE_PREFIXES = ("study", "assumed: ", "identified: ")


def test_default_loads_and_every_value_has_provenance():
    cfg = default_config()
    assert cfg.geometry.proximal_length_m > 0
    assert cfg.provenance, "the default must carry provenance"
    for field, source in cfg.provenance.items():
        assert source.startswith(PROVENANCE_PREFIXES), f"{field}: provenance {source!r}"
    # every leaf value of the TOML appears in the provenance map
    import tomllib

    def leaves(t, path=""):
        for k, v in t.items():
            full = f"{path}.{k}" if path else k
            if isinstance(v, dict) and "value" not in v:
                yield from leaves(v, full)
            elif k != "name":
                yield full

    assert set(leaves(tomllib.loads(default_config_text()))) == set(cfg.provenance)


def test_angles_converted_to_radians():
    cfg = default_config()
    deg = tomllib.loads(default_config_text())["geometry"]["base_angles_deg"]["value"][0]
    assert math.isclose(cfg.geometry.base_angles_rad[0], math.radians(deg))


def _write(tmp_path, body: str):
    p = tmp_path / "m.toml"
    p.write_text(textwrap.dedent(body))
    return p


BASE = """
[geometry]
base_radius_m = 0.3
base_angles_deg = [90, 210, 330]
proximal_length_m = 0.2
distal_length_m = 0.2
platform_radius_m = 0.05
platform_angles_deg = [90, 210, 330]
[section]
thickness_m = 0.01
height_m = 0.01
[material]
young_pa = 70e9
poisson = 0.33
density_kg_m3 = 2700
[hardware.platform]
mass_kg = 0.2
"""


def test_user_file_bare_values_get_user_provenance(tmp_path):
    cfg = load_config(_write(tmp_path, BASE))
    assert cfg.material.young_pa == 70e9
    assert cfg.provenance["material.young_pa"] == "user: m.toml"
    assert cfg.rig is None


@pytest.mark.parametrize(
    ("old", "new", "field"),
    [
        ("proximal_length_m = 0.2", "proximal_length_m = -0.2", "geometry.proximal_length_m"),
        ("poisson = 0.33", "poisson = 0.6", "material.poisson"),
        ("thickness_m = 0.01", "thickness_m = 0", "section.thickness_m"),
        ("young_pa = 70e9", 'young_pa = "stiff"', "material.young_pa"),
        ("base_angles_deg = [90, 210, 330]", "base_angles_deg = [90, 90, 330]", "geometry.base_angles_deg"),
        ("base_angles_deg = [90, 210, 330]", "base_angles_deg = [90, 210]", "geometry.base_angles_deg"),
        ("platform_radius_m = 0.05", "platform_radius_m = 0.5", "geometry.platform_radius_m"),
        ("mass_kg = 0.2", "mass_kg = -1", "hardware.platform.mass_kg"),
        ("height_m = 0.01", "height_m = 0.01\nwidth_m = 3", "section"),
        ("density_kg_m3 = 2700", "", "material.density_kg_m3"),
    ],
)
def test_invalid_values_name_the_field(tmp_path, old, new, field):
    assert old in BASE
    with pytest.raises(ConfigError, match=field.replace(".", r"\.").replace("[", r"\[")):
        load_config(_write(tmp_path, BASE.replace(old, new)))


def test_elbow_branch_and_motor_mode_checked(tmp_path):
    with pytest.raises(ConfigError, match=r"geometry\.elbow_branch"):
        load_config(_write(tmp_path, BASE.replace("[section]", "elbow_branch = [1, 0, 1]\n[section]")))
    with pytest.raises(ConfigError, match=r"motors\.mode"):
        load_config(_write(tmp_path, BASE + '\n[motors]\nmode = "spinning"\n'))
    with pytest.raises(ConfigError, match=r"motors\.servo_stiffness_nm_per_rad"):
        load_config(_write(tmp_path, BASE + '\n[motors]\nmode = "servo"\n'))


def test_missing_file_and_bad_toml(tmp_path):
    with pytest.raises(ConfigError, match="not found"):
        load_config(tmp_path / "nope.toml")
    with pytest.raises(ConfigError, match="invalid TOML"):
        load_config(_write(tmp_path, "[geometry\n"))


def test_provenance_table_form(tmp_path):
    body = BASE.replace("poisson = 0.33", 'poisson = { value = 0.33, source = "assumed: aluminium" }')
    cfg = load_config(_write(tmp_path, body))
    assert cfg.provenance["material.poisson"] == "assumed: aluminium"


def test_section_properties():
    from fpm_sim.config import Section

    s = Section(thickness_m=0.01, height_m=0.02)
    assert math.isclose(s.i_inplane_m4, 0.02 * 0.01**3 / 12)
    assert math.isclose(s.i_outofplane_m4, 0.01 * 0.02**3 / 12)
    # square section: Saint-Venant J = 0.1406 a^4 (Roark), within the series approximation's 0.5 %
    sq = Section(0.01, 0.01)
    assert math.isclose(sq.torsion_constant_m4, 0.1406 * 0.01**4, rel_tol=5e-3)
