"""fpm_sim.pytest_plugin, run inside throw-away pytest sessions (pytester): collection of requirements files,
the fixtures and their shared sweeps, the marker, the explained comparisons, failure messages, JUnit XML; and
that the plugin is light and opt-in (no pytest11 entry point)."""

from __future__ import annotations

import subprocess
import sys
import xml.etree.ElementTree as ET
from importlib.metadata import entry_points

import pytest

# loaded before pytester's snapshot of sys.modules: the in-process runs below would otherwise unload NumPy and
# MuJoCo at each test's end, and those load once per process only
import fpm_sim.study.requirements  # noqa: F401

pytest_plugins = ["pytester"]

CONFTEST = 'pytest_plugins = ["fpm_sim.pytest_plugin"]\n'
POSES = "[[0, 0, 0.0], [50, 0, 0.0]]"
REQUIREMENTS = f"""
[settings]
segments = 3

[[requirement]]
name = "f1 above 1 Hz"
kind = "min_frequency"
at_least_hz = 1.0
poses = {{ list = {POSES} }}

[[requirement]]
name = "f1 above 1 kHz"
kind = "min_frequency"
at_least_hz = 1000.0
poses = {{ list = {POSES} }}
payload_kg = [0.0, 0.5]

[[requirement]]
name = "no mode below 1 Hz"
kind = "band_exclusion"
band_hz = [0.0, 1.0]
n_modes = 3
poses = {{ list = {POSES} }}
"""


