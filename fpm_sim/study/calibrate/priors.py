"""Priors of ``fpm-sim calibrate``: one distribution per free parameter, read from a TOML file.

File layout (every table's ``reason`` is required, in the provenance style ``"study: ..."`` /
``"assumed: ... because ..."``)::

    [parameters."geometry.base_radius_m"]
    dist = "uniform"            # uniform | loguniform | normal | lognormal | truncnormal
    lower = 0.08                # uniform, loguniform, truncnormal
    upper = 0.45
    reason = "assumed: ..."

    [parameters."geometry.elbow_branch"]
    dist = "branches"           # uniform over the 8 elbow-branch combinations; or "fixed" (the base's)
    relabel = "cyclic"          # optional: classes that relabelling the chains maps onto each other are sampled
    reason = "..."              # once, weighted by their number (needs both rotations over a whole turn)

    [likelihood.discrepancy_rel]  # relative model-discrepancy sd; a distribution, or `value = 0.05` (fixed)
    dist = "loguniform"
    lower = 0.005
    upper = 0.5
    reason = "..."

    [likelihood.length_scale_m]   # optional: the discrepancy is a Gaussian process over the pose with this
    dist = "loguniform"           # correlation length (m) (fpm_sim.study.discrepancy); absent: independent
    lower = 0.02
    upper = 1.0
    reason = "..."

    [likelihood.mode_read]        # optional: the mode behind each measured f1 is latent (fpm_sim.study.readout)
    enabled = true
    modes = 3                     # the lowest modes the first clear peak may be
    height_db = -20.0             # a peak this far below the highest is lost (soft, width_db wide)
    width_db = 3.0
    reason = "..."

    [likelihood]
    rig_sigma_pct = 1.0         # rig tests' relative sd (%)

    [statements.singular_at_phi0]   # statement (a) of docs/study.md, a soft likelihood term
    enabled = true
    ...                             # see :class:`SingularAtPhi0`
    [statements.measured_poses_clear]
    enabled = true
    ...                             # see :class:`MeasuredPosesClear`

Normal: ``mean``, ``sd``; lognormal: ``median``, ``sigma_log`` (sd of the natural log); truncated normal:
``mean``, ``sd``, ``lower``, ``upper``. Every distribution maps a unit-cube coordinate to its value by its
inverse CDF (:meth:`Prior.transform`), as nested sampling needs.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.special import ndtr, ndtri

from fpm_sim.errors import FpmSimError, read_text_input
from fpm_sim.study.discrepancy import LENGTH_SCALE_PARAMETER
from fpm_sim.study.readout import ModeRead

__all__ = [
    "BRANCH_PARAMETER",
    "DISCREPANCY_PARAMETER",
    "DISTRIBUTIONS",
    "LENGTH_SCALE_PARAMETER",
    "MeasuredPosesClear",
    "Prior",
    "PriorError",
    "Priors",
    "SingularAtPhi0",
    "prior_names",
    "read_priors",
    "read_priors_text",
]

DISTRIBUTIONS = ("uniform", "loguniform", "normal", "lognormal", "truncnormal")
_KEYS = {
    "uniform": ("lower", "upper"),
    "loguniform": ("lower", "upper"),
    "normal": ("mean", "sd"),
    "lognormal": ("median", "sigma_log"),
    "truncnormal": ("mean", "sd", "lower", "upper"),
}
BRANCH_PARAMETER = "geometry.elbow_branch"
"""The elbow branches: ``dist = "branches"`` (sampled, uniform over the 8 combinations) or ``"fixed"``."""
DISCREPANCY_PARAMETER = "likelihood.discrepancy_rel"


class PriorError(FpmSimError):
    """A priors file that cannot be used; the message names the file and key and the fix."""


@dataclass(frozen=True)
class Prior:
    """One scalar distribution (see module docstring for the parameters of each ``dist``)."""

    name: str
    dist: str
    params: tuple[tuple[str, float], ...]
    reason: str

    def p(self, key: str) -> float:
        return dict(self.params)[key]

    def transform(self, u: np.ndarray | float) -> np.ndarray:
        """The value(s) at unit-cube coordinate(s) ``u`` (the inverse CDF)."""
        u = np.asarray(u, float)
        d = self.dist
        if d == "uniform":
            return self.p("lower") + u * (self.p("upper") - self.p("lower"))
        if d == "loguniform":
            lo, hi = math.log(self.p("lower")), math.log(self.p("upper"))
            return np.exp(lo + u * (hi - lo))
        if d == "normal":
            return self.p("mean") + self.p("sd") * ndtri(u)
        if d == "lognormal":
            return self.p("median") * np.exp(self.p("sigma_log") * ndtri(u))
        # truncnormal: the normal's CDF between the bounds, inverted
        m, s = self.p("mean"), self.p("sd")
        a, b = ndtr((self.p("lower") - m) / s), ndtr((self.p("upper") - m) / s)
        return np.clip(m + s * ndtri(a + u * (b - a)), self.p("lower"), self.p("upper"))

    def describe(self) -> str:
        args = ", ".join(f"{k}={v:g}" for k, v in self.params)
        return f"{self.dist}({args})"


@dataclass(frozen=True)
class SingularAtPhi0:
    """Statement (a) of ``docs/study.md``: at the poses written ``(x, 0)`` the platform, unturned
    (``phi = 0``), is near a parallel singularity, and the turn ``turn_rad`` moves it away.

    Per pose, the probability the statement holds under a layout is
    ``P = sigmoid(min(near - m_par(phi=0), m(turn) - near) / width)`` (both thresholds passed; the smaller
    margin counts; ``m_par``: the parallel measure, ``m``: min of serial and parallel, :mod:`fpm_sim.kinematics`;
    unreachable counts as not holding); the likelihood term is ``log(eps + (1 - eps) P)``: the statement is
    itself uncertain (it may be wrong with probability ``eps``), so it bends the posterior, it does not cut it.
    """

    poses_mm: tuple[tuple[float, float], ...] = ((100.0, 0.0), (50.0, 0.0), (0.0, 0.0), (-50.0, 0.0), (-100.0, 0.0))
    turn_rad: float = 0.2
    near: float = 0.05
    width: float = 0.01
    eps: float = 1e-3
    reason: str = ""


@dataclass(frozen=True)
class MeasuredPosesClear:
    """Statement (b): every measured pose is well away from a singularity (measure above ``min_measure``).
    Per pose ``log(eps + (1 - eps) sigmoid((m - min_measure) / width))``."""

    min_measure: float = 0.05
    width: float = 0.01
    eps: float = 1e-3
    reason: str = ""


@dataclass(frozen=True)
class Priors:
    """The parsed priors file: one :class:`Prior` per free parameter (in the parameter set's order),
    the elbow-branch choice, the discrepancy prior (or fixed value), the rig sigma and the statements."""

    parameters: tuple[Prior, ...]
    sample_branches: bool
    branch_reason: str
    discrepancy: Prior | None
    discrepancy_fixed: float
    rig_sigma_pct: float
    singular_at_phi0: SingularAtPhi0 | None
    measured_poses_clear: MeasuredPosesClear | None
    source: str = field(default="", repr=False)
    text: str = field(default="", repr=False)
    length_scale: Prior | None = None
    """The Gaussian-process discrepancy's correlation length (m) prior; ``None``: independent discrepancy."""
    mode_read: ModeRead | None = None
    """The latent-mode model of the measured first frequencies (:mod:`fpm_sim.study.readout`); ``None``: each
    measured f1 is mode 1."""
    branch_relabel: bool = False
    """``relabel = "cyclic"``: relabelling the chains ``i -> i + 1`` turns both joint layouts by 120 deg and shifts
    the elbow-branch pattern cyclically, so with both rotations over a whole turn the classes of one cyclic orbit hold
    the same machines; one class of each orbit is sampled, weighted by the orbit's size
    (:func:`~fpm_sim.study.identify.problem.cyclic_branch_orbits`)."""

    @property
    def periodic(self) -> tuple[int, ...]:
        """The parameters (indices into :attr:`parameters`) that are angles with a uniform prior over a whole turn
        (``*_deg``, ``upper - lower = 360``): their two bounds are one angle, and a sampler wraps them."""
        return tuple(
            i for i, p in enumerate(self.parameters)
            if p.name.endswith("_deg") and p.dist == "uniform" and math.isclose(p.p("upper") - p.p("lower"), 360.0)
        )  # fmt: skip

    @property
    def hyperpriors(self) -> tuple[Prior, ...]:
        """The likelihood's sampled hyperparameters, in the order of :attr:`names`."""
        return tuple(p for p in (self.discrepancy, self.length_scale) if p is not None)

    @property
    def names(self) -> list[str]:
        """The sampled coordinates, in order: parameters, then the discrepancy and the correlation length (when
        sampled), then the branch class."""
        out = [p.name for p in self.parameters]
        out += [p.name for p in self.hyperpriors]
        if self.sample_branches:
            out.append(BRANCH_PARAMETER)
        return out


def _number(tbl: Mapping[str, Any], key: str, where: str) -> float:
    if key not in tbl:
        raise PriorError(f"{where}: missing '{key}'")
    v = tbl[key]
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise PriorError(f"{where}.{key}: {v!r} is not a finite number")
    return float(v)


def _reason(tbl: Mapping[str, Any], where: str) -> str:
    r = tbl.get("reason")
    if not isinstance(r, str) or not r.strip():
        raise PriorError(
            f"{where}: give a 'reason' string (why this prior: 'study: ...' or 'assumed: ... because ...')"
        )
    return r


def _prior(name: str, tbl: Any, where: str) -> Prior:
    if not isinstance(tbl, Mapping):
        raise PriorError(f"{where}: expected a table with dist = ..., got {tbl!r}")
    dist = tbl.get("dist")
    if dist not in DISTRIBUTIONS:
        raise PriorError(f"{where}.dist: unknown distribution {dist!r}; choose from {', '.join(DISTRIBUTIONS)}")
    keys = _KEYS[dist]
    extra = set(tbl) - set(keys) - {"dist", "reason"}
    if extra:
        raise PriorError(f"{where}: unknown key(s) {sorted(extra)} for dist = {dist!r}; it takes {', '.join(keys)}")
    params = tuple((k, _number(tbl, k, where)) for k in keys)
    v = dict(params)
    if "lower" in v and not v["lower"] < v["upper"]:
        raise PriorError(f"{where}: lower ({v['lower']:g}) must be below upper ({v['upper']:g})")
    if dist == "loguniform" and not v["lower"] > 0:
        raise PriorError(f"{where}: a loguniform needs lower > 0, got {v['lower']:g}")
    for k in ("sd", "sigma_log", "median"):
        if k in v and not v[k] > 0:
            raise PriorError(f"{where}.{k}: must be > 0, got {v[k]:g}")
    return Prior(name, str(dist), params, _reason(tbl, where))


def _statement(cls: type, tbl: Any, where: str) -> Any:
    if not isinstance(tbl, Mapping):
        raise PriorError(f"{where}: expected a table")
    fields_ = {f.name for f in dataclasses.fields(cls) if f.name != "reason"}
    extra = set(tbl) - fields_ - {"enabled", "reason"}
    if extra:
        raise PriorError(
            f"{where}: unknown key(s) {sorted(extra)}; it takes enabled, reason, {', '.join(sorted(fields_))}"
        )
    enabled = tbl.get("enabled", True)
    if not isinstance(enabled, bool):
        raise PriorError(f"{where}.enabled: true or false, got {enabled!r}")
    if not enabled:
        return None
    kw: dict[str, Any] = {"reason": _reason(tbl, where)}
    for k in fields_ & set(tbl):
        if k == "poses_mm":
            try:
                kw[k] = tuple((float(x), float(y)) for x, y in tbl[k])
            except (TypeError, ValueError) as exc:
                raise PriorError(f"{where}.poses_mm: a list of [x_mm, y_mm] pairs, got {tbl[k]!r}") from exc
        else:
            kw[k] = _number(tbl, k, where)
    for k in ("width", "eps"):
        if k in kw and not kw[k] > 0:
            raise PriorError(f"{where}.{k}: must be > 0, got {kw[k]:g}")
    if kw.get("eps", 0.5) >= 1:
        raise PriorError(f"{where}.eps: the probability the statement is wrong must be < 1")
    return cls(**kw)


def read_priors(source: str | Path, free: Sequence[str], *, text: str | None = None) -> Priors:
    """Read a priors TOML file (or ``text``, named ``source``) for the free parameters ``free``.

    Raises
    ------
    PriorError
        For an unreadable file, a free parameter without a prior, a prior of a parameter that is not free, an
        unknown distribution, section or key, or a missing ``reason``; each names the key.
    """
    where = str(source)
    text = read_priors_text(source) if text is None else text
    doc = _document(where, text)
    unknown = set(doc) - {"parameters", "likelihood", "statements"}
    if unknown:
        raise PriorError(
            f"{where}: unknown section(s) {sorted(unknown)}; use [parameters.*], [likelihood], [statements.*]"
        )
    ptab = doc.get("parameters", {})
    params = _parameter_priors(ptab, list(free), where)
    sample_branches, branch_reason, relabel = _branches(ptab, where)
    lik = doc.get("likelihood", {})
    unknown = set(lik) - {"discrepancy_rel", "rig_sigma_pct", "length_scale_m", "mode_read"}
    if unknown:
        raise PriorError(
            f"{where} [likelihood]: unknown key(s) {sorted(unknown)}; it takes discrepancy_rel, length_scale_m, "
            "mode_read, rig_sigma_pct"
        )
    disc, disc_fixed = _discrepancy(lik, where)
    rig_sigma = float(lik.get("rig_sigma_pct", 1.0))
    if not rig_sigma > 0:
        raise PriorError(f"{where} [likelihood].rig_sigma_pct: must be > 0, got {rig_sigma:g}")
    a, b = _statements(doc.get("statements", {}), where)
    length = _length_scale(lik, disc, disc_fixed, where)
    read = _mode_read(lik.get("mode_read"), f"{where} [likelihood.mode_read]")
    if read is not None and length is not None:
        raise PriorError(
            f"{where} [likelihood]: mode_read and length_scale_m cannot be combined (a mixture per pose is not "
            "jointly Gaussian); choose one"
        )
    out = Priors(
        params, sample_branches, branch_reason, disc, disc_fixed, rig_sigma, a, b, where, text, length, read,
        branch_relabel=relabel,
    )  # fmt: skip
    _check_relabel(out, where)
    return out


RELABEL_ROTATIONS = ("geometry.base_rotation_deg", "geometry.platform_rotation_deg")
"""The rotations a cyclic relabelling of the chains turns by 120 deg: both must span a whole turn."""


def _check_relabel(pr: Priors, where: str) -> None:
    """``relabel = "cyclic"`` needs both rotations free with uniform priors over a whole turn."""
    if not pr.branch_relabel:
        return
    whole = {pr.parameters[i].name for i in pr.periodic}
    missing = [n for n in RELABEL_ROTATIONS if n not in whole]
    if missing:
        raise PriorError(
            f'{where} [parameters."{BRANCH_PARAMETER}"].relabel: "cyclic" samples one class of each cyclic orbit, '
            f"which holds every machine only when {' and '.join(RELABEL_ROTATIONS)} are free with uniform priors "
            f"over a whole turn (upper - lower = 360); {', '.join(missing)} is not: give it lower = -180, "
            "upper = 180, or remove relabel"
        )


def _document(where: str, text: str) -> dict[str, Any]:
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise PriorError(f"{where}: not valid TOML: {exc}") from exc


def prior_names(source: str | Path, text: str) -> list[str]:
    """The free parameters a priors file's ``text`` gives a prior for, in its order (the branch choice aside)."""
    ptab = _document(str(source), text).get("parameters", {})
    if not isinstance(ptab, Mapping):
        raise PriorError(f"{source}: [parameters] must be a table of tables, one per free parameter")
    return [k for k in ptab if k != BRANCH_PARAMETER]


def read_priors_text(source: str | Path) -> str:
    """The file's text; a missing file, a folder or a binary file is refused naming it."""
    try:
        return read_text_input(
            source, error=PriorError, parameter="priors", kind="a TOML file", hint="give a priors TOML file"
        )
    except FileNotFoundError as exc:
        raise PriorError(
            "priors file not found", parameter="priors", value=str(source), hint="give a priors TOML file"
        ) from exc
    except IsADirectoryError as exc:
        raise PriorError("is a folder", parameter="priors", value=str(source), hint="give a priors TOML file") from exc


def _parameter_priors(ptab: Mapping[str, Any], names: list[str], where: str) -> tuple[Prior, ...]:
    """One prior per free parameter, in their order; a stray or a missing one is refused."""
    stray = [k for k in ptab if k not in names and k != BRANCH_PARAMETER]
    if stray:
        raise PriorError(
            f'{where}: [parameters."{stray[0]}"] is not a free parameter of this run; the free ones are '
            f"{', '.join(names)} (and {BRANCH_PARAMETER}); remove it or add its group to the free groups (free)"
        )
    missing = [n for n in names if n not in ptab]
    if missing:
        raise PriorError(
            f'{where}: no prior for the free parameter(s) {", ".join(missing)}; add [parameters."{missing[0]}"]'
        )
    return tuple(_prior(n, ptab[n], f'{where} [parameters."{n}"]') for n in names)


def _branches(ptab: Mapping[str, Any], where: str) -> tuple[bool, str, bool]:
    """Whether the elbow branches are sampled, why, and whether one class of each cyclic orbit stands for it."""
    if BRANCH_PARAMETER not in ptab:
        return False, "fixed: the base description's elbow branches", False
    t = ptab[BRANCH_PARAMETER]
    w = f'{where} [parameters."{BRANCH_PARAMETER}"]'
    d = t.get("dist") if isinstance(t, Mapping) else None
    if d not in ("branches", "fixed"):
        raise PriorError(f'{w}.dist: {d!r}; use "branches" (uniform over the 8 combinations) or "fixed"')
    assert isinstance(t, Mapping)
    relabel = t.get("relabel", "none")
    if relabel not in ("cyclic", "none") or (relabel == "cyclic" and d != "branches"):
        raise PriorError(f'{w}.relabel: {relabel!r}; use "cyclic" (with dist = "branches") or leave it out')
    return d == "branches", _reason(t, w), relabel == "cyclic"


def _discrepancy(lik: Mapping[str, Any], where: str) -> tuple[Prior | None, float]:
    """The discrepancy's prior, or its fixed value (default 0: no discrepancy term)."""
    d_tbl = lik.get("discrepancy_rel", {"value": 0.0, "reason": "no discrepancy term"})
    if isinstance(d_tbl, Mapping) and "value" in d_tbl:
        fixed = _number(d_tbl, "value", f"{where} [likelihood.discrepancy_rel]")
        if fixed < 0:
            raise PriorError(f"{where} [likelihood.discrepancy_rel].value: must be >= 0, got {fixed:g}")
        return None, fixed
    return _prior(DISCREPANCY_PARAMETER, d_tbl, f"{where} [likelihood.discrepancy_rel]"), 0.0


def _statements(st: Mapping[str, Any], where: str) -> tuple[SingularAtPhi0 | None, MeasuredPosesClear | None]:
    """The study's statements (a) and (b), each ``None`` when absent."""
    unknown = set(st) - {"singular_at_phi0", "measured_poses_clear"}
    if unknown:
        raise PriorError(
            f"{where}: unknown statement(s) {sorted(unknown)}; known: singular_at_phi0, measured_poses_clear"
        )
    a = (
        _statement(SingularAtPhi0, st["singular_at_phi0"], f"{where} [statements.singular_at_phi0]")
        if "singular_at_phi0" in st
        else None
    )
    b = (
        _statement(MeasuredPosesClear, st["measured_poses_clear"], f"{where} [statements.measured_poses_clear]")
        if "measured_poses_clear" in st
        else None
    )
    return a, b


def _mode_read(tbl: Any, where: str) -> ModeRead | None:
    """The ``[likelihood.mode_read]`` table, or ``None`` (absent or ``enabled = false``)."""
    if tbl is None:
        return None
    if not isinstance(tbl, Mapping):
        raise PriorError(f"{where}: expected a table")
    extra = set(tbl) - {"enabled", "modes", "height_db", "width_db", "reason"}
    if extra:
        raise PriorError(
            f"{where}: unknown key(s) {sorted(extra)}; it takes enabled, modes, height_db, width_db, reason"
        )
    reason = _reason(tbl, where)
    if not tbl.get("enabled", True):
        return None
    modes = tbl.get("modes", 3)
    if isinstance(modes, bool) or not isinstance(modes, int) or not 1 <= modes <= 6:
        raise PriorError(f"{where}.modes: an integer 1-6, got {modes!r}")
    height = _number(tbl, "height_db", where) if "height_db" in tbl else -20.0
    width = _number(tbl, "width_db", where) if "width_db" in tbl else 3.0
    if not width > 0:
        raise PriorError(f"{where}.width_db: must be > 0, got {width:g}")
    return ModeRead(modes=modes, reference_modes=max(6, modes), height_db=height, width_db=width, reason=reason)


def _length_scale(lik: Mapping[str, Any], disc: Prior | None, disc_fixed: float, where: str) -> Prior | None:
    """The ``[likelihood.length_scale_m]`` prior (a Gaussian-process discrepancy), or ``None``."""
    if "length_scale_m" not in lik:
        return None
    w = f"{where} [likelihood.length_scale_m]"
    if disc is None and disc_fixed <= 0:
        raise PriorError(f"{w}: a correlation length needs a discrepancy; give [likelihood.discrepancy_rel]")
    prior = _prior(LENGTH_SCALE_PARAMETER, lik["length_scale_m"], w)
    if not prior.transform(1e-9) > 0:
        raise PriorError(f"{w}: the correlation length must be > 0 over the whole prior (lower > 0)")
    return prior
