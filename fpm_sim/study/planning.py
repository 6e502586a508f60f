"""What to measure next, on a posterior: candidates and target from poses, the draws through the pose loop, and
the plan as a result (:func:`plan_tests`; the method is :mod:`fpm_sim.study.plan`'s).

Candidates are the pairs (pose, quantity) of the given poses and quantities (:data:`~fpm_sim.study.plan.QUANTITIES`:
``f1``, ``f1+f2``, ``f1..f3``, the modes an experimental modal analysis labels at the pose; or
``read:LINK@POS:AXIS``, the first clear peak of a hammer test at that accelerometer point, its mode unlabelled:
:func:`read_point`). The target is frequency ``mode`` at the target poses: its 90 % band (default), or, with a
level ``f_min_hz``, whether it is at least that level (a requirement). The draws' frequencies at every candidate
and target pose come from one call of the pose loop (:func:`fpm_sim.study.posterior.predict_bands`), at the
likelihood's resolution.

A described machine's posterior (:mod:`fpm_sim.study.calibrate.described`) plans in its own task coordinates: its
candidates are its task grid or poses of your own (:class:`~fpm_sim.architecture.TaskPose`), its default target f1
over the posterior median's task grid, and its requirement targets the requirements file's task pose sets; the
study's 25 cells are the 3RRR's and are refused for it.
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fpm_sim.architecture import Description, TaskPose
from fpm_sim.batch.engine import EngineOptions
from fpm_sim.batch.pose_loop import STATUS_NEAR, STATUS_OK, fast_options, pose_assembly, read_poses_csv
from fpm_sim.batch.task_sweep import read_task_poses_csv, task_grid, task_statuses
from fpm_sim.config import Manipulator
from fpm_sim.errors import FpmSimWarning
from fpm_sim.kinematics import SINGULAR_TOL, Pose, assemble_many
from fpm_sim.model.options import ModelOptions
from fpm_sim.outputs import write_csv_rows
from fpm_sim.response import AXES, LinkPoint
from fpm_sim.study.plan import (
    BAND_Z,
    QUANTITIES,
    Ensemble,
    PlanError,
    PlanStep,
    Score,
    describe_candidates,
    greedy_plan,
    jsonable_score,
)
from fpm_sim.study.posterior import AnyPose, Posterior, pose_columns, pose_text, predict_bands
from fpm_sim.study.readout import ModeRead, read_probabilities, sensor_residues
from fpm_sim.study.sweep import dense_grid

__all__ = [
    "DEFAULT_DRAWS",
    "Candidate",
    "PlanResult",
    "Target",
    "plan_tests",
    "pose_file_candidates",
    "reachable",
    "read_point",
    "workspace_target",
]

DEFAULT_DRAWS = 200
"""Posterior draws the plan uses by default: a single measurement at 2 % keeps a few hundred of 200 draws'
weight (effective sample size), enough for a band's 5 % and 95 % points; fewer collapse sooner."""


READ_PREFIX = "read:"
"""A read quantity's prefix: ``read:LINK@POS:AXIS`` (:func:`read_point`)."""

READ_MODES = ModeRead().modes
"""The modes a read's first clear peak can be (the readout model's default: the lowest three)."""

READ_LINKS = (*(f"{kind}_{i}" for kind in ("proximal", "distal") for i in range(3)), "platform")
"""The 3RRR's links a read's accelerometer can sit on (the readout model is the 3RRR's)."""


