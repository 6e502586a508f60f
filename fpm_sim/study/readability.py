"""How readable the first mode is in a hammer test, pose by pose: can the model explain the study's
seven unreadable poses?

The study read the first natural frequency from the peaks of impact-hammer FRFs (hammer along the axis
of an accelerometer on a second link, three impacts averaged) at 25 poses and could not read it at
seven (the cells left empty in its Table 5, ``fpm_sim/data/comsol_table5.csv``), blaming links badly
placed for a clean impact and more damping. The model can say how strongly the impact excites mode 1
and how strongly the accelerometer sees it at each pose.

Metrics of mode 1 at one pose (driving-point accelerance from the linear model, :mod:`fpm_sim.response`,
model damping unless given):

- ``excitation``: ``|phi_1' b|``, the modal force of a unit hammer force (1/sqrt(kg)); for the
  driving point it equals the accelerometer's observation ``|c phi_1|``;
- ``residue``: the modal constant ``(c phi_1)(phi_1' b)`` (1/kg); its peak accelerance is about
  ``residue / (2 zeta_1)``;
- ``modal_share``: ``|residue_1| / sum |residue_r|`` over the modes up to ``f_max_hz``;
- ``peak_height_db``: ``|H|`` at mode 1's peak relative to the highest ``|H|`` up to ``f_max_hz``;
- ``prominence_db``: the prominence of the FRF peak at mode 1 (0 if there is no peak there within
  2 % of ``f_1``; e.g. a mode with a node at the measurement point).

Predicted readable: ``prominence_db >= READABLE_PROMINENCE_DB`` and ``peak_height_db >=
READABLE_HEIGHT_DB`` (thresholds assumed a priori, see their docstrings; not fitted to the study).
Agreement with the study, threshold-free: the AUC of ``prominence_db`` as a score separating the 18
readable from the 7 unreadable poses (the probability that a readable pose scores higher than an
unreadable one; 0.5 = no explanation, 1 = perfect) and its one-sided permutation p-value (with 7 of
25 poses, random labellings exceed an AUC of 0.71 one time in 20). The study does not say which chain carried the
accelerometer, so the prominence is reported for the same point on all three distal links.

The 25 poses: the study's 5 x 5 grid (:func:`fpm_sim.study.poses.study_poses`; -100..100 mm,
step 50) with the platform turned by ``phi_sign * 0.2`` rad at the cells written ``(x, 0)`` (second
label zero), and a choice of whether the table's row label is x or y.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from tqdm import tqdm

from fpm_sim.config import Manipulator
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import ModelOptions, resolution_footer
from fpm_sim.model.passive import dof_stiffness
from fpm_sim.response import FrequencyResponse, FrfError, LinkPoint, modal_frf, pick_peaks
from fpm_sim.rom.reduction import ModalSystem, modal_system
from fpm_sim.sim.impact import STUDY_IMPACT_POINT
from fpm_sim.study.poses import ROTATION_RAD, TableReading, study_poses

__all__ = [
    "READABLE_HEIGHT_DB",
    "READABLE_PROMINENCE_DB",
    "Mode1Readability",
    "ReadabilityRow",
    "ReadabilityTable",
    "auc",
    "auc_p_value",
    "mode1_readability",
    "readability_table",
]

READABLE_PROMINENCE_DB = 6.0
"""A mode-1 peak is readable if it stands at least 6 dB (twice the amplitude) above the deeper of
its two neighbouring valleys. Assumed: with three averaged impacts and a clean driving point, a peak
that low is already hard to tell from leakage and noise ripple on a log plot."""
READABLE_HEIGHT_DB = -20.0
"""...and if it is no more than 20 dB (ten times) below the highest peak of the band. Assumed: a
hammer test's usable dynamic range around a dominant resonance on a single range setting."""
F1_MATCH = 0.02
"""A peak within 2 % of ``f_1`` is mode 1's (a 1 %-damped peak lies within 0.01 % of ``f_1``; the
nearest other modes of the manipulator are > 10 % away at the study poses)."""


