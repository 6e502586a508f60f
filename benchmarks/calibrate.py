"""Calibration (issue 31): the study's cheap likelihood (the support and the statements) for many particles at once
against one at a time, as the SMC sampler's first stage evaluates it.

``CheapLikelihood``: ``N_PARTICLES`` prior draws of the study's calibration problem (its priors, data and statements,
the elbow branches sampled), :func:`fpm_sim.study.calibrate.vectorised.cheap_log_likelihood_batch` against
:meth:`~fpm_sim.study.calibrate.problem.CalibrationProblem.cheap_log_likelihood` row by row (the prior transform
included in both). ``track_one_at_a_time_over_vectorised`` is the ratio of their CPU seconds.

CPU time of this process (``time.process_time``), one BLAS thread.
"""

from __future__ import annotations

import time

import numpy as np

from benchmarks.common import OneBlasThread, warm_imports

N_PARTICLES = 4000


class CheapLikelihood(OneBlasThread):
    """The statements' likelihood of ``N_PARTICLES`` particles, vectorised against one at a time."""

    timeout = 600

    def setup(self) -> None:
        from fpm_sim.study.calibrate.problem import study_problem

        warm_imports()
        self.limit_blas()
        self.problem = study_problem()
        self.u = np.random.default_rng(0).random((N_PARTICLES, self.problem.ndim))

    def vectorised(self) -> np.ndarray:
        from fpm_sim.study.calibrate.vectorised import cheap_log_likelihood_batch

        return cheap_log_likelihood_batch(self.problem, self.problem.prior_transform(self.u))

    def one_at_a_time(self) -> np.ndarray:
        p = self.problem
        return np.array([p.cheap_log_likelihood(p.prior_transform(x)) for x in self.u])

    def time_vectorised(self) -> None:
        self.vectorised()

    def track_vectorised_us_per_particle(self) -> float:
        t = time.process_time()
        self.vectorised()
        return (time.process_time() - t) / N_PARTICLES * 1e6

    def track_one_at_a_time_over_vectorised(self) -> float:
        t = time.process_time()
        self.one_at_a_time()
        slow = time.process_time() - t
        t = time.process_time()
        self.vectorised()
        return slow / (time.process_time() - t)
