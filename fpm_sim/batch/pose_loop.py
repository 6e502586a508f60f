"""Fast first natural frequencies of the manipulator over many poses (the pose loop of reproduce/sweep).

The full analysis (:func:`fpm_sim.linear.analysis.manipulator_modes`: 12 segments per link, axial springs,
gravity equilibrium, ``mjd_transitionFD``) costs seconds per pose. Here each pose is solved by the
constrained eigenproblem at the assembled configuration with gravity off:

``M`` from ``mj_fullM`` at ``qpos0``, ``K = diag(joint spring stiffness)``, the weld Jacobian ``J``
from one ``mj_forward``; ``Z = null(J)``, ``Z'KZ x = w^2 Z'MZ x``.

This is exact for the linear model without prestress (straight, unstressed links at ``qpos0``); what
it leaves out is the geometric stiffness of gravity's prestress, a small effect for motor axes along
gravity (measured in ``docs/benchmarks.md`` and ``tests/test_fast_frequencies.py`` against the full
analysis). Coarser links (default :data:`FAST_SEGMENTS`) cost a discretisation error that scales as
``1/n^2`` and is also measured there.

:func:`first_frequencies` is the replaceable pose loop: ``backend="cpu"`` is this module; another
backend (e.g. MJX on an accelerator) registers itself with :func:`register_backend` and receives the
same arguments.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from multiprocessing import get_context

import mujoco
import numpy as np
import scipy.linalg

from fpm_sim.config import Manipulator
from fpm_sim.kinematics import (
    NEAR_SINGULAR_WARN,
    NearSingularityWarning,
    Pose,
    SingularPoseError,
    UnreachablePoseError,
    inverse_kinematics,
)
from fpm_sim.linear.modal import NULLSPACE_RCOND, equality_jacobian, mass_matrix
from fpm_sim.linear.threads import blas_threads
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import BuiltModel, ModelOptions, dof_stiffness, resolve_segments

__all__ = [
    "assemble_pose",
    "FAST_SEGMENTS",
    "PoseFrequencies",
    "fast_options",
    "IN_PLANE_KINDS",
]

FAST_SEGMENTS = resolve_segments()
"""Spring locations per link of the pose loop: the shared default (:data:`fpm_sim.model.options.DEFAULT_FIDELITY`),
so that a sweep and ``modes`` agree at a pose."""

IN_PLANE_KINDS = ("bend_in", "axial", "motor", "clamp")
"""Spring kinds whose strain energy counts as in-plane (the rest: bend_out, twist, tilt)."""

STATUS_OK = "ok"
STATUS_NEAR = "near_singular"
STATUS_SINGULAR = "singular"
STATUS_UNREACHABLE = "unreachable"


@dataclass
class PoseFrequencies:
    """Lowest natural frequencies at many poses.

    Attributes
    ----------
    poses
        The poses, in order.
    frequencies_hz
        ``(n_poses, n_modes)``; NaN where the pose is unreachable or singular.
    in_plane
        ``(n_poses, n_modes)`` fraction of each mode's strain energy in in-plane springs
        (:data:`IN_PLANE_KINDS`); NaN where not computed.
    singularity
        Singularity measure of each pose (0 singular .. 1; NaN if unreachable).
    status
        ``ok``, ``near_singular`` (computed, measure below ``NEAR_SINGULAR_WARN``), ``singular`` or
        ``unreachable`` (not computed).
    """

    poses: list[Pose]
    frequencies_hz: np.ndarray
    in_plane: np.ndarray
    singularity: np.ndarray
    status: list[str] = field(default_factory=list)

    @property
    def f1_hz(self) -> np.ndarray:
        return self.frequencies_hz[:, 0]


def fast_options(*, segments: int = FAST_SEGMENTS, axial: bool = False) -> ModelOptions:
    """Model options of the fast path: gravity off, ``segments`` per link, inextensible by default."""
    return ModelOptions(segments=segments, axial=axial, gravity=False)


def assemble_pose(config: Manipulator, pose: Pose, options: ModelOptions) -> tuple[BuiltModel | None, float, str]:
    """``(built model or None, singularity measure, status)`` of one pose, for any backend.

    Unreachable and singular poses get no model (status :data:`STATUS_UNREACHABLE` /
    :data:`STATUS_SINGULAR`); near-singular ones are built and marked :data:`STATUS_NEAR`.
    """
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NearSingularityWarning)
            asm = inverse_kinematics(config.geometry, pose)
    except UnreachablePoseError:
        return None, math.nan, STATUS_UNREACHABLE
    except SingularPoseError:
        asm = inverse_kinematics(config.geometry, pose, check_singularity=False)
        return None, asm.singularity.value, STATUS_SINGULAR
    built = build_manipulator(config, pose, options, assembly=asm)
    status = STATUS_NEAR if asm.singularity.value < NEAR_SINGULAR_WARN else STATUS_OK
    return built, asm.singularity.value, status


def _solve_pose(
    manip: Manipulator, pose: Pose, opts: ModelOptions, n_modes: int
) -> tuple[np.ndarray, np.ndarray, float, str]:
    nan = np.full(n_modes, np.nan)
    built, singularity, status = assemble_pose(manip, pose, opts)
    if built is None:
        return nan, nan, singularity, status
    model = built.model
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    mass = mass_matrix(model, data)
    k = dof_stiffness(model)
    jac = equality_jacobian(model, data)
    z = scipy.linalg.null_space(jac, rcond=NULLSPACE_RCOND)
    kr = z.T @ (k[:, None] * z)
    mr = z.T @ mass @ z
    n = min(n_modes, kr.shape[0])
    w2, x = scipy.linalg.eigh(0.5 * (kr + kr.T), 0.5 * (mr + mr.T), subset_by_index=[0, n - 1])
    freq = np.full(n_modes, np.nan)
    freq[:n] = np.sqrt(np.maximum(w2, 0.0)) / (2 * np.pi)
    inplane_mask = np.array([kind in IN_PLANE_KINDS for kind in built.dof_kinds])
    frac = np.full(n_modes, np.nan)
    for i in range(n):
        v = z @ x[:, i]
        e = k * v**2
        tot = float(e.sum())
        frac[i] = float(e[inplane_mask].sum()) / tot if tot > 0 else math.nan
    return freq, frac, singularity, status


def _solve_chunk(args: tuple[Manipulator, list[Pose], ModelOptions, int]) -> list[tuple]:
    manip, poses, opts, n_modes = args
    with blas_threads():  # one BLAS thread around the dense solves (fpm_sim.linear.threads)
        return [_solve_pose(manip, p, opts, n_modes) for p in poses]


def cpu_backend(
    config: Manipulator,
    poses: Sequence[Pose],
    *,
    n_modes: int,
    options: ModelOptions,
    workers: int,
    progress: bool,
    desc: str,
) -> PoseFrequencies:
    poses = list(poses)
    results: list[tuple] = []
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(poses), desc=desc, unit="pose")
    if workers <= 1 or len(poses) < 2 * workers:
        for p in poses:
            results.extend(_solve_chunk((config, [p], options, n_modes)))
            if bar is not None:
                bar.update(1)
    else:
        chunk = max(1, min(16, len(poses) // (4 * workers)))
        jobs = [(config, poses[i : i + chunk], options, n_modes) for i in range(0, len(poses), chunk)]
        with ProcessPoolExecutor(max_workers=workers, mp_context=get_context("fork")) as ex:
            for res in ex.map(_solve_chunk, jobs):
                results.extend(res)
                if bar is not None:
                    bar.update(len(res))
    if bar is not None:
        bar.close()
    return PoseFrequencies(
        poses=poses,
        frequencies_hz=np.array([r[0] for r in results]).reshape(len(poses), n_modes),
        in_plane=np.array([r[1] for r in results]).reshape(len(poses), n_modes),
        singularity=np.array([r[2] for r in results]),
        status=[r[3] for r in results],
    )
