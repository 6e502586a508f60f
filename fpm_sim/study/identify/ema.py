"""Experimental modal analysis of measured FRFs: natural frequencies and damping for ``identify``.

FRFs come from Universal File Format type-58 files (:mod:`pyuff`; ``.uff`` / ``.unv``) or from the CSV
that ``fpm-sim frf`` / ``fpm-sim impact --csv`` write (``freq_hz`` and ``re_*``, ``im_*`` columns).
Poles are estimated with sdypy-EMA (:class:`sdypy.EMA.Model`): the least-squares complex-frequency
method (LSCF) at model orders up to ``pol_order``; the physical poles are the *stable* ones
(frequency within ``fn_tol`` and damping within ``xi_tol`` between consecutive orders, the
stabilisation chart's criterion, :meth:`sdypy.EMA.Model.select_closest_poles`) nearest the FRF's
peaks (:func:`fpm_sim.response.pick_peaks`), so no chart has to be clicked.

The pose of a test comes from the UFF record's ``id4`` (``fpm-sim pose x_mm=.. y_mm=.. phi_rad=..``,
written by ``fpm-sim impact --uff``) or is given by the caller.

**Exponential response window.** Impact tests multiply the response (and the force) by ``exp(-t / tau)`` so
that it dies out within the record. The window adds the decay rate ``1 / tau`` to every pole: a mode
``-sigma + i omega_d`` is read as ``-(sigma + 1/tau) + i omega_d``. Uncorrected, the damping ratio comes out
``(sigma + 1/tau) / |pole|`` (e.g. 3.6 % for a mode of 1.1 % under a 0.5 s record's window) and the natural
frequency ``|pole|`` slightly high. Given ``tau`` (``window_tau_s``; ``fpm-sim impact --uff`` writes it into
the record's ``id5``, ``fpm-sim exp-window tau_s=..``, which :func:`read_frfs` reads back), each pole's real part
is corrected by ``1 / tau`` before its frequency and damping are reported: the standard correction of
exponential-window damping, exact for a pole model of the windowed FRF.

**Discrete integrator.** A virtual impact test stepped by MuJoCo's ``discrete`` integrator at the step ``h``
reads every mode with the step's numerical damping (``~ pi f h``) and period error (``~ (2 pi f h)^2 / 3``);
``fpm-sim impact --uff`` writes ``h`` into ``id5`` (``discrete-step_s=..``), and after the window's decay the
step's effect is inverted exactly (:func:`fpm_sim.sim.stepping.remove_integrator_effect`).
"""

from __future__ import annotations

import csv
import io
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fpm_sim.errors import FpmSimError
from fpm_sim.response import pick_peaks
from fpm_sim.study.identify.data import read_csv_rows

__all__ = [
    "EmaError",
    "MeasuredFrf",
    "ModalEstimate",
    "estimate_modes",
    "read_frfs",
    "remove_window_decay",
    "write_modes_csv",
]


class EmaError(FpmSimError):
    """An FRF file cannot be read or analysed; the message names the file."""


@dataclass
class MeasuredFrf:
    """One FRF with where it was measured (``pose_mm_rad`` None when the file does not say)."""

    freq_hz: np.ndarray
    h: np.ndarray
    source: str
    pose_mm_rad: tuple[float, float, float] | None
    window_tau_s: float | None = None
    """Time constant (s) of the exponential response window the FRF was computed with; None: no window, or
    the file does not say."""
    discrete_step_s: float | None = None
    """Step (s) of the discrete integrator that computed the FRF (a virtual test); None: a measurement, the
    explicit reference, or the file does not say."""


