"""The MJCF files checked into mjcf/ must be what the code generates now.

The export writes every number at full precision (``fpm_sim.model.xml_precision``), and the positions come from
trigonometry whose last digit can differ between maths libraries: the files are compared element by element and
attribute by attribute, numbers to 1e-12 relative (a few ulps of the assembly's sums of sines and cosines, far below
any change of the machine, which moves them at 1e-6 or more), everything else exactly."""

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
import pytest

from fpm_sim.model.mjcf_export import REFERENCE_MODELS, write_reference_mjcf

MJCF_DIR = Path(__file__).resolve().parents[2] / "mjcf"


@pytest.mark.parametrize("name", sorted(REFERENCE_MODELS))
def test_checked_in_mjcf_is_fresh(name):
    path = MJCF_DIR / name
    assert path.exists(), f"{path} missing: run python scripts/export_reference_mjcf.py"
    problem = _difference(path.read_text(), REFERENCE_MODELS[name]().to_xml())
    assert problem is None, f"{path} is stale ({problem}): run python scripts/export_reference_mjcf.py and commit it"


@pytest.mark.parametrize("name", sorted(REFERENCE_MODELS))
def test_checked_in_mjcf_loads(name):
    model = mujoco.MjModel.from_xml_path(str(MJCF_DIR / name))
    assert model.nv > 0


def test_write_reference_mjcf_writes_what_is_checked_in(tmp_path):
    paths = write_reference_mjcf(tmp_path / "mjcf")  # the script's own call (scripts/export_reference_mjcf.py)
    assert sorted(p.name for p in paths) == sorted(REFERENCE_MODELS)
    for p in paths:
        assert _difference(p.read_text(), (MJCF_DIR / p.name).read_text()) is None


def _numbers(text: str) -> list[float] | None:
    try:
        return [float(v) for v in text.split()]
    except ValueError:
        return None


def _difference(a: str, b: str) -> str | None:
    """Where two MJCF texts differ (numbers beyond 1e-12 relative), or None."""
    ea, eb = list(ET.fromstring(a).iter()), list(ET.fromstring(b).iter())
    if [e.tag for e in ea] != [e.tag for e in eb]:
        return "the elements differ"
    for x, y in zip(ea, eb):
        if set(x.attrib) != set(y.attrib):
            return f"<{x.tag}> attributes {sorted(x.attrib)} vs {sorted(y.attrib)}"
        for k, va in x.attrib.items():
            na, nb = _numbers(va), _numbers(y.attrib[k])
            if na is None or nb is None or len(na) != len(nb):
                if va != y.attrib[k]:
                    return f"<{x.tag} {k}>: {va!r} vs {y.attrib[k]!r}"
            elif not all(math.isclose(u, v, rel_tol=1e-12, abs_tol=1e-15) for u, v in zip(na, nb)):
                return f"<{x.tag} {k}>: {va!r} vs {y.attrib[k]!r}"
    return None


def test_the_comparison_sees_a_changed_number_and_forgives_the_last_digits():
    xml = '<mujoco><body pos="0.1 0.2 0.30000000000000004" name="b"/></mujoco>'
    assert _difference(xml, xml.replace("0.30000000000000004", "0.3")) is None  # one ulp
    assert _difference(xml, xml.replace("0.30000000000000004", "0.3000001")) is not None
    assert _difference(xml, xml.replace('name="b"', 'name="c"')) is not None
