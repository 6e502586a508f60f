"""How a model is discretised and simulated (:class:`ModelOptions`) and the one resolution policy of every
command (fidelity presets, segments per link, the estimated discretisation error every result states).

The spec skeleton, compilation and the timestep rule are in :mod:`fpm_sim.model.spec`.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any

from fpm_sim.errors import FpmSimError, FpmSimWarning
from fpm_sim.model.parts import DEFAULT_RESOLUTION, check_link_model

__all__ = [
    "DEFAULT_FIDELITY",
    "DEFAULT_SEGMENTS",
    "DISCRETISATION_COEFF",
    "FIDELITIES",
    "FIDELITY_RESOLUTION",
    "FIDELITY_SCALE",
    "RESOLUTION_WARN",
    "ModelOptions",
    "ResolutionWarning",
    "TimestepError",
    "discretisation_error",
    "resolution_footer",
    "resolution_label",
    "resolution_of_parameters",
    "resolution_summary",
    "resolution_text",
    "resolve_segments",
    "warn_if_coarse",
]

DEFAULT_SEGMENTS = DEFAULT_RESOLUTION["segments"]
"""Default spring locations per link (fidelity ``standard``): the 10 x 10 x 228 mm steel cantilever's
first three bending frequencies are then +0.16, +0.56, +0.91 % from Euler-Bernoulli (error ~ 1/n^2; see docs)."""


FIDELITIES = ("fast", "standard", "fine")
"""Named resolutions; ``--segments N`` overrides them."""


DEFAULT_FIDELITY = "standard"
"""Every command's default: the same model, hence the same first frequency, whatever the command."""


FIDELITY_RESOLUTION = {
    "segments": {"fast": 8, "standard": DEFAULT_RESOLUTION["segments"], "fine": 24},
    "cable": {"fast": 8, "standard": DEFAULT_RESOLUTION["cable"], "fine": 24},
    "flex": {"fast": 8, "standard": DEFAULT_RESOLUTION["flex"], "fine": 32},
    "rigid": {"fast": 1, "standard": 1, "fine": 1},
}
"""Resolution per link of each preset and link model (``standard`` is
:data:`fpm_sim.model.parts.DEFAULT_RESOLUTION`). ``fast`` is the coarsest resolution whose estimated f1 error
stays below :data:`RESOLUTION_WARN` (8: 0.64 %; the old pose-loop default 6 gives 1.1 %); ``fine`` halves
the spacing of ``standard`` (error / 4)."""


FIDELITY_SCALE = FIDELITY_RESOLUTION["segments"]


DISCRETISATION_COEFF = {"segments": 0.41, "cable": 0.41}
"""``c`` in the relative error of the first frequency ``e(n) ~ c / n^2`` (n per link), per link model.

Measured on the manipulator at (0, 0, 0) (the embedded description, constrained and transitionFD alike):
f1 = 73.5026 Hz at n = 6 and 72.8808 Hz at n = 12; Richardson's extrapolation with the 1/n^2 law gives
72.674 Hz, so e(12) = 0.285 % and c = 0.285 % * 144 = 0.41 (e(6) = 1.14 %). ``cable`` is the same linear
model as ``segments`` (agreement 5e-10). ``flex`` converges differently (from below, docs/link_models.md)
and gets no estimate; ``rigid`` has no discretisation."""


RESOLUTION_WARN = 0.01
"""Estimated relative discretisation error of f1 above which a :class:`ResolutionWarning` is issued."""


class ResolutionWarning(FpmSimWarning):
    """The estimated discretisation error of the first frequency exceeds :data:`RESOLUTION_WARN`."""


def resolve_segments(*, fidelity: str | None = None, segments: int | None = None, link_model: str = "segments") -> int:
    """Resolution per link of ``link_model``: ``segments`` if given, else the ``fidelity`` preset.

    Parameters
    ----------
    fidelity
        ``"fast"``, ``"standard"`` (default) or ``"fine"``; see :data:`FIDELITY_RESOLUTION`.
    segments
        Explicit resolution per link (spring locations, cable joints or flex edges); wins over ``fidelity``.
    link_model
        ``"segments"``, ``"rigid"``, ``"cable"`` or ``"flex"``.
    """
    if segments is not None:
        return segments
    fid = DEFAULT_FIDELITY if fidelity is None else fidelity
    if fid not in FIDELITY_SCALE:
        raise FpmSimError(
            "unknown fidelity", parameter="fidelity", value=fid, hint=f"choose one of {', '.join(FIDELITIES)}"
        )
    return FIDELITY_RESOLUTION.get(link_model, FIDELITY_RESOLUTION["segments"])[fid]


