"""``identify`` and ``calibrate`` on an imported model: dotted paths into the imported TOML fitted to frequencies
measured at joint-space poses (issue 29).

Truth: a synthetic one. dm_control's acrobot, both links flexible (a rect section each, the shoulder locked and the
actuated elbow locked with it), its lower link's section height 10 % above the file's (88 mm for 80 mm); f1..f3 at
four joint poses computed by the same model (:func:`~fpm_sim.batch.joint_sweep.sweep_joints`) with 0.5 % Gaussian
noise. Bad input: one error line, exit 2, nothing written."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

import fpm_sim as fs
from fpm_sim.architecture import description_value, with_description_value
from fpm_sim.batch.joint_sweep import sweep_joints
from fpm_sim.model.options import ModelOptions
from fpm_sim.study.identify.described import identify_description, parse_free_paths, read_joint_measured_csv
from tests.imported.test_import import MATERIALS, _acrobot, _cli, _write

pytestmark = pytest.mark.filterwarnings("ignore::fpm_sim.model.options.ResolutionWarning")
PATH = "sections.lower.height_m"
FILE_M, TRUE_M = 0.08, 0.088
POSES = [
    {"shoulder": 0.0, "elbow": 0.0},
    {"shoulder": 0.3, "elbow": -1.1},
    {"shoulder": 0.7, "elbow": 0.5},
    {"shoulder": -0.4, "elbow": 1.2},
]
SEG = 2  # the data and the fits share the model: the resolution only has to keep f1..f3 apart
NOISE = np.random.default_rng(7).standard_normal((4, 3))
"""The data's standard normal noise (12 values, within 2.1 sd)."""


def _toml(tmp_path: Path) -> Path:
    sections = "".join(
        f'[sections.{s}]\nshape = "rect"\nheight_m = 0.08\nthickness_m = 0.04\n' for s in ("upper", "lower")
    )
    flexible = "".join(
        f'[[flexible]]\nbody = "{b}_arm"\nsection = "{s}"\nmaterial = "aluminium"\n{end}'
        for b, s, end in (("upper", "upper", ""), ("lower", "lower", 'end_site = "tip"\n'))
    )
    body = f'kind = "imported"\nmodel = "{_acrobot()}"\nlocked_joints = ["shoulder"]\n{MATERIALS}{sections}{flexible}'
    return _write(tmp_path, body)


def _measured(tmp_path: Path, toml: Path) -> Path:
    """f1..f3 of the acrobot with the lower height at :data:`TRUE_M`, 0.5 % noise, as a joint-space measured file."""
    truth = with_description_value(fs.load_imported(toml), PATH, TRUE_M)
    opts = ModelOptions(segments=SEG, gravity=False, axial=False)
    f = sweep_joints(truth, POSES, options=opts, n_modes=3).freq_hz * (1.0 + 0.005 * NOISE)
    rows = [f"{q['shoulder']!r},{q['elbow']!r}," + ",".join(repr(v) for v in fk) for q, fk in zip(POSES, f.tolist())]
    path = tmp_path / "measured.csv"
    path.write_text("shoulder,elbow,f1_hz,f2_hz,f3_hz\n" + "\n".join(rows) + "\n")
    return path


def test_identify_recovers_the_lower_link_height(tmp_path: Path) -> None:
    """Bounded least squares from the file's 80 mm finds 88 mm within three of its Gauss-Newton standard deviations
    (the noise is Gaussian with the sigma the fit is told, so the estimate is within 3 sd of the truth with
    probability 0.997); the sd is small enough to tell 80 from 88 mm (the file's value lies beyond 3 sd), and the
    fitted file holds the value with its provenance."""
    toml = _toml(tmp_path)
    desc = fs.load_imported(toml)
    data = read_joint_measured_csv(_measured(tmp_path, toml), desc, sigma_pct=0.5)
    assert data.poses == POSES
    opts = ModelOptions(segments=SEG, gravity=False, axial=False)
    result = identify_description(desc, data, parse_free_paths(PATH, desc), options=opts)
    (value,), (sd,) = result.values, result.std
    assert abs(value - TRUE_M) < 3 * sd, (value, sd)
    assert abs(value - FILE_M) > 3 * sd, (value, sd)
    assert description_value(result.fitted, PATH) == pytest.approx(value, rel=1e-12)
    assert result.rows()[0]["shoulder"] == 0.0
    assert "identified" in result.fitted.provenance[PATH]


