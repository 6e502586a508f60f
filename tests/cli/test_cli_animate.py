"""``fpm-sim modes --animate FILE.gif --mode K``: the GIF of one mode, its options checked before computing, one
error line (exit 2) for a mode beyond those found, any described architecture."""

from pathlib import Path

import pytest
from PIL import Image

from fpm_sim.cli.main import main

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "architectures"
SMALL = ["--segments", "2", "--n-modes", "2"]


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def error_lines(err: str) -> list[str]:
    return [line for line in err.splitlines() if line.startswith("error:")]


def test_animate_writes_the_gif_of_the_mode_asked(capsys, tmp_path):
    gif = tmp_path / "mode3.gif"
    # --mode beyond --n-modes: the table keeps --n-modes rows, the animation draws mode 3
    code, out, _ = run(capsys, "modes", *SMALL, "--animate", gif, "--mode", "3")
    assert code == 0
    assert f"mode 3 animated to {gif}" in out
    with Image.open(gif) as im:
        assert im.format == "GIF"
        assert im.n_frames == 24


def test_a_mode_beyond_those_found_is_one_error_line_and_nothing_written(capsys, tmp_path):
    gif = tmp_path / "m.gif"
    code, out, err = run(capsys, "modes", *SMALL, "--animate", gif, "--mode", "200")
    assert code == 2
    assert out == ""
    [line] = error_lines(err)
    assert line.startswith("error: --mode: must be one of the ")
    assert "physical modes found (1-based), got 200; choose 1.." in line
    assert list(tmp_path.iterdir()) == []


def test_an_unwritable_animation_fails_before_computing(capsys, tmp_path, monkeypatch):
    def no_analysis(*args, **kwargs):
        raise AssertionError("computed before checking --animate")

    monkeypatch.setattr("fpm_sim.linear.analysis.analyse", no_analysis)
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    for path, words in ((blocker / "m.gif", "--animate"), (tmp_path / "m.png", "must end in .gif")):
        code, _, err = run(capsys, "modes", *SMALL, "--animate", path)
        assert code == 2
        [line] = error_lines(err)
        assert "--animate" in line
        assert words in line
    code, _, err = run(capsys, "modes", *SMALL, "--mode", "2")  # --mode alone: nothing to draw
    assert code == 2
    assert error_lines(err) == ["error: --mode picks the mode that --animate draws; add --animate FILE.gif"]


@pytest.mark.filterwarnings("ignore::fpm_sim.FpmSimWarning")
def test_a_described_architecture_animates(capsys, tmp_path):
    gif = tmp_path / "five_bar.gif"
    config = EXAMPLES / "five_bar.toml"
    code, out, _ = run(capsys, "modes", "--config", config, "--no-gravity", *SMALL, "--animate", gif)
    assert code == 0
    assert "mode 1 animated to" in out
    with Image.open(gif) as im:
        assert im.n_frames == 24
