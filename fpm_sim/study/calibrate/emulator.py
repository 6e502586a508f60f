"""An emulator of the segment model's first frequencies for the calibration's data stage, and the importance weights
that make a posterior sampled on it the segment model's.

The segment model costs about 36 ms a description (its 12 measured poses); a data stage of tempered SMC needs some
20 000 calls a run, so 8 elbow-branch classes times 3 runs are about 2.4 hours on 2 cores. The in-plane surrogate
(:mod:`fpm_sim.study.inplane_surrogate`) costs microseconds, but it is biased: on the first stage's particles (the
prior times the study's statements) the segment model's f1 is about 17 % below it on average (the log ratio -0.17
to -0.20 over three such populations), with a spread of 0.17-0.21 in the log (widest at thin sections); on the
surrogate's own posterior the segment model's log-likelihood is 14 nats lower at the median
(docs/identification.md, "An emulator of the segment model"). So the surrogate alone gives another posterior.

The emulator corrects it multiplicatively (Kennedy & O'Hagan's 2000 autoregressive form, on a log scale), with
the surrogate's own frequencies among the correction's inputs (the nonlinear autoregressive form of Perdikaris et al.
2017), and it does so for each of the two mode families on its own. At zero gravity the planar 3RRR's modes are
in-plane or out-of-plane, never both, so the segment model's first frequency is the lower of its lowest in-plane and
its lowest out-of-plane one; each has a surrogate (:mod:`fpm_sim.study.inplane_surrogate`,
:mod:`fpm_sim.study.outofplane_surrogate`), and

    f_emulated(theta)_j = min over families k of f_surrogate,k(theta)_j * exp(g_kj(u, s_k z_k(theta))),

``z_k`` family ``k``'s surrogate log frequencies at the measured poses, standardised on the training runs and
projected on their principal directions (:data:`EMULATOR_FEATURE_RANK`), ``s_k`` a feature scale, and ``g_k`` a
thin-plate-spline radial-basis fit (:class:`scipy.interpolate.RBFInterpolator`, smoothing 0.01, a linear tail) of
``log(f_segments,k / f_surrogate,k)`` at each measured pose ``j`` over the free parameters' unit-cube coordinates ``u``
(the discrepancy's left out: it does not change a frequency) and ``s_k z_k``. Each family's correction is smooth; the
switch from one family to the other, which a single correction of the lowest frequency had to bend around, is the
minimum's. Measured on the dominant class (docs/identification.md, "Two mode families"): one correction of the
in-plane surrogate, 2-8 % held-out rms per pose; the two families, 0.4-0.6 % (each family's own about the same), and,
fitted to one run's stage-1 runs, within 0.2 nat of the segment model at another
run's narrow peak where the single correction was 9.6 nats low. ``s_k`` is chosen per fit from
:data:`EMULATOR_FEATURE_SCALES` by the family's held-out error. The emulator is trained on segment-model runs at the
first stage's particles (the prior times the study's statements: where the posterior can be), then refitted with runs
at the data stage's particles. A fifth of the runs is held out, and each pose's held-out rms of the log of the lowest
frequency is added to the emulated likelihood as that pose's relative model error (``s_j^2 = sigma_j^2 + (d f_j)^2 +
(e_j f_j)^2``): the emulator's error is never silent, and it widens the emulated posterior where the emulator is least
sure, which keeps it a proposal that covers the segment model's.

The emulated posterior is then made the segment model's by importance weights (multifidelity importance sampling,
Peherstorfer, Willcox & Gunzburger 2016): each particle of the emulated data stage is weighted by
``L_segments / L_emulated``, and the evidence multiplied by their mean. That is exact whatever the emulator's error;
its error shows only as fewer effective draws, measured by the weights' effective sample size and their Pareto
shape ``k`` (Vehtari et al. 2024: the weighted estimates are reliable for ``k < 0.7``), both reported per run. Where
``k >= 0.7`` the data stage went beyond the runs the emulator was fitted on; the segment-model runs at its particles
(the weights' own) are where it was missing, so the run refits on every run so far and samples its data stage once
more (:func:`~fpm_sim.study.calibrate.smc.emulated_two_stage`, ``again``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from fpm_sim.study.calibrate.importance import importance_diagnostics
from fpm_sim.study.calibrate.problem import CalibrationError

__all__ = [
    "EMULATOR_ERROR_FACTOR", "EMULATOR_FEATURE_RANK", "EMULATOR_FEATURE_SCALES", "EMULATOR_HELD_OUT", "PARETO_K_MAX",
    "Emulator", "Inputs", "importance_diagnostics", "train_emulator",
]  # fmt: skip

EMULATOR_ERROR_FACTOR = 1.0
"""The emulated likelihood's relative model error, in held-out rms errors of the emulator."""
PARETO_K_MAX = 0.7
"""Importance weights whose Pareto shape ``k`` is this or more are unreliable (Vehtari et al. 2024)."""
EMULATOR_HELD_OUT = 0.2
"""The fraction of the training runs held out to measure the emulator's error."""
EMULATOR_FEATURE_SCALES = (0.1, 0.3)
"""The candidate scales ``s`` of the surrogate's standardised log frequencies among the fit's inputs (the unit-cube
coordinates span 1): at the dominant class's posterior particles, fitted on stage 1's runs and the first data stage's,
rms 0.023/0.046/0.031 at 0.1, 0.018/0.036/0.024 at 0.3, 0.019/0.046/0.025 at 1, and 0.055/0.099/0.083 without
(three runs; fitted on stage 1's runs alone, 0.14/0.08/0.14 at 0.1 and 0.18/0.12/0.15 at 0.3): the held-out error
picks one per fit."""
EMULATOR_FEATURE_RANK = 1e-6
"""Principal directions of the standardised surrogate log frequencies kept among the fit's inputs: those whose
singular value on the training runs is above this fraction of the largest (numerically independent ones)."""
EMULATOR_SMOOTHING = 0.01
"""The radial-basis fit's smoothing: the segment model's log ratio is smooth in the parameters except where the
lowest mode changes family; an exact interpolant rings there (held-out rms 0.056 at smoothing 1e-3, 0.055 at 0.01,
0.059 at 0.1, fitted on 640 runs of the study's problem at stage-1 particles; measured)."""