def discretisation_error(segments: int, link_model: str = "segments") -> float:
    """Estimated relative error of the first natural frequency at ``segments`` per link (``c / n^2``).

    Returns 0 for rigid links and NaN where no estimate is known (``flex``); see :data:`DISCRETISATION_COEFF`.
    """
    if link_model == "rigid":
        return 0.0
    c = DISCRETISATION_COEFF.get(link_model)
    if c is None or segments < 1:
        return math.nan
    return c / segments**2


def resolution_summary(options: ModelOptions) -> dict[str, Any]:
    """What every result states about its resolution (JSON-ready).

    Keys: ``link_model``, ``segments`` (per link), ``fidelity`` (the preset, or ``None`` if
    ``segments`` was set explicitly), ``f1_error_estimate`` (relative, ``c / n^2``; NaN if unknown).
    """
    n = int(options.segments or 1)
    return {
        "link_model": options.link_model,
        "segments": n,
        "fidelity": options.fidelity,
        "f1_error_estimate": discretisation_error(n, options.link_model),
        "axial": options.axial,
        "gravity": options.gravity,
    }


def resolution_of_parameters(parameters: dict[str, Any]) -> dict[str, Any]:
    """:func:`resolution_summary` from a built model's ``parameters`` (its ``options`` entry); ``{}`` if absent."""
    o = parameters.get("options") if isinstance(parameters, dict) else None
    if not isinstance(o, dict) or "segments" not in o:
        return {}
    lm = o.get("link_model", "segments")
    n = int(o.get("segments") or 1)
    out: dict[str, Any] = {
        "link_model": lm,
        "segments": n,
        "fidelity": o.get("fidelity"),
        "f1_error_estimate": discretisation_error(n, lm),
    }
    out.update({k: bool(o[k]) for k in ("axial", "gravity") if k in o})
    return out


def resolution_text(summary: dict[str, Any]) -> str:
    """One line from a :func:`resolution_summary` (or :func:`resolution_of_parameters`) dict, e.g.
    ``12 segments per link (fidelity standard), estimated f1 discretisation error 0.28 %; axial springs off
    (inextensible links), gravity off``; the axial springs and gravity are named where the dict records them
    (commands differ in both, so every result says which it used)."""
    lm = summary.get("link_model", "segments")
    if lm == "rigid":
        text = "rigid links (no discretisation)"
    else:
        n = int(summary.get("segments") or 1)
        fid = summary.get("fidelity")
        if fid:
            how = f"fidelity {fid}"
        else:  # no preset recorded: set explicitly, or read from a file (an atlas, a reduced model)
            same = [f for f, r in FIDELITY_RESOLUTION.get(lm, {}).items() if r == n]
            how = f"= fidelity {same[0]}" if same else "set explicitly"
        err = summary.get("f1_error_estimate", discretisation_error(n, lm))
        est = "not estimated" if err is None or math.isnan(err) else f"{100 * err:.2g} %"
        text = f"{n} {lm} per link ({how}), estimated f1 discretisation error {est}"
    extra = []
    if "axial" in summary:
        extra.append("axial springs on" if summary["axial"] else "axial springs off (inextensible links)")
    if "gravity" in summary:
        extra.append("gravity on" if summary["gravity"] else "gravity off")
    return text + ("; " + ", ".join(extra) if extra else "")


def resolution_footer(source: ModelOptions | dict[str, Any] | None) -> str:
    """The line every result's table ends with, ``resolution: ...`` (:func:`resolution_text`), from model
    options or a built model's ``parameters``; '' when ``source`` records no resolution."""
    if source is None:
        return ""
    summary = resolution_summary(source) if isinstance(source, ModelOptions) else resolution_of_parameters(source)
    return "resolution: " + resolution_text(summary) if summary else ""


def resolution_label(options: ModelOptions) -> str:
    """One line: ``12 segments per link (fidelity standard), estimated f1 discretisation error 0.28 %; axial
    springs off (inextensible links), gravity off`` (:func:`resolution_text`)."""
    return resolution_text(resolution_summary(options))