@dataclass
class ModalEstimate:
    """Natural frequencies (Hz) and damping ratios estimated from one FRF."""

    source: str
    pose_mm_rad: tuple[float, float, float] | None
    freq_hz: np.ndarray
    damping: np.ndarray
    mode_label: str | None = None
    """``in_plane`` / ``out_of_plane`` when the test says which kind of mode it sees (e.g. an accelerometer
    along the motor axes sees only out-of-plane modes of a planar structure); written to the ``mode`` column."""
    window_tau_s: float | None = None
    """The exponential window's time constant (s) removed from the poles; None: no correction."""
    discrete_step_s: float | None = None
    """The discrete integrator's step (s) whose effect was removed from the poles; None: no correction."""

    def table(self) -> str:
        """Each estimated mode's frequency (Hz) and damping ratio, with where the FRF was measured."""
        lines = [f"{self.source} at {self.pose_mm_rad} (x mm, y mm, phi rad)"]
        lines.append(f"{'mode':>4}  {'freq (Hz)':>10}  {'damping':>8}")
        for i, (f, z) in enumerate(zip(self.freq_hz, self.damping), 1):
            lines.append(f"{i:>4}  {f:>10.3f}  {z:>8.4f}")
        return "\n".join(lines)

    def plot(self, ax: Any = None) -> Any:
        """Damping ratio (%) against natural frequency (Hz) of the estimated modes; returns the ``Figure``."""
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(figsize=(5.5, 3.5), constrained_layout=True)
        ax.stem(self.freq_hz, 100.0 * self.damping)
        ax.set_xlabel("natural frequency (Hz)")
        ax.set_ylabel("damping ratio (%)")
        ax.set_title(f"EMA of {Path(self.source).name}", fontsize=9)
        return ax.figure

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: source, pose (mm, mm, rad), frequencies (Hz), damping ratios, mode label, window."""
        return {
            "mode_label": self.mode_label,
            "window_tau_s": self.window_tau_s,
            "discrete_step_s": self.discrete_step_s,
            "source": self.source,
            "pose_mm_rad": self.pose_mm_rad,
            "freq_hz": self.freq_hz.tolist(),
            "damping": self.damping.tolist(),
        }


_POSE_RE = re.compile(r"x_mm=([-+0-9.eE]+)\s+y_mm=([-+0-9.eE]+)\s+phi_rad=([-+0-9.eE]+)")
_WINDOW_RE = re.compile(r"fpm-sim exp-window tau_s=([-+0-9.eE]+)")
_STEP_RE = re.compile(r"discrete-step_s=([-+0-9.eE]+)")


def _check_frequencies(freq_hz: np.ndarray, path: Path, lines: list[int] | None, record: int | None = None) -> None:
    """Refuse frequencies that are negative or not strictly increasing (a resorted or duplicated line would be
    fitted as a mode); ``lines`` are the rows' line numbers in a CSV."""
    where = f"record {record}, " if record is not None else ""
    if freq_hz.size and freq_hz[0] < 0:
        row = lines[0] if lines else None
        raise EmaError(
            f"{where}frequencies must be >= 0", parameter="freq_hz", value=float(freq_hz[0]), file=path, row=row
        )
    steps = np.diff(freq_hz)
    if np.any(steps <= 0):
        k = int(np.argmax(steps <= 0)) + 1
        row = lines[k] if lines else None
        raise EmaError(
            f"{where}frequencies must be strictly increasing ({freq_hz[k - 1]:g} Hz, then {freq_hz[k]:g} Hz)"
            + ("" if lines else f" at line {k + 1}"),
            parameter="freq_hz",
            file=path,
            row=row,
        )


def read_frfs(path: str | Path) -> list[MeasuredFrf]:
    """FRFs of a UFF 58 file (every type-58 record) or of an FRF CSV."""
    p = Path(path)
    if not p.is_file():
        raise EmaError(f"FRF file not found: {p}")
    if p.suffix.lower() == ".csv":
        rows = read_csv_rows(p, "files")
        re_col = next((c for c in rows[0][1] if c.startswith("re_")), None)
        im_col = next((c for c in rows[0][1] if c.startswith("im_")), None)
        if "freq_hz" not in rows[0][1] or re_col is None or im_col is None:
            raise EmaError("an FRF CSV needs freq_hz, re_<unit> and im_<unit> columns", file=p)
        values = np.empty((len(rows), 3))
        for k, (line, r) in enumerate(rows):
            for j, col in enumerate(("freq_hz", re_col, im_col)):
                try:
                    values[k, j] = float(r[col])
                except ValueError:
                    raise EmaError("not a number", parameter=col, value=r[col], file=p, row=line) from None
                if not math.isfinite(values[k, j]):
                    raise EmaError("must be finite", parameter=col, value=r[col], file=p, row=line)
        _check_frequencies(values[:, 0], p, [line for line, _ in rows])
        return [MeasuredFrf(values[:, 0], values[:, 1] + 1j * values[:, 2], p.name, None)]
    import pyuff

    hint = "give Universal Files of type-58 (function) records (.uff/.unv) or FRF CSVs"
    try:
        uff = pyuff.UFF(str(p))
        types = list(uff.get_set_types())
    except Exception as exc:  # pyuff raises bare Exceptions on malformed files
        raise EmaError(f"{p}: not a readable Universal File ({exc})", parameter="files", hint=hint) from None
    if not types:  # binary garbage, or any text without a '    -1' delimited data set
        raise EmaError(f"{p} is not a Universal File: no data set in it", parameter="files", hint=hint)
    out = []
    for i, t in enumerate(types):
        if int(t) != 58:
            continue
        try:
            d = uff.read_sets(i)
        except Exception as exc:  # pyuff's bare Exception on a damaged record
            raise EmaError(f"{p}: record {i} (type 58) cannot be read ({exc})", parameter="files", hint=hint) from None
        m = _POSE_RE.search(str(d.get("id4", "")))
        pose = (float(m.group(1)), float(m.group(2)), float(m.group(3))) if m else None
        w = _WINDOW_RE.search(str(d.get("id5", "")))
        tau = float(w.group(1)) if w else None
        st = _STEP_RE.search(str(d.get("id5", "")))
        step = float(st.group(1)) if st else None
        frf = MeasuredFrf(np.asarray(d["x"], float), np.asarray(d["data"], complex), f"{p.name}#{i}", pose, tau, step)
        bad = ~(np.isfinite(frf.freq_hz) & np.isfinite(frf.h))
        if bad.any():
            k = int(np.argmax(bad))
            raise EmaError(f"record {i}, line {k + 1}: the frequency or FRF value is not finite", file=p)
        _check_frequencies(frf.freq_hz, p, None, record=i)
        out.append(frf)
    if not out:
        kinds = ", ".join(sorted({str(int(t)) for t in types}))
        raise EmaError(f"{p}: no type-58 (function) record (its data sets are of type {kinds})", parameter="files")
    return out