@dataclass(frozen=True)
class Mode1Readability:
    """Mode-1 readability metrics at one pose and one measurement point (see module docstring)."""

    point: str
    f1_hz: float
    excitation: float
    residue: float
    modal_share: float
    peak_height_db: float
    prominence_db: float

    @property
    def readable(self) -> bool:
        return self.prominence_db >= READABLE_PROMINENCE_DB and self.peak_height_db >= READABLE_HEIGHT_DB


def _grid(system: ModalSystem, f_max_hz: float, df_hz: float) -> np.ndarray:
    f = np.arange(max(df_hz, 1.0), f_max_hz + df_hz / 2, df_hz)
    modal = system.frequencies_hz[system.frequencies_hz <= f_max_hz]
    return np.unique(np.concatenate([f, modal]))


def mode1_readability(
    system: ModalSystem,
    point: LinkPoint = STUDY_IMPACT_POINT,
    *,
    f_max_hz: float = 500.0,
    df_hz: float = 0.05,
    damping_ratio: float | None = None,
) -> tuple[Mode1Readability, FrequencyResponse]:
    """Mode-1 metrics for a driving-point test at ``point`` (hammer and accelerometer), with its FRF.

    Parameters
    ----------
    f_max_hz
        Top of the band (Hz) the FRF is read in.
    df_hz
        Frequency resolution (Hz); the modal frequencies are added to the grid.
    damping_ratio
        ``None``: the model's modal damping; else one ratio for all modes.
    """
    f1 = float(system.frequencies_hz[0])
    if f_max_hz <= f1:
        raise FrfError(f"f_max_hz ({f_max_hz:g} Hz) must exceed the first frequency {f1:.4g} Hz")
    frf = modal_frf(
        system,
        excitation=point,
        response=point,
        freq_hz=_grid(system, f_max_hz, df_hz),
        damping_ratio=damping_ratio,
    )
    mag = frf.magnitude
    in_band = system.frequencies_hz <= f_max_hz
    res = frf.residues
    share = float(abs(res[0]) / np.sum(np.abs(res[in_band]))) if np.any(res[in_band]) else 0.0
    peaks = pick_peaks(frf.freq_hz, mag, min_prominence_db=0.0)
    near = [p for p in peaks if abs(p.freq_hz / f1 - 1.0) <= F1_MATCH]
    best = max(near, key=lambda p: p.prominence_db) if near else None
    at_f1 = best.magnitude if best else float(mag[np.argmin(np.abs(frf.freq_hz - f1))])
    top = max(float(mag.max()), at_f1)  # the refined peak may top the samples
    b = frf.residues[0]
    exc = float(math.sqrt(abs(b)))  # driving point: (c phi)(phi' b) = (phi' b)^2
    metrics = Mode1Readability(
        point=point.label(),
        f1_hz=f1,
        excitation=exc,
        residue=float(res[0]),
        modal_share=share,
        peak_height_db=float(20 * math.log10(max(at_f1, 1e-300) / top)),
        prominence_db=float(best.prominence_db) if best else 0.0,
    )
    return metrics, frf


def auc_p_value(scores: np.ndarray, negative: np.ndarray, *, draws: int = 20000, seed: int = 0) -> float:
    """One-sided permutation p-value of the ROC area: the fraction of random relabellings (same number of
    negatives) whose AUC is at least the observed one (Monte Carlo, seeded; resolution ``1 / draws``)."""
    s = np.asarray(scores, float)
    neg = np.asarray(negative, bool)
    observed = auc(s[~neg], s[neg])
    if math.isnan(observed):
        return math.nan
    rng = np.random.default_rng(seed)
    k = int(neg.sum())
    hits = 0
    for _ in range(draws):
        perm = np.zeros(len(s), bool)
        perm[rng.choice(len(s), k, replace=False)] = True
        hits += auc(s[~perm], s[perm]) >= observed - 1e-12
    return hits / draws


