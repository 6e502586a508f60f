"""The objective of an identification: one picklable object, the problem with its search settings, whose
residuals (in sigmas, over parameters normalised to their bounds) every search strategy minimises.

Cost: ``sum(r_i^2)`` with ``r_i = (f_model,i - f_measured,i) / sigma_i`` over every observation and rig test,
then the workspace prior's residuals (:func:`fpm_sim.study.identify.problem.workspace_residuals`). An
observation the model cannot give has the residual :data:`~fpm_sim.study.identify.problem.PENALTY_SIGMAS`.
"""

from __future__ import annotations

import numpy as np

from fpm_sim.config import ConfigError
from fpm_sim.study.identify.problem import (
    PENALTY_SIGMAS,
    IdentifyOptions,
    Problem,
    predict_observations,
    subsystem_predictions,
    with_branch,
    workspace_residuals,
)

__all__ = ["Objective"]


class Objective:
    """Residual function in normalised parameters ``z in [0, 1]``, counting model evaluations (``nfev``).

    Plain data (the problem, the options, a mask of the observations used and a cache of predictions), so it
    pickles: a ``spawn`` worker receives it whole in its pool initializer.

    Parameters
    ----------
    problem
        What is fitted.
    opts
        The search settings (model resolution, workers of each pose loop).
    obs_mask
        The observations used (default: all); cross-validation fits with some held out.
    branch
        Fit on this elbow-branch combination instead of the start description's.
    """

    def __init__(
        self,
        problem: Problem,
        opts: IdentifyOptions,
        obs_mask: np.ndarray | None = None,
        *,
        branch: tuple[int, int, int] | None = None,
    ) -> None:
        self.problem = problem if branch is None else with_branch(problem, branch)
        self.branch = branch
        self.opts = opts
        self.ps = self.problem.parameters
        self.width = self.ps.width
        n_obs = len(problem.observations)
        self.obs_mask = np.ones(n_obs, bool) if obs_mask is None else obs_mask
        self.obs = [o for o, k in zip(problem.observations, self.obs_mask) if k]
        self.measured = np.concatenate([problem.measured[:n_obs][self.obs_mask], problem.measured[n_obs:]])
        self.sigma = np.concatenate([problem.sigma[:n_obs][self.obs_mask], problem.sigma[n_obs:]])
        self.sub_idx = self.ps.subset(True)
        self.man_idx = self.ps.subset(False)
        self.nfev = 0
        self._cache: dict[bytes, np.ndarray] = {}

    def x(self, z: np.ndarray) -> np.ndarray:
        """Parameters (their units) at normalised ``z`` (clipped to [0, 1])."""
        return self.ps.from_unit(z)

    def z(self, x: np.ndarray) -> np.ndarray:
        """Normalised parameters of ``x``."""
        return self.ps.to_unit(x)

    def predictions(self, x: np.ndarray) -> np.ndarray:
        """Observations then rig tests (Hz). The two blocks are cached apart: a finite-difference step in a rig
        parameter re-solves only the rigs, one in a manipulator parameter only the poses."""
        x = np.asarray(x, float)
        n = len(self.obs) + len(self.problem.subsystem_tests)
        try:
            cfg = self.ps.apply(x)
        except (ConfigError, ValueError):
            return np.full(n, np.nan)
        key_m = b"m" + x[self.man_idx].tobytes()
        key_s = b"s" + x[self.sub_idx].tobytes()
        if key_m not in self._cache:
            self.nfev += 1
            self._cache[key_m] = predict_observations(
                cfg, self.obs, options=self.opts.model_options(), workers=self.opts.workers, pairing=self.opts.pairing
            )
        if key_s not in self._cache:
            self._cache[key_s] = subsystem_predictions(cfg, self.problem.subsystem_tests, self.opts.subsystem_segments)
        out = np.concatenate([self._cache[key_m], self._cache[key_s]])
        if len(self._cache) > 8192:
            self._cache.clear()
        return out

    def workspace_residuals(self, x: np.ndarray) -> np.ndarray:
        """The workspace prior's residuals at parameters ``x`` (:func:`workspace_residuals`)."""
        if not self.problem.workspace:
            return np.zeros(0)
        try:
            cfg = self.ps.apply(np.asarray(x, float))
        except (ConfigError, ValueError):
            return np.full(len(self.problem.workspace), PENALTY_SIGMAS)
        return workspace_residuals(self.problem, cfg)

    def residuals(self, z: np.ndarray) -> np.ndarray:
        """Observations, then rig tests, then workspace poses (in sigmas)."""
        x = self.x(z)
        f = self.predictions(x)
        r = (f - self.measured) / self.sigma
        r = np.where(np.isfinite(r), r, PENALTY_SIGMAS)
        if not self.problem.workspace:
            return r
        return np.concatenate([r, self.workspace_residuals(x)])

    def jacobian(self, z: np.ndarray, columns: list[int] | None = None) -> np.ndarray:
        """``d residuals / d z`` (``IdentifyOptions.jacobian == "exact"``): the observations' rows from the
        eigen-solve's sensitivities for the manipulator's parameters (:mod:`.sensitivity`), zero where a residual
        is the constant penalty; the rig tests' and the workspace prior's rows, and the rig parameters' columns,
        by forward differences (step ``1e-3`` of the bounds' width, as the ``"fd"`` Jacobian). ``columns``: the
        parameters whose columns are wanted (default all; the others' columns are 0)."""
        from fpm_sim.study.identify.sensitivity import observation_gradients

        z = np.clip(np.asarray(z, float), 0.0, 1.0)
        x = self.x(z)
        r0 = self.residuals(z)
        n_obs = len(self.obs)
        jac = np.zeros((len(r0), len(z)))
        wanted = list(range(len(z))) if columns is None else list(columns)
        try:
            dfdx = observation_gradients(
                self.ps,
                x,
                [k for k in self.man_idx if k in wanted],
                self.obs,
                self.opts.model_options(),
                pairing=self.opts.pairing,
            )
        except (ConfigError, ValueError):  # an impossible description at x or a step from it: a flat penalty
            dfdx = np.zeros((n_obs, len(z)))
        finite = np.isfinite((self.predictions(x)[:n_obs] - self.measured[:n_obs]) / self.sigma[:n_obs])
        jac[:n_obs] = np.where(finite[:, None], dfdx * self.width[None, :] / self.sigma[:n_obs, None], 0.0)
        if len(r0) == n_obs:
            return jac
        for k in wanted:  # the rig tests' and the workspace prior's rows: no pose eigen-solve
            h = 1e-3 if z[k] + 1e-3 <= 1.0 else -1e-3
            zk = z.copy()
            zk[k] += h
            jac[n_obs:, k] = (self._other_residuals(self.x(zk)) - r0[n_obs:]) / h
        return jac

    def _other_residuals(self, x: np.ndarray) -> np.ndarray:
        """The rig tests' residuals (in sigmas, the penalty where not finite), then the workspace prior's."""
        n_obs, tests = len(self.obs), self.problem.subsystem_tests
        try:
            cfg = self.ps.apply(np.asarray(x, float))
        except (ConfigError, ValueError):
            return np.full(len(tests) + len(self.problem.workspace), PENALTY_SIGMAS)
        f = subsystem_predictions(cfg, tests, self.opts.subsystem_segments)
        r = (f - self.measured[n_obs:]) / self.sigma[n_obs:]
        return np.concatenate([np.where(np.isfinite(r), r, PENALTY_SIGMAS), workspace_residuals(self.problem, cfg)])

    def cost(self, z: np.ndarray) -> float:
        """``sum(residuals(z)^2)``."""
        return float(np.sum(self.residuals(z) ** 2))
