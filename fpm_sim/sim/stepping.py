"""Time stepping of the rollouts: MuJoCo's ``discrete`` integrator at a step chosen from a frequency band.

The models are compiled with ``implicitfast`` (:mod:`fpm_sim.model.options`), whose spring hinges are
integrated explicitly: the step must resolve the stiffest spring's highest (discretisation) mode and shrinks as
``1 / segments^2`` (12 segments: 0.4-0.8 us; at 1-2 ms of wall time a step, 20-80 min per simulated second).
Every time-domain path (rollouts, the study transient, the virtual impact test, the dm_control environment,
``fpm-sim move``) instead runs by default on MuJoCo's ``discrete`` integrator (MuJoCo >= 3.13): the constraint
solve and the implicit velocity update are one solve in the metric ``M + h D + h^2 K``, so springs, dampers and the
loop-closing welds are implicit and the scheme is stable at any step. ``integrator="explicit"`` keeps the
model's own integrator and step: the reference.

**Its error on one mode.** For a mode of natural frequency ``omega`` and damping ratio ``zeta``
(``c = 2 zeta omega``), one step is ``(1 + h c + a^2) v' = v - h omega^2 x``, ``x' = x + h v'`` with
``a = omega h``. Its amplification matrix has the characteristic polynomial
``(1 + h c + a^2) z^2 - (2 + h c) z + 1``; the sampled response is a sum of ``z^n = exp(s n h)``, so the mode
is read (by a pole fit, an FFT, a settling time) as the continuous pole ``s = ln(z) / h``. Undamped
(``c = 0``): ``|z| = (1 + a^2)^(-1/2)`` and ``arg z = atan(a)``, i.e.

- numerical damping ratio ``zeta_num = ln(1 + a^2) / (2 |s h|) ~ a / 2 = pi f h`` (like a stiffness-proportional
  damping ``beta = h``), :func:`numerical_damping`;
- period error ``T_num / T - 1 = a / atan(a) - 1 ~ a^2 / 3`` (the period comes out long),
  :func:`period_error`.

Both are exact for the scheme on a linear mode (checked against a one-hinge MuJoCo model to 1e-9,
``tests/sim/test_stepping.py``). The map from ``(omega, zeta)`` to ``z`` is linear in ``(h c, a^2)``, so a pole
read from a discrete-integrator response is inverted exactly (:func:`remove_integrator_effect`): the virtual
impact test's EMA removes the numerical damping as it removes the response window's.

**The step from the band** (:func:`choose_stepping`). The user names the band the result must be right in
(``band_hz``); by default :data:`BAND_F1_MULTIPLE` times the model's first natural frequency at
the pose (a modal analysis; the first few modes carry nearly all of the response to loads and moves that are
slow against them). The step is the largest with a numerical damping ratio of at most
:data:`MAX_NUMERICAL_DAMPING` at the band's top, ``h = zeta_max / (pi f_band)`` (``a / 2 >= zeta_num``, so the
bound holds exactly), at most :data:`MAX_STEP_S` and rounded down to divide the output step: at the band's top
the numerical damping is then at most 2 % and the period error at most ``(2 zeta_max)^2 / 3`` = 0.053 %; at
``f1`` (a fifth of the band) 0.4 % and 0.002 %. Default machine, 12 segments (f1 64 Hz): ``h`` = 20 us, 50 times
the explicit step. The numbers are in every result (:meth:`Stepping.to_dict`).

The explicit reference (``implicitfast``, undamped springs: symplectic Euler) has no numerical damping and the
period error ``a / (2 asin(a / 2)) - 1 ~ -a^2 / 24`` (stable for ``a < 2``).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, replace
from typing import Any

import mujoco
import numpy as np
from numpy.typing import ArrayLike

from fpm_sim.errors import FpmSimError
from fpm_sim.model.spec import BuiltModel

__all__ = [
    "BAND_F1_MULTIPLE",
    "DEFAULT_INTEGRATOR",
    "INTEGRATORS",
    "MAX_NUMERICAL_DAMPING",
    "MAX_STEP_S",
    "Stepping",
    "SteppingError",
    "apply_stepping",
    "choose_stepping",
    "discrete_pole",
    "first_frequency_hz",
    "numerical_damping",
    "period_error",
    "remove_integrator_effect",
    "reraise_as",
]

INTEGRATORS = ("discrete", "explicit")
"""``discrete``: MuJoCo's implicit ``discrete`` integrator at a step from the band (module docstring);
``explicit``: the model's own ``implicitfast`` integrator and automatic step (explicit springs), the reference."""
DEFAULT_INTEGRATOR = "discrete"
BAND_F1_MULTIPLE = 5.0
"""Default band: this many times the model's first natural frequency at the pose (module docstring)."""
MAX_NUMERICAL_DAMPING = 0.02
"""Largest numerical damping ratio allowed at the band's top (module docstring): a fifth of it, 0.4 %, at f1 with
the default band, below the 0.5-2 % of a bolted steel structure."""
MAX_STEP_S = 1e-4
"""Largest step (s) the rule picks, whatever the band (the explicit rule's cap,
:data:`~fpm_sim.model.spec.TIMESTEP_MAX_S`)."""


