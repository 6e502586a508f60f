"""Frequency requirements on described architectures: ``fpm-sim check`` and the evaluation behind it."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from fpm_sim.architecture import load_description
from fpm_sim.cli.main import main
from fpm_sim.study.requirements import RequirementError, check_requirements, parse_requirements

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "architectures"


def _reqs(text: str, tmp_path: Path):
    path = tmp_path / "fpm-requirements.toml"
    path.write_text(text)
    return parse_requirements(tomllib.loads(text), path)


def test_a_five_bar_requirement_passes_and_fails_at_its_worst_listed_pose(tmp_path):
    desc = load_description(EXAMPLES / "five_bar.toml")
    text = """
[settings]
segments = 3
[[requirement]]
name = "f1 floor"
kind = "min_frequency"
at_least_hz = {bound}
poses = {{ list = [[0, 250], [40, 180], [-60, 220]] }}
"""
    low = check_requirements(_reqs(text.format(bound=5.0), tmp_path), desc)
    high = check_requirements(_reqs(text.format(bound=1e4), tmp_path), desc)
    assert low.passed
    assert not high.passed
    worst = low.outcomes[0].worst_pose
    assert worst is not None
    assert (round(worst.x_m, 6), round(worst.y_m, 6)) in {(0.0, 0.25), (0.04, 0.18), (-0.06, 0.22)}
    assert low.outcomes[0].worst_value_hz == pytest.approx(high.outcomes[0].worst_value_hz)  # the same pose's f1


@pytest.mark.parametrize(
    ("poses", "extra", "message"),
    [
        ("{ list = [[0, 250, 0.1]] }", "", r"takes \[x, y\]"),
        ("{ list = [[0, 900]] }", "", "is unreachable"),
        ("{ list = [[0, 250]] }", "payload_kg = [0.0, 1.0]", "payload_kg varies the 3RRR's hardware.payload"),
        ('{ grid = "paper" }', "", "the study's 25 poses are the 3RRR's"),
        ("{ cylinder = { radius_mm = 0, z_mm = [0, 1], step_mm = 10 } }", "", "must be > 0"),
    ],
)
def test_what_a_described_architecture_cannot_take_is_named(poses, extra, message, tmp_path):
    desc = load_description(EXAMPLES / "five_bar.toml")
    text = f"""
[settings]
segments = 3
[[requirement]]
name = "r"
kind = "min_frequency"
at_least_hz = 1.0
poses = {poses}
{extra}
"""
    with pytest.raises(RequirementError, match=message):
        check_requirements(_reqs(text, tmp_path), desc)


def test_fpm_sim_check_runs_the_delta_s_requirement_on_a_small_cylinder(tmp_path, capsys):
    """The shipped Delta requirement's form (a working cylinder), on a smaller cylinder for speed."""
    text = (EXAMPLES / "delta_requirements" / "fpm-requirements.toml").read_text()
    text = text.replace('config = "../delta.toml"', f'config = "{EXAMPLES / "delta.toml"}"')
    text = text.replace(
        "radius_mm = 100, z_mm = [-340, -260], step_mm = 40", "radius_mm = 30, z_mm = [-300, -300], step_mm = 40"
    )
    path = tmp_path / "fpm-requirements.toml"
    path.write_text(text)
    code = main(["check", str(path), "--segments", "3"])
    out = capsys.readouterr().out
    assert code == 0
    assert "worst pose (x mm, y mm, z mm)" in out
    assert "(0.0, 0.0, -300.0)" in out
