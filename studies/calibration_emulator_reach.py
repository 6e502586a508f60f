"""Where runs of one class of the emulated calibration differ, and whether the emulator or the sampler is the cause
(issue 31; docs/identification.md, "A ridge, not a needle"). The study's problem on the segment model, the elbow
branches fixed, one SMC run per seed with ``--emulator``; each run's data stages and its emulator's two fits are
kept (in this process), then compared across the runs:

    python studies/calibration_emulator_reach.py --branch -1 -1 1 --seeds 0 1 2 3 4 5
    python studies/calibration_emulator_reach.py --branch -1 -1 1 --seeds 0 1 2 --ess-fraction 0.9 --moves 10
    python studies/calibration_emulator_reach.py --branch -1 -1 1 --seeds 0 1 2 --ess-fraction 0.9 --moves 10 \
        --particles 2000 --cheap-particles 4000
    python studies/calibration_emulator_reach.py --branch -1 -1 1 --seeds 2 0 1 --ess-fraction 0.9 --moves 10 \
        --split geometry.base_rotation_deg 2 --part 0        # the motors' rotation's negative half alone

``--split NAME N --part K``: only part ``K`` (from 0) of ``N`` equal prior parts of ``NAME`` is sampled
(``SamplerOptions.split``; the particles' unit-cube coordinates are then the part's own).

Prints per run its ln Z, weights' ESS and Pareto k, best exact log L, the parameters there and the weighted
5/50/95 % points of ``--parameters``; then, at each run's 20 best particles, every run's stage 1's nearest particle
(unit-cube distance) and every run's emulator (first fit, at stage 1's particles; refit, with the first data stage's)
against the segment model; then the runs' posteriors clustered (average linkage at unit-cube distance ``--cut``,
whole-turn angles on a circle)
with each run's share of each cluster.
"""

from __future__ import annotations

import argparse
import time
import warnings
from typing import Any

import numpy as np
from scipy.cluster.hierarchy import fcluster, linkage
from scipy.spatial.distance import pdist

from fpm_sim.study.calibrate import SamplerOptions, run_calibration
from fpm_sim.study.calibrate import sampler as S
from fpm_sim.study.calibrate import smc as SM
from fpm_sim.study.calibrate.emulator import importance_diagnostics
from fpm_sim.study.calibrate.problem import study_problem

KEPT: dict[str, Any] = {}


def _keep() -> None:
    """Wrap the sampler's pieces so that each run's data stages, result and emulator fits are kept."""
    data_stage, emulated = SM._data_stage, S.emulated_two_stage

    def stage(one: Any, full: Any, s: Any, rng: Any) -> Any:
        two = data_stage(one, full, s, rng)
        KEPT.setdefault("stages", []).append(two.u.copy())
        KEPT["one"] = one.u.copy()
        return two

    def run(*a: Any, **k: Any) -> Any:
        KEPT["run"] = emulated(*a, **k)
        return KEPT["run"]

    class Emu(S._SegmentEmulator):
        def __init__(self, **kw: Any) -> None:
            super().__init__(**kw)
            self.fits: list[Any] = []
            KEPT["emu"] = self

        def _fit(self) -> Any:
            self.fits.append(super()._fit())
            return self.fits[-1]

    SM._data_stage, S.emulated_two_stage, S._SegmentEmulator = stage, run, Emu  # type: ignore[assignment,misc]