def estimate_modes(
    frf: MeasuredFrf,
    *,
    f_lower_hz: float,
    f_upper_hz: float,
    n_modes: int = 3,
    pol_order: int = 40,
    fn_tol: float = 0.001,
    xi_tol: float = 0.05,
    min_prominence_db: float = 3.0,
    window_tau_s: float | None = None,
    discrete_step_s: float | None = None,
) -> ModalEstimate:
    """LSCF poles (sdypy-EMA) at the ``n_modes`` lowest FRF peaks in ``[f_lower_hz, f_upper_hz]``.

    ``window_tau_s`` (s): the exponential response window's time constant, removed from every pole
    (:func:`remove_window_decay`); None takes the FRF's own (``frf.window_tau_s``, read from the file); ``inf``:
    no window. ``discrete_step_s`` (s): the discrete integrator's step, whose effect is then inverted
    (:func:`fpm_sim.sim.stepping.remove_integrator_effect`); None takes the FRF's own; 0: none.
    """
    import contextlib

    from sdypy import EMA

    band = (frf.freq_hz >= f_lower_hz) & (frf.freq_hz <= f_upper_hz)
    if band.sum() < 10:
        raise EmaError(f"{frf.source}: fewer than 10 frequency lines in {f_lower_hz}..{f_upper_hz} Hz")
    peaks = pick_peaks(frf.freq_hz[band], np.abs(frf.h[band]), min_prominence_db=min_prominence_db)
    approx = sorted(pk.freq_hz for pk in peaks)[:n_modes]
    if not approx:
        raise EmaError(f"{frf.source}: no FRF peak in {f_lower_hz}..{f_upper_hz} Hz")
    model = EMA.Model(
        frf=frf.h[None, :],
        freq=frf.freq_hz,
        lower=f_lower_hz,
        upper=f_upper_hz,
        pol_order_high=pol_order,
        frf_form="accelerance",
    )
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        model.get_poles(method="lscf", show_progress=False)
        model.select_closest_poles(approx, f_window=max(2.0, 0.05 * min(approx)), fn_temp=fn_tol, xi_temp=xi_tol)
    fn, xi = _stable_column_medians(model.all_poles, np.asarray(model.nat_freq, float), fn_tol=fn_tol)
    tau = frf.window_tau_s if window_tau_s is None else window_tau_s
    tau = None if tau == np.inf else tau  # an infinite time constant: no window
    if tau is not None:
        fn, xi = remove_window_decay(fn, xi, window_tau_s=tau, source=frf.source)
    step = frf.discrete_step_s if discrete_step_s is None else (discrete_step_s or None)
    if step is not None:
        from fpm_sim.sim.stepping import SteppingError, remove_integrator_effect, reraise_as

        try:
            fn, xi = remove_integrator_effect(fn, xi, step_s=step, source=frf.source, parameter="discrete_step_s")
        except SteppingError as e:
            raise reraise_as(EmaError, e) from None
    order = np.argsort(fn)
    return ModalEstimate(frf.source, frf.pose_mm_rad, fn[order], xi[order], window_tau_s=tau, discrete_step_s=step)


