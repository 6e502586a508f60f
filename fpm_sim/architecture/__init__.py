"""Any flexible manipulator: its description (chains of joints and links, end effector, task coordinates), read
from TOML, and its kinematics (inverse, forward, closure, mobility, singularity). Below ``model``, which builds the
MuJoCo model from a description assembled at a pose."""

from fpm_sim.architecture.description import (
    ChainDesc,
    Description,
    EndEffectorDesc,
    GeneralSection,
    JointDesc,
    LinkDesc,
    PlacedLump,
    TubeSection,
)
from fpm_sim.architecture.edit import (
    ParameterPathError,
    description_value,
    machine_parameter,
    settable_paths,
    with_description_value,
    with_machine_parameter,
)
from fpm_sim.architecture.kinematics import (
    MobilityError,
    TaskAssembly,
    TaskPose,
    UnreachableTaskPoseError,
    check_mobility,
    solve_task_pose,
    task_unknowns,
)
from fpm_sim.architecture.reader import is_description_file, load_description, parse_description
from fpm_sim.architecture.writer import description_toml

__all__ = [
    "ChainDesc",
    "Description",
    "EndEffectorDesc",
    "GeneralSection",
    "JointDesc",
    "LinkDesc",
    "MobilityError",
    "ParameterPathError",
    "PlacedLump",
    "TaskAssembly",
    "TaskPose",
    "TubeSection",
    "UnreachableTaskPoseError",
    "check_mobility",
    "description_toml",
    "description_value",
    "is_description_file",
    "load_description",
    "machine_parameter",
    "parse_description",
    "settable_paths",
    "solve_task_pose",
    "task_unknowns",
    "with_description_value",
    "with_machine_parameter",
]
