"""A design study's parts for a described architecture (:class:`fpm_sim.architecture.Description`): its masses and
its pose loop over designs x task poses (:func:`fpm_sim.batch.task_sweep.sweep_task_many`).

The designs themselves are the description with dotted paths of its file set
(:func:`fpm_sim.architecture.with_description_value`); :func:`fpm_sim.designs.design_study` dispatches here.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fpm_sim.architecture import Description, JointDesc, LinkDesc, TaskPose
from fpm_sim.batch.task_sweep import sweep_task_many
from fpm_sim.model.options import ModelOptions

__all__ = ["description_link_mass_kg", "description_moving_mass_kg", "solve_descriptions"]


def description_link_mass_kg(desc: Description) -> float:
    """Mass of every link (kg): length x section area x density, rigid links included."""
    return sum(
        e.length_m * e.section.area_m2 * e.material.density_kg_m3
        for c in desc.chains
        for e in c.path
        if isinstance(e, LinkDesc)
    )


def description_moving_mass_kg(desc: Description) -> float:
    """Everything that moves (kg): the links, their end lumps, the joints' lumps but those on the ground (a chain's
    first joint's ``lump`` when the chain starts on the ground: a motor flange turning in place), the end effector's
    lumps. For the 3RRR written as a description this is the 3RRR's own :func:`fpm_sim.designs.moving_mass_kg`."""
    total = description_link_mass_kg(desc)
    for c in desc.chains:
        for k, e in enumerate(c.path):
            if isinstance(e, LinkDesc):
                total += e.end_lump.mass_kg
            elif isinstance(e, JointDesc):
                on_ground = k == 0 and c.parent is None
                total += e.lump_after.mass_kg + (0.0 if on_ground else e.lump.mass_kg)
    return total + sum(p.lump.mass_kg for p in desc.end_effector.lumps)


def solve_descriptions(
    descs: Sequence[Description],
    poses: Sequence[TaskPose],
    *,
    n_modes: int,
    options: ModelOptions,
    workers: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(frequencies (design, pose, mode), in-plane share of mode 1 (NaN: not computed on this path),
    singularity (the smaller of the type 1 and type 2 measures), status)`` of every design at every pose."""
    sweeps = sweep_task_many(descs, list(poses), options=options, n_modes=n_modes, workers=workers)
    freq = np.stack([s.freq_hz for s in sweeps])
    singularity = np.stack([np.fmin(s.type1, s.type2) for s in sweeps])
    status = np.array([s.status for s in sweeps], dtype=object)
    return freq, np.full(freq.shape[:2], np.nan), singularity, status
