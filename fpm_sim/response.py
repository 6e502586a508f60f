"""Frequency response functions (FRFs) of the linearised manipulator between points on its links.

The model is linearised at its static equilibrium under gravity and solved by the constrained
eigenproblem of :func:`fpm_sim.rom.reduction.modal_system` (all modes, mass-normalised shapes ``phi_r``,
natural frequencies ``omega_r``). A unit force along the world direction ``e_in`` at a point ``p_in``
of a link enters as the generalised force ``b = J_in' e_in`` (``J_in`` the translational Jacobian of
the material point); an accelerometer at ``p_out`` with sensitive axis ``e_out`` reads
``c qddot`` with ``c = e_out' J_out``. With modal (diagonal) damping ratios ``zeta_r``::

    H(w) = g(w) * sum_r  (c phi_r)(phi_r' b) / (omega_r^2 - w^2 + 2 j zeta_r omega_r w)

``g = 1`` (receptance, m/N), ``j w`` (mobility, m/s/N) or ``-w^2`` (accelerance, m/s^2/N, what an
accelerometer and an impact hammer measure). The modal damping ratios are the model's own by default
(``zeta_r = Xi_rr / (2 omega_r)``, ``Xi = Phi' C Phi`` from the joint dampers, i.e. the configuration's
stiffness-proportional damping, however it was set: assumed or identified); a user value (one ratio
for all modes, or one per mode) replaces them, e.g. a ratio identified from a measured FRF by
:func:`half_power_damping`.

Points (:class:`LinkPoint`) are given by link name (the 3RRR's ``proximal_i``, ``distal_i``; a described
machine's ``<chain>_<link>``, :attr:`BuiltModel.links`; or ``platform``, the end effector's reference point),
a fraction of the link's length from its start (the motor for a proximal link, the elbow for a
distal link) and an axis: ``normal`` (in the base plane, normal to the link: the bending direction),
``along`` (the link axis), ``z`` (out of the plane), or the world axes ``x`` / ``y``. The point is a
material point of the segment body that holds it (anywhere along the link, not only at the segment
sites), and link-frame axes follow the link as it moves.

Peak picking (:func:`pick_peaks`): local maxima of ``|H|`` in dB with a prominence of at least
``min_prominence_db``, each refined by a parabola through the three samples around it (sub-bin
accuracy on a sampled spectrum).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import scipy.signal
from numpy.typing import ArrayLike

from fpm_sim.errors import FpmSimError
from fpm_sim.model.spec import BuiltModel
from fpm_sim.rom.reduction import ModalSystem

__all__ = [
    "AXES",
    "QUANTITIES",
    "FrequencyResponse",
    "FrfError",
    "LinkPoint",
    "MaterialPoint",
    "Peak",
    "default_point",
    "frf_grid",
    "half_power_damping",
    "locate",
    "material_point",
    "modal_frf",
    "pick_peaks",
    "point_row",
]

AXES = ("normal", "along", "z", "x", "y")
QUANTITIES = {"receptance": "m/N", "mobility": "m/s/N", "accelerance": "m/s^2/N"}
DEFAULT_MIN_PROMINENCE_DB = 3.0
"""Default prominence (dB) a local maximum of ``|H|`` needs to count as a peak: a 3 dB (half-power)
rise above the deeper of the two surrounding valleys, the half-power criterion of modal testing."""


class FrfError(FpmSimError):
    """Inconsistent FRF options (named in the message)."""


@dataclass(frozen=True)
class LinkPoint:
    """A material point on a link and a direction there (an excitation or an accelerometer).

    Parameters
    ----------
    link
        ``proximal_i``, ``distal_i`` (``i`` in 0..2) on the 3RRR, ``<chain>_<link>`` on a described machine, or
        ``platform`` (the end effector's reference point).
    fraction
        Position along the link as a fraction of its length from its start (0..1); ignored for the
        platform.
    axis
        ``normal`` (in-plane normal to the link), ``along`` (link axis), ``z`` (out of plane), or the
        world axes ``x``, ``y``.
    """

    link: str = "distal_0"
    fraction: float = 0.5
    axis: str = "normal"

    def label(self) -> str:
        if self.link == "platform":
            return f"platform/{self.axis}"
        return f"{self.link}@{self.fraction:g}/{self.axis}"

    def check(self, built: BuiltModel, role: str = "") -> None:
        """Raise :class:`FrfError` for a point the model does not have; ``role`` (``input``/``output``) names
        the fraction parameter ``<role>_fraction``."""
        if self.link != "platform" and self.link not in built.links:
            raise FrfError(f"unknown link {self.link!r}; choose one of platform, {', '.join(sorted(built.links))}")
        if not (0.0 <= self.fraction <= 1.0) or not math.isfinite(self.fraction):
            raise FrfError(
                f"the fraction must lie in [0, 1] (position along {self.link})",
                parameter=f"{role}_fraction" if role else "fraction",
                value=self.fraction,
            )
        if self.axis not in AXES:
            raise FrfError(f"axis must be one of {', '.join(AXES)}, got {self.axis!r}")
        if self.link == "platform" and self.axis in ("normal", "along"):
            raise FrfError("the platform has no link axis: use axis x, y or z")


def default_point(built: BuiltModel) -> LinkPoint:
    """The model's default excitation and accelerometer point (:attr:`BuiltModel.test_point`): on the 3RRR the
    study's, mid-span of ``distal_0`` along z; on a described machine mid-span of the first chain's last flexible
    link along the link frame's z (:mod:`fpm_sim.model.general`)."""
    if built.test_point is None:
        raise FrfError(
            f"the {built.name} model has no default test point (no flexible link to excite)",
            parameter="excitation",
            hint="give the point (a LinkPoint on a flexible link)",
        )
    link, fraction, axis = built.test_point
    return LinkPoint(link, fraction, axis)


@dataclass(frozen=True)
class MaterialPoint:
    """Where a :class:`LinkPoint` sits in a compiled model: its body, the body-frame position (m) and
    the axis rule; :meth:`world` gives the world position and axis in any state (after a forward pass)."""

    body_id: int
    local_m: np.ndarray
    axis: str
    platform: bool

    def world(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        rot = data.xmat[self.body_id].reshape(3, 3)
        pos = data.xpos[self.body_id] + rot @ self.local_m
        if self.axis == "x":
            return pos, np.array([1.0, 0.0, 0.0])
        if self.axis == "y":
            return pos, np.array([0.0, 1.0, 0.0])
        if self.axis == "z" and self.platform:
            return pos, np.array([0.0, 0.0, 1.0])
        axis = rot[:, {"normal": 1, "along": 0, "z": 2}[self.axis]].copy()
        if self.axis == "normal":  # keep it in the base plane
            axis[2] = 0.0
        return pos, axis / np.linalg.norm(axis)


def material_point(built: BuiltModel, point: LinkPoint) -> MaterialPoint:
    """The body and body-frame position of ``point`` (checked against ``built``)."""
    point.check(built)
    model = built.model
    if point.link == "platform":
        sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, built.end_effector_site or "platform_center")
        return MaterialPoint(int(model.site_bodyid[sid]), model.site_pos[sid].copy(), point.axis, True)
    sites = built.links[point.link]
    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, s) for s in sites]
    # sites p0..p{n} sit at the origins of the link's bodies b0..b{n} (spring locations) and p{n+1} at
    # the link's end; body b{j+1} sits at (piece_j, 0, 0) in b{j}'s frame, and the end site at
    # (last piece, 0, 0) in the last body's frame
    bodies = [int(model.site_bodyid[k]) for k in ids[:-1]]
    pieces = [float(model.body_pos[b][0]) for b in bodies[1:]] + [float(model.site_pos[ids[-1]][0])]
    starts = np.concatenate([[0.0], np.cumsum(pieces)])
    arc = point.fraction * float(starts[-1])
    j = int(np.clip(np.searchsorted(starts, arc, side="right") - 1, 0, len(bodies) - 1))
    return MaterialPoint(bodies[j], np.array([arc - starts[j], 0.0, 0.0]), point.axis, False)