def test_identify_command_writes_the_fitted_imported_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The CLI runs the same fit and writes a description that reads back as an imported model (its model path
    absolute) with the fitted height."""
    toml = _toml(tmp_path)
    measured = f"{_measured(tmp_path, toml)},sigma_pct=0.5"
    argv = ["identify", "--config", str(toml), "--free", PATH, "--measured", measured]
    code, text = _cli([*argv, "--segments", str(SEG), "--out", str(tmp_path / "out"), "--json"], capsys)
    assert code == 0, text
    (p,) = json.loads(text)["result"]["parameters"]
    fitted = fs.load_imported(tmp_path / "out" / "description.toml")
    assert description_value(fitted, PATH) == pytest.approx(p["value"], rel=1e-12)
    assert abs(p["value"] - TRUE_M) < 3 * p["std"]


@pytest.mark.slow  # ~450 likelihood calls of four joint poses (0.1 s each): ~50 s on a shared 2-core machine
def test_calibrate_puts_the_lower_link_height_inside_the_90_interval(tmp_path: Path) -> None:
    """A uniform prior 50..120 mm on the lower height: the posterior's 5-95 % interval holds 88 mm and excludes the
    file's 80 mm (the data move the height by 10 %, the 0.5 % noise resolves it to well under 1 %)."""
    from fpm_sim.study.calibrate import SamplerOptions, run_calibration
    from fpm_sim.study.calibrate.described import described_problem

    toml = _toml(tmp_path)
    desc = fs.load_imported(toml)
    data = read_joint_measured_csv(_measured(tmp_path, toml), desc, sigma_pct=0.5)
    problem = described_problem(desc, data, priors=None, free=f"{PATH}=0.05:0.12", segments=SEG)
    opts = SamplerOptions(live_points=8, sample="unif", runs=1, draws=200, probe_draws=10)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cal = run_calibration(problem, opts, progress=False)
    lo, med, hi = cal.quantiles()[0]
    assert lo < TRUE_M < hi, (lo, med, hi)
    assert not lo < FILE_M < hi, (lo, med, hi)


@pytest.mark.parametrize("command", ["identify", "calibrate"])
@pytest.mark.parametrize(
    ("free", "measured", "words"),
    [
        ("sections.middle.height_m", "shoulder,elbow,f1_hz\n0,0,9\n", "no 'middle' under sections"),
        (PATH, "shoulder,knee,f1_hz\n0,0,9\n", "column(s) knee name no hinge or slide joint of acrobot.xml"),
    ],
    ids=["path-not-in-file", "joint-not-in-model"],
)
def test_bad_input_is_one_error_line_and_nothing_written(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str, free: str, measured: str, words: str
) -> None:
    toml = _toml(tmp_path)
    (tmp_path / "m.csv").write_text(measured)
    before = sorted(p.name for p in tmp_path.iterdir())
    argv = [command, "--config", str(toml), "--free", free + ("=0.05:0.12" if command == "calibrate" else "")]
    argv += ["--measured", str(tmp_path / "m.csv"), "--segments", "1", "--out", str(tmp_path / "out")]
    code, text = _cli(argv, capsys)
    assert code == 2, text
    lines = text.strip().splitlines()
    assert len(lines) == 1, text
    assert lines[0].startswith("error: ")
    assert words in lines[0], text
    assert sorted(p.name for p in tmp_path.iterdir()) == before