def read_point(quantity: str) -> LinkPoint | None:
    """The accelerometer point and axis of a read quantity ``read:LINK@POS:AXIS`` (``POS``: the fraction of the
    link's length from its start, 0..1; ``AXIS``: ``normal``, ``along``, ``z``, ``x`` or ``y``), e.g.
    ``read:distal_0@0.5:z``; ``None`` for a labelled quantity (a key of :data:`~fpm_sim.study.plan.QUANTITIES`).
    A bad read or an unknown quantity raises :class:`~fpm_sim.study.plan.PlanError` naming it."""
    if quantity in QUANTITIES:
        return None
    use = f"use {', '.join(QUANTITIES)} or read:LINK@POS:AXIS (e.g. read:distal_0@0.5:z)"
    if not quantity.startswith(READ_PREFIX):
        raise PlanError(f"unknown quantity {quantity!r}", parameter="quantities", hint=use)
    where, _, axis = quantity[len(READ_PREFIX) :].rpartition(":")
    link, at, pos = where.partition("@")
    if not (where and at and link and pos):
        raise PlanError(f"quantity {quantity!r} is not read:LINK@POS:AXIS", parameter="quantities", hint=use)
    try:
        fraction = float(pos)
    except ValueError:
        fraction = math.nan
    if not 0.0 <= fraction <= 1.0:
        raise PlanError(
            f"quantity {quantity!r}: the position {pos!r} is not a fraction of the link's length in [0, 1]",
            parameter="quantities",
        )
    if link not in READ_LINKS:
        raise PlanError(
            f"quantity {quantity!r}: unknown link {link!r} (the readout model is the 3RRR's)",
            parameter="quantities",
            hint=f"use one of {', '.join(READ_LINKS)}",
        )
    if axis not in AXES or (link == "platform" and axis in ("normal", "along")):
        ok = ("x", "y", "z") if link == "platform" else AXES
        raise PlanError(
            f"quantity {quantity!r}: unknown axis {axis!r}", parameter="quantities", hint=f"use {', '.join(ok)}"
        )
    return LinkPoint(link, fraction, axis)


def refuse_reads(posterior: Posterior, quantities: Sequence[str]) -> None:
    """Refuse read quantities on a described machine's posterior, naming them (the readout model,
    :func:`~fpm_sim.study.readout.sensor_residues`, is the 3RRR's)."""
    reads = [q for q in quantities if q.startswith(READ_PREFIX)]
    if reads and posterior.described:
        raise PlanError(
            f"{', '.join(map(repr, reads))}: the readout model (which mode a hammer test's first clear peak is) is "
            f"the 3RRR's; {posterior.base.name!r} is a described machine",
            parameter="quantities",
            hint=f"use {', '.join(QUANTITIES)}",
        )


@dataclass(frozen=True)
class Candidate:
    """One candidate measurement: a pose (the 3RRR's, or a described machine's task pose) and the modes read there."""

    pose: AnyPose
    quantity: str
    """A key of :data:`~fpm_sim.study.plan.QUANTITIES`, or a read ``read:LINK@POS:AXIS`` (:func:`read_point`)."""
    label: str = ""

    @property
    def modes(self) -> tuple[int, ...]:
        """The modes measured (labelled), or those a read's peak can be (the lowest :data:`READ_MODES`)."""
        return QUANTITIES.get(self.quantity) or tuple(range(1, READ_MODES + 1))

    @property
    def point(self) -> LinkPoint | None:
        """A read's accelerometer point and axis; ``None`` for a labelled quantity."""
        return read_point(self.quantity)

    def name(self, task: tuple[str, ...] | None = None) -> str:
        """``QUANTITY at POSE`` (``task``: a described machine's task coordinates)."""
        p = self.pose
        if self.label:
            at = self.label
        elif task is None and isinstance(p, Pose):
            at = f"({p.x_m * 1e3:g}, {p.y_m * 1e3:g}) mm, phi {p.phi_rad:g}"
        else:
            at = pose_text(p, task or ("x", "y", "z", "phi"))
        return f"{self.quantity} at {at}"


@dataclass(frozen=True)
class Target:
    """Where the predictions matter: frequency ``mode`` at ``poses``; its band, or (``f_min_hz`` given) whether it
    is at least that level."""

    poses: tuple[AnyPose, ...]
    mode: int = 1
    f_min_hz: float | None = None
    description: str = "target poses"

    @property
    def kind(self) -> str:
        return "band" if self.f_min_hz is None else "requirement"


def candidates_of(
    poses: Sequence[AnyPose], quantities: Sequence[str], labels: Sequence[str] | None = None
) -> list[Candidate]:
    """Every (pose, quantity) pair, refusing an unknown quantity or a bad read by name (:func:`read_point`)."""
    for q in quantities:
        read_point(q)
    if not quantities:
        raise PlanError("no quantity to measure", parameter="quantities", hint=f"use {', '.join(QUANTITIES)}")
    if labels is not None and len(labels) != len(poses):
        raise PlanError(f"{len(labels)} labels for {len(poses)} poses", parameter="labels")
    return [Candidate(p, q, labels[i] if labels else "") for i, p in enumerate(poses) for q in quantities]