class SteppingError(FpmSimError):
    """A bad integrator, band or step (named in the message)."""


def discrete_pole(freq_hz: ArrayLike, damping: ArrayLike, step_s: float) -> np.ndarray:
    """The continuous pole ``ln(z) / h`` (1/s) a mode of ``freq_hz`` (Hz) and damping ratio ``damping`` shows
    when stepped by the ``discrete`` integrator at ``step_s`` (module docstring); upper half plane."""
    w = 2.0 * np.pi * np.asarray(freq_hz, float)
    xi = np.asarray(damping, float)
    a2 = (w * step_s) ** 2
    hc = 2.0 * xi * w * step_s
    den = 1.0 + hc + a2
    disc = (2.0 + hc) ** 2 - 4.0 * den + 0j
    z = ((2.0 + hc) + np.sqrt(disc)) / (2.0 * den)
    z = np.where(z.imag < 0, np.conj(z), z)
    return np.log(z) / step_s


def numerical_damping(freq_hz: ArrayLike, step_s: float) -> np.ndarray:
    """Damping ratio the ``discrete`` step adds to an undamped mode of ``freq_hz`` (exact; ``~ pi f h``)."""
    s = discrete_pole(freq_hz, 0.0, step_s)
    return -s.real / np.abs(s)


def period_error(freq_hz: ArrayLike, step_s: float) -> np.ndarray:
    """Relative period error ``T_num / T - 1`` of an undamped mode under the ``discrete`` step
    (``a / atan(a) - 1 ~ (2 pi f h)^2 / 3``, exact)."""
    a = 2.0 * np.pi * np.asarray(freq_hz, float) * step_s
    return a / np.arctan(a) - 1.0


def _explicit_period_error(freq_hz: float, step_s: float) -> float:
    a = 2.0 * math.pi * freq_hz * step_s
    return a / (2.0 * math.asin(a / 2.0)) - 1.0 if a < 2.0 else math.inf


def remove_integrator_effect(
    freq_hz: ArrayLike, damping: ArrayLike, *, step_s: float, source: str = "FRF", parameter: str = "step_s"
) -> tuple[np.ndarray, np.ndarray]:
    """Natural frequencies (Hz) and damping ratios of the modes whose ``discrete``-integrator response was read
    as ``freq_hz`` / ``damping`` (``|s| / 2 pi`` and ``-Re s / |s|`` of the fitted pole ``s``) at ``step_s`` (s).

    The exact inverse of :func:`discrete_pole`: with ``z = exp(s h)``, ``(h c) (z^2 - z) + a^2 z^2 = -(z - 1)^2``
    is two real linear equations in ``h c`` and ``a^2``. Raises :class:`SteppingError` for a pole less damped than
    half of what the step alone adds (no fit error does that: the step is wrong), naming ``parameter`` (the
    caller's name of ``step_s``); a slightly negative damping (a fit error on an undamped mode) is returned as it is.
    """
    if not (isinstance(step_s, (int, float)) and math.isfinite(step_s) and step_s > 0):
        raise SteppingError(
            f"{source}: the integrator step must be a positive time (s)", parameter=parameter, value=step_s
        )
    wn = 2.0 * np.pi * np.atleast_1d(np.asarray(freq_hz, float))
    xi = np.atleast_1d(np.asarray(damping, float))
    s = -xi * wn + 1j * wn * np.sqrt(np.clip(1.0 - xi**2, 0.0, None))
    z = np.exp(s * step_s)
    p, q, r = z * z - z, z * z, -((z - 1.0) ** 2)
    det = p.real * q.imag - q.real * p.imag
    hc = (r.real * q.imag - q.real * r.imag) / det
    a2 = (p.real * r.imag - r.real * p.imag) / det
    a = np.sqrt(np.clip(a2, 0.0, None))
    zeta = np.divide(hc, 2.0 * a, out=np.full_like(a, -np.inf), where=a > 0)
    # a read damping below half of what the step alone adds is no fit error: the step is not this one
    bad = (a2 <= 0.0) | (zeta < -0.5 * numerical_damping(wn / (2.0 * np.pi), step_s))
    if np.any(bad):
        k = int(np.flatnonzero(bad)[0])
        raise SteppingError(
            f"{source}: the pole at {wn[k] / 2 / np.pi:.4g} Hz (damping {xi[k]:.3g}) is less damped than the "
            f"discrete integrator at this step alone makes it "
            f"({float(numerical_damping(wn[k] / 2 / np.pi, step_s)):.3g}): the step is wrong",
            parameter=parameter,
            value=step_s,
            hint="give the step the response was computed with",
        )
    return a / (2.0 * np.pi * step_s), zeta


