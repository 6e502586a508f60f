"""Identification of what the study does not state, by bounded least squares on its frequencies.

Generic part: :func:`fit` takes a model ``theta -> predicted frequencies``, the data and
:class:`Parameter` bounds, solves ``min sum((pred / data - 1)^2)`` with
:func:`scipy.optimize.least_squares` and reports, at the solution, the relative sensitivities
``d ln f / d ln theta``, the parameters' standard deviations and correlations from the Gauss-Newton
covariance ``s^2 (J'J)^-1`` (``s^2`` the residual variance; where the fit has no residual degrees of
freedom, an assumed measurement scatter :data:`ASSUMED_MEASUREMENT_REL_STD` instead), and the residuals.

The study's steps (each a small fit with few parameters):

1. :func:`identify_link`: link length and clamped length from the single-link tests (free-free
   985 Hz, cantilever 221 Hz). A bar's bending frequencies fix only ``sqrt(E/rho) t / L^2``: with
   ``E``, ``rho`` (steel) and ``t`` (10 mm, the study) held, ``L`` carries that group; the
   cantilever then fixes the free length, i.e. the clamped length (a rigid clamp assumed: clamp
   compliance and clamped length are not separable from one frequency).
2. :func:`identify_chain`: hinge hardware mass and the hinge's tilt compliance from the chain tests
   (79 / 88 / 81 Hz at 60 / 90 / 180 degrees).
3. :func:`identify_manipulator`: geometry and platform mass against COMSOL's 18 frequencies.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from fpm_sim.batch.frequencies import pose_frequencies
from fpm_sim.config import Geometry, LumpedMass, Manipulator
from fpm_sim.kinematics import Pose
from fpm_sim.model.options import ModelOptions
from fpm_sim.study.reproduce import subsystem_frequencies
from fpm_sim.study.tables import SubsystemTest, subsystem_tests

__all__ = [
    "ASSUMED_MEASUREMENT_REL_STD",
    "GEOMETRY_PARAMETERS",
    "FitResult",
    "Parameter",
    "fit",
    "geometry_from",
    "identify_chain",
    "identify_link",
    "identify_manipulator",
]

ASSUMED_MEASUREMENT_REL_STD = 0.01
"""Relative scatter assumed for a measured frequency where a fit leaves no residual to estimate it
(impact-hammer FRF peaks read to about 1 %)."""


@dataclass(frozen=True)
class Parameter:
    """A free parameter: name (with unit), initial value and bounds (SI)."""

    name: str
    initial: float
    lower: float
    upper: float


@dataclass
class FitResult:
    """Outcome of :func:`fit`.

    ``sensitivity`` holds ``d ln f / d ln theta`` for every parameter (as computed: the Jacobian times
    ``theta / f``), angles included.
    """

    parameters: list[Parameter]
    values: np.ndarray
    std: np.ndarray
    correlation: np.ndarray
    sensitivity: np.ndarray
    """``(n_data, n_params)`` relative sensitivities ``d ln f / d ln theta`` for every parameter, angles
    included (an angle's entry is ``theta * d ln f / d theta`` with theta in the parameter's own unit)."""
    labels: list[str]
    data: np.ndarray
    predicted: np.ndarray
    success: bool
    nfev: int
    std_source: str

    @property
    def residual_pct(self) -> np.ndarray:
        return 100.0 * (self.predicted / self.data - 1.0)

    def as_dict(self) -> dict[str, float]:
        return {p.name: float(v) for p, v in zip(self.parameters, self.values)}

    def table(self) -> str:
        lines = [f"{'parameter':<34}{'value':>14}{'std':>12}  bounds"]
        for p, v, s in zip(self.parameters, self.values, self.std):
            lines.append(f"{p.name:<34}{v:>14.6g}{s:>12.3g}  [{p.lower:g}, {p.upper:g}]")
        lines.append(f"std from {self.std_source}")
        lines.append(f"{'data':<28}{'target':>10}{'fit':>10}{'resid %':>9}")
        for lab, d, f in zip(self.labels, self.data, self.predicted):
            lines.append(f"{lab:<28}{d:>10.3f}{f:>10.3f}{100 * (f / d - 1):>+9.2f}")
        if len(self.parameters) > 1:
            lines.append("correlations:")
            for i, p in enumerate(self.parameters):
                lines.append(f"  {p.name:<32}" + " ".join(f"{c:+.2f}" for c in self.correlation[i]))
        return "\n".join(lines)

    def to_dict(self) -> dict:
        return {
            "parameters": {
                p.name: {"value": float(v), "std": float(s)} for p, v, s in zip(self.parameters, self.values, self.std)
            },
            "std_source": self.std_source,
            "correlation": self.correlation.tolist(),
            "sensitivity": self.sensitivity.tolist(),
            "data": dict(zip(self.labels, self.data.tolist())),
            "predicted": dict(zip(self.labels, self.predicted.tolist())),
            "residual_pct": dict(zip(self.labels, self.residual_pct.tolist())),
            "success": self.success,
            "nfev": self.nfev,
        }


def fit(
    model: Callable[[np.ndarray], np.ndarray],
    data: Sequence[float],
    parameters: Sequence[Parameter],
    *,
    labels: Sequence[str] | None = None,
    diff_step: float = 1e-3,
    max_nfev: int = 200,
) -> FitResult:
    """Bounded least squares on relative residuals ``model(theta) / data - 1`` (see module docstring)."""
    d = np.asarray(data, float)
    params = list(parameters)
    lo = np.array([p.lower for p in params])
    hi = np.array([p.upper for p in params])
    x0 = np.clip(np.array([p.initial for p in params]), lo, hi)
    scale = np.maximum(np.abs(x0), 1e-12)

    def resid(z: np.ndarray) -> np.ndarray:
        return np.asarray(model(z * scale), float) / d - 1.0

    sol = least_squares(
        resid, x0 / scale, bounds=(lo / scale, hi / scale), diff_step=diff_step, max_nfev=max_nfev, x_scale="jac"
    )
    x = sol.x * scale
    pred = (sol.fun + 1.0) * d
    jac = sol.jac / scale  # d (f/d) / d theta
    n, k = len(d), len(params)
    dof = n - k
    if dof > 0:
        s2 = float(np.sum(sol.fun**2)) / dof
        source = f"residual variance ({dof} residual degrees of freedom)"
    else:
        s2 = ASSUMED_MEASUREMENT_REL_STD**2
        source = (
            f"an assumed {100 * ASSUMED_MEASUREMENT_REL_STD:g} % measurement scatter (no residual degrees of freedom)"
        )
    jtj = jac.T @ jac
    try:
        cov = s2 * np.linalg.inv(jtj)
        std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        corr = cov / np.outer(std, std)
    except np.linalg.LinAlgError:
        std = np.full(k, np.nan)
        corr = np.full((k, k), np.nan)
    sens = jac * (d / pred)[:, None] * x[None, :]  # d ln f / d ln theta
    return FitResult(
        params,
        x,
        std,
        corr,
        sens,
        list(labels or [f"data {i}" for i in range(n)]),
        d,
        pred,
        bool(sol.success),
        sol.nfev,
        source,
    )


# ---------------------------------------------------------------------------------------------
# step 1 and 2: subsystems


def _with_rig(config: Manipulator, **changes: Any) -> Manipulator:
    # Any: RigConfig fields of several types (lengths, LumpedMass); dataclasses.replace checks the names.
    rig = config.rig
    if rig is None:
        raise ValueError("the configuration has no [rig] table: the subsystem tests need the test piece")
    return config.replace(rig=dataclasses.replace(rig, **changes))


def identify_link(
    config: Manipulator,
    *,
    tests: list[SubsystemTest] | None = None,
    segments: int = 12,
) -> tuple[FitResult, Manipulator]:
    """Rig length and clamped length from the single-link free-free and cantilever tests."""
    tests = [t for t in (tests or subsystem_tests()) if t.rig in ("free-free", "cantilever")]
    rig = config.rig
    if rig is None:
        raise ValueError("the configuration has no [rig] table")

    def model(theta: np.ndarray) -> np.ndarray:
        cfg = _with_rig(config, length_m=float(theta[0]), clamped_length_m=float(theta[1]))
        return np.array([r.ours_hz for r in subsystem_frequencies(cfg, segments=segments, tests=tests)])

    params = [
        Parameter("rig.length_m", rig.length_m, 0.5 * rig.length_m, 2.0 * rig.length_m),
        Parameter("rig.clamped_length_m", max(rig.clamped_length_m, 0.02 * rig.length_m), 0.0, 0.5 * rig.length_m),
    ]
    res = fit(model, [t.experimental_hz for t in tests], params, labels=[t.label for t in tests])
    return res, _with_rig(config, length_m=float(res.values[0]), clamped_length_m=float(res.values[1]))


HINGE_GYRATION_RADIUS_M = 0.015
"""Assumed radius of gyration of the passive-joint hardware (bearing housing): inertia = m r^2."""


def _hinge(mass_kg: float, gyration_radius_m: float = HINGE_GYRATION_RADIUS_M) -> LumpedMass:
    i = mass_kg * gyration_radius_m**2
    return LumpedMass(mass_kg, (i, i, i))


def identify_chain(
    config: Manipulator,
    *,
    tests: list[SubsystemTest] | None = None,
    segments: int = 12,
    tilt: bool = True,
    gyration: bool = False,
) -> tuple[FitResult, Manipulator]:
    """Chain hinge mass (with ``tilt`` the hinge tilt stiffness, with ``gyration`` the hardware's
    radius of gyration) from the chain tests."""
    tests = [t for t in (tests or subsystem_tests()) if t.rig == "chain"]
    rig = config.rig
    if rig is None:
        raise ValueError("the configuration has no [rig] table")

    def configure(theta: np.ndarray) -> Manipulator:
        r_g = float(theta[-1]) if gyration else HINGE_GYRATION_RADIUS_M
        cfg = _with_rig(config, chain_hinge=_hinge(float(theta[0]), r_g))
        if tilt:
            cfg = cfg.replace(
                compliance=dataclasses.replace(cfg.compliance, passive_joint_tilt_nm_per_rad=float(theta[1]))
            )
        return cfg

    def model(theta: np.ndarray) -> np.ndarray:
        return np.array([r.ours_hz for r in subsystem_frequencies(configure(theta), segments=segments, tests=tests)])

    params = [Parameter("rig.chain_hinge.mass_kg", max(rig.chain_hinge.mass_kg, 0.05), 0.0, 2.0)]
    if tilt:
        params.append(Parameter("compliance.passive_joint_tilt_nm_per_rad", 2e4, 1e2, 1e7))
    if gyration:
        params.append(Parameter("rig.chain_hinge.gyration_radius_m", HINGE_GYRATION_RADIUS_M, 0.003, 0.06))
    res = fit(model, [t.experimental_hz for t in tests], params, labels=[t.label for t in tests])
    return res, configure(res.values)


SUBSYSTEM_PARAMETERS: dict[str, tuple[float, float]] = {
    "rig.length_m": (0.1, 0.5),
    "rig.clamped_length_m": (0.0, 0.1),
    "compliance.base_clamp_nm_per_rad": (1e2, 1e7),
    "rig.chain_hinge.mass_kg": (0.0, 2.0),
    "compliance.passive_joint_tilt_nm_per_rad": (1e1, 1e7),
    "rig.section.height_m": (0.004, 0.03),
}
"""Subsystem parameters :func:`identify_subsystems` can free, with their bounds (SI)."""


def _set_subsystem(config: Manipulator, name: str, value: float) -> Manipulator:
    rig = config.rig
    assert rig is not None
    if name == "rig.length_m":
        return config.replace(rig=dataclasses.replace(rig, length_m=value))
    if name == "rig.clamped_length_m":
        return config.replace(rig=dataclasses.replace(rig, clamped_length_m=value))
    if name == "rig.chain_hinge.mass_kg":
        return config.replace(rig=dataclasses.replace(rig, chain_hinge=_hinge(value)))
    if name == "rig.section.height_m":
        return config.replace(rig=dataclasses.replace(rig, section=dataclasses.replace(rig.section, height_m=value)))
    if name.startswith("compliance."):
        return config.replace(compliance=dataclasses.replace(config.compliance, **{name.split(".")[1]: value}))
    raise ValueError(f"unknown subsystem parameter {name!r}; choose from {sorted(SUBSYSTEM_PARAMETERS)}")


def identify_subsystems(
    config: Manipulator,
    free: Sequence[str],
    *,
    tests: list[SubsystemTest] | None = None,
    initial: dict[str, float] | None = None,
    segments: int = 12,
) -> tuple[FitResult, Manipulator]:
    """Fit the parameters named in ``free`` (keys of :data:`SUBSYSTEM_PARAMETERS`) to the tests' measured
    frequencies, all tests at once."""
    if config.rig is None:
        raise ValueError("the configuration has no [rig] table")
    tests = tests or subsystem_tests()
    init = initial or {}

    def configure(theta: np.ndarray) -> Manipulator:
        cfg = config
        for name, v in zip(free, theta):
            cfg = _set_subsystem(cfg, name, float(v))
        return cfg

    def model(theta: np.ndarray) -> np.ndarray:
        return np.array([r.ours_hz for r in subsystem_frequencies(configure(theta), segments=segments, tests=tests)])

    params = []
    for name in free:
        lo, hi = SUBSYSTEM_PARAMETERS[name]
        params.append(Parameter(name, init[name], lo, hi))
    res = fit(model, [t.experimental_hz for t in tests], params, labels=[t.label for t in tests])
    return res, configure(res.values)


# ---------------------------------------------------------------------------------------------
# step 3: the manipulator


GEOMETRY_PARAMETERS = (
    "base_radius_m",
    "platform_radius_m",
    "proximal_length_m",
    "distal_length_m",
    "base_rotation_deg",
    "platform_offset_deg",
)
"""The geometry is parametrised as a symmetric layout (motors and platform joints 120 deg apart):
base radius, platform radius, the two link lengths, the rotation of the motor triangle (0 = first
motor at 90 deg) and the platform joints' angular offset from the motors at phi = 0."""


