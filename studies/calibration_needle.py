"""Where the calibration's best region hides, and which searches reach it (issue 31; docs/identification.md,
"Why independent runs still disagree", "The needle"). The study's calibration problem on the in-plane surrogate,
elbow branches (-1, -1, -1) (:func:`fpm_sim.study.calibrate.problem.study_problem`):

    python studies/calibration_needle.py stage1 --seed 2 --particles 1000     # writes out/needle/stage1_seed2.npz
    python studies/calibration_needle.py stage2 --stage1 out/needle/stage1_seed2.npz --particles 200 --seed 0
    python studies/calibration_needle.py powell --stage1 out/needle/stage1_seed2.npz --starts 12
    python studies/calibration_needle.py de --seed 0 --generations 400 --popsize 15 --one-at-a-time
    python studies/calibration_needle.py de --seed 0 --generations 1000 --popsize 30   # vectorised, deferred updating
    python studies/calibration_needle.py search --seed 70000 --starts 5 --parts 5 --part 0   # the sampler's search
    python studies/calibration_needle.py gap --seed 0 --draws 400     # the surrogate's posterior on the segment model

``stage1``: the SMC's first stage (prior -> prior x the study's statements), its share of particles at the compact
geometry (base radius < 0.16 m) and their best data log-likelihood against the rest's. ``stage2``: the data stage
from a saved stage-1 population. ``powell``: local searches of the full log-likelihood from stage-1 particles at the
compact geometry and elsewhere. ``de``: a global search (scipy's differential evolution) of it. ``search``: the
sampler's own mode search, on the whole prior or on one part of the base radius's. ``gap``: the surrogate's
posterior (one SMC run with a 12-start mode search) importance-weighted to the segment model. The surrogate
(``model="inplane"``) is for checks of the sampler, never for a reported result."""

from __future__ import annotations

import argparse
import math
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.optimize import differential_evolution, minimize

from fpm_sim.study.calibrate.problem import study_problem
from fpm_sim.study.calibrate.smc import SmcSettings, _first_data_step, _from_prior, _move, temper
from fpm_sim.study.calibrate.vectorised import inplane_log_likelihood_batch

COMPACT_M = 0.16
"""Base radius below which a geometry counts as the compact region (the runs that found it: ~0.115 m)."""

PROB = study_problem(model="inplane", branch=(-1, -1, -1))
BASE = PROB.names.index("geometry.base_radius_m")