def warn_if_coarse(options: ModelOptions, *, stacklevel: int = 2) -> None:
    """Warn (:class:`ResolutionWarning`) when the estimated f1 error passes :data:`RESOLUTION_WARN`."""
    err = discretisation_error(int(options.segments or 1), options.link_model)
    if err > RESOLUTION_WARN:
        finer = max(n for n in range(1, 201) if DISCRETISATION_COEFF[options.link_model] / n**2 > RESOLUTION_WARN) + 1
        warnings.warn(
            ResolutionWarning(
                f"coarse resolution: {options.segments} {options.link_model} per link gives an estimated "
                f"discretisation error of {100 * err:.2g} % on the first frequency; use segments >= {finer} "
                f"or fidelity 'standard' for below {100 * RESOLUTION_WARN:g} %",
                parameter="segments",
            ),
            stacklevel=stacklevel + 1,
        )


class TimestepError(FpmSimError):
    """The requested timestep cannot integrate the model's stiffest spring stably."""


@dataclass(frozen=True)
class ModelOptions:
    """How a model is discretised and simulated.

    Parameters
    ----------
    link_model
        ``"segments"`` (rigid-finite-element chain, default), ``"rigid"``, ``"cable"`` (MuJoCo's
        cable plugin) or ``"flex"`` (a 1D flex); see :mod:`fpm_sim.model.deformable_links`.
    segments
        Resolution per link: spring locations (``segments``), elastic joints (``cable``) or flex
        edges (``flex``); ``None`` takes the ``fidelity`` preset (:func:`resolve_segments`).
    fidelity
        ``"fast"``, ``"standard"`` or ``"fine"`` (:data:`FIDELITY_RESOLUTION`); ``None`` with ``segments``
        ``None`` means ``"standard"``; recorded as ``None`` when ``segments`` is given explicitly.
    axial
        Add an axial spring at each spring location (default). Without it the links are
        inextensible: 2.4 times cheaper for the manipulator and within 0.1 % on its in-plane modes,
        but a straight chain clamped at both ends then cannot sag without stretching, and the tension
        that gravity builds in it is set by the weld's softness instead of the links' EA.
    rotary_inertia
        Add the rotary inertia of the link sections about their bending axes: the chain then
        converges to a Rayleigh beam instead of an Euler-Bernoulli beam (for the 10 mm x 228 mm steel
        bar this lowers the free-free modes 1-3 by 0.4, 0.9 and 1.5 %). Off by default, as shear is
        not modelled either (``shear`` adds it: both together give a Timoshenko beam).
    shear
        Add transverse shear springs ``kappa G A / l`` at each spring location (``segments`` links only):
        with ``rotary_inertia`` the links converge to Timoshenko beams (30 mm deep links on ~150 mm spans:
        about 1.5 % below Euler-Bernoulli on their first in-plane mode).
    gravity
        Gravity (9.81 m/s^2) along ``-z``, the motor axes.
    timestep_s
        Simulation step; ``None`` picks it from the highest natural frequency (see :mod:`fpm_sim.model.spec`).
    """

    link_model: str = "segments"
    segments: int | None = None
    axial: bool = True
    rotary_inertia: bool = False
    shear: bool = False
    gravity: bool = True
    timestep_s: float | None = None
    fidelity: str | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        if self.segments is None and self.link_model in DEFAULT_RESOLUTION:
            fid = DEFAULT_FIDELITY if self.fidelity is None else self.fidelity
            object.__setattr__(
                self, "segments", resolve_segments(fidelity=fid, segments=None, link_model=self.link_model)
            )
            object.__setattr__(self, "fidelity", fid)
        elif self.fidelity is not None:
            if self.fidelity not in FIDELITY_SCALE:
                raise FpmSimError(
                    "unknown fidelity",
                    parameter="fidelity",
                    value=self.fidelity,
                    hint=f"choose one of {', '.join(FIDELITIES)}",
                )
            if self.segments != resolve_segments(fidelity=self.fidelity, link_model=self.link_model):
                object.__setattr__(self, "fidelity", None)  # an explicit resolution overrides the preset
        check_link_model(self.link_model, self.segments)
        if self.timestep_s is not None and not (0.0 < self.timestep_s <= 1e-2):
            raise TimestepError("must be in (0, 0.01] s", parameter="timestep_s", value=self.timestep_s)
