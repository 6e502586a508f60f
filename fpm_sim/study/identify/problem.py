"""What an identification fits (:class:`Problem`), how it is searched (:class:`IdentifyOptions`), and the
model's predictions of the data (mode matching, penalties for what the model cannot give).

Mode matching: an unlabelled ``fK`` is the model's K-th lowest mode at that pose; a labelled one
(``in_plane`` / ``out_of_plane``) is the K-th lowest of that kind, the kind decided by the mode's
strain-energy split (in-plane springs vs the rest), so sorted order is not assumed and a swap of an
in-plane and an out-of-plane mode near a crossing does not swap the match.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Sequence
from dataclasses import KW_ONLY, dataclass, field

import numpy as np

from fpm_sim.batch.frequencies import pose_frequencies
from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.config import Manipulator
from fpm_sim.errors import FpmSimError, FpmSimWarning
from fpm_sim.kinematics import NearSingularityWarning, Pose, assemble_many
from fpm_sim.model.options import ModelOptions
from fpm_sim.study.identify.data import MODE_LABELS, Observation
from fpm_sim.study.identify.parameters import GEOMETRY_GROUPS, ParameterSet
from fpm_sim.study.rigs import subsystem_frequencies
from fpm_sim.study.tables import SubsystemTest

__all__ = [
    "ELBOW_BRANCHES",
    "FAMILY_MODES",
    "GLOBAL_METHODS",
    "IN_PLANE_THRESHOLD",
    "JACOBIANS",
    "MODE_MARGIN",
    "PAIRINGS",
    "PENALTY_SIGMAS",
    "RICH_DATA_RATIO",
    "SURROGATE_BRANCHES",
    "IdentificationError",
    "IdentificationWarning",
    "IdentifyOptions",
    "Problem",
    "check_problem",
    "cyclic_branch_orbits",
    "family_frequencies",
    "modes_needed",
    "pair_modes",
    "predict_observations",
    "subsystem_predictions",
    "unique_poses",
    "with_branch",
    "workspace_measures",
    "workspace_residuals",
]

GLOBAL_METHODS = ("auto", "de", "hybrid", "multistart", "surrogate-de", "staged", "none")
RICH_DATA_RATIO = 3
"""``global_method="auto"`` runs ``"staged"`` where the data (observations and rig tests) number at least this many
times the free parameters (rich data: the continuation reaches the noise floor from the start's basin), else
``"de"``."""
JACOBIANS = ("fd", "exact")
IN_PLANE_THRESHOLD = 0.5
"""A mode is ``in_plane`` when more than this fraction of its strain energy is in in-plane springs."""
FAMILY_MODES = 6
"""Modes computed at a pose for :func:`family_frequencies`: enough that both kinds' lowest are nearly always among
them (the study's problem: the lowest in-plane mode was missing from 6 at 0 of 670 descriptions; measured)."""
PENALTY_SIGMAS = 30.0
"""Residual (in sigmas) of an observation the model cannot give (unreachable or singular pose, too few
modes of the asked kind): large, finite, so that the search moves away from it."""
MODE_MARGIN = 4
"""Modes computed beyond the highest one asked for, so that labelled matching finds its kind."""
ELBOW_BRANCHES: tuple[tuple[int, int, int], ...] = (
    (1, 1, 1),
    (-1, -1, -1),
    (1, 1, -1),
    (1, -1, 1),
    (-1, 1, 1),
    (-1, -1, 1),
    (-1, 1, -1),
    (1, -1, -1),
)
"""Every elbow-branch combination: the discrete variable of ``global_method="de"``."""


def cyclic_branch_orbits() -> dict[int, int]:
    """``{representative: orbit size}`` of the elbow-branch classes (indices into :data:`ELBOW_BRANCHES`) under the
    chains' cyclic relabelling: a machine of class ``k`` with the motors' and the platform's rotations ``(a, b)`` is
    the machine of class ``roll(k, -1)`` at ``(a + 120, b + 120)`` deg (the 3RRR's three chains alike, its joints
    120 deg apart; ``tests/study/test_calibrate_orbits.py`` checks it on the segment model). The orbits are
    ``(1, 1, 1)``, ``(-1, -1, -1)``, the three with one ``-1`` and the three with two; each is represented by its
    first member in :data:`ELBOW_BRANCHES`' order."""
    out: dict[int, int] = {}
    seen: set[int] = set()
    for k, b in enumerate(ELBOW_BRANCHES):
        if k in seen:
            continue
        orbit = {ELBOW_BRANCHES.index(tuple(int(x) for x in np.roll(b, r))) for r in range(3)}
        seen |= orbit
        out[k] = len(orbit)
    return out


SURROGATE_BRANCHES: tuple[tuple[int, int, int], ...] = (
    (1, 1, 1),
    (-1, -1, -1),
    (1, 1, -1),
    (1, -1, -1),
    (-1, -1, 1),
    (-1, 1, 1),
)
"""The elbow-branch classes ``global_method="surrogate-de"`` and ``"hybrid"`` explore (kept as published:
their results depend on it); ``"de"`` seeds its population from all of :data:`ELBOW_BRANCHES`."""


class IdentificationError(FpmSimError):
    """The identification cannot run as asked (no data, no free parameter, a start that cannot assemble)."""


class IdentificationWarning(FpmSimWarning):
    """An identification that runs but whose uncertainties the data cannot check (as many data as free
    parameters)."""


@dataclass(frozen=True)
class IdentifyOptions:
    """Search settings. ``segments``: spring locations per link of the model fitted."""

    segments: int = 4
    global_method: str = "auto"
    """The global exploration (:data:`GLOBAL_METHODS`, :mod:`fpm_sim.study.identify.engine`): ``"auto"`` (the
    default) is ``"staged"`` for rich data (:data:`RICH_DATA_RATIO`), else ``"de"``; the result's options name the
    one that ran."""
    n_starts: int = 24
    n_refine: int = 4
    generations: int = 200
    """``de``: generations of the differential evolution (each ``popsize`` x dimensions evaluations)."""
    popsize: int = 8
    """``de``: population size per dimension (scipy's ``popsize``)."""
    surrogate_seeds: int = 2
    """``de`` with the geometry free: members of the initial population per elbow-branch combination whose
    geometry is that branch's in-plane surrogate optimum (:func:`fpm_sim.study.identify.strategies.surrogate.
    surrogate_starts`; their other parameters from the Sobol sequence like the rest). ``0``: a Sobol population
    only."""
    de_strategy: str = "best1bin"
    """``de``: scipy's mutation strategy (``"best1bin"``: around the best member, greedy; ``"rand1bin"``: around
    a random member, keeps more basins alive)."""
    refine_per_class: int = 1
    """``de``: final-population members of each elbow-branch class that are candidates for the local
    refinement (its best ones). The candidates are taken class leaders first (every class's best, then every
    class's second best, ...), ``n_refine`` of them."""
    seed: int = 0
    max_nfev: int = 40
    workers: int = 1
    subsystem_segments: int = 8
    timoshenko: bool = False
    """Links as Timoshenko beams (shear springs and section rotary inertia, :class:`ModelOptions`)."""
    pairing: str = "order"
    """How measured modes are paired with the model's at a pose (:func:`pair_modes`): ``"order"`` (the default,
    the study's numbers) or ``"frequency"`` (the assignment problem, surviving crossings)."""
    jacobian: str = "fd"
    """The local refinement's Jacobian: ``"fd"`` (forward finite differences of the whole frequency computation,
    step ``1e-3`` of the bounds' width; what the study's shipped numbers were made with) or ``"exact"`` (the
    eigen-solve's sensitivities, :mod:`fpm_sim.study.identify.sensitivity`, for the observations and the
    manipulator's parameters; finite differences for the rig tests and the workspace prior)."""
    _: KW_ONLY
    staged_starts: int = 4
    """``staged``: starts of the continuation, the start description and ``staged_starts - 1`` samples of the
    prior (:mod:`fpm_sim.study.identify.strategies.staged`); each start's end is a candidate."""
    staged_max_nfev: int = 100
    """``staged``: residual evaluations of each stage's least squares at most (each with an exact Jacobian where the
    model allows it: cheap; the per-chain stage of 23 parameters takes 25-60)."""
    staged_spread: float = 0.3
    """``staged``: the prior samples' spread of each geometry parameter about its start, as a fraction of its
    bounds' width (uniform within +-half of it); the other parameters are drawn over their whole bounds."""

    def model_options(self) -> ModelOptions:
        if self.timoshenko:
            return ModelOptions(segments=self.segments, axial=False, gravity=False, shear=True, rotary_inertia=True)
        return fast_options(segments=self.segments)


@dataclass
class Problem:
    """What is fitted: the free parameters, the observations, the rig tests (plain data: picklable)."""

    parameters: ParameterSet
    observations: list[Observation]
    subsystem_tests: list[SubsystemTest] = field(default_factory=list)
    subsystem_sigma_pct: float = 1.0
    workspace: list[Pose] = field(default_factory=list)
    """Poses the machine is known to work at (it was placed there with its motors locked): a description
    under which one is unreachable or has a singularity measure below ``min_singularity`` is penalised
    (:func:`workspace_residuals`). Prior knowledge, not data: no frequency is read there."""
    min_singularity: float = 0.05
    """Smallest singularity measure (:mod:`fpm_sim.kinematics`) accepted at a ``workspace`` pose."""

    @property
    def measured(self) -> np.ndarray:
        return np.array([o.freq_hz for o in self.observations] + [t.experimental_hz for t in self.subsystem_tests])

    @property
    def sigma(self) -> np.ndarray:
        return np.array(
            [o.sigma_hz for o in self.observations]
            + [t.experimental_hz * self.subsystem_sigma_pct / 100.0 for t in self.subsystem_tests]
        )

    @property
    def labels(self) -> list[str]:
        return [o.describe() for o in self.observations] + [f"rig {t.label}" for t in self.subsystem_tests]

    @property
    def geometry_free(self) -> bool:
        """Whether a free parameter moves the joint layout (the elbow-branch choice then matters)."""
        return any(p.group in GEOMETRY_GROUPS for p in self.parameters.parameters)


def with_branch(problem: Problem, branch: tuple[int, int, int]) -> Problem:
    """``problem`` with its start description on the elbow-branch combination ``branch``."""
    ps = problem.parameters
    start = ps.start.replace(geometry=dataclasses.replace(ps.start.geometry, elbow_branch=branch))
    return dataclasses.replace(problem, parameters=ParameterSet(start, ps.parameters))


def check_problem(problem: Problem) -> None:
    """Refuse a problem that cannot be fitted: fewer data than free parameters (the fit would report an optimum
    and uncertainties that the data do not determine), or a measured pose the start description cannot reach
    (its residual would be NaN). Raises :class:`IdentificationError` naming the file and row. Warns
    (:class:`IdentificationWarning`) where there are exactly as many data as free parameters: the fit can pass
    through every value, so its standard deviations rest on the stated sigmas alone, unchecked by any residual."""
    n_free, n_data = len(problem.parameters.parameters), len(problem.observations) + len(problem.subsystem_tests)
    names = ", ".join(problem.parameters.names)
    if n_data < n_free:
        raise IdentificationError(
            f"{n_data} measured value(s) for {n_free} free parameters ({names})",
            parameter="measured",
            hint="measure more poses or modes, or free fewer parameters",
        )
    if n_data == n_free:
        warnings.warn(
            IdentificationWarning(
                f"{n_data} measured value(s) for {n_free} free parameters ({names}): no residual degree of freedom, "
                "so the fit can match every value and its standard deviations rest on the stated sigmas alone, "
                "unchecked; measure more poses or modes, or free fewer parameters",
                parameter="measured",
            ),
            stacklevel=3,
        )
    obs = problem.observations
    if not obs:
        return
    asm = assemble_many(
        problem.parameters.start.geometry,
        [o.pose.x_m for o in obs],
        [o.pose.y_m for o in obs],
        [o.pose.phi_rad for o in obs],
    )
    bad = [o for o, ok in zip(obs, asm.reachable) if not ok]
    if bad:
        o = bad[0]
        where = f"row {o.line}" if o.line is not None else o.describe()
        raise IdentificationError(
            f"{o.source}: {where}: the pose (x = {o.pose.x_m * 1e3:g} mm, y = {o.pose.y_m * 1e3:g} mm, phi = "
            f"{o.pose.phi_rad:g} rad) is unreachable for the start description"
            + (f" ({len(bad)} such rows)" if len(bad) > 1 else ""),
            parameter="measured",
            hint="check the pose columns (x_mm, y_mm in mm, phi_rad in rad) or the start description",
        )


def workspace_measures(problem: Problem, config: Manipulator) -> np.ndarray:
    """The singularity measure of each ``problem.workspace`` pose under ``config`` (NaN where unreachable)."""
    ws = problem.workspace
    return assemble_many(config.geometry, [p.x_m for p in ws], [p.y_m for p in ws], [p.phi_rad for p in ws]).singularity


def workspace_residuals(problem: Problem, config: Manipulator) -> np.ndarray:
    """One residual per ``problem.workspace`` pose: ``PENALTY_SIGMAS * (1 - m / m_min)`` where its singularity
    measure ``m`` is below ``m_min = problem.min_singularity`` (a hinge: 0 at and above it), ``PENALTY_SIGMAS``
    where it is unreachable."""
    if not problem.workspace:
        return np.zeros(0)
    m = workspace_measures(problem, config)
    r = PENALTY_SIGMAS * np.clip(1.0 - m / problem.min_singularity, 0.0, 1.0)
    return np.where(np.isfinite(r), r, PENALTY_SIGMAS)


def unique_poses(obs: Sequence[Observation]) -> tuple[list[Pose], list[int]]:
    """The distinct poses of ``obs`` (to 1e-9) and, per observation, the index of its pose."""
    keys: dict[tuple[float, float, float], int] = {}
    poses: list[Pose] = []
    index = []
    for o in obs:
        k = (round(o.pose.x_m, 9), round(o.pose.y_m, 9), round(o.pose.phi_rad, 9))
        if k not in keys:
            keys[k] = len(poses)
            poses.append(o.pose)
        index.append(keys[k])
    return poses, index


PAIRINGS = ("order", "frequency")
"""How measured modes are paired with the model's (:func:`pair_modes`)."""


def pair_modes(
    observations: Sequence[Observation],
    index: Sequence[int],
    freqs: Sequence[np.ndarray | None],
    fracs: Sequence[np.ndarray | None],
    pairing: str = "order",
) -> list[int | None]:
    """Which of its pose's sorted model modes each observation is (``None``: none of its kind).

    ``"order"`` (the default; the study's numbers): ``fK`` is the K-th lowest (of its kind, when labelled).
    ``"frequency"``: the observations of one pose, kind and file are paired with that pose's modes of the kind by
    the assignment problem (:func:`scipy.optimize.linear_sum_assignment`) on ``((f_model - f_measured) / sigma)^2``,
    so that a model mode the file did not measure (one that crossed into the band) does not shift the pairing of
    the others; a group of one observation, one with fewer candidates than observations, or one without finite
    measured values and positive sigmas (observations to predict), is paired by order.
    """
    groups: dict[tuple[int, str | None, str], list[int]] = {}
    for j, (o, ip) in enumerate(zip(observations, index)):
        groups.setdefault((ip, o.label, o.source), []).append(j)
    out: list[int | None] = [None] * len(observations)
    for (ip, label, _), members in groups.items():
        f, frac = freqs[ip], fracs[ip]
        if f is None:
            continue
        want = np.isfinite(f)
        if label is not None and frac is not None:
            want &= frac > IN_PLANE_THRESHOLD if label == "in_plane" else frac <= IN_PLANE_THRESHOLD
        cand = np.flatnonzero(want)
        meas = np.array([[observations[j].freq_hz, observations[j].sigma_hz] for j in members])
        measured = bool(np.all(np.isfinite(meas)) and np.all(meas[:, 1] > 0))  # a prediction's placeholder: not
        if pairing == "frequency" and measured and 1 < len(members) <= len(cand):
            from scipy.optimize import linear_sum_assignment

            cost = ((f[cand][None, :] - meas[:, :1]) / meas[:, 1:]) ** 2
            rows, cols = linear_sum_assignment(cost)
            for r, c in zip(rows, cols):
                out[members[r]] = int(cand[c])
            continue
        for j in members:
            k = observations[j].mode - 1
            if label is None:
                out[j] = k if k < len(f) and np.isfinite(f[k]) else None
            elif k < len(cand):
                out[j] = int(cand[k])
    return out


def modes_needed(observations: Sequence[Observation], pairing: str = "order") -> int:
    """Model modes to compute at each pose: the highest asked for, and :data:`MODE_MARGIN` more where labelled
    matching or pairing by frequency needs candidates beyond it."""
    labelled = any(o.label for o in observations)
    return max(o.mode for o in observations) + (MODE_MARGIN if labelled or pairing == "frequency" else 0)


def predict_observations(
    config: Manipulator,
    observations: Sequence[Observation],
    *,
    options: ModelOptions | None = None,
    workers: int = 1,
    pairing: str = "order",
) -> np.ndarray:
    """The model's frequency (Hz) for each observation (mode matching as in the module docstring, pairing as
    :func:`pair_modes`); NaN where the model cannot give it."""
    if not observations:
        return np.zeros(0)
    poses, index = unique_poses(observations)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NearSingularityWarning)
        pf = pose_frequencies(
            config, poses, n_modes=modes_needed(observations, pairing), options=options or fast_options(),
            workers=workers,
        )  # fmt: skip
    which = pair_modes(observations, index, list(pf.frequencies_hz), list(pf.in_plane), pairing)
    out = np.full(len(observations), np.nan)
    for j, (ip, k) in enumerate(zip(index, which)):
        if k is not None:
            out[j] = pf.frequencies_hz[ip][k]
    return out


def family_frequencies(
    config: Manipulator, observations: Sequence[Observation], *, options: ModelOptions | None = None
) -> np.ndarray:
    """``(2, n_obs)`` the lowest in-plane and the lowest out-of-plane frequency (Hz) at each observation's pose
    (:data:`IN_PLANE_THRESHOLD`), among the :data:`FAMILY_MODES` lowest modes; NaN where that kind is not among
    them or the pose cannot be computed. At zero gravity the two kinds are decoupled, so the lower of the two is the
    first mode that :func:`predict_observations` gives an unlabelled ``f1``."""
    out = np.full((2, len(observations)), np.nan)
    if not observations:
        return out
    poses, index = unique_poses(observations)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NearSingularityWarning)
        pf = pose_frequencies(config, poses, n_modes=FAMILY_MODES, options=options or fast_options())
    # each observation's f1 read as each kind's (labelled matching), paired as predict_observations pairs
    kinds = [dataclasses.replace(o, mode=1, label=label) for label in MODE_LABELS for o in observations]
    which = pair_modes(kinds, list(index) * len(MODE_LABELS), list(pf.frequencies_hz), list(pf.in_plane))
    for i, k in enumerate(which):
        if k is not None:
            out[divmod(i, len(observations))] = pf.frequencies_hz[index[i % len(observations)]][k]
    return out


def subsystem_predictions(config: Manipulator, tests: Sequence[SubsystemTest], segments: int) -> np.ndarray:
    """The model's first frequency (Hz) of each rig test (:func:`fpm_sim.study.rigs.subsystem_frequencies`)."""
    if not tests:
        return np.zeros(0)
    return np.array([r.ours_hz for r in subsystem_frequencies(config, segments=segments, tests=list(tests))])
