"""Identification: local refinements of several candidates, in parallel processes or one after another (issue 12).

(Was ``scripts/benchmark_identify_refine.py``.) The study's 12 measured poses and COMSOL's 18 (as
``scripts/identify_study.py``), the shipped default's geometry, hardware and section height free (10
parameters), 2 starts drawn around the shipped optimum, each refined by 3 trust-region iterations
(``FPM_SIM_BENCH_FULL=1``: the docs' 4 starts, 5 iterations). The parameter ``way``: the starts refined in two
spawned processes, one pose loop each (``fpm-sim identify --workers 2``), or one after another with each
evaluation's pose loop split over the same two processes (what it did before). ``track_cost_difference`` checks
that both ways compute the same thing (difference of the refined costs: round-off).
"""

from __future__ import annotations

import numpy as np

from benchmarks.common import full_run

WAYS = ["starts in parallel processes", "one after another, pose loop split"]
WORKERS = 2


def _problem():
    from importlib import resources

    from fpm_sim.config import default_config
    from fpm_sim.study.identify import IdentifyOptions, Problem, parameter_set, read_measured_csv
    from fpm_sim.study.identify.objective import Objective
    from fpm_sim.study.identify.strategies import Candidate
    from fpm_sim.study.poses import parse_reading

    n_starts, max_nfev = (4, 5) if full_run() else (2, 3)
    data = resources.files("fpm_sim.data")
    obs = []
    for name, sigma in (("measured_table4_train.csv", 2.0), ("comsol_table5.csv", 7.0)):
        obs += read_measured_csv(str(data / name), reading=parse_reading("x+"), sigma_pct=sigma).observations
    ps = parameter_set(default_config(), ["geometry", "hardware", "section-height"])
    problem = Problem(ps, obs)
    opts = IdentifyOptions(workers=WORKERS, max_nfev=max_nfev)
    z0 = Objective(problem, opts).z(ps.x0)
    rng = np.random.default_rng(0)
    starts = [
        Candidate(np.clip(z0 + 0.03 * rng.standard_normal(len(z0)), 0, 1), float("nan"), f"start {k}", None)
        for k in range(n_starts)
    ]
    return problem, opts, starts


def _refine(problem, opts, starts, way: str) -> list:
    from fpm_sim.study.identify.objective import Objective
    from fpm_sim.study.identify.strategies.lsq import LeastSquares

    objective = Objective(problem, opts)
    if way == WAYS[0]:  # the starts in parallel processes, one pose loop each
        return list(LeastSquares(tuple(starts)).ends(objective, workers=opts.workers))
    # one after another, each evaluation's pose loop split over opts.workers processes
    return [next(LeastSquares((s,)).ends(objective, workers=1)) for s in starts]


class Refinements:
    """The starts' local refinements, one way (the parameter), wall time."""

    params = [WAYS]
    param_names = ["way"]
    number = 1
    repeat = (1, 3, 60.0)
    timeout = 600.0

    def setup(self, way: str) -> None:
        self.problem, self.opts, self.starts = _problem()

    def time_refine(self, way: str) -> None:
        _refine(self.problem, self.opts, self.starts, way)


class RefinementAgreement:
    """Largest difference of the refined costs (sum of squared residuals) between the two ways."""

    timeout = 600.0

    def track_cost_difference(self) -> float:
        problem, opts, starts = _problem()
        a, b = (_refine(problem, opts, starts, way) for way in WAYS)
        return max(abs(float(np.sum(x.residuals**2)) - float(np.sum(y.residuals**2))) for x, y in zip(a, b))

    track_cost_difference.unit = "cost"
