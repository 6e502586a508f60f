"""Frequency requirements as plain assertions, for a designer's own test suite (pytest or not).

Each helper raises :class:`AssertionError` whose message names the requirement, the pose (mm, rad), the mode,
the margin (Hz and %) and the resolution, and hides its own frames from pytest's traceback
(``__tracebackhide__``). Bad input (an unreachable pose, an empty pose set, an unreadable CSV) raises an
:class:`fpm_sim.errors.FpmSimError` instead: that is a broken test, not a failed requirement.

This module does not import pytest; the optional plugin is :mod:`fpm_sim.pytest_plugin`. The pose loop, the
grids and the measured-CSV reader are those of :mod:`fpm_sim.study.requirements` (imported when called, so
that ``import fpm_sim.testing`` stays light).

>>> from fpm_sim.testing import assert_min_frequency
>>> assert_min_frequency(config, 40.0, poses="workspace", payload_kg=(0.0, 1.0))  # doctest: +SKIP
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fpm_sim.errors import FpmSimError

if TYPE_CHECKING:
    from fpm_sim.config import Manipulator
    from fpm_sim.kinematics import Pose
    from fpm_sim.study.requirements import Requirement, RequirementOutcome, SweepCache

__all__ = [
    "assert_frequencies_close",
    "assert_matches_measurements",
    "assert_min_frequency",
    "assert_no_mode_in_band",
    "assert_requirement",
]

POSTERIOR_MESSAGE = "probability= needs a posterior (fpm-sim calibrate)"


def _no_posterior(probability: float | None, posterior: Any) -> None:
    """The helpers other than :func:`assert_min_frequency` check the description's own values only."""
    if probability is not None or posterior is not None:
        raise FpmSimError(
            "this helper checks the description's own values; a requirement with a posterior probability is "
            "assert_min_frequency(..., probability=, posterior=)",
            parameter="probability",
            value=probability,
        )


def _min_frequency_probability(
    posterior: Any, poses: list[Pose], at_least_hz: float, mode: int, segments: int | None
) -> tuple[float, np.ndarray, Any]:
    """Posterior probability that mode ``mode`` is at least ``at_least_hz`` at every pose, and per pose.

    Over the posterior's draws (all of them): a draw's machine has ``f (1 + d z)`` at each pose (the predictive
    model of the calibration, ``d`` its model discrepancy, ``z`` standard normal and independent between poses,
    as in its likelihood), so a draw meets the requirement with the product over poses of
    :meth:`fpm_sim.study.posterior.PredictiveBands.meet_probability`. A draw that cannot reach a pose fails there.
    """
    from fpm_sim.batch.pose_loop import fast_options
    from fpm_sim.study.posterior import Posterior, predict_bands

    post = posterior if isinstance(posterior, Posterior) else Posterior.from_netcdf(posterior)
    opts = fast_options(segments=segments) if segments is not None else None
    bands = predict_bands(post, poses, n_draws=None, n_modes=mode, options=opts)
    per = bands.meet_probability(at_least_hz, mode)
    return float(np.prod(per, axis=1).mean()), per.mean(axis=0), bands


def pose_spec_of(poses: Any, grid: Any) -> tuple[Any, list[Pose] | None]:
    """``(PoseSpec, explicit poses or None)`` from the helpers' ``poses=``/``grid=`` arguments."""
    from fpm_sim.kinematics import Pose
    from fpm_sim.study.requirements import PoseSpec, RequirementError, parse_pose_spec

    if poses is not None and grid is not None:
        raise RequirementError("give poses= or grid=, not both")
    if grid is not None:
        spec = {"grid": grid} if isinstance(grid, str) else dict(grid)
        return parse_pose_spec(spec, "grid", Path(".")), None
    if poses is None or (isinstance(poses, str) and poses == "workspace"):
        return PoseSpec(), None
    pts = list(poses)
    out = [p if isinstance(p, Pose) else Pose.from_mm(*(float(c) for c in p)) for p in pts]
    return PoseSpec(kind="list", points=tuple((p.x_m * 1e3, p.y_m * 1e3, p.phi_rad) for p in out)), out