def reachable(config: Manipulator | Description, poses: Sequence[AnyPose]) -> np.ndarray:
    """``(len(poses),)`` whether ``config``'s machine reaches each pose away from singularities (status ``ok`` or
    ``near_singular`` by the kinematics alone)."""
    if isinstance(config, Description):
        task = [p for p in poses if isinstance(p, TaskPose)]
        return np.array([s in (STATUS_OK, STATUS_NEAR) for s in task_statuses(config, task)], dtype=bool)
    return np.array([isinstance(p, Pose) and pose_assembly(config, p)[2] in (STATUS_OK, STATUS_NEAR) for p in poses])


def workspace_target(posterior: Posterior, *, step_mm: float = 50.0, phi_rad: float = 0.0, mode: int = 1) -> Target:
    """The default target: frequency ``mode`` over the posterior median description's reachable, non-singular
    workspace on a ``step_mm`` grid (a described machine: its task grid, z at its first check pose's, phi at
    ``phi_rad`` where it sets phi)."""
    cfg = posterior.median_config()
    if isinstance(cfg, Description):
        home = cfg.check_poses[0] if cfg.check_poses else {}
        z = home.get("z", 0.0)
        grid_t = task_grid(cfg, step_mm=step_mm, held={"z": z, "phi": phi_rad})[0]
        keep_t = reachable(cfg, grid_t)
        held = f", z {z * 1e3:g} mm" if "z" in cfg.task else ""
        held += f", phi {phi_rad:g} rad" if "phi" in cfg.task else ""
        what = f"f{mode} over the workspace ({step_mm:g} mm task grid{held})"
        return Target(tuple(p for p, k in zip(grid_t, keep_t) if k), mode, None, what)
    grid = dense_grid(cfg, step_mm=step_mm, phi_rad=phi_rad)
    many = assemble_many(cfg.geometry, [p.x_m for p in grid], [p.y_m for p in grid], [p.phi_rad for p in grid])
    keep = many.reachable & (many.singularity >= SINGULAR_TOL)
    poses = tuple(p for p, k in zip(grid, keep) if k)
    return Target(poses, mode, None, f"f{mode} over the workspace ({step_mm:g} mm grid, phi {phi_rad:g} rad)")


def _discrepancy(posterior: Posterior, index: np.ndarray, poses: Sequence[AnyPose]) -> tuple[np.ndarray, np.ndarray]:
    """``(shift, sd)``, each ``(len(index), len(poses))``, zero where the posterior has no discrepancy."""
    shift, sd = posterior.discrepancy_at(index, poses)
    shape = (len(index), len(poses))
    sh = np.zeros(shape) if shift is None else np.broadcast_to(np.asarray(shift, float), shape)
    if sd is None:
        d = np.zeros(shape)
    else:
        d_arr = np.asarray(sd, float)
        d = np.broadcast_to(d_arr[:, None] if d_arr.ndim == 1 else d_arr, shape)
    return np.array(sh), np.array(d)


def _sigma_rel(posterior: Posterior, sigma_rel: float | None) -> float:
    """The measurement's relative sd: given, or the posterior's data's median (the same rig)."""
    if sigma_rel is None:
        if posterior.data is None:
            raise PlanError(
                "the posterior holds no data to take the measurement's sd from",
                parameter="sigma_rel",
                hint="give the planned measurement's relative sd (e.g. 0.02 for 2 %)",
            )
        return float(np.median(posterior.data.sigma_hz / posterior.data.measured_hz))
    if not (math.isfinite(sigma_rel) and sigma_rel > 0):
        raise PlanError("must be > 0", parameter="sigma_rel", value=sigma_rel, hint="e.g. 0.02 for 2 %")
    return float(sigma_rel)


