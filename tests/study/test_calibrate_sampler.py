"""The sampler's checkpoints: runs stopped early resume from their checkpoint files to convergence, and a
checkpoint is refused for another problem."""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from fpm_sim.kinematics import Pose
from fpm_sim.study.calibrate import CalibrationError, CalibrationProblem, SamplerOptions, read_priors, run_calibration
from fpm_sim.study.identify import Observation

PRIORS = """
[parameters."hardware.platform.mass_kg"]
dist = "loguniform"
lower = 0.5
upper = 5.0
reason = "assumed: test"
"""


@pytest.mark.slow  # ~10-30 s of wall time on a shared machine (two short sampling runs)
def test_a_stopped_run_resumes_from_its_checkpoint(default_manip, tmp_path):
    base = default_manip
    obs = tuple(Observation(Pose.from_mm(x, y, 0.0), 1, 60.0, 1.0, None, "t") for x, y in ((0, -50), (50, 50)))
    # the hardware group frees three masses; the two hinge masses get narrow priors
    names = ["hardware.platform.mass_kg", "hardware.elbow_joint.mass_kg", "hardware.platform_joint.mass_kg"]
    text = PRIORS + "".join(
        f'[parameters."{n}"]\ndist = "uniform"\nlower = 0.3\nupper = 0.31\nreason = "assumed: test"\n'
        for n in names[1:]
    )
    pr = read_priors("p.toml", names, text=text)
    prob = CalibrationProblem(base, ("hardware",), pr, obs, model="inplane")
    ck = tmp_path / "ck.dynesty"
    opts = SamplerOptions(live_points=20, dlogz=0.5, sample="unif", checkpoint_every_s=0.0, max_calls=150)
    first = run_calibration(prob, opts, checkpoint=ck, progress=False)
    assert not first.converged
    # one checkpoint per run (the branches are fixed here: one class, seeds 0, 1, 2), none finished
    runs = [tmp_path / f"ck.dynesty.seed{s}" for s in range(opts.runs)]
    assert all(f.exists() for f in runs)
    assert not list(tmp_path.glob("*.done"))
    done = run_calibration(prob, dataclasses.replace(opts, max_calls=None), checkpoint=ck, resume=True, progress=False)
    assert done.converged
    assert done.n_calls > first.n_calls
    assert all(Path(f"{f}.done").exists() for f in runs)
    assert done.runs_check is not None
    assert math.isfinite(done.log_evidence)
    assert np.all(np.isfinite(done.f_pred))
    other = dataclasses.replace(prob, observations=obs[:1])
    with pytest.raises(CalibrationError, match="belongs to another problem"):
        run_calibration(other, opts, checkpoint=ck, resume=True, progress=False)


@pytest.mark.slow  # starts two spawn pools (~10-20 s of wall time on a shared machine)
def test_runs_on_workers_give_the_serial_posterior(default_manip):
    """One run per worker is the same computation as the runs one after another here (each run is serial
    dynesty with its own seed): identical draws and evidence. With fewer runs than workers, the likelihood
    calls go to the pool instead (dynesty's queue): a converged posterior."""
    obs = tuple(Observation(Pose.from_mm(x, y, 0.0), 1, 60.0, 1.0, None, "t") for x, y in ((0, -50), (50, 50)))
    names = ["hardware.platform.mass_kg", "hardware.elbow_joint.mass_kg", "hardware.platform_joint.mass_kg"]
    text = PRIORS + "".join(
        f'[parameters."{n}"]\ndist = "uniform"\nlower = 0.3\nupper = 0.31\nreason = "assumed: test"\n'
        for n in names[1:]
    )
    prob = CalibrationProblem(
        default_manip, ("hardware",), read_priors("p.toml", names, text=text), obs, model="inplane"
    )
    opts = SamplerOptions(live_points=15, dlogz=1.0, sample="unif", runs=2, draws=50)
    serial = run_calibration(prob, opts, progress=False)
    parallel = run_calibration(prob, dataclasses.replace(opts, workers=2), progress=False)
    assert np.array_equal(serial.draws, parallel.draws)
    assert serial.log_evidence == parallel.log_evidence
    pooled = run_calibration(prob, dataclasses.replace(opts, workers=2, runs=1), progress=False)
    assert pooled.converged
    assert math.isfinite(pooled.log_evidence)