def _clusters(res: list[dict[str, Any]], periodic: tuple[int, ...], cut: float) -> None:
    rng = np.random.default_rng(0)
    pts, lbs, who = [], [], []
    for r in res:
        w = np.exp(r["logw"])
        idx = rng.choice(len(w), 300, p=w / w.sum())
        pts.append(r["u"][idx])
        lbs.append(r["lb"][idx])
        who += [r["seed"]] * 300
    u, lb, seeds = np.concatenate(pts), np.concatenate(lbs), np.array(who)
    per = list(periodic)

    def dist(a: np.ndarray, b: np.ndarray) -> float:
        d = np.abs(a - b)
        d[per] = np.minimum(d[per], 1 - d[per])
        return float(np.sqrt(np.sum(d**2)))

    lab = fcluster(linkage(pdist(u, dist), "average"), t=cut, criterion="distance")
    print(f"clusters at {cut}: {len(np.unique(lab))} (those with >= 15 of the {len(u)} draws below)")
    for c in np.unique(lab):
        m = lab == c
        if m.sum() < 15:
            continue
        share = " ".join(f"{np.mean(lab[seeds == r['seed']] == c):.2f}" for r in res)
        print(f"  best log L {lb[m].max():.2f}, centre {np.round(np.median(u[m], 0), 2)}; share per run {share}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--branch", type=int, nargs=3, default=[-1, -1, 1])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--particles", type=int, default=1000)
    p.add_argument("--cheap-particles", type=int, default=2000)
    p.add_argument("--emulator", type=int, default=500)
    p.add_argument("--ess-fraction", type=float, default=0.5)
    p.add_argument("--moves", type=float, default=3.0)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--cut", type=float, default=0.35)
    p.add_argument("--split", nargs=2, metavar=("NAME", "N"), help="sample one part of this split (with --part)")
    p.add_argument("--part", type=int, default=0, help="the part of --split sampled (from 0)")
    p.add_argument("--parameters", nargs="+", default=["geometry.distal_length_m", "geometry.platform_radius_m"],
                   help="parameters whose weighted 5/50/95 %% points each run prints")  # fmt: skip
    a = p.parse_args()
    warnings.simplefilter("ignore")
    _keep()
    split = None if a.split is None else (a.split[0], int(a.split[1]))
    prob = study_problem(model="segments", branch=tuple(a.branch))  # type: ignore[arg-type]
    part = None
    if split is not None:  # the sampler samples only that part (its unit-cube coordinates are the part's own)
        parts = S._parts
        S._parts = lambda problem, opts: parts(problem, opts)[a.part : a.part + 1]  # type: ignore[assignment]
        part = S._parts(prob, SamplerOptions(sampler="smc", split=split))[0]
    res = []
    for seed in a.seeds:
        t0 = time.time()
        KEPT.clear()
        opts = SamplerOptions(sampler="smc", particles=a.particles, cheap_particles=a.cheap_particles, runs=1,
                              seed=seed, workers=a.workers, emulator=a.emulator, ess_fraction=a.ess_fraction,
                              moves=a.moves, split=split)  # fmt: skip
        run_calibration(prob, opts, progress=False)
        run, emu = KEPT["run"], KEPT["emu"]
        ess, k = importance_diagnostics(run.log_weights)
        res.append(
            {"seed": seed, "u": run.u, "lb": run.log_b, "logw": run.log_weights, "fits": emu.fits, "one": KEPT["one"]}
        )
        print(f"seed {seed}: ln Z {run.log_evidence:.2f} +- {run.log_evidence_err:.2f}, weights' ESS {ess:.0f}, "
              f"k {k:.2f}, best exact log L {np.max(run.log_b):.2f}, sampled again on a refit {emu.rounds} time(s), "
              f"{time.time() - t0:.0f} s", flush=True)  # fmt: skip
        theta, w = S._class_thetas(run.u, None, part), np.exp(run.log_weights)
        best = theta[int(np.argmax(run.log_b))]
        print("  best particle: " + ", ".join(f"{n.split('.', 1)[1]} {v:.4g}" for n, v in zip(prob.names, best)))
        for name in a.parameters:
            pts = np.quantile(theta[:, prob.names.index(name)], (0.05, 0.5, 0.95), weights=w, method="inverted_cdf")
            print(f"  {name} 5/50/95 %: {' / '.join(f'{v:.4g}' for v in pts)}", flush=True)
    for r in res:
        top = np.argsort(r["lb"])[-20:]
        print(f"at seed {r['seed']}'s 20 best particles (segment model's log L, median {np.median(r['lb'][top]):.2f}):")
        for o in res:
            first, refit = (float(np.median(f(r["u"][top])[1])) for f in (o["fits"][0], o["fits"][-1]))
            near = np.min(np.linalg.norm(o["one"][:, None, :] - r["u"][top][None], axis=2), axis=0)
            print(
                f"  seed {o['seed']}'s emulator: first fit {first:.2f}, refit {refit:.2f}; its stage 1's nearest "
                f"particle {np.median(near):.2f} away (median)"
            )
    _clusters(res, tuple(prob.priors.periodic), a.cut)


if __name__ == "__main__":
    main()