def locate(built: BuiltModel, data: mujoco.MjData, point: LinkPoint) -> tuple[int, np.ndarray, np.ndarray]:
    """Body id, world position (m) and world unit axis of ``point`` after a forward pass of ``data``."""
    mp = material_point(built, point)
    pos, axis = mp.world(data)
    return mp.body_id, pos, axis


def point_row(built: BuiltModel, qpos: np.ndarray, point: LinkPoint) -> np.ndarray:
    """``e' J_p`` (nv,): the point's velocity along its axis per unit generalised velocity at ``qpos``.

    As an input row it is the generalised force of a unit force along the axis (``b = J_p' e``).
    """
    model = built.model
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_forward(model, data)
    bid, pos, axis = locate(built, data, point)
    jacp = np.zeros((3, model.nv))
    mujoco.mj_jac(model, data, jacp, None, pos, bid)
    return axis @ jacp


@dataclass(frozen=True)
class Peak:
    """One FRF peak: refined frequency (Hz), magnitude (the FRF's unit) and prominence (dB)."""

    freq_hz: float
    magnitude: float
    prominence_db: float


def pick_peaks(
    freq_hz: np.ndarray,
    magnitude: np.ndarray,
    *,
    min_prominence_db: float = DEFAULT_MIN_PROMINENCE_DB,
    f_min_hz: float = 0.0,
    f_max_hz: float | None = None,
) -> list[Peak]:
    """Peaks of a sampled FRF magnitude, ascending in frequency (see module docstring).

    Parameters
    ----------
    freq_hz, magnitude
        Uniform or non-uniform frequency grid (Hz) and ``|H|`` on it.
    min_prominence_db
        Smallest prominence (dB) of a peak (``scipy.signal.find_peaks`` on ``20 log10 |H|``).
    f_min_hz, f_max_hz
        Band searched.
    """
    f = np.asarray(freq_hz, float)
    mag = np.asarray(magnitude, float)
    band = (f >= f_min_hz) & (f <= (np.inf if f_max_hz is None else f_max_hz))
    idx_band = np.flatnonzero(band)
    if idx_band.size < 3:
        return []
    db = 20.0 * np.log10(np.maximum(mag[idx_band], 1e-300))
    idx, props = scipy.signal.find_peaks(db, prominence=min_prominence_db)
    out = []
    for k, prom in zip(idx, props["prominences"]):
        i = int(idx_band[k])
        fk, mk = f[i], mag[i]
        if 0 < k < len(db) - 1:
            y0, y1, y2 = db[k - 1], db[k], db[k + 1]
            den = y0 - 2.0 * y1 + y2
            if den < 0.0:
                d = 0.5 * (y0 - y2) / den  # vertex offset in samples, |d| <= 0.5
                step = f[i + 1] - f[i] if d > 0 else f[i] - f[i - 1]
                fk = f[i] + d * step
                mk = 10.0 ** ((y1 - 0.25 * (y0 - y2) * d) / 20.0)
        out.append(Peak(float(fk), float(mk), float(prom)))
    return out