def plan_tests(
    posterior: Posterior,
    candidates: Sequence[Candidate],
    target: Target,
    *,
    k: int = 3,
    sigma_rel: float | None = None,
    n_draws: int | None = DEFAULT_DRAWS,
    outcomes: int = 64,
    seed: int = 0,
    ess_min: float = 20.0,
    screen: int = 40,
    options: ModelOptions | None = None,
    engine: EngineOptions | None = None,
) -> PlanResult:
    """Rank single measurements and choose ``k`` greedily by the target's expected spread after them.

    Parameters
    ----------
    posterior
        The calibration's posterior (:meth:`Posterior.from_netcdf`).
    candidates
        The candidate measurements (:func:`candidates_of`).
    target
        Where the predictions matter (:func:`workspace_target`, or poses of your own).
    k
        How many measurements to choose (1 .. the number of candidates).
    sigma_rel
        The planned measurement's sd relative to the frequency (default: the posterior's data's median).
    n_draws, seed
        Posterior draws used (``None``: all) and which (:meth:`Posterior.draws`); ``seed`` also seeds the outcomes.
    outcomes
        Simulated outcomes per set (the Monte Carlo size of each expectation).
    ess_min
        Effective sample size below which an outcome's re-weighting counts as collapsed (Bayes-linear update).
    screen
        With more candidates than this (band target), all are screened by the band's moments and this many best
        are scored and chosen from (:func:`~fpm_sim.study.plan.greedy_plan`).
    options, engine
        The pose loop's discretisation (default: the likelihood's resolution) and where it runs.
    """
    if not candidates:
        raise PlanError("no candidate measurements", parameter="candidates", hint="give at least one pose")
    if not target.poses:
        raise PlanError("the target has no poses", parameter="target", hint="give at least one pose to predict at")
    if not 1 <= k <= len(candidates):
        raise PlanError(f"must be 1..{len(candidates)} (the number of candidates)", parameter="k", value=k)
    if not 1 <= target.mode <= 3:
        raise PlanError("must be 1..3", parameter="target.mode", value=target.mode)
    refuse_reads(posterior, list(dict.fromkeys(c.quantity for c in candidates)))
    sig = _sigma_rel(posterior, sigma_rel)
    if posterior.length_scale_m is not None:
        warnings.warn(
            "the posterior's discrepancy is a Gaussian process: the plan conditions it on the calibration's data, "
            "not on the planned outcomes, so it understates what measuring near a target pose buys",
            FpmSimWarning,
            stacklevel=2,
        )
    t0 = time.perf_counter()
    ens, n_used = _ensemble(
        posterior, candidates, target, sig, n_draws=n_draws, seed=seed, options=options, engine=engine
    )
    g = greedy_plan(ens, k, outcomes=outcomes, seed=seed, mode=target.kind, ess_min=ess_min, screen=screen)
    floor = float(BAND_Z * np.median(ens.target_disc)) if target.kind == "band" else math.nan
    return PlanResult(
        list(candidates), target, g.before, g.singles, g.steps, sig, n_used, outcomes, ess_min,
        time.perf_counter() - t0, posterior.base.name, discrepancy_floor=floor, screening=g.screening,
        task=posterior.base.task if isinstance(posterior.base, Description) else None,
    )  # fmt: skip


def _ensemble(
    posterior: Posterior,
    candidates: Sequence[Candidate],
    target: Target,
    sigma_rel: float,
    *,
    n_draws: int | None,
    seed: int,
    options: ModelOptions | None,
    engine: EngineOptions | None,
) -> tuple[Ensemble, int]:
    """The draws' predictions at every candidate and target pose, in one call of the pose loop; and the number
    of draws used."""
    cand_poses = list(dict.fromkeys(c.pose for c in candidates))
    poses = cand_poses + list(target.poses)
    used = describe_candidates([c.modes for c in candidates])
    n_modes = max(used.shape[1], target.mode)
    bands = predict_bands(posterior, poses, n_draws=n_draws, seed=seed, n_modes=n_modes, options=options, engine=engine)
    f = bands.frequencies_hz  # (S, P, M)
    shift, disc = _discrepancy(posterior, bands.draw_index, poses)
    where = {p: i for i, p in enumerate(cand_poses)}
    ci = np.array([where[c.pose] for c in candidates])
    ti = np.arange(len(cand_poses), len(poses))
    ens = Ensemble(
        cand_hz=f[:, ci, : used.shape[1]],
        cand_used=used,
        cand_shift=shift[:, ci],
        cand_disc=disc[:, ci],
        sigma_rel=sigma_rel,
        target_hz=f[:, ti, target.mode - 1],
        target_shift=shift[:, ti],
        target_disc=disc[:, ti],
        f_min_hz=None if target.f_min_hz is None else np.full(len(ti), target.f_min_hz),
        cand_read_weight=_read_weights(posterior, candidates, bands.draw_index, used.shape[1], options),
    )
    return ens, len(bands.draw_index)


