"""A design study's parts for an imported model (:class:`fpm_sim.architecture.imported.ImportedDescription`): its
masses and its pose loop over designs x poses (:func:`fpm_sim.batch.joint_sweep.sweep_joints`, one compiled model per
design re-posed by joint values).

The designs are the imported description with dotted paths of its file set (``sections.bar.height_m``,
``materials.steel.young_pa``, ``flexible[0].end_m[0]``: :func:`fpm_sim.architecture.with_description_value`), as the
described architectures' are; :func:`fpm_sim.designs.design_study` dispatches here. The file's numbers are the beams'
sections, materials and ends, and its servo gains: none of them moves the model's joints, so a pose's joint values
are the same for every design. Task poses (where the model names an ``[end_effector]``) are solved to joint values
once, on the base description (:func:`fpm_sim.model.imported_pose.joint_poses_of`), and every design takes those.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from fpm_sim.architecture import TaskPose
from fpm_sim.architecture.imported import ImportedDescription
from fpm_sim.batch.joint_sweep import check_joint_poses, sweep_joints
from fpm_sim.model.options import ModelOptions

__all__ = ["imported_joint_poses", "imported_link_mass_kg", "imported_moving_mass_kg", "solve_imported"]


def imported_link_mass_kg(desc: ImportedDescription) -> float:
    """Mass of the flexible links' beams (kg): each beam's length (as the import places it,
    :func:`fpm_sim.model.imported.import_report`) x its section's area x its material's density. The model's rigid
    bodies are not links here (they are in :func:`imported_moving_mass_kg`)."""
    from fpm_sim.model.imported import import_report

    beams = import_report(desc).beam
    return sum(float(beams[f.body]["length_m"]) * f.section.area_m2 * f.material.density_kg_m3 for f in desc.flexible)


def imported_moving_mass_kg(desc: ImportedDescription) -> float:
    """Everything that moves (kg): the mass of every body of the flexible model that a joint separates from the world
    (the beams, their bodies' rigid lumps, the model's other moving bodies), the motors kept as joints (the pose
    loop's model, :class:`fpm_sim.batch.imported_pose_model.ImportedPoseModel`). A body welded to the world (a base,
    a motor's stator) does not move."""
    from fpm_sim.model.imported import build_imported

    model = build_imported(desc, None, ModelOptions(segments=1), keep_locked=True).model
    return float(sum(model.body_mass[b] for b in range(1, model.nbody) if model.body_weldid[b] != 0))


def imported_joint_poses(
    desc: ImportedDescription, poses: Sequence[TaskPose] | Sequence[Mapping[str, float]]
) -> list[dict[str, float]]:
    """``poses`` as joint values: task poses solved on ``desc`` (module docstring), joint poses checked."""
    if poses and all(isinstance(p, TaskPose) for p in poses):
        from fpm_sim.model.imported_pose import joint_poses_of

        return joint_poses_of(desc, poses)  # type: ignore[arg-type]
    return check_joint_poses(desc, poses)  # type: ignore[arg-type]


def solve_imported(
    descs: Sequence[ImportedDescription],
    joint_poses: Sequence[Mapping[str, float]],
    *,
    n_modes: int,
    options: ModelOptions,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(frequencies (design, pose, mode), in-plane share of mode 1 (NaN: not computed), singularity (NaN: an
    imported model states no singularity measure), status ("ok": a pose the loop cannot take is refused by its
    row))`` of every design at every joint pose, one design after the other in this process."""
    freq = np.stack([sweep_joints(d, joint_poses, options=options, n_modes=n_modes).freq_hz for d in descs])
    nan = np.full(freq.shape[:2], np.nan)
    return freq, nan, nan.copy(), np.full(freq.shape[:2], "ok", dtype=object)