def half_power_damping(freq_hz: np.ndarray, magnitude: np.ndarray, peak_hz: float) -> float:
    """Damping ratio of the peak at ``peak_hz`` by the half-power bandwidth: ``(f2 - f1) / (2 f_peak)``.

    ``f1 < f_peak < f2`` are where ``|H|`` falls to ``|H(f_peak)| / sqrt 2`` (linear interpolation
    between samples). Returns NaN if the FRF does not fall that far on both sides before the next
    peak (the peak is not separated enough to measure).
    """
    f = np.asarray(freq_hz, float)
    mag = np.asarray(magnitude, float)
    i = int(np.argmin(np.abs(f - peak_hz)))
    top = mag[max(i - 1, 0) : i + 2].max()
    half = top / math.sqrt(2.0)
    lo = i
    while lo > 0 and mag[lo] > half:
        if mag[lo - 1] > mag[lo] * (1 + 1e-12) and mag[lo] < top:
            return math.nan  # rising again: another peak before the half-power point
        lo -= 1
    hi = i
    while hi < len(f) - 1 and mag[hi] > half:
        if mag[hi + 1] > mag[hi] * (1 + 1e-12) and mag[hi] < top:
            return math.nan
        hi += 1
    if mag[lo] > half or mag[hi] > half:
        return math.nan
    f1 = np.interp(half, [mag[lo], mag[lo + 1]], [f[lo], f[lo + 1]])
    f2 = np.interp(half, [mag[hi], mag[hi - 1]], [f[hi], f[hi - 1]])
    return float((f2 - f1) / (2.0 * peak_hz))