def auc(scores_positive: np.ndarray, scores_negative: np.ndarray) -> float:
    """Probability that a positive scores above a negative (ties count half): the ROC area."""
    p = np.asarray(scores_positive, float)[:, None]
    n = np.asarray(scores_negative, float)[None, :]
    if p.size == 0 or n.size == 0:
        return math.nan
    return float(np.mean((p > n) + 0.5 * (p == n)))


@dataclass
class ReadabilityRow:
    """One pose of the table: the study cell, mode 1's frequency and character, metrics per chain.

    ``cell`` is any object with ``row_mm``, ``col_mm``, ``pose`` and ``comsol_hz`` (NaN: unreadable in the
    study): a :class:`~fpm_sim.study.poses.StudyPose`, or a pose of another study-pose generator with those fields.
    """

    cell: Any
    f1_hz: float
    f1_character: str
    metrics: list[Mode1Readability]

    @property
    def primary(self) -> Mode1Readability:
        return self.metrics[0]

    @property
    def study_unreadable(self) -> bool:
        """The study gives no frequency for this cell (NaN ``comsol_hz``)."""
        return not math.isfinite(self.cell.comsol_hz)


@dataclass
class ReadabilityTable:
    """Mode-1 readability over the study poses (see module docstring); ``metrics[0]`` per row is the
    configured point, the others the same point on the other distal links."""

    rows: list[ReadabilityRow]
    point: LinkPoint
    reading: str
    parameters: dict[str, Any] = field(default_factory=dict)

    @property
    def points(self) -> list[str]:
        return [m.point for m in self.rows[0].metrics] if self.rows else []

    def agreement(self, k: int = 0) -> dict[str, Any]:
        """Against the study for point ``k``: AUC of the prominence and the confusion counts."""
        ok = np.array([not r.study_unreadable for r in self.rows])
        prom = np.array([r.metrics[k].prominence_db for r in self.rows])
        pred = np.array([r.metrics[k].readable for r in self.rows])
        return {
            "point": self.points[k],
            "auc_prominence": auc(prom[ok], prom[~ok]),
            "auc_p_value": auc_p_value(prom, ~ok, draws=5000),
            "predicted_unreadable": int(np.sum(~pred)),
            "study_unreadable": int(np.sum(~ok)),
            "both_unreadable": int(np.sum(~pred & ~ok)),
            "both_readable": int(np.sum(pred & ok)),
            "agree": int(np.sum(pred == ok)),
            "n": len(self.rows),
        }

    def to_dict(self) -> dict[str, Any]:
        return {
            "reading": self.reading,
            "thresholds": {"prominence_db": READABLE_PROMINENCE_DB, "peak_height_db": READABLE_HEIGHT_DB},
            "agreement": [self.agreement(k) for k in range(len(self.points))],
            "rows": [
                {
                    "row_mm": r.cell.row_mm,
                    "col_mm": r.cell.col_mm,
                    "x_mm": r.cell.pose.x_m * 1e3,
                    "y_mm": r.cell.pose.y_m * 1e3,
                    "phi_rad": r.cell.pose.phi_rad,
                    "comsol_hz": r.cell.comsol_hz,
                    "study_unreadable": r.study_unreadable,
                    "f1_hz": r.f1_hz,
                    "f1_character": r.f1_character,
                    "metrics": [
                        {
                            "point": m.point,
                            "excitation": m.excitation,
                            "residue_per_kg": m.residue,
                            "modal_share": m.modal_share,
                            "peak_height_db": m.peak_height_db,
                            "prominence_db": m.prominence_db,
                            "readable": m.readable,
                        }
                        for m in r.metrics
                    ],
                }
                for r in self.rows
            ],
            "parameters": self.parameters,
        }

    def _lines(self, sep: str, markdown: bool) -> list[str]:
        chains = [p.split("@")[0] for p in self.points]
        head = ["cell (row, col) mm", "pose x, y mm; phi rad", "study", "model f1 Hz", "mode 1", "share %", "height dB"]
        head += [f"prom. dB {c}" for c in chains] + ["predicted", "agrees"]
        body = []
        for r in self.rows:
            m = r.primary
            study = "unreadable" if r.study_unreadable else f"{r.cell.comsol_hz:.2f} Hz"
            pred = "readable" if m.readable else "UNREADABLE"
            agrees = "yes" if m.readable != r.study_unreadable else "no"
            cells = [
                f"({r.cell.row_mm:g}, {r.cell.col_mm:g})",
                f"{r.cell.pose.x_m * 1e3:g}, {r.cell.pose.y_m * 1e3:g}; {r.cell.pose.phi_rad:g}",
                study,
                f"{r.f1_hz:.2f}",
                r.f1_character,
                f"{m.modal_share * 100:.1f}",
                f"{m.peak_height_db:.1f}",
            ]
            cells += [f"{x.prominence_db:.1f}" for x in r.metrics] + [pred, agrees]
            body.append(cells)
        if markdown:
            out = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
            return out + ["| " + " | ".join(c) + " |" for c in body]
        # plain text: every column as wide as its widest cell, text left, numbers right
        width = [max(len(c[k]) for c in [head, *body]) for k in range(len(head))]
        left = {0, 1, 2, 4, len(head) - 2, len(head) - 1}
        return [
            sep.join(c.ljust(w) if k in left else c.rjust(w) for k, (c, w) in enumerate(zip(cells, width))).rstrip()
            for cells in [head, *body]
        ]

    def summary_lines(self) -> list[str]:
        out = []
        for k in range(len(self.points)):
            a = self.agreement(k)
            out.append(
                f"{a['point']}: predicted unreadable {a['predicted_unreadable']}/{a['n']} "
                f"(study {a['study_unreadable']}), "
                f"both unreadable {a['both_unreadable']}, agreement {a['agree']}/{a['n']}, "
                f"AUC of prominence {a['auc_prominence']:.2f} (0.5 = no explanation, 1 = perfect; permutation "
                f"p = {a['auc_p_value']:.2f})"
            )
        return out

    def to_markdown(self) -> str:
        """A markdown table (one row per pose) and the agreement summary, for the reproduce report."""
        p = self.parameters
        intro = (
            f"Mode-1 readability in a driving-point hammer test at {self.point.label()} "
            f"(model: {p.get('options', {}).get('segments', '?')} segments, axial {p.get('options', {}).get('axial')}; "
            f"table reading {self.reading}; band up to {p.get('f_max_hz', '?')} Hz). Predicted readable: prominence "
            f">= {READABLE_PROMINENCE_DB:g} dB and peak height >= {READABLE_HEIGHT_DB:g} dB re the band's highest "
            "peak (assumed thresholds). 'prom. dB distal_i': the same point on each chain's distal link."
        )
        return "\n".join([intro, "", *self._lines(" | ", True), "", *("- " + s for s in self.summary_lines())])

    def plot(self, ax: Any = None, *, axes: Any = None) -> Any:
        """Mode-1 prominence (dB) at each pose for each point, study-unreadable poses circled; the ``Figure``.

        ``ax``: one axes for the first point (the hammer's); ``axes``: one per point; default a new figure.
        """
        import matplotlib.pyplot as plt

        n = len(self.points)
        if ax is not None:
            axes = [ax]
        elif axes is None:
            _, axes = plt.subplots(1, n, figsize=(4.2 * n, 3.8), squeeze=False, constrained_layout=True)
            axes = axes[0]
        x = np.array([r.cell.pose.x_m * 1e3 for r in self.rows])
        y = np.array([r.cell.pose.y_m * 1e3 for r in self.rows])
        bad = np.array([r.study_unreadable for r in self.rows])
        for k, ax in enumerate(np.atleast_1d(axes)):
            prom = np.array([r.metrics[k].prominence_db for r in self.rows])
            sc = ax.scatter(x, y, c=prom, s=160, cmap="viridis", vmin=0.0)
            ax.scatter(x[bad], y[bad], s=420, facecolors="none", edgecolors="r", linewidths=1.5)
            ax.set_title(f"{self.points[k]}\nmode-1 prominence (dB)", fontsize=9)
            ax.set_xlabel("x (mm)")
            ax.set_ylabel("y (mm)")
            ax.set_aspect("equal")
            ax.figure.colorbar(sc, ax=ax, shrink=0.8)
        fig = np.atleast_1d(axes)[0].figure
        fig.suptitle("mode-1 readability (red circles: unreadable in the study)", fontsize=10)
        return fig

    def table(self) -> str:
        """Plain-text version."""
        footer = resolution_footer(self.parameters)
        return "\n".join([*self._lines("  ", False), *self.summary_lines(), *([footer] if footer else [])])