def _payload(payload_kg: float | Sequence[float] | None) -> tuple[float, ...]:
    if payload_kg is None:
        return ()
    vals = [float(payload_kg)] if isinstance(payload_kg, int | float) else [float(m) for m in payload_kg]
    if not 1 <= len(vals) <= 2 or any(not (math.isfinite(m) and m >= 0) for m in vals):
        raise FpmSimError(f"payload_kg must be a mass >= 0 or a range (low, high) in kg, got {payload_kg!r}")
    return tuple(sorted(set(vals)))


def _run(req: Requirement, config: Manipulator, cache: SweepCache | None, explicit: list[Pose] | None) -> None:
    __tracebackhide__ = True
    from fpm_sim.study.requirements import evaluate

    poses = None if explicit is None else req.poses.resolve(config, f"requirement {req.name!r}")
    outcome = evaluate(req, config, cache=cache, poses=poses)
    if not outcome.passed:
        raise AssertionError(outcome.message)


def assert_requirement(
    outcome_or_requirement: RequirementOutcome | Requirement,
    config: Manipulator | None = None,
    *,
    cache: SweepCache | None = None,
) -> None:
    """Raise :class:`AssertionError` with the outcome's message unless the requirement passes.

    Takes an outcome (:func:`fpm_sim.study.requirements.evaluate`) or a requirement and the description.
    """
    __tracebackhide__ = True
    from fpm_sim.study.requirements import Requirement, evaluate

    if isinstance(outcome_or_requirement, Requirement):
        if config is None:
            raise FpmSimError("assert_requirement(requirement, config): give the description to evaluate it on")
        outcome = evaluate(outcome_or_requirement, config, cache=cache)
    else:
        outcome = outcome_or_requirement
    if not outcome.passed:
        raise AssertionError(outcome.message)


def assert_min_frequency(
    config: Manipulator,
    at_least_hz: float,
    *,
    poses: str | Sequence[Pose | Sequence[float]] | None = None,
    grid: str | dict[str, Any] | None = None,
    payload_kg: float | Sequence[float] | None = None,
    mode: int = 1,
    segments: int | None = None,
    probability: float | None = None,
    posterior: Any = None,
    name: str | None = None,
    cache: SweepCache | None = None,
) -> None:
    """Assert that mode ``mode`` is at least ``at_least_hz`` at every pose, for every payload of the range.

    Parameters
    ----------
    config
        The description.
    at_least_hz
        Lowest allowed frequency (Hz).
    poses
        ``"workspace"`` (default: the reachable points of the 10 mm grid at phi 0) or explicit poses
        (:class:`fpm_sim.Pose` or ``(x_mm, y_mm, phi_rad)``); an unreachable one raises ``FpmSimError``.
    grid
        Instead of ``poses``: ``"paper"``, ``"dense"`` or a table ``{"grid": "dense", "step_mm": 20}``.
    payload_kg
        One mass or a range ``(low, high)`` (kg); frequencies fall monotonically with the payload, so the two
        ends cover the range (:mod:`fpm_sim.study.requirements`). Default: the description's payload.
    mode
        1-based mode index (sorted order).
    segments
        Resolution per link (default: the shared default fidelity).
    probability, posterior
        With a posterior (``posterior.nc`` of ``fpm-sim calibrate`` or a
        :class:`fpm_sim.study.posterior.Posterior`): assert that the requirement holds at every pose with at
        least this posterior probability (the predictive model ``f (1 + d z)`` over all draws; see
        :func:`_min_frequency_probability`). Payload ranges are not combined with a posterior (refused).
    name
        The requirement's name in the message (default: ``"f<mode> >= <at_least_hz> Hz"``).
    cache
        A :class:`fpm_sim.study.requirements.SweepCache` shared between calls (the plugin's ``fpm_sweep``).

    Long because: the signature and the documentation of its options are half of it; the body (checks, sweep,
    verdict, message) is about 40 lines.
    """
    __tracebackhide__ = True
    from fpm_sim.model.options import resolution_summary, resolution_text
    from fpm_sim.study.requirements import Requirement, pose_text

    spec, explicit = pose_spec_of(poses, grid)
    if probability is not None or posterior is not None:
        if posterior is None or probability is None or not 0.0 < probability < 1.0:
            raise FpmSimError(
                POSTERIOR_MESSAGE if posterior is None else "must be a probability strictly between 0 and 1",
                parameter="posterior" if posterior is None else "probability",
                value=posterior if posterior is None else probability,
                hint="give both probability= (e.g. 0.95) and posterior= (posterior.nc of fpm-sim calibrate)",
            )
        if payload_kg is not None:
            raise FpmSimError(
                "a payload is not combined with a posterior's draws",
                parameter="payload_kg",
                value=payload_kg,
                hint="calibrate with the payload in the description, or leave payload_kg out",
            )
        pose_list = spec.resolve(config, name or "assert_min_frequency")
        prob, per_pose, bands = _min_frequency_probability(posterior, pose_list, at_least_hz, mode, segments)
        if prob < probability:
            worst = int(np.argmin(per_pose))
            raise AssertionError(
                f"requirement {name or f'f{mode} >= {at_least_hz:g} Hz'!r} (min_frequency: f{mode} >= "
                f"{at_least_hz:g} Hz with posterior probability >= {probability:g}) FAILED: the probability is "
                f"{prob:.3g} over {bands.n_draws} draws at {len(pose_list)} poses; least likely at pose "
                f"{pose_text(pose_list[worst])} ({per_pose[worst]:.3g}); {bands.kind_line()}; resolution: "
                f"{resolution_text(resolution_summary(bands.options))}"
            )
        return
    req = Requirement(
        name=name or f"f{mode} >= {at_least_hz:g} Hz",
        kind="min_frequency",
        poses=spec,
        payload_kg=_payload(payload_kg),
        segments=segments,
        at_least_hz=float(at_least_hz),
        mode=int(mode),
    )
    _run(req, config, cache, explicit)