@dataclass(frozen=True)
class Inputs:
    """How the fit reads a row: its first ``n_free`` unit-cube coordinates (the free parameters'; the discrepancy's
    excluded), each ``periodic`` one as the point ``(cos 2 pi u, sin 2 pi u) / (2 pi)`` of a circle (its two ends one
    point; near distances as along ``u``), beside ``s z``, the surrogate's log frequencies standardised on the
    training runs (module docstring)."""

    n_free: int
    feature_scale: float
    """``s``: the weight of the surrogate's standardised log frequencies among the inputs."""
    log_f_mean: np.ndarray
    """``(n_obs,)`` the training runs' mean of the surrogate's log frequencies (the standardisation's)."""
    log_f_sd: np.ndarray
    """``(n_obs,)`` and their sd."""
    periodic: tuple[int, ...] = ()
    """Unit-cube coordinates that are whole-turn angles."""
    basis: np.ndarray | None = None
    """``(n_obs, k)`` orthonormal directions the standardised log frequencies are projected on (their principal
    ones on the training runs: a family whose frequency hardly changes between poses gives nearly equal columns, and
    the fit's linear tail needs independent inputs); ``None``: all of them."""

    def __call__(self, u: np.ndarray, log_f: np.ndarray) -> np.ndarray:
        """The fit's input rows at unit-cube rows ``u`` given the surrogate's log frequencies ``log_f`` there."""
        u = np.atleast_2d(u)[:, : self.n_free]
        z = (log_f - self.log_f_mean) / self.log_f_sd
        if self.basis is not None:
            z = z @ self.basis
        per = list(self.periodic)
        if per:
            angle = 2.0 * np.pi * u[:, per]
            keep = [i for i in range(u.shape[1]) if i not in per]
            u = np.hstack([u[:, keep], np.cos(angle) / (2.0 * np.pi), np.sin(angle) / (2.0 * np.pi)])
        out: np.ndarray = np.hstack([u, self.feature_scale * z])
        return out