def geometry_from(values: Sequence[float] | np.ndarray, elbow_branch: tuple[int, int, int]) -> Geometry:
    """Geometry from :data:`GEOMETRY_PARAMETERS` values (SI, degrees)."""
    r_b, r_p, l1, l2, rot, off = (float(v) for v in values[:6])
    base = (math.radians(rot + 90.0), math.radians(rot + 210.0), math.radians(rot + 330.0))
    plat = (math.radians(rot + off + 90.0), math.radians(rot + off + 210.0), math.radians(rot + off + 330.0))
    return Geometry(r_b, base, l1, l2, r_p, plat, elbow_branch)


def identify_manipulator(
    config: Manipulator,
    poses: Sequence[Pose],
    comsol_hz: Sequence[float],
    *,
    initial: Sequence[float],
    elbow_branch: tuple[int, int, int],
    options: ModelOptions | None = None,
    free_platform_mass: bool = True,
    geometry_free: bool = True,
    span: float = 0.25,
    span_deg: float = 20.0,
    max_nfev: int = 60,
) -> tuple[FitResult, Manipulator]:
    """Geometry (and platform mass) against COMSOL's frequencies at ``poses`` (NaN entries skipped).

    ``initial``: the :data:`GEOMETRY_PARAMETERS` values (and the platform mass); lengths may move by
    ``span`` (relative) and angles by ``span_deg`` around them (a local refinement of a screened
    geometry). ``geometry_free=False`` fits the platform mass alone (the frequency level).
    """
    c = np.asarray(comsol_hz, float)
    ok = np.isfinite(c)
    use = [p for p, k in zip(poses, ok) if k]

    fixed_geometry = np.asarray(initial[:6], float)

    def configure(theta: np.ndarray) -> Manipulator:
        g_vals = theta[:6] if geometry_free else fixed_geometry
        cfg = config.replace(geometry=geometry_from(g_vals, elbow_branch))
        theta = np.concatenate([g_vals, theta[6:] if geometry_free else theta])
        if free_platform_mass:
            hw = config.hardware
            m0 = hw.platform.mass_kg
            ratio = float(theta[6]) / m0
            i0, i1, i2 = hw.platform.inertia_kg_m2
            plat = LumpedMass(float(theta[6]), (i0 * ratio, i1 * ratio, i2 * ratio))
            cfg = cfg.replace(hardware=dataclasses.replace(hw, platform=plat))
        return cfg

    def model(theta: np.ndarray) -> np.ndarray:
        try:
            cfg = configure(theta)
        except ValueError:
            return np.full(len(use), 1e3)
        f = pose_frequencies(cfg, use, n_modes=1, options=options).f1_hz
        return np.where(np.isfinite(f), f, 1e3)  # unreachable/singular: a large residual

    r_b, r_p, l1, l2, rot, off = initial[:6]
    lo, hi = 1.0 - span, 1.0 + span
    params = [
        Parameter("geometry.base_radius_m", r_b, lo * r_b, hi * r_b),
        Parameter("geometry.platform_radius_m", r_p, lo * r_p, hi * r_p),
        Parameter("geometry.proximal_length_m", l1, lo * l1, hi * l1),
        Parameter("geometry.distal_length_m", l2, lo * l2, hi * l2),
        Parameter("geometry.base_rotation_deg", rot, rot - span_deg, rot + span_deg),
        Parameter("geometry.platform_offset_deg", off, off - span_deg, off + span_deg),
    ]
    if not geometry_free:
        params = []
    if free_platform_mass:
        m = config.hardware.platform.mass_kg if len(initial) < 7 else initial[6]
        params.append(Parameter("hardware.platform.mass_kg", m, 0.05, 10.0))
    labels = [f"pose ({p.x_m * 1e3:g}, {p.y_m * 1e3:g}, {p.phi_rad:g})" for p in use]
    res = fit(model, c[ok], params, labels=labels, max_nfev=max_nfev)
    return res, configure(res.values)