def _read_weights(
    posterior: Posterior, candidates: Sequence[Candidate], index: np.ndarray, n_slots: int, options: ModelOptions | None
) -> np.ndarray | None:
    """``(S, C, J)`` each read candidate's probability that its first clear peak is each mode under each draw
    (:func:`~fpm_sim.study.readout.read_probabilities` of one
    :func:`~fpm_sim.study.readout.sensor_residues` call per draw over the read candidates' poses and points; the
    posterior's readout settings where it has them); NaN for labelled candidates; ``None`` when none reads.
    The modes' frequencies are the pose loop's, as for the labelled candidates."""
    reads = [i for i, c in enumerate(candidates) if c.point is not None]
    if not reads:
        return None
    read = dataclasses.replace(posterior.mode_read or ModeRead(), modes=READ_MODES)
    poses = list(dict.fromkeys(p for i in reads if isinstance(p := candidates[i].pose, Pose)))
    points = list(dict.fromkeys(pt for i in reads if (pt := candidates[i].point) is not None))
    pi = [poses.index(candidates[i].pose) for i in reads]  # type: ignore[arg-type]  # 3RRR poses (refuse_reads)
    qi = [points.index(candidates[i].point) for i in reads]  # type: ignore[arg-type]  # reads have a point
    opts = options or (fast_options(segments=posterior.segments) if posterior.segments else fast_options())
    out = np.full((len(index), len(candidates), n_slots), np.nan)
    for row, i in enumerate(index):
        cfg = posterior.config(int(i))
        assert isinstance(cfg, Manipulator)  # refused for a described machine (refuse_reads)
        _, res = sensor_residues(cfg, poses, n_modes=max(read.reference_modes, READ_MODES), points=points, options=opts)
        probs = read_probabilities(res, read)  # (poses, points, modes)
        out[row, reads, :READ_MODES] = probs[pi, qi]
    return out