def assert_no_mode_in_band(
    config: Manipulator,
    low_hz: float,
    high_hz: float,
    *,
    poses: str | Sequence[Pose | Sequence[float]] | None = None,
    grid: str | dict[str, Any] | None = None,
    n_modes: int = 6,
    payload_kg: float | Sequence[float] | None = None,
    segments: int | None = None,
    name: str | None = None,
    cache: SweepCache | None = None,
) -> None:
    """Assert that none of the lowest ``n_modes`` modes lies in ``[low_hz, high_hz]`` at any pose or payload.

    The margin of a mode is its signed distance from the band (negative inside: the smallest shift that
    clears it); over a payload range the mode sweeps [f(heaviest), f(lightest)]. The failure message names
    the worst mode, pose and payload. See :func:`assert_min_frequency` for the other parameters.
    """
    __tracebackhide__ = True
    from fpm_sim.study.requirements import Requirement

    if not 0 <= low_hz < high_hz:
        raise FpmSimError(f"the band must satisfy 0 <= low_hz < high_hz, got {low_hz:g}..{high_hz:g}")
    spec, explicit = pose_spec_of(poses, grid)
    req = Requirement(
        name=name or f"no mode in {low_hz:g}..{high_hz:g} Hz",
        kind="band_exclusion",
        poses=spec,
        payload_kg=_payload(payload_kg),
        segments=segments,
        band_hz=(float(low_hz), float(high_hz)),
        n_modes=int(n_modes),
    )
    _run(req, config, cache, explicit)


def assert_matches_measurements(
    config: Manipulator,
    measured_csv: Any,
    *,
    tolerance_pct: float = 5.0,
    payload_kg: float | None = None,
    segments: int | None = None,
    name: str | None = None,
) -> None:
    """Assert that the model is within ``tolerance_pct`` of every frequency of ``measured_csv``.

    The CSV is read by :func:`fpm_sim.study.identify.data.read_measured_csv` (``x_mm,y_mm,phi_rad,f1_hz,...``,
    optional ``mode`` = in_plane/out_of_plane); the message names the worst pose, mode, model and measured
    frequency, the difference (Hz, %) and the margin left of the tolerance.
    """
    __tracebackhide__ = True
    from fpm_sim.study.requirements import Requirement

    if not (math.isfinite(tolerance_pct) and tolerance_pct > 0):
        raise FpmSimError(f"tolerance_pct must be > 0, got {tolerance_pct!r}")
    if len(_payload(payload_kg)) > 1:
        raise FpmSimError("payload_kg: measurements were taken at one payload; give one mass (kg)")
    req = Requirement(
        name=name or f"within {tolerance_pct:g} % of {Path(measured_csv).name}",
        kind="match_measurements",
        payload_kg=_payload(payload_kg),
        segments=segments,
        measured_csv=str(measured_csv),
        tolerance_pct=float(tolerance_pct),
    )
    _run(req, config, None, None)


