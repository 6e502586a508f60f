"""Why independent calibration runs disagree (issue 31; docs/identification.md, "Why independent runs still
disagree"): the study's calibration problem on the in-plane surrogate, one elbow-branch class, several seeds.

    python studies/calibration_runs_surrogate.py --branch -1 -1 -1 --live-points 100 --runs 3
    python studies/calibration_runs_surrogate.py --branch -1 -1 -1 --sampler smc --particles 200 --cheap-particles 1000
    python studies/calibration_runs_surrogate.py --sampler smc --together --mode-starts 12 --workers 2 --seed 0 \
        --particles 1000 --cheap-particles 2000
    python studies/calibration_runs_surrogate.py --model segments --branch -1 -1 1 --together --sampler smc \
        --workers 2 --seed 0 --particles 1000 --cheap-particles 2000 --emulator 500 --min-measure 0.08
    python studies/calibration_runs_surrogate.py --model segments --branch -1 -1 1 --together --sampler smc \
        --workers 2 --seed 0 --particles 1000 --cheap-particles 2000 --emulator 500 --as-built 1 0.01

``--together``: one calibration of ``--runs`` runs (seeds ``--seed``, ``--seed + 1``, ...; a mode search pooled over
them, ``--mode-starts`` per part; ``--split geometry.base_radius_m 5``) and its between-run check, instead of one
calibration per seed.

Prints each run's ln Z, the between-run check and, per run, the best draw's log-likelihood split into the data's
and the study statements' terms. The surrogate (``model="inplane"``) is for checks of the sampler, never for a
reported result (fpm_sim.study.calibrate.problem).
"""

from __future__ import annotations

import argparse
import dataclasses
import time
import warnings

import numpy as np

from fpm_sim.study.calibrate import CalibrationProblem, SamplerOptions, run_calibration
from fpm_sim.study.calibrate.problem import study_problem


def problem(
    branch: tuple[int, int, int], model: str = "inplane", as_built: tuple[float, float] | None = None
) -> CalibrationProblem:
    """The study's calibration (its data, priors and statements) on the surrogate (or ``model``), the elbow branches
    fixed (``as_built``: :func:`~fpm_sim.study.calibrate.problem.study_problem`'s)."""
    return study_problem(model=model, branch=branch, as_built=as_built)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--branch", type=int, nargs=3, default=[-1, -1, -1])
    p.add_argument("--live-points", type=int, default=100)
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--sample", default="rwalk")
    p.add_argument("--sampler", default="dynesty", choices=("dynesty", "smc"))
    p.add_argument("--particles", type=int, default=200)
    p.add_argument("--cheap-particles", type=int, default=1000)
    p.add_argument("--mode-starts", type=int, default=0)
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--together", action="store_true")
    p.add_argument("--ess-fraction", type=float, default=0.5)
    p.add_argument("--moves", type=float, default=3.0)
    p.add_argument("--final-moves", type=float, default=0.0)
    p.add_argument("--jumps", type=float, default=0.0)
    p.add_argument("--importance", type=int, default=0, help="SamplerOptions.importance: independent draws")
    p.add_argument("--islands", type=int, default=1, help="SamplerOptions.islands: independent islands per run")
    p.add_argument("--crossover", action="store_true", help="SamplerOptions.crossover: moves in random subspaces")
    p.add_argument("--split", nargs=2, metavar=("NAME", "N"), help="SamplerOptions.split: NAME's prior in N parts")
    p.add_argument("--model", default="inplane", choices=("inplane", "segments"), help="segments: the reported model")
    p.add_argument("--emulator", type=int, default=0, help="SamplerOptions.emulator (with --model segments)")
    p.add_argument(
        "--min-measure", type=float, help="statement (b)'s least singularity measure at a measured pose (a diagnostic)"
    )
    p.add_argument(
        "--as-built", type=float, nargs=2, metavar=("ANGLE_SD_DEG", "LENGTH_SD_REL"),
        help="free the as-built group too, with normal priors of these sds (e.g. 1 0.01)",
    )  # fmt: skip
    p.add_argument("--save", help="with --together: an .npz of the merged draws and each run's quantiles")
    a = p.parse_args()
    warnings.simplefilter("ignore")
    prob = problem(tuple(a.branch), a.model, None if a.as_built is None else (a.as_built[0], a.as_built[1]))
    if a.min_measure is not None:
        assert prob.priors.measured_poses_clear is not None, "the study's priors state (b)"
        clear = dataclasses.replace(prob.priors.measured_poses_clear, min_measure=a.min_measure)
        prob = dataclasses.replace(prob, priors=dataclasses.replace(prob.priors, measured_poses_clear=clear))
    t = time.time()
    if a.together:
        together(prob, a)
        print(f"{time.time() - t:.0f} s")
        return
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


def together(prob: CalibrationProblem, a: argparse.Namespace) -> None:
    """One calibration of ``a.runs`` runs and its between-run check, with each run's best draw and base radius."""
    opts = SamplerOptions(
        sampler="smc", particles=a.particles, cheap_particles=a.cheap_particles, runs=a.runs, seed=a.seed,
        mode_starts=a.mode_starts, workers=a.workers, ess_fraction=a.ess_fraction, moves=a.moves, emulator=a.emulator,
        importance=a.importance, islands=a.islands, crossover=a.crossover, final_moves=a.final_moves, jumps=a.jumps,
        split=None if a.split is None else (a.split[0], int(a.split[1])),
    )  # fmt: skip
    cal = run_calibration(prob, opts, progress=True, print_func=print)
    check = cal.runs_check
    assert check is not None
    print(check.table())
    if a.save:
        np.savez(a.save, draws=cal.draws, names=np.array(prob.names), quantiles=check.quantiles, sd=check.merged_sd)
    base = prob.names.index("geometry.base_radius_m")
    for i, s in enumerate(check.seeds):
        print(f"seed {s}: ln Z {check.log_evidence[i]:.2f} +- {check.log_evidence_err[i]:.2f}, base radius 5/50/95 % "
              + " / ".join(f"{q:.3f}" for q in check.quantiles[i, base]))  # fmt: skip
    print(f"merged: base radius below 0.16 m in {np.mean(cal.draws[:, base] < 0.16):.0%} of the draws")
    print("check passed" if check.passed else f"check failed: {'; '.join(check.failures)}")


if __name__ == "__main__":
    main()