def _stable_column_medians(
    poles_by_order: Sequence[np.ndarray], picked_fn_hz: np.ndarray, *, fn_tol: float
) -> tuple[np.ndarray, np.ndarray]:
    """Each picked pole's column of the stabilisation chart, read as one value: the median over model orders.

    sdypy-EMA reports the single stable pole nearest the column's centre, so *which order* supplies it is an
    argmin that round-off can flip; an ill-conditioned high order's pole is often off by 1 % in damping while
    its frequency is within ``fn_tol``. An analyst reads the column, not one of its points: here every physical
    pole (positive damping) of every order within ``fn_tol`` (relative) of the picked frequency, and its
    frequency (Hz) and damping ratio are the medians over them, which one spoiled order cannot move.
    """
    fn_all, xi_all = [], []
    for s in poles_by_order:
        s = np.ravel(np.asarray(s, complex))
        s = s[np.imag(s) > 0]  # one of each conjugate pair
        w = np.abs(s)
        fn_all.append(w / (2 * np.pi))
        xi_all.append(-np.real(s) / np.where(w > 0, w, 1.0))
    fn_cat, xi_cat = np.concatenate(fn_all), np.concatenate(xi_all)
    fn_out, xi_out = np.empty_like(picked_fn_hz), np.empty_like(picked_fn_hz)
    for k, f0 in enumerate(picked_fn_hz):
        column = (np.abs(fn_cat / f0 - 1.0) < fn_tol) & (xi_cat > 0)
        # the picked pole is a stable one within fn_tol of itself, so the column is never empty
        fn_out[k], xi_out[k] = np.median(fn_cat[column]), np.median(xi_cat[column])
    return fn_out, xi_out


def remove_window_decay(
    freq_hz: np.ndarray, damping: np.ndarray, *, window_tau_s: float, source: str = "FRF"
) -> tuple[np.ndarray, np.ndarray]:
    """Natural frequencies (Hz) and damping ratios with an exponential window's decay removed (module docstring).

    ``freq_hz`` and ``damping`` are what a pole fit of the windowed FRF reports (``|pole| / 2 pi`` and
    ``-Re(pole) / |pole|``); ``window_tau_s`` is the window ``exp(-t / tau)``'s time constant (s; ``inf`` = no
    window). Raises :class:`EmaError` when a pole decays slower than the window alone (a wrong ``tau``).
    """
    if not window_tau_s > 0.0:
        raise EmaError(f"{source}: the exponential window's time constant must be > 0 s, got {window_tau_s!r}")
    wn = 2.0 * np.pi * np.asarray(freq_hz, float)
    xi = np.asarray(damping, float)
    sigma = xi * wn - 1.0 / window_tau_s
    wd = wn * np.sqrt(np.clip(1.0 - xi**2, 0.0, None))
    if np.any(sigma < 0.0):
        k = int(np.argmin(sigma))
        raise EmaError(
            f"{source}: the pole at {freq_hz[k]:.4g} Hz decays at {xi[k] * wn[k]:.4g} 1/s, slower than the exponential "
            f"window's 1/tau = {1.0 / window_tau_s:.4g} 1/s alone: the window's time constant "
            f"({window_tau_s:.4g} s) is wrong",
            parameter="window_tau_s",
        )
    wn_true = np.hypot(sigma, wd)
    return wn_true / (2.0 * np.pi), sigma / wn_true


def write_modes_csv(estimates: Sequence[ModalEstimate], path: str | Path, *, header: str = "") -> Path:
    """The CSV ``fpm-sim identify --measured`` reads: ``x_mm,y_mm,phi_rad,f1_hz..,zeta1..,mode,source``."""
    p = Path(path)
    n = max(len(e.freq_hz) for e in estimates)
    cols = ["x_mm", "y_mm", "phi_rad"] + [f"f{k + 1}_hz" for k in range(n)] + [f"zeta{k + 1}" for k in range(n)]
    cols += ["mode", "source"]
    with open(p, "w", newline="") as fh:
        for ln in header.splitlines():
            fh.write(f"# {ln}\n")
        w = csv.writer(fh)
        w.writerow(cols)
        for e in estimates:
            if e.pose_mm_rad is None:
                raise EmaError(f"{e.source}: the pose of this FRF is unknown", parameter="pose_mm_rad", hint="give it")
            f = [f"{v:.6g}" for v in e.freq_hz] + [""] * (n - len(e.freq_hz))
            z = [f"{v:.5g}" for v in e.damping] + [""] * (n - len(e.damping))
            w.writerow([f"{v:.6g}" for v in e.pose_mm_rad] + f + z + [e.mode_label or "", e.source])
    return p
