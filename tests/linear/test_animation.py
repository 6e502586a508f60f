"""Mode shapes you can watch (fpm_sim.linear.animation, ModalResult.animate): a looping GIF that moves, drawn in 3D
when the mode leaves the plane, scaled to the model's size, for the 3RRR and a described architecture."""

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import fpm_sim as fs
from fpm_sim.linear.animation import AMPLITUDE_FRACTION, AnimationError, mode_motion
from fpm_sim.model.options import ModelOptions

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "architectures"

pytestmark = pytest.mark.filterwarnings("ignore::fpm_sim.FpmSimWarning")  # coarse on purpose: 3 segments


@pytest.fixture(scope="module")
def three_rrr():
    """The default 3RRR at (0, 0, 0), 3 segments per link: mode 1 out of plane, mode 2 in plane."""
    return fs.modes(None, None, options=ModelOptions(segments=3), n_modes=3)


@pytest.fixture(scope="module")
def delta():
    """The Delta (a spatial machine, six rods on its platform) without gravity, 2 segments per link."""
    desc = fs.load_description(EXAMPLES / "delta.toml")
    return fs.modes(desc, None, options=ModelOptions(segments=2, gravity=False), n_modes=2)


def frames_of(path: Path) -> list[np.ndarray]:
    with Image.open(path) as im:
        assert im.format == "GIF"
        assert im.info.get("loop") == 0  # loops forever
        out = []
        for k in range(im.n_frames):
            im.seek(k)
            out.append(np.asarray(im.convert("RGB"), dtype=float))
    return out


def test_the_gif_loops_over_one_period_and_moves(three_rrr, tmp_path):
    path = three_rrr.animate(tmp_path / "mode1.gif", mode=1)
    assert path == tmp_path / "mode1.gif"
    frames = frames_of(path)
    assert len(frames) == 24  # the default: one period
    assert path.stat().st_size < 1_000_000
    assert np.abs(frames[0] - frames[12]).max() > 0  # the peak and the trough differ: it moves
    assert [p.name for p in tmp_path.iterdir()] == ["mode1.gif"]  # written atomically, no temporary left


def test_frames_and_rate_are_the_callers(three_rrr, tmp_path):
    for frames in (3, 6):  # odd and even: every frame kept (none equal to its neighbour)
        path = three_rrr.animate(tmp_path / "m.gif", mode=2, frames=frames, fps=5)
        with Image.open(path) as im:
            assert im.n_frames == frames
            assert im.info["duration"] == 200  # ms per frame at 5 frames per second


@pytest.mark.parametrize(
    ("kwargs", "parameter"),
    [
        ({"mode": 4}, "mode"),
        ({"mode": 0}, "mode"),
        ({"frames": 1}, "frames"),
        ({"fps": 0}, "fps"),
        ({"scale_m": -0.01}, "scale_m"),
    ],
)
def test_bad_options_are_named_and_nothing_is_written(three_rrr, tmp_path, kwargs, parameter):
    with pytest.raises(AnimationError) as err:
        three_rrr.animate(tmp_path / "m.gif", **kwargs)
    assert err.value.parameter == parameter
    assert list(tmp_path.iterdir()) == []


def test_out_of_plane_modes_are_3d_and_in_plane_ones_2d_scaled_to_the_model(three_rrr):
    out_of_plane, in_plane = mode_motion(three_rrr, 0), mode_motion(three_rrr, 1)
    assert out_of_plane.axes == (0, 1, 2)
    assert out_of_plane.out_of_plane > 0.9  # bend_out and twist: along z
    assert in_plane.axes == (0, 1)
    assert in_plane.out_of_plane < 0.05
    for motion in (out_of_plane, in_plane):
        largest = max(np.linalg.norm(d, axis=1).max() for d in motion.displacements.values())
        assert largest == pytest.approx(AMPLITUDE_FRACTION * motion.size_m)
        assert len(motion.platform) == 4  # the platform triangle, closed, through the three distal ends
    assert mode_motion(three_rrr, 0, scale_m=0.01).amplitude_m == 0.01


def test_a_described_spatial_machine_animates_with_its_platform(delta, tmp_path):
    motion = mode_motion(delta, 0)
    assert motion.axes == (0, 1, 2)  # spatial: always 3D
    assert len(motion.platform) == 7  # the six rod ends on the platform, closed
    frames = frames_of(delta.animate(tmp_path / "delta.gif", frames=4))
    assert len(frames) == 4
    assert np.abs(frames[0] - frames[2]).max() > 0