@dataclass
class PlanResult:
    """The plan (:func:`plan_tests`): the target's spread now, every single candidate's expected spread after
    it, and the greedy set with the spread after each step. Spreads are relative half-widths of the 90 % band
    (``band`` target) or mean pass/fail entropies in bits (``requirement`` target)."""

    candidates: list[Candidate]
    target: Target
    before: Score
    singles: list[Score]
    steps: list[PlanStep]
    sigma_rel: float
    n_draws: int
    outcomes: int
    ess_min: float
    elapsed_s: float
    name: str = ""
    discrepancy_floor: float = math.nan
    screening: np.ndarray | None = None
    """Every candidate's screening estimate (the band's moments) when the candidates were screened, else ``None``."""
    """The band target's half-width if the parameters were known exactly: the model discrepancy's alone
    (1.645 times its posterior median), which no measurement elsewhere narrows under an independent discrepancy."""
    task: tuple[str, ...] | None = None
    """A described machine's task coordinates (the poses' columns); ``None``: the 3RRR's x, y, phi."""

    def _fmt(self, v: float) -> str:
        return f"+-{100 * v:.1f} %" if self.target.kind == "band" else f"{v:.3f} bits"

    @property
    def after(self) -> float:
        """The target's expected spread after the whole set."""
        return self.steps[-1].score.spread

    @property
    def collapsed(self) -> int:
        """Outcomes whose re-weighting collapsed, over every set scored in the plan's steps and singles."""
        return sum(s.collapsed for s in self.singles) + sum(p.score.collapsed for p in self.steps[1:])

    def summary(self) -> str:
        """The one line a person reads first."""
        chosen = [self.candidates[p.candidate] for p in self.steps]
        order = list(QUANTITIES)
        qs = sorted({c.quantity for c in chosen}, key=lambda q: (order.index(q) if q in order else len(order), q))
        what = " / ".join(qs)
        n = len(chosen)
        where = f"at these {n} poses" if n > 1 else "at this pose"
        if self.target.kind == "band":
            return (
                f"measuring {what} {where} is expected to narrow the median 90 % band of f{self.target.mode} from "
                f"{self._fmt(self.before.spread)} to {self._fmt(self.after)}"
            )
        return (
            f"measuring {what} {where} is expected to lower the pass/fail uncertainty of f{self.target.mode} >= "
            f"{self.target.f_min_hz:g} Hz from {self._fmt(self.before.spread)} to {self._fmt(self.after)} (entropy)"
        )

    def _reads(self) -> bool:
        return any(c.quantity.startswith(READ_PREFIX) for c in self.candidates)

    def ranking(self) -> list[int]:
        """Candidates by their single measurement's expected spread, best first (NaN last)."""
        scr = self.screening[:-1] if self.screening is not None else np.full(len(self.singles), np.nan)
        key = [
            (math.isnan(s.spread), s.spread if not math.isnan(s.spread) else 0.0, np.nan_to_num(scr[i], nan=np.inf), i)
            for i, s in enumerate(self.singles)
        ]
        return [k[-1] for k in sorted(key)]

    def rows(self) -> list[dict[str, Any]]:
        """The plan's table: one row per chosen measurement, the spread after the set up to it and the gain."""
        out = []
        prev = self.before.spread
        for r, step in enumerate(self.steps, 1):
            c, s = self.candidates[step.candidate], step.score
            out.append(
                {
                    "rank": r,
                    **pose_columns(c.pose, self.task),
                    "label": c.label,
                    "quantity": c.quantity,
                    "spread_after": s.spread,
                    "gain": prev - s.spread,
                    "ess_median": s.ess_median,
                    "collapsed_outcomes": s.collapsed,
                }
            )
            prev = s.spread
        return out

    def table(self) -> str:
        unit = "90 % band half-width" if self.target.kind == "band" else "pass/fail entropy"
        lines = [
            self.summary(),
            f"  target: {self.target.description}; now {self._fmt(self.before.spread)} ({unit}, "
            f"{'median' if self.target.kind == 'band' else 'mean'} over {len(self.target.poses)} poses)",
            f"  {self.n_draws} draws, {self.outcomes} simulated outcomes per set, measurement sd "
            f"{100 * self.sigma_rel:.2f} %",
        ]
        if math.isfinite(self.discrepancy_floor):
            lines.append(
                f"  the model discrepancy at its posterior median alone gives {self._fmt(self.discrepancy_floor)}: "
                "new data narrow the rest, and the discrepancy only by pinning its size"
            )
        wq = max([8] + [len(self.candidates[p.candidate].quantity) for p in self.steps])
        lines.append(f"  {'rank':>4}  {'pose':<34} {'quantity':<{wq}} {'after':>12} {'gain':>10} {'ESS':>7}")
        for r, step in zip(self.rows(), self.steps):
            pose = r["label"] or pose_text(self.candidates[step.candidate].pose, self.task)
            lines.append(
                f"  {r['rank']:>4}  {pose:<34} {r['quantity']:<{wq}} {self._fmt(r['spread_after']):>12} "
                f"{self._fmt(r['gain']).replace('+-', ''):>10} {r['ess_median']:>7.0f}"
            )
        if self.collapsed:
            reads = " (a read's value by its mixture's mean and variance)" if self._reads() else ""
            lines.append(
                f"  note: {self.collapsed} simulated outcomes re-weighted to an effective sample size below "
                f"{self.ess_min:g}; their update is the Bayes-linear one{reads} (module fpm_sim.study.plan)"
            )
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        singles = []
        for i in self.ranking():
            c, s = self.candidates[i], self.singles[i]
            singles.append(
                {
                    **pose_columns(c.pose, self.task),
                    "label": c.label,
                    "quantity": c.quantity,
                    **jsonable_score(s),
                    "gain": self.before.spread - s.spread,
                    "screening_spread": None if self.screening is None else float(self.screening[i]),
                }
            )
        return {
            "summary": self.summary(),
            "task": list(self.task) if self.task is not None else None,
            "target": {
                "kind": self.target.kind,
                "mode": self.target.mode,
                "f_min_hz": self.target.f_min_hz,
                "description": self.target.description,
                "n_poses": len(self.target.poses),
            },
            "spread_now": self.before.spread,
            "spread_after": self.after,
            "discrepancy_floor": self.discrepancy_floor,
            "screening_now": None if self.screening is None else float(self.screening[-1]),
            "plan": self.rows(),
            "singles": singles,
            "sigma_rel": self.sigma_rel,
            "n_draws": self.n_draws,
            "outcomes": self.outcomes,
            "ess_min": self.ess_min,
            "collapsed_outcomes": self.collapsed,
            "elapsed_s": self.elapsed_s,
        }

    def plot(self, ax: Any = None) -> Any:
        """The expected gain of one measurement of the best quantity at each candidate pose over the workspace,
        the chosen poses numbered."""
        import matplotlib.pyplot as plt

        fig = ax.figure if ax is not None else plt.figure(figsize=(6.4, 5.2))
        ax = ax if ax is not None else fig.add_subplot()
        best: dict[AnyPose, float] = {}
        scr = self.screening
        for i, (c, s) in enumerate(zip(self.candidates, self.singles)):
            g = self.before.spread - s.spread if scr is None else scr[-1] - scr[i]
            if math.isfinite(g):
                best[c.pose] = max(best.get(c.pose, -math.inf), g)
        xs = np.array([p.x_m * 1e3 for p in best])
        ys = np.array([p.y_m * 1e3 for p in best])
        gain = np.array(list(best.values())) * (100.0 if self.target.kind == "band" else 1.0)
        dense = len(best) > 60  # a dense grid: squares that tile it, no edges
        size = max(6.0, 30000.0 / len(best)) if dense else 160.0
        sc = ax.scatter(
            xs, ys, c=gain, s=size, cmap="viridis", marker="s" if dense else "o", edgecolors="k",
            linewidths=0 if dense else 0.4,
        )  # fmt: skip
        unit = "points of the band's half-width, %" if self.target.kind == "band" else "bits of entropy"
        fig.colorbar(sc, ax=ax, label=f"expected gain ({unit})", shrink=0.85)
        tx = [p.x_m * 1e3 for p in self.target.poses]
        ty = [p.y_m * 1e3 for p in self.target.poses]
        ax.scatter(tx, ty, s=6, c="0.6", marker=".", label="target poses", zorder=0)
        for r, step in enumerate(self.steps, 1):
            c = self.candidates[step.candidate]
            ax.annotate(
                f"{r}",
                (c.pose.x_m * 1e3, c.pose.y_m * 1e3),
                color="red",
                fontsize=11,
                fontweight="bold",
                ha="center",
                va="center",
            )
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("y (mm)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(
            f"Where to measure next: the expected gain of one measurement\nat each candidate pose"
            f"{' (screened by the band' + chr(39) + 's moments)' if scr is not None else ''}; the chosen "
            f"{len(self.steps)} numbered in red",
            fontsize=10,
        )
        ax.legend(loc="lower right", fontsize=8)
        return fig

    def write(self, out_dir: str | Path) -> list[Path]:
        """``plan.csv`` (the chosen set), ``candidates.csv`` (every single candidate, best first) and
        ``gain_map.png`` into ``out_dir`` (which must exist)."""
        out = Path(out_dir)
        paths = [out / "plan.csv", out / "candidates.csv", out / "gain_map.png"]
        write_csv_rows(paths[0], self.rows())
        write_csv_rows(paths[1], self.to_dict()["singles"])
        fig = self.plot()
        fig.savefig(paths[2], dpi=130, bbox_inches="tight")
        import matplotlib.pyplot as plt

        plt.close(fig)
        return paths


