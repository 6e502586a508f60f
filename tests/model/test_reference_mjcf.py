"""The MJCF files checked into mjcf/ must be what the code generates now."""

from pathlib import Path

import mujoco
import pytest

from fpm_sim.model.mjcf_export import REFERENCE_MODELS, write_reference_mjcf

MJCF_DIR = Path(__file__).resolve().parents[2] / "mjcf"


@pytest.mark.parametrize("name", sorted(REFERENCE_MODELS))
def test_checked_in_mjcf_is_fresh(name):
    path = MJCF_DIR / name
    assert path.exists(), f"{path} missing: run python scripts/export_reference_mjcf.py"
    assert path.read_text() == REFERENCE_MODELS[name]().to_xml(), (
        f"{path} is stale: run python scripts/export_reference_mjcf.py and commit the result"
    )


@pytest.mark.parametrize("name", sorted(REFERENCE_MODELS))
def test_checked_in_mjcf_loads(name):
    model = mujoco.MjModel.from_xml_path(str(MJCF_DIR / name))
    assert model.nv > 0


def test_write_reference_mjcf_writes_what_is_checked_in(tmp_path):
    paths = write_reference_mjcf(tmp_path / "mjcf")  # the script's own call (scripts/export_reference_mjcf.py)
    assert sorted(p.name for p in paths) == sorted(REFERENCE_MODELS)
    for p in paths:
        assert p.read_text() == (MJCF_DIR / p.name).read_text()