@dataclass
class FrequencyResponse:
    """A computed or estimated FRF (complex, SI units) with what it was computed from.

    Attributes
    ----------
    freq_hz
        Frequency grid (Hz).
    h
        Complex FRF on ``freq_hz`` (``unit``).
    quantity, unit
        ``accelerance`` (m/s^2/N), ``mobility`` (m/s/N) or ``receptance`` (m/N).
    excitation, response
        Labels of the force input and of the response point/axis.
    modal_freq_hz, damping_ratios, residues
        The model's natural frequencies, the damping ratios used and the modal constants
        ``(c phi_r)(phi_r' b)`` (1/kg) of each mode (empty for an estimate from time signals).
    coherence
        Ordinary coherence of an averaged estimate (empty for a model FRF).
    """

    freq_hz: np.ndarray
    h: np.ndarray
    quantity: str
    unit: str
    excitation: str
    response: str
    modal_freq_hz: np.ndarray = field(default_factory=lambda: np.zeros(0))
    damping_ratios: np.ndarray = field(default_factory=lambda: np.zeros(0))
    residues: np.ndarray = field(default_factory=lambda: np.zeros(0))
    coherence: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def magnitude(self) -> np.ndarray:
        return np.abs(self.h)

    def peaks(self, *, min_prominence_db: float = DEFAULT_MIN_PROMINENCE_DB, f_min_hz: float = 0.0) -> list[Peak]:
        return pick_peaks(self.freq_hz, self.magnitude, min_prominence_db=min_prominence_db, f_min_hz=f_min_hz)

    def first_peak_hz(self, *, min_prominence_db: float = DEFAULT_MIN_PROMINENCE_DB, f_min_hz: float = 0.0) -> float:
        """Frequency of the lowest peak (NaN when there is none)."""
        p = self.peaks(min_prominence_db=min_prominence_db, f_min_hz=f_min_hz)
        return p[0].freq_hz if p else math.nan

    def columns(self) -> dict[str, np.ndarray]:
        u = self.unit.replace("/", "_per_").replace("^", "")
        cols = {
            "freq_hz": self.freq_hz,
            f"re_{u}": self.h.real,
            f"im_{u}": self.h.imag,
            f"mag_{u}": np.abs(self.h),
            "mag_db": 20.0 * np.log10(np.maximum(np.abs(self.h), 1e-300)),
            "phase_deg": np.degrees(np.angle(self.h)),
        }
        if self.coherence.size:
            cols["coherence"] = self.coherence
        return cols

    def save_csv(self, path: str | Path) -> Path:
        p = Path(path)
        if p.suffix != ".csv":
            raise FrfError(f"FRF file {str(p)!r} must end in .csv")
        p.parent.mkdir(parents=True, exist_ok=True)
        cols = self.columns()
        header = (
            f"# {self.quantity} ({self.unit}), excitation {self.excitation}, response {self.response}\n"
            + ",".join(cols)
        )
        np.savetxt(p, np.column_stack(list(cols.values())), delimiter=",", header=header, comments="", fmt="%.10g")
        return p

    def to_dict(self, *, n_peaks: int = 10) -> dict[str, Any]:
        return {
            "quantity": self.quantity,
            "unit": self.unit,
            "excitation": self.excitation,
            "response": self.response,
            "f_min_hz": float(self.freq_hz[0]),
            "f_max_hz": float(self.freq_hz[-1]),
            "n_freq": len(self.freq_hz),
            "peaks": [
                {"freq_hz": p.freq_hz, "magnitude": p.magnitude, "prominence_db": p.prominence_db}
                for p in self.peaks()[:n_peaks]
            ],
            "modal_freq_hz": self.modal_freq_hz[:n_peaks].tolist(),
            "damping_ratios": self.damping_ratios[:n_peaks].tolist(),
            "residues_per_kg": self.residues[:n_peaks].tolist(),
        }

    def table(self, *, n_peaks: int = 10) -> str:
        """The modes in the band (frequency Hz, damping ratio, modal constant 1/kg) and the FRF's peaks."""
        f_top = float(self.freq_hz[-1])
        lines = [
            f"{self.quantity} ({self.unit}) from {self.excitation} to {self.response}, "
            f"{len(self.freq_hz)} frequencies {self.freq_hz[0]:g}..{f_top:g} Hz"
        ]
        if self.modal_freq_hz.size:
            lines.append(f"{'mode':>4}  {'freq (Hz)':>10}  {'damping':>8}  {'residue (1/kg)':>15}")
            for i, (f, z, r) in enumerate(zip(self.modal_freq_hz, self.damping_ratios, self.residues)):
                if f > f_top:
                    break
                lines.append(f"{i + 1:>4}  {f:>10.3f}  {z:>8.4f}  {r:>15.4e}")
        lines.append(f"{'peak':>4}  {'freq (Hz)':>10}  {'|H|':>10}  {'prominence (dB)':>15}")
        for i, p in enumerate(self.peaks()[:n_peaks], 1):
            lines.append(f"{i:>4}  {p.freq_hz:>10.3f}  {p.magnitude:>10.4g}  {p.prominence_db:>15.1f}")
        return "\n".join(lines)

    def plot(self, ax: Any = None, *, axes: Any = None, label: str | None = None, modal_lines: bool = True) -> Any:
        """Magnitude (dB) and phase against frequency; returns the ``Figure``.

        ``ax``: one axes (the magnitude alone) or two (magnitude, phase); ``axes``: two axes; default a new
        figure with both.
        """
        import matplotlib.pyplot as plt

        axes = ax if ax is not None else axes
        if axes is None:
            _, axes = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True, gridspec_kw={"height_ratios": [2, 1]})
        ax, axp = (axes, None) if not np.iterable(axes) else axes
        ax.plot(self.freq_hz, 20 * np.log10(np.maximum(self.magnitude, 1e-300)), lw=1.2, label=label)
        if axp is not None:
            axp.plot(self.freq_hz, np.degrees(np.angle(self.h)), lw=1.0)
            axp.set_ylabel("phase (deg)")
            axp.set_xlabel("frequency (Hz)")
        else:
            ax.set_xlabel("frequency (Hz)")
        if modal_lines:
            for f in self.modal_freq_hz:
                if self.freq_hz[0] <= f <= self.freq_hz[-1]:
                    ax.axvline(f, color="0.8", lw=0.7, zorder=0)
        ax.set_ylabel(f"|H| (dB re 1 {self.unit})")
        ax.set_title(f"{self.quantity}: {self.excitation} -> {self.response}", fontsize=10)
        if label:
            ax.legend(fontsize=8)
        return ax.figure


