"""Local refinements of several candidates, two ways on the same starts: the starts refined in parallel
processes (one pose loop each, what ``fpm-sim identify --workers N`` does) against one after the other with
each evaluation's pose loop split over the same N processes (what it did before).

    python scripts/benchmark_identify_refine.py --starts 4 --workers 2

The problem: the study's 12 measured poses and COMSOL's 18 (as ``scripts/identify_study.py``), the shipped
default's geometry, hardware and section height free (10 parameters), starts drawn around the shipped
optimum; each refinement ``--max-nfev`` trust-region iterations. Prints both times, their ratio and the
largest difference of the refined costs (the same computation: ~round-off)."""

from __future__ import annotations

import argparse
import time
from importlib import resources

import numpy as np

from fpm_sim.config import default_config
from fpm_sim.study.identify import IdentifyOptions, Problem, engine, parameter_set, read_measured_csv
from fpm_sim.study.poses import parse_reading


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--starts", type=int, default=4)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--max-nfev", type=int, default=5)
    args = ap.parse_args()
    data = resources.files("fpm_sim.data")
    obs = []
    for name, sigma in (("measured_table4_train.csv", 2.0), ("comsol_table5.csv", 7.0)):
        obs += read_measured_csv(str(data / name), reading=parse_reading("x+"), sigma_pct=sigma).observations
    ps = parameter_set(default_config(), ["geometry", "hardware", "section-height"])
    problem = Problem(ps, obs)
    opts = IdentifyOptions(workers=args.workers, max_nfev=args.max_nfev)
    obj = engine._Objective(problem, opts)
    rng = np.random.default_rng(0)
    z0 = obj.z(ps.x0)
    starts = [(np.clip(z0 + 0.03 * rng.standard_normal(len(z0)), 0, 1), f"start {k}", None) for k in range(args.starts)]
    t0 = time.perf_counter()
    parallel = list(engine._refine_all(problem, opts, starts))
    t_par = time.perf_counter() - t0
    t0 = time.perf_counter()
    serial = [next(engine._refine_all(problem, opts, [s])) for s in starts]
    t_ser = time.perf_counter() - t0
    d_cost = max(abs(float(np.sum(a[1] ** 2)) - float(np.sum(b[1] ** 2))) for a, b in zip(parallel, serial))
    print(f"{args.starts} refinements, {args.workers} workers, {args.max_nfev} iterations each")
    print(f"  starts in parallel processes:         {t_par:7.1f} s")
    print(f"  one after another, pose loop split:   {t_ser:7.1f} s")
    print(f"  ratio: {t_ser / t_par:.2f}x; largest cost difference {d_cost:.2e}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
