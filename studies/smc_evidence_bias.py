"""Whether the calibration's two-stage SMC estimates the evidence without bias, on the two-mode mixture of
``tests/study/test_calibrate_smc.py`` (Z = 1 exactly), with its own moves or with others (issue 31; the closing
note of 7 Dec 2026):

    python studies/smc_evidence_bias.py de --seeds 100                 # the differential-evolution moves as built
    python studies/smc_evidence_bias.py de --seeds 100 --ess-fraction 0.9
    python studies/smc_evidence_bias.py rw --seeds 60                  # random-walk moves of a fixed scale
    python studies/smc_evidence_bias.py nocopy --seeds 40              # DE differences without the particle's copies

Prints the mean of ln Z and of Z over the seeds with their standard errors (an unbiased estimator of Z has a mean
of Z within a few standard errors of 1). ``rw``'s proposal does not depend on the population; ``de``'s does, through
the two other particles whose difference it takes, which after a resampling may be copies of the moved one.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from fpm_sim.study.calibrate import smc as SM
from tests.study.test_calibrate_smc import D, _cheap, _full


def rw_sweep(u: np.ndarray, la: np.ndarray, lb: np.ndarray, beta: float, gamma: float, evaluate: Any,
             rng: np.random.Generator, periodic: tuple[int, ...] = ()) -> Any:  # fmt: skip
    """Random-walk Metropolis, steps of ``gamma`` times the modes' sd (0.01): no dependence on the population."""
    return SM.metropolis(u, la, lb, beta, SM._fold(u + gamma * 0.01 * rng.standard_normal(u.shape), periodic),
                       evaluate, rng)  # fmt: skip


def nocopy_sweep(u: np.ndarray, la: np.ndarray, lb: np.ndarray, beta: float, gamma: float, evaluate: Any,
                 rng: np.random.Generator, periodic: tuple[int, ...] = ()) -> Any:  # fmt: skip
    """The differential-evolution sweep with ``a, b`` drawn among the rows that are not copies of the moved one."""
    n = len(u)
    keys = np.unique(u, axis=0, return_inverse=True)[1].ravel()
    a, b = np.empty(n, int), np.empty(n, int)
    for i in range(n):
        while True:
            x, y = rng.integers(0, n, 2)
            if x != y and keys[x] != keys[i] and keys[y] != keys[i]:
                break
        a[i], b[i] = x, y
    prop = SM._fold(u + gamma * (u[a] - u[b]) + 1e-6 * rng.standard_normal(u.shape), periodic)
    return SM.metropolis(u, la, lb, beta, prop, evaluate, rng)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("moves", choices=("de", "rw", "nocopy"))
    p.add_argument("--seeds", type=int, default=100)
    p.add_argument("--ess-fraction", type=float, default=0.5)
    a = p.parse_args()
    if a.moves == "rw":
        SM._sweep = rw_sweep
    elif a.moves == "nocopy":
        SM._sweep = nocopy_sweep
    s1, s2 = SM.SmcSettings(particles=500, ess_fraction=a.ess_fraction), SM.SmcSettings(1600, a.ess_fraction)
    z = np.array([SM.two_stage(_cheap, _full, D, s1, s2, np.random.default_rng(s)).log_evidence
                  for s in range(a.seeds)])  # fmt: skip
    se = np.std(z, ddof=1) / np.sqrt(len(z))
    ez = np.exp(z)
    print(
        f"{a.moves}, ESS fraction {a.ess_fraction}, {a.seeds} seeds: mean ln Z {z.mean():.4f} +- {se:.4f} "
        f"(sd {np.std(z, ddof=1):.3f}); mean Z {ez.mean():.4f} +- {np.std(ez, ddof=1) / np.sqrt(len(z)):.4f}"
    )


if __name__ == "__main__":
    main()
