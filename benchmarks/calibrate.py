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


N_TRAIN = 300
N_EXACT = 60


class EmulatedLikelihood(OneBlasThread):
    """The data stage's likelihood per particle: the emulator of the segment model as the sampler fits it
    (:mod:`fpm_sim.study.calibrate.emulator`: its two mode families, each on its surrogate, fitted to ``N_TRAIN``
    segment-model runs at prior draws that reach the measured poses; elbow branches (-1, -1, -1)) vectorised over
    4000 particles, against the segment model one at a time over ``N_EXACT`` (``track_segments_over_emulated``, the
    ratio of their CPU seconds per particle) and against the one-family emulator that preceded it (the in-plane
    surrogate alone, fitted to the same runs' first frequencies: ``track_two_families_over_one``)."""

    timeout = 600

    def setup(self) -> None:
        from fpm_sim.study.calibrate.emulator import train_emulator
        from fpm_sim.study.calibrate.problem import study_problem
        from fpm_sim.study.calibrate.vectorised import family_frequencies_batch

        warm_imports()
        self.limit_blas()
        p = self.problem = study_problem(branch=(-1, -1, -1))
        rng = np.random.default_rng(0)
        u = rng.random((20 * N_TRAIN, p.ndim))
        theta = p.prior_transform(u)
        f_sur, cheap = family_frequencies_batch(p, theta)
        ok = np.flatnonzero(np.isfinite(cheap))[:N_TRAIN]
        self.u, self.theta = u[ok], theta[ok]
        f_seg = np.array([p.predict_families(t) for t in self.theta])
        n_free, per = len(p.priors.parameters), p.priors.periodic
        self.emulator = train_emulator(self.u, f_seg, f_sur[ok], n_free=n_free, rng=rng, periodic=per)
        self.one_family = train_emulator(
            self.u, np.fmin(f_seg[:, 0], f_seg[:, 1]), f_sur[ok, 0], n_free=n_free, rng=rng, periodic=per
        )
        self.particles = np.repeat(self.u, 4000 // len(self.u) + 1, axis=0)[:4000]

    def emulated(self) -> np.ndarray:
        from fpm_sim.study.calibrate.vectorised import family_frequencies_batch, frequencies_log_likelihood_batch

        th = self.problem.prior_transform(self.particles)
        f, cheap = family_frequencies_batch(self.problem, th)
        emu = self.emulator
        return frequencies_log_likelihood_batch(
            self.problem, th, emu.frequencies(self.particles, f), cheap, model_error_rel=emu.model_error_rel
        )

    def emulated_one_family(self) -> np.ndarray:
        from fpm_sim.study.calibrate.vectorised import frequencies_log_likelihood_batch, inplane_frequencies_batch

        th = self.problem.prior_transform(self.particles)
        f, cheap = inplane_frequencies_batch(self.problem, th)
        emu = self.one_family
        return frequencies_log_likelihood_batch(
            self.problem, th, emu.frequencies(self.particles, f), cheap, model_error_rel=emu.model_error_rel
        )

    def track_emulated_us_per_particle(self) -> float:
        t = time.process_time()
        self.emulated()
        return (time.process_time() - t) / len(self.particles) * 1e6

    def track_two_families_over_one(self) -> float:
        t = time.process_time()
        self.emulated_one_family()
        one = time.process_time() - t
        t = time.process_time()
        self.emulated()
        return (time.process_time() - t) / one

    def track_segments_over_emulated(self) -> float:
        t = time.process_time()
        for x in self.theta[:N_EXACT]:
            self.problem.log_likelihood(x)
        exact = (time.process_time() - t) / N_EXACT
        t = time.process_time()
        self.emulated()
        return exact / ((time.process_time() - t) / len(self.particles))


N_MATRICES = 12_000
"""A data stage's evaluation: 1000 particles at the study's 12 measured poses."""


class SmallMatrices(OneBlasThread):
    """The closed forms of :mod:`fpm_sim.linalg3` against NumPy's batched LAPACK on ``N_MATRICES`` 3x3 matrices: the
    singular-value ratio (the parallel singularity measure) against ``svd``, and the pencil's smallest eigenvalue (the
    in-plane surrogate's first frequency) against ``eigvals(solve(M, K))``. ``track_*`` are LAPACK's CPU seconds over
    the closed form's."""

    timeout = 300

    def setup(self) -> None:
        self.limit_blas()
        rng = np.random.default_rng(0)
        self.j = rng.standard_normal((N_MATRICES, 3, 3))
        jm = rng.standard_normal((N_MATRICES, 3, 3))
        self.k = self.j @ np.swapaxes(self.j, 1, 2)
        self.m = jm @ np.swapaxes(jm, 1, 2) + 0.1 * np.eye(3)

    @staticmethod
    def _ratio(fast, slow, repeat: int = 20) -> float:
        t = time.process_time()
        for _ in range(repeat):
            slow()
        s = time.process_time() - t
        t = time.process_time()
        for _ in range(repeat):
            fast()
        return s / (time.process_time() - t)

    def track_svd_over_closed_form(self) -> float:
        from fpm_sim.linalg3 import inverse_condition3

        return self._ratio(lambda: inverse_condition3(self.j), lambda: np.linalg.svd(self.j, compute_uv=False))

    def track_eigvals_over_closed_form(self) -> float:
        from fpm_sim.linalg3 import smallest_generalized_eigenvalue3

        return self._ratio(
            lambda: smallest_generalized_eigenvalue3(self.k, self.m),
            lambda: np.linalg.eigvals(np.linalg.solve(self.m, self.k)).real.min(axis=1),
        )
