"""Bad descriptions: one error line naming the path in the file, exit code 2, no traceback, nothing written."""

from __future__ import annotations

from pathlib import Path

import pytest

from fpm_sim.cli.main import main

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "architectures"
FIVE_BAR = (EXAMPLES / "five_bar.toml").read_text()
THREE_PRR = (EXAMPLES / "three_prr.toml").read_text()

CASES = {
    "chain out of reach": (
        FIVE_BAR.replace("base_position_m = [0.080, 0.0, 0.0]", "base_position_m = [5.0, 0.0, 0.0]"),
        "chains[1]",
        "cannot reach its attachment point 'p'",
    ),
    "unknown joint type": (
        FIVE_BAR.replace('{ joint = "elbow", type = "revolute"', '{ joint = "elbow", type = "hinge"', 1),
        "chains[0].path[2].type",
        "unknown joint type",
    ),
    "no attachment points": (
        FIVE_BAR.replace("attachments_m = { p = [0.0, 0.0, 0.0] }", "attachments_m = {}"),
        "end_effector.attachments_m",
        "at least one attachment point",
    ),
    "an attachment point missing": (
        THREE_PRR.replace(", c3 = [", ", c4 = ["),
        "chains[2].path[3].at",
        "no attachment point of that name",
    ),
    "two chains with one name": (
        FIVE_BAR.replace('name = "right"', 'name = "left"'),
        "chains[1].name",
        "two chains are named 'left'",
    ),
    "a zero section dimension": (
        FIVE_BAR.replace("thickness_m = 0.025", "thickness_m = 0.0"),
        "sections.bar.thickness_m",
        "must be > 0",
    ),
    "mobility left with the actuators locked": (
        FIVE_BAR.replace('axis = [0, 0, 1], actuated = true },\n  { link = "proximal", length_m = 0.180, section = '
                         '"bar", material = "steel" },\n  { joint = "elbow", type = "revolute", axis = [0, 0, 1], '
                         'lump = "elbow", branch_deg = [0, 180]',
                         'axis = [0, 0, 1] },\n  { link = "proximal", length_m = 0.180, section = "bar", material = '
                         '"steel" },\n  { joint = "elbow", type = "revolute", axis = [0, 0, 1], lump = "elbow", '
                         'branch_deg = [0, 180]'),
        "chains",
        "keeps 1 degree(s) of freedom",
    ),
    "task coordinates the architecture lacks": (
        FIVE_BAR.replace('task = ["x", "y"]', 'task = ["x", "y", "z"]'),
        "task",
        "distinct task coordinates of a planar machine",
    ),
    "binary garbage": (None, "", "is not a TOML file"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_a_bad_description_is_one_error_line_naming_its_path(case, tmp_path, capsys):
    text, path, message = CASES[case]
    cfg = tmp_path / "machine.toml"
    if text is None:
        cfg.write_bytes(bytes(range(256)))
    else:
        assert text not in (FIVE_BAR, THREE_PRR), "the case's edit did not apply"
        cfg.write_text(text)
    plot = tmp_path / "modes.png"
    code = main(["modes", "--config", str(cfg), "--no-gravity", "--fidelity", "fast", "--plot", str(plot)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1, err
    assert err[0].startswith("error: ")
    assert path in err[0]
    assert message in err[0]
    assert "Traceback" not in err[0]
    assert not plot.exists()


def test_an_option_the_architecture_lacks_is_refused_by_name(capsys):
    code = main(["modes", "--config", str(EXAMPLES / "delta.toml"), "--phi-rad", "0.1"])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert err.startswith("error: --phi-rad: Delta (example specification) has no task coordinate phi")


def test_calibrate_runs_on_a_description_and_says_what_it_lacks_in_one_line(capsys, tmp_path):
    """calibrate was the last command on the 3RRR form only: on a description it now asks for its own inputs (the
    study's priors name no dotted path of the five-bar, and the measured file is missing)."""
    priors = Path(__file__).resolve().parents[2] / "fpm_sim" / "data" / "study_priors.toml"
    args = ["--priors", str(priors), "--out", str(tmp_path / "o")]
    code = main(["calibrate", "--config", str(EXAMPLES / "five_bar.toml"), *args])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1
    assert "3RRR form only" not in err[0]
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("command", [["reproduce"], ["readability"], ["transient"], ["rig", "chain"]])
def test_the_study_s_own_commands_say_they_are_the_study_s(command, capsys):
    code = main([*command, "--config", str(EXAMPLES / "five_bar.toml")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1
    assert f"'{command[0]}' is the study's own command" in err[0]