def cheap(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.zeros(len(u)), np.array([PROB.cheap_log_likelihood(PROB.prior_transform(x)) for x in u])


def full(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    th = [PROB.prior_transform(x) for x in u]
    c = np.array([PROB.cheap_log_likelihood(t) for t in th])
    f = np.array([PROB.log_likelihood(t) if np.isfinite(ci) else -np.inf for t, ci in zip(th, c)])
    with np.errstate(invalid="ignore"):
        return c, np.where(np.isfinite(f), f - c, -np.inf)


def stage1(a: argparse.Namespace) -> None:
    rng = np.random.default_rng(a.seed)
    s1 = SmcSettings(particles=a.particles, moves=10.0)
    start = _from_prior(cheap, PROB.ndim, s1, rng)
    assert start is not None
    u, _, lc, log_mass, _, _ = start
    one = temper(u, np.zeros(len(u)), lc, cheap, s1, rng)
    th = np.array([PROB.prior_transform(x) for x in one.u])
    ll = np.array([PROB.log_likelihood(x) for x in th])
    st = np.array([PROB.statements_log_likelihood(PROB.config(x)) for x in th])
    small = th[:, BASE] < COMPACT_M
    best_small = f"{(ll - st)[small].max():.1f}" if small.any() else "none"
    print(f"stage 1, seed {a.seed}: ln Z {one.log_evidence + log_mass:.2f}; compact share {small.mean():.3f} "
          f"({small.sum()} particles); best data log L at the compact geometry {best_small}, elsewhere "
          f"{(ll - st)[~small].max():.1f}")  # fmt: skip
    out = Path(a.out) / f"stage1_seed{a.seed}.npz"
    out.parent.mkdir(parents=True, exist_ok=True)
    np.savez(out, u=one.u, th=th, ll=ll)


def stage2(a: argparse.Namespace) -> None:
    z = np.load(a.stage1)
    rng = np.random.default_rng(a.seed)
    s2 = SmcSettings(particles=a.particles, moves=a.moves)
    u, la, lb, beta, lz, var = _first_data_step(z["u"], full, s2, rng)
    u, la, lb, _, _, _ = _move(u, la, lb, beta, full, s2, rng, 1.0)
    two = temper(u, la, lb, full, s2, rng, beta=beta)
    th = np.array([PROB.prior_transform(x) for x in two.u])
    print(f"stage 2 from {a.stage1}, {a.particles} particles, {a.moves:g} moves, seed {a.seed}: ln Z_2 "
          f"{lz + two.log_evidence:.2f} +- {math.sqrt(var + two.log_evidence_var):.2f}; compact share "
          f"{(th[:, BASE] < COMPACT_M).mean():.2f}; best log L {(two.log_a + two.log_b).max():.2f}")  # fmt: skip


def neg_log_l(x: np.ndarray) -> float:
    if np.any(x < 0) or np.any(x > 1):
        return 1e4
    v = PROB.log_likelihood(PROB.prior_transform(x))
    return -v if np.isfinite(v) else 1e4


def powell(a: argparse.Namespace) -> None:
    z = np.load(a.stage1)
    small = np.flatnonzero(z["th"][:, BASE] < COMPACT_M)
    _, first = np.unique(z["u"], axis=0, return_index=True)
    others = np.random.default_rng(0).choice(np.setdiff1d(first, small), a.starts, replace=False)
    for tag, idx in (("compact", small[: a.starts]), ("elsewhere", others)):
        for i in idx:
            r = minimize(neg_log_l, z["u"][i], method="Powell", options={"maxfev": 4000, "xtol": 1e-4, "ftol": 1e-6})
            end = PROB.prior_transform(r.x)[BASE]
            print(f"{tag}: log L {z['ll'][i]:.1f} -> {-r.fun:.2f}, base radius {z['th'][i, BASE]:.3f} -> {end:.3f} m")


def neg_log_l_columns(x: np.ndarray) -> np.ndarray:
    """``-log L`` of the columns of ``x`` (``(d, S)``, scipy's vectorised form), vectorised over them."""
    v = inplane_log_likelihood_batch(PROB, PROB.prior_transform(np.clip(x.T, 0.0, 1.0)))
    out: np.ndarray = np.where(np.isfinite(v), -v, 1e4)
    return out


def de(a: argparse.Namespace) -> None:
    t = time.perf_counter()
    kw: dict[str, object] = {"vectorized": True, "updating": "deferred"}
    fun = neg_log_l_columns
    if a.one_at_a_time:
        kw, fun = {}, neg_log_l  # type: ignore[assignment]
    r = differential_evolution(fun, [(0.0, 1.0)] * PROB.ndim, seed=a.seed, maxiter=a.generations,  # type: ignore[arg-type]
                               popsize=a.popsize, tol=1e-8 if a.one_at_a_time else 1e-10, polish=False, init="sobol",
                               **kw)  # fmt: skip
    print(f"differential evolution, seed {a.seed}: best log L {-r.fun:.2f}, base radius "
          f"{PROB.prior_transform(r.x)[BASE]:.3f} m, {r.nit} generations, {r.nfev} calls of the objective (vectorised: "
          f"a generation each), {time.perf_counter() - t:.0f} s")  # fmt: skip


def search(a: argparse.Namespace) -> None:
    """The sampler's own mode search (``sampler._search_start``: differential evolution to convergence, then
    particles spread over its optimum), ``--starts`` starts from seed ``--seed``, on the whole prior or on part
    ``--part`` of ``--parts`` equal prior-mass parts of the base radius (``SamplerOptions.split``)."""
    from fpm_sim.study.calibrate import sampler

    sampler._init_worker(PROB)
    part = None if a.parts is None else (BASE, a.parts, a.part)
    for k in range(a.starts):
        t = time.perf_counter()
        best, pop = sampler._search_start((None, part, PROB.ndim, a.seed + k))
        radius = np.median(sampler._class_thetas(pop, None, part)[:, BASE])
        print(f"seed {a.seed + k}: best log L {best:.2f}, spread particles' median base radius {radius:.3f} m, "
              f"{time.perf_counter() - t:.0f} s", flush=True)  # fmt: skip


def _segment_log_likelihood(theta: np.ndarray) -> float:
    return SEGMENTS.log_likelihood(theta)


SEGMENTS = study_problem(model="segments", branch=(-1, -1, -1))


def gap(a: argparse.Namespace) -> None:
    """The surrogate's posterior (one run, 1000 + 2000 particles, a 12-start mode search, seed ``--seed``) at
    ``--draws`` of its draws on the segment model: ``log L_segments - log L_surrogate`` in the compact region and
    elsewhere, and the draws' importance weights to the segment model (effective sample size, Pareto k)."""
    import multiprocessing

    from fpm_sim.study.calibrate import SamplerOptions, run_calibration
    from fpm_sim.study.calibrate.emulator import importance_diagnostics

    opts = SamplerOptions(sampler="smc", particles=1000, cheap_particles=2000, runs=1, seed=a.seed, mode_starts=12,
                          workers=2)  # fmt: skip
    draws = run_calibration(PROB, opts, progress=False).draws
    d = draws[np.random.default_rng(1).choice(len(draws), min(a.draws, len(draws)), replace=False)]
    with multiprocessing.get_context("spawn").Pool(2) as pool:
        segments = np.array(pool.map(_segment_log_likelihood, list(d), chunksize=8))
    log_w = segments - inplane_log_likelihood_batch(PROB, d)
    compact = d[:, BASE] < COMPACT_M
    for name, rows in (("compact", compact), ("elsewhere", ~compact)):
        if rows.any():
            q = np.percentile(log_w[rows], [5, 50, 95])
            print(f"{name}: {rows.mean():.1%} of the draws, log L_segments - log L_surrogate 5/50/95 %: "
                  + " / ".join(f"{v:.1f}" for v in q))  # fmt: skip
    ess, k = importance_diagnostics(log_w)
    print(f"weights to the segment model: ESS {ess:.1f} of {len(d)}, Pareto k {k:.2f}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(required=True)
    s = sub.add_parser("stage1")
    s.add_argument("--seed", type=int, default=2)
    s.add_argument("--particles", type=int, default=1000)
    s.add_argument("--out", default="out/needle")
    s.set_defaults(func=stage1)
    s = sub.add_parser("search")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--starts", type=int, default=5)
    s.add_argument("--parts", type=int, default=None)
    s.add_argument("--part", type=int, default=0)
    s.set_defaults(func=search)
    s = sub.add_parser("gap")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--draws", type=int, default=400)
    s.set_defaults(func=gap)
    s = sub.add_parser("stage2")
    s.add_argument("--stage1", required=True)
    s.add_argument("--particles", type=int, default=200)
    s.add_argument("--moves", type=float, default=3.0)
    s.add_argument("--seed", type=int, default=0)
    s.set_defaults(func=stage2)
    s = sub.add_parser("powell")
    s.add_argument("--stage1", required=True)
    s.add_argument("--starts", type=int, default=12)
    s.set_defaults(func=powell)
    s = sub.add_parser("de")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--generations", type=int, default=400)
    s.add_argument("--popsize", type=int, default=15)
    s.add_argument("--one-at-a-time", action="store_true", help="immediate updating, one call per candidate")
    s.set_defaults(func=de)
    warnings.simplefilter("ignore")
    a = p.parse_args()
    a.func(a)


if __name__ == "__main__":
    main()