# ---------------------------------------------------------------------------------------------
# global screening of the geometry with the in-plane surrogate

ELBOW_BRANCH_CLASSES = ((1, 1, 1), (-1, -1, -1), (1, 1, -1), (1, -1, -1))
"""Elbow branches up to a rotation of the layout by 120 deg (the base rotation covers the rest)."""

SCREEN_BOUNDS = (
    (0.12, 0.5),  # base radius (m)
    (0.02, 0.16),  # platform radius (m)
    (0.12, 0.4),  # proximal length (m)
    (0.12, 0.4),  # distal length (m)
    (-180.0, 180.0),  # base rotation (deg)
    (-180.0, 180.0),  # platform offset (deg)
)


@dataclass
class Screening:
    """Best scale-free geometry of one (reading, elbow branch) combination."""

    reading: str
    elbow_branch: tuple[int, int, int]
    values: np.ndarray
    rms_log: float
    spearman: float
    scale: float


def _screen_residuals(config: Manipulator, poses: Sequence[Pose], comsol: np.ndarray, values, branch) -> np.ndarray:
    from fpm_sim.study.inplane_surrogate import inplane_first_frequencies

    ok = np.isfinite(comsol)
    try:
        cfg = config.replace(geometry=geometry_from(values, branch))
    except ValueError:
        return np.full(len(poses), 2.0)
    f = inplane_first_frequencies(cfg, poses)
    bad = ~np.isfinite(f) | (f <= 0)
    lf = np.log(np.where(bad, 1.0, f))
    d = lf[ok] - np.log(comsol[ok])
    good = ~bad[ok]
    if good.any():
        d = d - d[good].mean()
    d[~good] = 2.0  # an unreachable or singular study pose: the study measured there
    return np.concatenate([d, np.where(bad[~ok], 2.0, 0.0)])


