"""Why independent calibration runs disagree (issue 31; docs/identification.md, "Why independent runs still
disagree"): the study's calibration problem on the in-plane surrogate, one elbow-branch class, several seeds.

    python studies/calibration_runs_surrogate.py --branch -1 -1 -1 --live-points 100 --runs 3
    python studies/calibration_runs_surrogate.py --branch -1 -1 -1 --sampler smc --particles 200 --cheap-particles 1000

Prints each run's ln Z, the between-run check and, per run, the best draw's log-likelihood split into the data's
and the study statements' terms. The surrogate (``model="inplane"``) is for checks of the sampler, never for a
reported result (fpm_sim.study.calibrate.problem).
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

from fpm_sim.study.calibrate import CalibrationProblem, SamplerOptions, run_calibration
from fpm_sim.study.calibrate.problem import study_problem


def problem(branch: tuple[int, int, int]) -> CalibrationProblem:
    """The study's calibration (its data, priors and statements) on the surrogate, the elbow branches fixed."""
    return study_problem(model="inplane", branch=branch)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--branch", type=int, nargs=3, default=[-1, -1, -1])
    p.add_argument("--live-points", type=int, default=100)
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--sample", default="rwalk")
    p.add_argument("--sampler", default="dynesty", choices=("dynesty", "smc"))
    p.add_argument("--particles", type=int, default=200)
    p.add_argument("--cheap-particles", type=int, default=1000)
    a = p.parse_args()
    warnings.simplefilter("ignore")
    prob = problem(tuple(a.branch))
    t = time.time()
    for seed in range(a.runs):
        opts = SamplerOptions(
            sampler=a.sampler, live_points=a.live_points, sample=a.sample, particles=a.particles,
            cheap_particles=a.cheap_particles, runs=1, seed=seed,
        )  # fmt: skip
        cal = run_calibration(prob, opts, progress=True)
        ll = np.array([prob.log_likelihood(th) for th in cal.draws[:400]])
        best = cal.draws[int(np.argmax(ll))]
        st = prob.statements_log_likelihood(prob.config(best))
        print(f"seed {seed}: best draw log L {ll.max():.2f} (statements {st:.2f}, data {ll.max() - st:.2f})")
    print(f"{time.time() - t:.0f} s")


if __name__ == "__main__":
    main()