def _dominant(system: ModalSystem) -> str:
    k = dof_stiffness(system.built.model)
    e = k * system.phi[:, 0] ** 2
    kinds = np.array(system.built.dof_kinds)
    shares = {kd: float(e[kinds == kd].sum()) for kd in set(kinds)}
    tot = sum(shares.values()) or 1.0
    kd = max(shares, key=shares.__getitem__)
    return f"{kd} {shares[kd] / tot:.0%}"


def readability_table(
    manip: Manipulator,
    *,
    options: ModelOptions | None = None,
    point: LinkPoint = STUDY_IMPACT_POINT,
    row_is: str = "x",
    phi_sign: int = 1,
    f_max_hz: float = 500.0,
    damping_ratio: float | None = None,
    poses: list[Any] | None = None,
    progress: bool = False,
    desc: str | None = None,
) -> ReadabilityTable:
    """Mode-1 readability at the study's 25 poses (or ``poses``) for a driving-point test at ``point``
    and at the same point on the other two distal links (see module docstring).

    Parameters
    ----------
    options
        Model options (default: 6 segments, inextensible links).
    row_is, phi_sign
        Reading of the study's table (:func:`fpm_sim.study.poses.study_poses`).
    f_max_hz
        FRF band (Hz).
    damping_ratio
        ``None``: the model's modal damping; else one ratio for every mode.
    poses
        Cells to evaluate instead of the study's 25: objects with ``row_mm``, ``col_mm``, ``pose`` and
        ``comsol_hz`` (NaN where the study could not read the first peak), e.g. :class:`~fpm_sim.study.poses.StudyPose`.
    progress
        Show a tqdm progress bar.
    desc
        Its label (default: what it computes, ``mode-1 readability, hammer along <axis>``).
    """
    opts = options or ModelOptions(segments=6, axial=False)
    cells = poses if poses is not None else study_poses(TableReading(row_is, phi_sign))
    others = [point]
    if point.link.startswith("distal_"):
        others += [replace(point, link=f"distal_{i}") for i in range(3) if f"distal_{i}" != point.link]
    rows = []
    label = desc or f"mode-1 readability, hammer along {point.axis}"
    it = tqdm(cells, desc=label, unit="pose", leave=False) if progress else cells
    for cell in it:
        built = build_manipulator(manip, cell.pose, opts)
        system = modal_system(built)
        metrics = [mode1_readability(system, p, f_max_hz=f_max_hz, damping_ratio=damping_ratio)[0] for p in others]
        rows.append(ReadabilityRow(cell, float(system.frequencies_hz[0]), _dominant(system), metrics))
    return ReadabilityTable(
        rows=rows,
        point=point,
        reading=f"row={row_is}, phi={'+' if phi_sign > 0 else '-'}{ROTATION_RAD:g}",
        parameters={
            "config": manip.name,
            "options": {
                "segments": opts.segments,
                "fidelity": opts.fidelity,
                "axial": opts.axial,
                "gravity": opts.gravity,
                "link_model": opts.link_model,
            },
            "f_max_hz": f_max_hz,
            "damping_ratio": damping_ratio,
            "grid_source": "fpm_sim.study.poses.study_poses",
        },
    )