def _damping(system: ModalSystem, damping_ratio: float | Sequence[float] | None) -> np.ndarray:
    n = len(system.omega_rad_s)
    if damping_ratio is None:
        return np.diag(system.xi) / (2.0 * system.omega_rad_s)
    z = np.atleast_1d(np.asarray(damping_ratio, float))
    if z.size == 1:
        z = np.full(n, float(z[0]))
    elif z.size < n:
        # the modes not given keep the model's own damping
        z = np.concatenate([z, np.diag(system.xi)[z.size :] / (2.0 * system.omega_rad_s[z.size :])])
    if np.any(~np.isfinite(z)) or np.any(z < 0.0) or np.any(z >= 1.0):
        raise FrfError(f"damping ratios must lie in [0, 1), got {damping_ratio!r}")
    return z[:n]


def frf_grid(f_min_hz: float, f_max_hz: float, df_hz: float, modal_freq_hz: ArrayLike) -> np.ndarray:
    """Make a frequency grid (Hz) from ``f_min_hz`` to ``f_max_hz`` by ``df_hz``, plus the natural frequencies.

    The natural frequencies inside the band are added so that every resonance peak is sampled at its top.
    """
    need = "need 0 <= f_min_hz < f_max_hz and df_hz > 0"
    if not 0.0 <= f_min_hz < math.inf:
        raise FrfError(need, parameter="f_min_hz", value=f_min_hz)
    if not f_min_hz < f_max_hz < math.inf:
        raise FrfError(need, parameter="f_max_hz", value=f_max_hz)
    if not df_hz > 0:
        raise FrfError(need, parameter="df_hz", value=df_hz)
    if (f_max_hz - f_min_hz) / df_hz > 1e6:
        raise FrfError(
            "the band holds more than 1e6 frequencies", parameter="df_hz", value=df_hz, hint="use a larger one"
        )
    freq = np.arange(f_min_hz, f_max_hz + df_hz / 2, df_hz)
    fm = np.asarray(modal_freq_hz, float)
    return np.unique(np.concatenate([freq, fm[(fm >= freq[0]) & (fm <= freq[-1])]]))