def screen_geometry(
    config: Manipulator,
    poses: Sequence[Pose],
    comsol_hz: Sequence[float],
    *,
    elbow_branch: tuple[int, int, int],
    reading: str = "",
    seed: int = 0,
    maxiter: int = 300,
) -> Screening:
    """Global search (differential evolution) of the geometry on the in-plane surrogate.

    Scale-free: the objective is the spread of ``ln(f_surrogate / f_comsol)`` over the poses with a
    COMSOL value (the level is set later by the masses); every one of ``poses`` must be reachable
    and non-singular.
    """
    from scipy.optimize import differential_evolution
    from scipy.stats import spearmanr

    from fpm_sim.study.inplane_surrogate import inplane_first_frequencies

    c = np.asarray(comsol_hz, float)

    def cost(v: np.ndarray) -> float:
        return float(np.sum(_screen_residuals(config, poses, c, v, elbow_branch) ** 2))

    sol = differential_evolution(cost, SCREEN_BOUNDS, seed=seed, maxiter=maxiter, popsize=20, tol=1e-7, polish=True)
    cfg = config.replace(geometry=geometry_from(sol.x, elbow_branch))
    f = inplane_first_frequencies(cfg, poses)
    ok = np.isfinite(c) & np.isfinite(f)
    rho = float(spearmanr(f[ok], c[ok]).statistic) if ok.sum() > 2 else math.nan
    scale = float(np.exp(np.mean(np.log(c[ok] / f[ok])))) if ok.any() else math.nan
    rms = float(np.sqrt(np.mean(_screen_residuals(config, poses, c, sol.x, elbow_branch) ** 2)))
    return Screening(reading, elbow_branch, sol.x, rms, rho, scale)
