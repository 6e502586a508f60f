"""``fpm-sim check``: exit 0 / 1 / 2, the table, --json, --junit-xml; bad input -> one ``error:`` line."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from fpm_sim.cli.main import main

POSES = "[[0, 0, 0.0], [50, 0, 0.0]]"


def run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def write(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "fpm-requirements.toml"
    path.write_text("[settings]\nsegments = 3\n\n" + body)
    return path


def min_req(name: str, at_least_hz: float, poses: str = POSES) -> str:
    return (
        f'[[requirement]]\nname = "{name}"\nkind = "min_frequency"\nat_least_hz = {at_least_hz}\n'
        f"poses = {{ list = {poses} }}\n\n"
    )


def test_check_passes_and_fails_with_exit_codes_table_json_and_junit(tmp_path, capsys):
    ok = write(tmp_path, min_req("low bar", 1.0))
    code, out, err = run(capsys, "check", str(ok))
    assert code == 0, err
    assert "low bar" in out
    assert "pass" in out
    bad = write(tmp_path, min_req("low bar", 1.0) + min_req("high bar", 1000.0))
    junit = tmp_path / "reports" / "junit.xml"
    code, out, err = run(capsys, "check", str(bad), "--junit-xml", str(junit))
    assert code == 1
    assert "FAIL" in out
    assert "requirement 'high bar'" in out
    assert "(x=" in out
    cases = ET.parse(junit).getroot().iter("testcase")
    assert {c.get("name"): c.find("failure") is not None for c in cases} == {"low bar": False, "high bar": True}
    code, out, _ = run(capsys, "check", str(bad), "--json")
    assert code == 1
    d = json.loads(out)
    assert [r["passed"] for r in d["requirements"]] == [True, False]
    assert d["sweeps"] == 1  # both requirements use the same poses, payload and resolution


@pytest.mark.parametrize(
    ("body", "match"),
    [
        ("[[requirement]\nname =", "is not valid TOML"),
        ('[[requirement]]\nname = "r"\nkind = "stiffness"\n', "requirement 'r': unknown kind 'stiffness'"),
        (min_req("far", 1.0, "[[900, 0, 0.0]]"), r"requirement 'far'.poses: pose (x=900.0 mm"),
        (min_req("none", 1.0, "[]"), "requirement 'none'.poses: the pose set (0 listed poses) is empty"),
        (
            '[[requirement]]\nname = "edge"\nkind = "min_frequency"\nat_least_hz = 1\n'
            'poses = { grid = "dense", step_mm = 50, min_singularity = 0.9999 }\n',
            "requirement 'edge'.poses: the pose set (reachable workspace, 50 mm grid",
        ),
    ],
)
def test_bad_input_is_one_error_line_and_exit_2(tmp_path, capsys, body, match):
    code, out, err = run(capsys, "check", str(write(tmp_path, body)))
    assert code == 2
    assert out == ""
    assert err.startswith("error: ")
    assert err.count("\n") == 1
    assert match in err
    assert "Traceback" not in err


def test_missing_file_and_bad_report_path(tmp_path, capsys):
    code, _, err = run(capsys, "check", str(tmp_path / "nope.toml"))
    assert code == 2
    assert "file not found" in err
    ok = write(tmp_path, min_req("low bar", 1.0))
    code, _, err = run(capsys, "check", str(ok), "--junit-xml", str(tmp_path / "report.txt"))
    assert code == 2
    assert "--junit-xml" in err


def test_description_from_the_settings_or_config_option(tmp_path, capsys):
    from fpm_sim.config import config_to_toml, default_config

    (tmp_path / "mine.toml").write_text(config_to_toml(default_config().replace(name="my cell")))
    path = tmp_path / "fpm-requirements.toml"
    path.write_text('[settings]\nconfig = "mine.toml"\nsegments = 3\n\n' + min_req("low bar", 1.0))
    code, out, _ = run(capsys, "check", str(path))
    assert code == 0
    assert out.startswith("fpm-requirements.toml on my cell:")
    (tmp_path / "other.toml").write_text(config_to_toml(default_config().replace(name="other cell")))
    code, out, _ = run(capsys, "check", str(path), "--config", str(tmp_path / "other.toml"))
    assert code == 0
    assert out.startswith("fpm-requirements.toml on other cell:")
