"""Does a least-squares search on the segment model itself reach the calibration's narrow peaks (issue 31;
docs/identification.md, "The second mode is a peak the emulator cannot see")? The study's problem with the elbow
branches fixed, optionally one part of a split prior (as ``studies/calibration_emulator_reach.py``): ``--starts``
prior draws inside the support and the study's statements (the first stage's region), each the start of a bounded
trust-region least-squares fit (scipy, forward-difference Jacobian) of the data's weighted residuals
``(f - measured) / s(f, d)`` at a fixed discrepancy ``d`` (``--discrepancy``); each optimum's full log-likelihood
(the statements included, the discrepancy at its value) is printed with its parameters:

    python studies/calibration_peak_search.py --branch -1 -1 1 --split geometry.base_rotation_deg 2 --part 0
"""

from __future__ import annotations

import argparse
import time
import warnings
from multiprocessing import get_context
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from fpm_sim.study.calibrate import SamplerOptions
from fpm_sim.study.calibrate import sampler as S
from fpm_sim.study.calibrate.problem import study_problem

STATE: dict[str, Any] = {}


def _init(branch: tuple[int, int, int], split: tuple[str, int] | None, part: int, d: float) -> None:
    warnings.simplefilter("ignore")
    prob = study_problem(model="segments", branch=branch)
    S._init_worker(prob)
    chosen = S._parts(prob, SamplerOptions(sampler="smc", split=split))[part] if split else None
    STATE.update(prob=prob, part=chosen, d=d)


def _theta(u: np.ndarray) -> np.ndarray:
    th: np.ndarray = S._class_thetas(np.clip(u, 0.0, 1.0)[None], None, STATE["part"])[0]
    th[len(STATE["prob"].priors.parameters)] = STATE["d"]
    return th


def _residuals(u: np.ndarray) -> np.ndarray:
    prob = STATE["prob"]
    th = _theta(u)
    f = prob.predict(th)
    r = (f - prob.measured) / prob.noise_sd(f, STATE["d"])
    return np.where(np.isfinite(r), r, 1e3)


def _fit(u0: np.ndarray) -> tuple[float, float, np.ndarray, int, float]:
    t0 = time.time()
    r = least_squares(_residuals, u0, bounds=(0.0, 1.0), method="trf", diff_step=1e-3, max_nfev=300)
    prob = STATE["prob"]
    return prob.log_likelihood(_theta(u0)), prob.log_likelihood(_theta(r.x)), _theta(r.x), r.nfev, time.time() - t0


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--branch", type=int, nargs=3, default=[-1, -1, 1])
    p.add_argument("--split", nargs=2, metavar=("NAME", "N"))
    p.add_argument("--part", type=int, default=0)
    p.add_argument("--starts", type=int, default=16)
    p.add_argument("--discrepancy", type=float, default=0.15)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--workers", type=int, default=2)
    a = p.parse_args()
    split = None if a.split is None else (a.split[0], int(a.split[1]))
    args = (tuple(a.branch), split, a.part, a.discrepancy)
    _init(*args)
    prob, part = STATE["prob"], STATE["part"]
    rng = np.random.default_rng(a.seed)
    u = rng.random((20 * a.starts, prob.ndim))
    ok = np.isfinite(S._smc_cheap(u, None, part)[1])
    starts = u[ok][: a.starts]
    print(f"{ok.sum()} of {len(u)} prior draws inside the statements; {len(starts)} starts", flush=True)
    t0 = time.time()
    with get_context("spawn").Pool(a.workers, initializer=_init, initargs=args) as pool:
        found = list(pool.imap(_fit, list(starts)))
    names = [n.split(".", 1)[1] for n in prob.names]
    for l0, l1, th, nfev, sec in sorted(found, key=lambda x: -x[1]):
        pars = ", ".join(f"{n} {v:.4g}" for n, v in zip(names, th))
        print(f"  log L {l0:.2f} -> {l1:.2f} ({nfev} evaluations, {sec:.0f} s): {pars}", flush=True)
    print(f"{len(starts)} starts in {time.time() - t0:.0f} s on {a.workers} workers")


if __name__ == "__main__":
    main()