def study_candidates(quantities: Sequence[str], posterior: Posterior | None = None) -> list[Candidate]:
    """The study's 25 cells (reading ``x+``, the shipped data's) as candidates, labelled ``row,col`` (mm); refused
    for a described machine's ``posterior`` (the cells are the 3RRR's)."""
    from fpm_sim.study.poses import study_poses

    if posterior is not None and isinstance(posterior.base, Description):
        raise PlanError(
            f"'study': the study's 25 cells are the 3RRR's; {posterior.base.name!r} has its own task coordinates "
            f"({', '.join(posterior.base.task)})",
            parameter="candidates",
            hint="use 'grid' (its task grid) or a CSV of poses in its task coordinates",
        )
    sp = study_poses()
    return candidates_of([p.pose for p in sp], quantities, [f"{p.row_mm:g},{p.col_mm:g}" for p in sp])


def grid_candidates(posterior: Posterior, quantities: Sequence[str], *, step_mm: float) -> list[Candidate]:
    """The posterior median description's reachable, non-singular workspace on a ``step_mm`` grid (phi 0; a
    described machine: its task grid, :func:`workspace_target`)."""
    refuse_reads(posterior, quantities)
    return candidates_of(list(workspace_target(posterior, step_mm=step_mm).poses), quantities)


def read_pose_file(
    posterior: Posterior, path: str | Path, *, parameter: str, lines: list[int] | None = None
) -> list[AnyPose]:
    """The poses of a CSV file in the posterior's machine's coordinates: ``x_mm,y_mm,phi_rad`` for the 3RRR, its
    task coordinates for a described one (:func:`~fpm_sim.batch.task_sweep.read_task_poses_csv`); ``lines``
    receives each pose's row in the file."""
    if isinstance(posterior.base, Description):
        return list(read_task_poses_csv(path, posterior.base, parameter=parameter, lines=lines))
    return list(read_poses_csv(path, parameter=parameter, lines=lines))