def modal_frf(
    system: ModalSystem,
    *,
    excitation: LinkPoint,
    response: LinkPoint,
    freq_hz: np.ndarray,
    quantity: str = "accelerance",
    damping_ratio: float | Sequence[float] | None = None,
    n_modes: int | None = None,
) -> FrequencyResponse:
    """FRF of the linearised model from a force at ``excitation`` to ``response`` (module docstring).

    Parameters
    ----------
    system
        The modal system (:func:`fpm_sim.rom.reduction.modal_system`) of the model at its equilibrium.
    excitation, response
        Force input point/direction and response point/axis.
    freq_hz
        Frequency grid (Hz, >= 0).
    quantity
        ``accelerance`` (default), ``mobility`` or ``receptance``.
    damping_ratio
        ``None``: the model's modal damping; a number: that ratio for every mode; a sequence: one per
        mode from mode 1 (the modes beyond it keep the model's own).
    n_modes
        Sum over the lowest ``n_modes`` modes only (default all: exact for the linear model with modal
        damping).
    """
    if quantity not in QUANTITIES:
        raise FrfError(f"quantity must be one of {', '.join(QUANTITIES)}, got {quantity!r}")
    f = np.asarray(freq_hz, float)
    if f.ndim != 1 or f.size == 0 or np.any(f < 0) or np.any(~np.isfinite(f)):
        raise FrfError("freq_hz must be a non-empty 1-D array of frequencies >= 0 Hz")
    n_all = len(system.omega_rad_s)
    k = n_all if n_modes is None else int(n_modes)
    if not (1 <= k <= n_all):
        raise FrfError(f"n_modes must lie in [1, {n_all}], got {n_modes!r}")
    b = point_row(system.built, system.qpos, excitation)
    c = point_row(system.built, system.qpos, response)
    phi = system.phi[:, :k]
    w = system.omega_rad_s[:k]
    zeta = _damping(system, damping_ratio)[:k]
    residues = (c @ phi) * (phi.T @ b)
    om = 2.0 * np.pi * f
    den = w[None, :] ** 2 - om[:, None] ** 2 + 2j * zeta[None, :] * w[None, :] * om[:, None]
    h = (residues[None, :] / den).sum(axis=1)
    if quantity == "mobility":
        h = h * (1j * om)
    elif quantity == "accelerance":
        h = h * (-(om**2))
    return FrequencyResponse(
        freq_hz=f,
        h=h,
        quantity=quantity,
        unit=QUANTITIES[quantity],
        excitation=excitation.label(),
        response=response.label(),
        modal_freq_hz=w / (2.0 * np.pi),
        damping_ratios=zeta,
        residues=residues,
    )