def _frequency_rows(result: Any) -> tuple[np.ndarray, list[Pose | None], str]:
    """``(frequencies (n_poses, n_modes), pose per row, resolution)`` of a result or an array."""
    from fpm_sim.model.options import resolution_label

    freqs = getattr(result, "frequencies", None)
    if freqs is not None and hasattr(freqs, "frequencies_hz"):  # WorkspaceSweep
        opts = getattr(result, "options", None)
        return np.atleast_2d(freqs.frequencies_hz), list(freqs.poses), resolution_label(opts) if opts else "unknown"
    if hasattr(result, "frequencies_hz") and hasattr(result, "poses"):  # PoseFrequencies
        return np.atleast_2d(result.frequencies_hz), list(result.poses), "unknown"
    if hasattr(result, "frequencies_hz") and hasattr(result, "built"):  # ModalResult
        params = result.built.parameters
        pose = params.get("pose")
        p = None
        if isinstance(pose, dict) and {"x_m", "y_m", "phi_rad"} <= set(pose):
            from fpm_sim.kinematics import Pose

            p = Pose(pose["x_m"], pose["y_m"], pose["phi_rad"])
        o = params.get("options", {})
        res = f"{o.get('segments')} {o.get('link_model')} per link" if o else "unknown"
        return np.atleast_2d(result.frequencies_hz), [p], res
    arr = np.atleast_2d(np.asarray(result, dtype=float))
    return arr, [None] * arr.shape[0], "unknown"


def assert_frequencies_close(
    result: Any, expected_hz: Any, *, rtol: float = 0.01, atol_hz: float = 0.0, name: str | None = None
) -> None:
    """Assert ``|result - expected| <= atol_hz + rtol * |expected|`` for every pose and mode given.

    ``result``: a :class:`~fpm_sim.batch.pose_loop.PoseFrequencies`, a
    :class:`~fpm_sim.study.sweep.WorkspaceSweep`, a :class:`~fpm_sim.linear.modes.ModalResult` or an array
    ``(n_poses, n_modes)``; ``expected_hz`` broadcasts against its first ``expected`` modes (NaN: not checked).
    The message names the worst pose (mm, rad) and mode, both values, the difference (Hz, %) and the resolution.
    """
    __tracebackhide__ = True
    from fpm_sim.study.requirements import pose_text

    got, poses, res = _frequency_rows(result)
    exp = np.atleast_1d(np.asarray(expected_hz, dtype=float))
    n_modes = exp.shape[-1]
    if n_modes > got.shape[1]:
        raise FpmSimError(f"expected_hz has {n_modes} modes, the result only {got.shape[1]}; compute more modes")
    try:
        exp = np.broadcast_to(exp, (got.shape[0], n_modes))
    except ValueError:
        raise FpmSimError(
            f"expected_hz of shape {np.shape(expected_hz)} does not match the result's {got.shape[0]} poses"
        ) from None
    g = got[:, :n_modes]
    tol = atol_hz + rtol * np.abs(exp)
    diff = g - exp
    check = ~np.isnan(exp)
    bad = check & ~(np.abs(diff) <= tol)  # NaN in the result fails
    if not bad.any():
        return
    excess = np.where(bad, np.where(np.isnan(diff), np.inf, np.abs(diff) - tol), -np.inf)
    i, k = np.unravel_index(int(np.argmax(excess)), excess.shape)
    pose = poses[i] if i < len(poses) else None
    where = f"pose {pose_text(pose)}" if pose is not None else f"row {i}"
    label = name or "frequencies close"
    rel = 100.0 * diff[i, k] / exp[i, k] if exp[i, k] else math.nan
    raise AssertionError(
        f"requirement {label!r} FAILED: worst mode {k + 1} at {where}: {g[i, k]:.4f} Hz vs expected "
        f"{exp[i, k]:.4f} Hz, {diff[i, k]:+.4f} Hz ({rel:+.3f} %), tolerance {tol[i, k]:.4f} Hz "
        f"(rtol {rtol:g}, atol {atol_hz:g} Hz); {int(bad.sum())} of {int(check.sum())} values fail; resolution: {res}"
    )