def first_frequency_hz(built: BuiltModel, qpos: np.ndarray | None = None) -> float:
    """The model's first natural frequency (Hz) at ``qpos`` (default its static equilibrium)."""
    from fpm_sim.rom.reduction import modal_system

    return float(modal_system(built, qpos=qpos).frequencies_hz[0])


@dataclass(frozen=True)
class Stepping:
    """How a rollout is stepped, and what that costs in accuracy in the band (module docstring).

    Attributes
    ----------
    integrator
        ``"discrete"`` or ``"explicit"`` (:data:`INTEGRATORS`).
    step_s
        Integrator step (s).
    band_hz
        Top of the band the bounds refer to (Hz).
    band_source
        Where the band comes from (``"5 x f1"`` or ``"given"``).
    f1_hz
        The model's first natural frequency (Hz) when it was computed, else ``None``.
    max_damping
        The bound on the numerical damping ratio at the band's top that chose the step (discrete).
    """

    integrator: str
    step_s: float
    band_hz: float
    band_source: str
    f1_hz: float | None = None
    max_damping: float = MAX_NUMERICAL_DAMPING

    def damping_at(self, freq_hz: float) -> float:
        """Numerical damping ratio at ``freq_hz`` (0 for the explicit reference)."""
        return float(numerical_damping(freq_hz, self.step_s)) if self.integrator == "discrete" else 0.0

    def period_error_at(self, freq_hz: float) -> float:
        """Relative period error at ``freq_hz``."""
        if self.integrator == "discrete":
            return float(period_error(freq_hz, self.step_s))
        return _explicit_period_error(freq_hz, self.step_s)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: integrator, step, band and the numerical damping / period error at its top (and f1)."""
        d: dict[str, Any] = {
            "integrator": self.integrator,
            "step_s": self.step_s,
            "band_hz": self.band_hz,
            "band_source": self.band_source,
            "f1_hz": self.f1_hz,
            "max_numerical_damping": self.max_damping if self.integrator == "discrete" else None,
            "numerical_damping_at_band_top": self.damping_at(self.band_hz),
            "period_error_at_band_top": self.period_error_at(self.band_hz),
        }
        if self.f1_hz is not None:
            d["numerical_damping_at_f1"] = self.damping_at(self.f1_hz)
            d["period_error_at_f1"] = self.period_error_at(self.f1_hz)
        return d

    def line(self) -> str:
        """One line for the text outputs."""
        f1 = f", f1 {self.f1_hz:.4g} Hz" if self.f1_hz is not None else ""
        return (
            f"integrator {self.integrator}, step {self.step_s:.3g} s; band {self.band_hz:.4g} Hz ({self.band_source}"
            f"{f1}): numerical damping {100 * self.damping_at(self.band_hz):.3g} % and period error "
            f"{100 * self.period_error_at(self.band_hz):+.2g} % at its top"
        )

    def table(self) -> str:
        """The same as :meth:`line` (the result protocol)."""
        return self.line()

    def plot(self, ax: Any = None) -> Any:
        """Numerical damping ratio and period error against frequency up to twice the band; the ``Figure``."""
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(figsize=(6, 3.5))
        f = np.linspace(self.band_hz / 200, 2 * self.band_hz, 400)
        ax.plot(f, [100 * self.damping_at(v) for v in f], label="numerical damping ratio (%)")
        ax.plot(f, [100 * self.period_error_at(v) for v in f], label="period error (%)")
        ax.axvline(self.band_hz, color="0.5", ls="--", lw=0.8, label="band top")
        ax.set_xlabel("frequency (Hz)")
        ax.set_title(f"{self.integrator} integrator, step {self.step_s:.3g} s", fontsize=9)
        ax.legend(fontsize=8)
        ax.figure.tight_layout()
        return ax.figure


def _check_positive(name: str, value: Any) -> float:
    if not (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value > 0):
        raise SteppingError("must be a positive finite number", parameter=name, value=value)
    return float(value)


def reraise_as(error: type[FpmSimError], exc: FpmSimError) -> FpmSimError:
    """``exc`` as an ``error`` with the same message, parameter, value, hint, file and row (for ``raise ... from
    None``: a module's own error type around a lower layer's, keeping the contract's fields)."""
    return error(exc.message, parameter=exc.parameter, value=exc.value, hint=exc.hint, file=exc.file, row=exc.row)


def choose_stepping(
    built: BuiltModel,
    *,
    integrator: str = DEFAULT_INTEGRATOR,
    band_hz: float | None = None,
    divides_s: float | None = None,
    max_step_s: float | None = None,
    step_s: float | None = None,
    f1_hz: float | None = None,
    qpos: np.ndarray | None = None,
) -> Stepping:
    """The stepping of a rollout of ``built`` (module docstring).

    Parameters
    ----------
    integrator
        ``"discrete"`` (default) or ``"explicit"``.
    band_hz
        Top of the band (Hz); default :data:`BAND_F1_MULTIPLE` times f1 (a modal analysis
        unless ``f1_hz`` is given).
    divides_s
        The output or control step (s) the step must divide (rounded down to it).
    max_step_s
        A further upper bound on the step (s), e.g. a tenth of an impact pulse.
    step_s
        A given discrete step (s) instead of the band's (still rounded down to divide ``divides_s``).
    f1_hz, qpos
        The model's first frequency if known; the state to compute it at (default the equilibrium).
    """
    if integrator not in INTEGRATORS:
        raise SteppingError(
            "unknown integrator",
            parameter="integrator",
            value=integrator,
            hint=f"choose one of {', '.join(INTEGRATORS)}",
        )
    if band_hz is not None:
        band_hz = _check_positive("band_hz", band_hz)
    if step_s is not None:
        step_s = _check_positive("step_s", step_s)
    if integrator == "explicit":
        if step_s is not None:
            raise SteppingError(
                "sets the discrete integrator's step",
                parameter="step_s",
                value=step_s,
                hint="drop it with the explicit integrator (it runs at the model's own step)",
            )
        h = float(built.model.opt.timestep)
        if band_hz is not None:
            return Stepping("explicit", h, band_hz, "given", f1_hz, 0.0)
        if f1_hz is not None:
            return Stepping("explicit", h, BAND_F1_MULTIPLE * f1_hz, f"{BAND_F1_MULTIPLE:g} x f1", f1_hz, 0.0)
        return Stepping("explicit", h, 0.5 / h, "Nyquist of the step", None, 0.0)
    source = "given"
    if band_hz is None:
        f1_hz = f1_hz if f1_hz is not None else first_frequency_hz(built, qpos)
        band_hz = BAND_F1_MULTIPLE * f1_hz
        source = f"{BAND_F1_MULTIPLE:g} x f1"
    h = step_s if step_s is not None else min(MAX_STEP_S, MAX_NUMERICAL_DAMPING / (math.pi * band_hz))
    if max_step_s is not None:
        h = min(h, max_step_s)
    h_explicit = float(built.model.opt.timestep)
    # the culprit: the step (or band) itself, or the output step it must divide
    given, value = ("step_s", step_s) if step_s is not None else ("band_hz", band_hz)
    remedy = "a larger step" if step_s is not None else "a lower band"
    if divides_s is not None:
        if h >= h_explicit * (1 - 1e-9):
            given, value, remedy = "output_step_s", divides_s, "a larger output step"
        h = divides_s / math.ceil(divides_s / h * (1 - 1e-12))
    if h < h_explicit * (1 - 1e-9):
        raise SteppingError(
            f"the discrete step from it, {h:.3g} s, is below the explicit reference's own {h_explicit:.3g} s (which "
            "is then both cheaper and exact in the band)",
            parameter=given,
            value=value,
            hint=f"use the explicit integrator, or {remedy}",
        )
    return Stepping("discrete", h, band_hz, source, f1_hz)


def apply_stepping(built: BuiltModel, stepping: Stepping) -> BuiltModel:
    """A copy of ``built`` stepped as ``stepping`` says (``built`` is not changed).

    The welds keep the time constant they were compiled with (``2 h`` of the model's own step): the discrete
    integrator treats them implicitly, so they stay as stiff as in the modal analysis at any step.
    """
    if stepping.integrator == "explicit":
        if not math.isclose(stepping.step_s, float(built.model.opt.timestep), rel_tol=1e-12):
            raise SteppingError("the explicit reference runs at the model's own step (build it with that step)")
        return built
    model = copy.copy(built.model)
    model.opt.integrator = mujoco.mjtIntegrator.mjINT_DISCRETE
    model.opt.timestep = stepping.step_s
    return replace(built, model=model)