@dataclass(frozen=True)
class Emulator:
    """The fitted corrections ``g`` (module docstring), one per mode family, and the measured error of their
    minimum."""

    fits: tuple[Any, ...]
    """Per family, the :class:`scipy.interpolate.RBFInterpolator` of its :attr:`inputs`' rows to ``(n, n_obs)`` log
    ratios."""
    inputs: tuple[Inputs, ...]
    n_train: int
    held_out_rms_per_obs: np.ndarray
    """``(n_obs,)`` each pose's held-out rms of ``log(f_segments / f_emulated)``: its relative error."""
    held_out_max: float

    @property
    def held_out_rms(self) -> float:
        """The held-out rms over every pose."""
        return float(np.sqrt(np.mean(self.held_out_rms_per_obs**2)))

    @property
    def model_error_rel(self) -> np.ndarray:
        """``(n_obs,)`` the relative error the emulated likelihood adds at each pose (:data:`EMULATOR_ERROR_FACTOR`
        held-out rms errors of that pose)."""
        out: np.ndarray = EMULATOR_ERROR_FACTOR * self.held_out_rms_per_obs
        return out

    def frequencies(self, u: np.ndarray, f_surrogate: np.ndarray) -> np.ndarray:
        """``(n, n_obs)`` the emulated frequencies (Hz) at unit-cube rows ``u`` given the surrogate's there (``(n,
        n_obs)``, or ``(n, F, n_obs)`` for ``F`` families: the lowest of the families'); NaN where a surrogate's is
        not finite and positive."""
        families = zip(self.fits, self.inputs, _families(f_surrogate))
        return _lowest([_corrected(fit, inp, u, f) for fit, inp, f in families])


def _families(f: np.ndarray) -> list[np.ndarray]:
    """``(n, n_obs)`` or ``(n, F, n_obs)`` frequencies as ``F`` arrays ``(n, n_obs)``."""
    f = np.asarray(f, float)
    return [f] if f.ndim == 2 else [f[:, k] for k in range(f.shape[1])]


def _lowest(families: list[np.ndarray]) -> np.ndarray:
    """The families' elementwise minimum; NaN where any is NaN."""
    out: np.ndarray = np.minimum.reduce(families)
    return out


def _corrected(fit: Any, inputs: Inputs, u: np.ndarray, f_surrogate: np.ndarray) -> np.ndarray:
    """One family's emulated frequencies: the surrogate's times ``exp(g)``; NaN where the surrogate's is not finite
    and positive."""
    with np.errstate(divide="ignore", invalid="ignore"):
        log_f = np.log(f_surrogate)
    ok = np.all(np.isfinite(log_f), axis=1)
    out = np.full(log_f.shape, np.nan)
    if ok.any():
        out[ok] = np.exp(log_f[ok] + fit(inputs(np.atleast_2d(u)[ok], log_f[ok])))
    return out