def test_plugin_and_helpers_import_light():
    code = (
        "import sys; import fpm_sim.pytest_plugin, fpm_sim.testing; "
        "print([m for m in ('mujoco', 'jax', 'matplotlib', 'scipy', 'dm_control') if m in sys.modules])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_no_pytest11_entry_point():
    """Installing fpm-sim must not load anything into other projects' pytest runs."""
    assert not [ep for ep in entry_points(group="pytest11") if ep.value.startswith("fpm_sim")]


def test_requirements_file_collected_one_item_per_requirement(pytester):
    pytester.makeconftest(CONFTEST)
    pytester.makefile(".toml", **{"fpm-requirements": REQUIREMENTS})
    result = pytester.runpytest("--collect-only", "-q")
    result.stdout.fnmatch_lines(
        [
            "fpm-requirements.toml::f1 above 1 Hz",
            "fpm-requirements.toml::f1 above 1 kHz",
            "fpm-requirements.toml::no mode below 1 Hz",
        ]
    )
    junit = pytester.path / "junit.xml"
    result = pytester.runpytest("-q", f"--junit-xml={junit}")
    result.assert_outcomes(passed=2, failed=1)
    # the failure is the requirement's message, not a traceback into the plugin
    result.stdout.fnmatch_lines(
        [
            "*requirement 'f1 above 1 kHz' (min_frequency*FAILED: worst mode 1 at pose (x=*mm, y=*mm, phi=*rad)"
            " with payload 0.5 kg: * Hz, short by * Hz (*%*)*resolution: 3 segments per link*"
        ]
    )
    result.stdout.no_fnmatch_line("*pytest_plugin.py*")
    cases = {c.get("name"): c for c in ET.parse(junit).getroot().iter("testcase")}
    assert set(cases) == {"f1 above 1 Hz", "f1 above 1 kHz", "no mode below 1 Hz"}
    assert cases["f1 above 1 kHz"].find("failure") is not None
    props = {p.get("name"): p.get("value") for p in cases["f1 above 1 Hz"].iter("property")}
    assert props["fpm_requirement"] == "f1 above 1 Hz"
    assert float(props["margin_hz"]) > 0


def test_bad_requirements_file_is_a_collection_error_naming_the_key(pytester):
    pytester.makeconftest(CONFTEST)
    pytester.makefile(".toml", **{"fpm-requirements-bad": '[[requirement]]\nname = "r"\nkind = "stiffness"\n'})
    result = pytester.runpytest("-q")
    assert result.ret == pytest.ExitCode.INTERRUPTED  # collection errors stop the session
    result.stdout.fnmatch_lines(["*error: *fpm-requirements-bad.toml: requirement 'r': unknown kind 'stiffness'*"])


def test_unreachable_pose_fails_its_item_only(pytester):
    pytester.makeconftest(CONFTEST)
    far = REQUIREMENTS.replace(
        f"poses = {{ list = {POSES} }}\npayload_kg", "poses = { list = [[900, 0, 0.0]] }\npayload_kg"
    )
    pytester.makefile(".toml", **{"fpm-requirements": far})
    result = pytester.runpytest("-q")
    result.assert_outcomes(passed=2, failed=1)
    result.stdout.fnmatch_lines(["*error: requirement 'f1 above 1 kHz'.poses: pose (x=900.0 mm*unreachable*"])


TESTS = f"""
import pytest
from fpm_sim.testing import assert_min_frequency

POSES = {POSES}


def test_description_is_loaded(fpm_config):
    assert fpm_config.name


@pytest.mark.fpm_requirement("f1 above 1 Hz")
def test_mode_comparison_passes(fpm_sweep):
    assert fpm_sweep.mode(1, poses=POSES) >= 1.0


def test_second_test_reuses_the_sweep(fpm_sweep):
    assert fpm_sweep.mode(1, poses=POSES) > 1.0
    assert fpm_sweep.cache.computed == 1


def test_mode_comparison_fails(fpm_sweep):
    assert fpm_sweep.mode(1, poses=POSES) >= 1000.0


def test_reversed_comparison_fails(fpm_sweep):
    assert 1000.0 <= fpm_sweep.mode(1, poses=POSES)


def test_requirement_checked_on_the_shared_sweeps(fpm_sweep):
    from fpm_sim.study.requirements import PoseSpec, Requirement

    spec = PoseSpec(kind="list", points=tuple(tuple(p) for p in POSES))
    outcome = fpm_sweep.check(Requirement("f2", "min_frequency", spec, at_least_hz=1.0, mode=2))
    assert outcome.passed
    assert outcome.resolution.startswith("3 segments per link")
    assert fpm_sweep.cache.computed == 2  # mode 2 needs one more mode than the sweep of the tests above


def test_helper_fails(fpm_config, fpm_sweep):
    assert_min_frequency(fpm_config, 1000.0, poses=POSES, segments=3, cache=fpm_sweep.cache, name="fast enough")
"""


def test_fixtures_marker_and_explained_failures(pytester):
    pytester.makeconftest(CONFTEST)
    # a name no test module of this suite has: pytester runs in this process, where `test_design` is imported
    pytester.makepyfile(test_cell_requirements=TESTS)
    junit = pytester.path / "junit.xml"
    result = pytester.runpytest("-q", "--fpm-segments", "3", f"--junit-xml={junit}", "-p", "no:randomly")
    result.assert_outcomes(passed=4, failed=3)
    # the comparison explained: worst pose, mode, margin, resolution (both operand orders)
    result.stdout.fnmatch_lines(
        [
            "*f1 >= 1000 Hz fails at 2 of 2 poses (the description's payload)",
            "*worst: mode 1 at pose (x=*mm, y=*mm, phi=*rad): * Hz, * Hz (*%) below 1000 Hz",
            "*resolution: 3 segments per link*",
        ]
    )
    # once per failing comparison in the tracebacks ("E" lines; the short summary repeats it in full where CI is set)
    message = "f1 >= 1000 Hz fails at 2 of 2 poses"
    explained = [ln for ln in result.stdout.lines if ln.startswith("E ") and message in ln]
    assert len(explained) == 2
    # the helper's message, its own frames hidden
    result.stdout.fnmatch_lines(["*AssertionError: requirement 'fast enough' (min_frequency*FAILED: worst mode 1*"])
    result.stdout.no_fnmatch_line("*fpm_sim/testing.py*")
    cases = {c.get("name"): c for c in ET.parse(junit).getroot().iter("testcase")}
    props = {p.get("name"): p.get("value") for p in cases["test_mode_comparison_passes"].iter("property")}
    assert props == {"fpm_requirement": "f1 above 1 Hz"}
    result = pytester.runpytest("--markers")
    result.stdout.fnmatch_lines(["@pytest.mark.fpm_requirement(name)*"])


def test_fpm_config_option_loads_the_given_description(pytester, tmp_path):
    from fpm_sim.config import config_to_toml, default_config

    path = tmp_path / "mine.toml"
    path.write_text(config_to_toml(default_config().replace(name="my cell")))
    pytester.makeconftest(CONFTEST)
    pytester.makepyfile("def test_name(fpm_config):\n    assert fpm_config.name == 'my cell'\n")
    pytester.runpytest("-q", f"--fpm-config={path}").assert_outcomes(passed=1)


def test_requirements_on_an_imported_model_are_collected(pytester):
    """A requirements file whose settings.config is an imported model (joint-space pose sets, docs/import.md) is
    collected and evaluated like any: f1 >= 20 Hz holds on the clamped 2 m tube (24 Hz), f3 >= 120 Hz fails at the
    bent pose (98 Hz), the failure naming the pose by its joint values."""
    pytest.importorskip("dm_control")
    from tests.imported.test_import import _acrobot_toml

    toml = _acrobot_toml(pytester.path)
    pytester.makeconftest(CONFTEST)
    body = f'[settings]\nconfig = "{toml.name}"\nsegments = 2\n'
    for name, mode, bound in (("f1 above 20 Hz", 1, 20.0), ("f3 above 120 Hz", 3, 120.0)):
        body += f'\n[[requirement]]\nname = "{name}"\nkind = "min_frequency"\nmode = {mode}\nat_least_hz = {bound}\n'
        body += "poses = { joints = [{ shoulder = 0.0, elbow = 0.0 }, { shoulder = 0.3, elbow = -1.1 }] }\n"
    pytester.makefile(".toml", **{"fpm-requirements": body})
    result = pytester.runpytest("-q", "-W", "ignore::UserWarning")
    result.assert_outcomes(passed=1, failed=1)
    result.stdout.fnmatch_lines(["*'f3 above 120 Hz'*FAILED: worst mode 3 at pose (shoulder=0.3, elbow=-1.1)*"])