def pose_file_candidates(
    posterior: Posterior, path: str | Path, quantities: Sequence[str], *, parameter: str = "candidates"
) -> list[Candidate]:
    """The poses of a CSV file as candidates: ``x_mm,y_mm,phi_rad`` for the 3RRR, the machine's task coordinates
    for a described one (:func:`~fpm_sim.batch.task_sweep.read_task_poses_csv`). A pose the posterior median's
    machine does not reach away from singularities is refused, naming its row (no draw's measurement there could be
    simulated reliably)."""
    refuse_reads(posterior, quantities)
    cfg = posterior.median_config()
    lines: list[int] = []
    poses = read_pose_file(posterior, path, parameter=parameter, lines=lines)
    task = cfg.task if isinstance(cfg, Description) else None
    ok = reachable(cfg, poses)
    for i, pose in enumerate(poses):
        if not ok[i]:
            raise PlanError(
                f"pose {pose_text(pose, task)} is unreachable or singular for the posterior median's machine",
                parameter=parameter,
                file=str(path),
                row=lines[i],
                hint="remove the row or move the pose inside the reachable workspace (a sweep shows it)",
            )
    return candidates_of(poses, quantities)


def requirement_target(posterior: Posterior, path: str | Path, name: str | None = None) -> Target:
    """The target of a requirements file's ``min_frequency`` requirement (``name``, else the first): its poses
    (resolved on the posterior median description), mode and level."""
    from fpm_sim.study.requirements import load_requirements

    reqs = load_requirements(path)
    mins = [r for r in reqs.requirements if r.kind == "min_frequency"]
    if name is not None:
        mins = [r for r in mins if r.name == name]
    if not mins:
        what = f"no min_frequency requirement named {name!r}" if name else "no min_frequency requirement"
        raise PlanError(f"{path}: {what}", parameter="target", hint="name one of the file's min_frequency requirements")
    req = mins[0]
    if not 1 <= req.mode <= 3:
        raise PlanError(
            f"{path}: requirement {req.name!r} is on mode {req.mode}", parameter="target", hint="modes 1..3"
        )
    median = posterior.median_config()
    resolved = req.poses.resolve(median, f"requirement {req.name!r}")
    if any(isinstance(p, dict) for p in resolved):
        raise PlanError(f"{path}: requirement {req.name!r} poses the machine by joint values", parameter="target")
    poses: Sequence[AnyPose] = [p for p in resolved if not isinstance(p, dict)]
    if isinstance(median, Description):  # a grid's unreachable points are dropped (the 3RRR's resolve drops them)
        poses = [p for p, ok in zip(poses, reachable(median, poses)) if ok]
        if not poses:
            raise PlanError(
                f"{path}: requirement {req.name!r}: none of its poses is reachable by the posterior median's machine",
                parameter="target",
            )
    return Target(tuple(poses), req.mode, req.at_least_hz, req.describe())


def candidates_from(
    posterior: Posterior,
    candidates: str | Sequence[AnyPose] | None,
    quantities: Sequence[str],
    *,
    step_mm: float = 50.0,
) -> list[Candidate]:
    """The candidates the facade names: ``"study"`` (the study's 25 cells), ``"grid"`` (the workspace every
    ``step_mm``), poses, or ``None`` (``"study"`` for the 3RRR, ``"grid"`` for a described machine)."""
    which = candidates if candidates is not None else "grid" if posterior.described else "study"
    if which == "study":
        return study_candidates(quantities, posterior)
    if which == "grid":
        return grid_candidates(posterior, quantities, step_mm=step_mm)
    if isinstance(which, str):
        raise PlanError(f"unknown {which!r}", parameter="candidates", hint="'study', 'grid' or poses")
    return candidates_of(list(which), quantities)


def target_from(posterior: Posterior, target: Target | Sequence[AnyPose] | None) -> Target:
    """The target the facade names: a :class:`Target`, poses (f1's band there), or ``None`` (f1 over the
    workspace, :func:`workspace_target`)."""
    if target is None:
        return workspace_target(posterior)
    if isinstance(target, Target):
        return target
    return Target(tuple(target), 1, None, "f1 at the given poses")