def _fit_family(
    x: np.ndarray, y: np.ndarray, log_sur: np.ndarray, fit_on: np.ndarray, *, n_free: int, periodic: tuple[int, ...]
) -> tuple[Any, Inputs, Any]:  # fmt: skip
    """One family's correction: the feature scale of :data:`EMULATOR_FEATURE_SCALES` with the least error at the
    rows not in ``fit_on`` (the family's finite rows only), as ``(fit on fit_on, inputs, fit on every finite row)``."""
    from scipy.interpolate import RBFInterpolator

    finite = np.all(np.isfinite(y), axis=1)
    on = np.intersect1d(fit_on, np.flatnonzero(finite))
    held = np.setdiff1d(np.flatnonzero(finite), on)
    if len(on) < 2 * (n_free + y.shape[1] + 1) or len(held) < 1:
        raise CalibrationError(
            f"too few usable segment-model runs to fit the emulator: {int(finite.sum())} of {len(x)}",
            parameter="emulator", value=len(x), hint="train it on more segment-model runs, or leave it 0",
        )  # fmt: skip
    sd = np.std(log_sur[finite], axis=0)
    mean, sd = np.mean(log_sur[finite], axis=0), np.where(sd > 0, sd, 1.0)
    _, sv, vt = np.linalg.svd((log_sur[finite] - mean) / sd, full_matrices=False)
    basis = vt[sv > EMULATOR_FEATURE_RANK * sv[0]].T

    def fitted(rows: np.ndarray, inputs: Inputs) -> Any:
        return RBFInterpolator(
            inputs(x[rows], log_sur[rows]), y[rows], kernel="thin_plate_spline", smoothing=EMULATOR_SMOOTHING, degree=1
        )

    best: tuple[float, Inputs, Any] | None = None
    for scale in EMULATOR_FEATURE_SCALES:
        inputs = Inputs(n_free, scale, mean, sd, periodic, basis)
        fit = fitted(on, inputs)
        err = float(np.mean((y[held] - fit(inputs(x[held], log_sur[held]))) ** 2))
        if best is None or err < best[0]:
            best = (err, inputs, fit)
    assert best is not None
    return best[2], best[1], fitted(np.flatnonzero(finite), best[1])


def train_emulator(
    u: np.ndarray, f_segments: np.ndarray, f_surrogate: np.ndarray, *, n_free: int, rng: np.random.Generator,
    periodic: tuple[int, ...] = (),
) -> Emulator:  # fmt: skip
    """The emulator fitted at unit-cube rows ``u`` (``(n, >= n_free)``; ``periodic``: the coordinates that are
    whole-turn angles, read on a circle). ``f_*`` in Hz, ``(n, n_obs)`` for one family or ``(n, F, n_obs)`` for
    ``F`` mode families whose lowest is the frequency (module docstring): each family's correction fitted to its
    log ratios, with the feature scale of :data:`EMULATOR_FEATURE_SCALES` that has its least held-out error
    (:data:`EMULATOR_HELD_OUT` of the rows held out; a family's rows where its segment-model frequency is not finite
    and positive left out of its fit), each pose's error measured there on the lowest family, then every family
    refitted on all its rows. Rows where a surrogate frequency is not finite and positive, or where the segment
    model gives no frequency at all, are left out."""
    seg, sur = _families(f_segments), _families(f_surrogate)
    with np.errstate(divide="ignore", invalid="ignore"):
        log_sur = [np.log(f) for f in sur]
        y = [np.log(fs) - ls for fs, ls in zip(seg, log_sur)]
        low = np.log(_lowest([np.where(np.isfinite(v), v, np.inf) for v in seg]))
    ok = np.all([np.all(np.isfinite(v), axis=1) for v in log_sur], axis=0) & np.all(np.isfinite(low), axis=1)
    x = np.asarray(u, float)[ok, :n_free]
    periodic = tuple(i for i in periodic if i < n_free)
    n = len(x)
    n_out = round(EMULATOR_HELD_OUT * n)
    order = rng.permutation(n)
    fit_on, held = np.sort(order[n_out:]), np.sort(order[:n_out])
    parts = [_fit_family(x, v[ok], ls[ok], fit_on, n_free=n_free, periodic=periodic) for v, ls in zip(y, log_sur)]
    pred = _lowest([_corrected(p[0], p[1], x[held], np.exp(ls[ok][held])) for p, ls in zip(parts, log_sur)])
    res = low[ok][held] - np.log(pred)
    return Emulator(
        fits=tuple(p[2] for p in parts), inputs=tuple(p[1] for p in parts), n_train=n,
        held_out_rms_per_obs=np.sqrt(np.mean(res**2, 0)), held_out_max=float(np.max(np.abs(res))),
    )  # fmt: skip
