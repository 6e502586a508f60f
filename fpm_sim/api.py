"""The public entry points, one per capability of the command line (re-exported lazily by :mod:`fpm_sim`).

The one public surface: ``import fpm_sim as fs`` and call ``fs.modes``, ``fs.sweep``, ... (the modules below
are the library behind them). Every function takes the description first (``config``: a
:class:`fpm_sim.config.Manipulator`, ``None`` for the embedded study prototype), then the pose where there is
one (a :class:`fpm_sim.kinematics.Pose` in m, m, rad; ``None`` for the function's default pose), and
everything else keyword-only. The model options are ONE parameter, ``options`` (a
:class:`fpm_sim.model.options.ModelOptions`, exported as ``fs.ModelOptions``: resolution by ``fidelity`` or
``segments``, link model, axial springs, gravity, ...); ``None`` takes the function's default, the same one
as its command's. The model is always built here from ``(config, pose, options)``, so a result cannot mix a
description with another model.

Every result has ``.to_dict()`` (JSON-ready), ``.table()`` (text) and ``.plot(ax=None)`` (a
``matplotlib.figure.Figure``); see :class:`fpm_sim.results.Result`. These are thin functions over the
library: no computation of their own.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, overload

if TYPE_CHECKING:
    from fpm_sim.architecture import Description, TaskPose
    from fpm_sim.architecture.imported import ImportedDescription
    from fpm_sim.batch.joint_sweep import JointSweep
    from fpm_sim.batch.task_sweep import TaskSweep
    from fpm_sim.config import Manipulator, RigConfig
    from fpm_sim.designs.study import DesignResult
    from fpm_sim.kinematics import Pose
    from fpm_sim.linear.analysis import ModalComparison
    from fpm_sim.linear.modes import ModalResult
    from fpm_sim.model.options import ModelOptions
    from fpm_sim.model.spec import BuiltModel
    from fpm_sim.response import FrequencyResponse, LinkPoint
    from fpm_sim.rom.atlas import ModalAtlas
    from fpm_sim.rom.reduction import ReducedModel
    from fpm_sim.sim.batched import BatchedRollouts
    from fpm_sim.sim.impact import ImpactSetup, ImpactTestResult
    from fpm_sim.sim.rollout import RolloutMachine, RolloutResult
    from fpm_sim.sim.trajectory import MoveResult
    from fpm_sim.study.calibrate import Calibration, SamplerOptions
    from fpm_sim.study.identify import Identification, IdentifyOptions, Observation
    from fpm_sim.study.identify.ema import ModalEstimate
    from fpm_sim.study.readability import ReadabilityTable
    from fpm_sim.study.reproduce import StudyReproduction
    from fpm_sim.study.sweep import WorkspaceSweep
    from fpm_sim.study.tables import SubsystemTest
    from fpm_sim.study.transient import TransientResult

__all__ = [
    "atlas",
    "batched_rollouts",
    "calibrate",
    "design",
    "ema",
    "export_mjcf",
    "frf",
    "identify",
    "impact",
    "modes",
    "move",
    "plan_tests",
    "predict_bands",
    "readability",
    "reduce",
    "reproduce",
    "rig_modes",
    "rollout",
    "sweep",
    "transient",
]


def _config(config: Manipulator | None) -> Manipulator:
    from fpm_sim.config import default_config

    return config if config is not None else default_config()


def _pose(pose: Pose | None) -> Pose:
    from fpm_sim.kinematics import Pose

    return pose if pose is not None else Pose(0.0, 0.0, 0.0)


def _options(options: ModelOptions | None, *, stacklevel: int = 3) -> ModelOptions | None:
    """Return the caller's options, warned about when coarse; ``None`` stays (each function's default)."""
    from fpm_sim.model.options import warn_if_coarse

    if options is not None:
        warn_if_coarse(options, stacklevel=stacklevel)  # pointing at the caller of the facade
    return options


def _built(
    config: Manipulator | Description | ImportedDescription | None,
    pose: Pose | TaskPose | None,
    options: ModelOptions | None,
    q: dict[str, float] | None = None,
) -> BuiltModel:
    from fpm_sim.architecture import Description, TaskPose
    from fpm_sim.architecture.imported import ImportedDescription

    if isinstance(config, ImportedDescription):
        from fpm_sim.model.imported import build_imported

        if pose is not None:
            from fpm_sim.model.imported_pose import ImportedKinematics

            if not isinstance(pose, TaskPose):
                raise TypeError("an imported model's task pose is an fs.TaskPose, with q a mapping of fixed joints")
            q = ImportedKinematics(config).solve(pose, fixed=q)
        return build_imported(config, q, _options(options, stacklevel=4))
    if q is not None:
        from fpm_sim.errors import FpmSimError

        raise FpmSimError("joint values are for an imported model", parameter="q", hint="give a pose instead")

    if isinstance(config, Description):  # a described architecture (fpm_sim.architecture)
        from fpm_sim.model.general import build_general

        if pose is not None and not isinstance(pose, TaskPose):
            raise TypeError("a described architecture takes a fs.TaskPose (x_m, y_m, z_m, phi_rad)")
        home = config.check_poses[0] if config.check_poses else {}
        task_pose = pose if pose is not None else TaskPose.from_coordinates(home)
        return build_general(config, task_pose, _options(options, stacklevel=4))
    from fpm_sim.model.manipulator import build_manipulator

    if isinstance(pose, TaskPose):
        raise TypeError("the 3RRR takes a fs.Pose (x_m, y_m, phi_rad)")
    return build_manipulator(_config(config), _pose(pose), _options(options, stacklevel=4))


def _task_pose(desc: Description, pose: Pose | TaskPose | None) -> TaskPose:
    """``pose`` (a :class:`TaskPose`), or the description's first check pose."""
    from fpm_sim.architecture import TaskPose

    if pose is not None and not isinstance(pose, TaskPose):
        raise TypeError("a described architecture takes a fs.TaskPose (x_m, y_m, z_m, phi_rad)")
    home = desc.check_poses[0] if desc.check_poses else {}
    return pose if pose is not None else TaskPose.from_coordinates(home)


def _aligned(
    config: Manipulator | Description | ImportedDescription | None,
    pose: Pose | TaskPose | None,
    options: ModelOptions | None,
    output_step_s: float,
    motors: str = "locked",
    q: dict[str, float] | None = None,
) -> tuple[Manipulator | RolloutMachine, BuiltModel]:
    """Return the description and its model for a rollout (the timestep rounded down to divide the output step).

    A described architecture's or imported model's description is its :class:`RolloutMachine`
    (:func:`fpm_sim.sim.task.rollout_machine`), its motors ``motors``; an imported model posed by ``pose`` and/or
    ``q`` (:meth:`fpm_sim.sim.imported_move.ImportedMover.state_at`).
    """
    from fpm_sim.architecture import Description, TaskPose, solve_task_pose
    from fpm_sim.architecture.imported import ImportedDescription
    from fpm_sim.errors import FpmSimError
    from fpm_sim.model.options import ModelOptions
    from fpm_sim.sim.rollout import RolloutError, aligned_options

    opts = _options(options, stacklevel=4) or ModelOptions()
    if q is not None and not isinstance(config, ImportedDescription):
        raise FpmSimError("joint values are for an imported model", parameter="q", hint="give a pose instead")
    if isinstance(config, Description | ImportedDescription):
        from fpm_sim.sim.task import mover_of, rollout_machine

        mover: Any = mover_of(config, need_motors=motors == "servo")  # an imported model needs its [end_effector]
        if isinstance(config, Description):
            state = solve_task_pose(config, _task_pose(config, pose))
        elif pose is not None and not isinstance(pose, TaskPose):
            raise TypeError("an imported model's task pose is an fs.TaskPose, with q a mapping of fixed joints")
        else:
            state = mover.state_at(pose, q)
        return rollout_machine(mover, state, opts, output_step_s, motors)
    from fpm_sim.model.manipulator import build_manipulator

    if motors != "locked":
        raise RolloutError(
            "sets a described architecture's actuated joints",
            parameter="motors",
            value=motors,
            hint="for the 3RRR set config.motors (Motors(mode='servo', ...))",
        )
    if isinstance(pose, TaskPose):
        raise TypeError("the 3RRR takes a fs.Pose (x_m, y_m, phi_rad)")
    manip, p3 = _config(config), _pose(pose)
    return manip, build_manipulator(manip, p3, aligned_options(manip, p3, opts, output_step_s))


def _task_load(
    machine: Manipulator | RolloutMachine, values: dict[str, float], *, what: str = "end-effector load"
) -> list[float]:
    """Return the end-effector load along the machine's coordinates from the named components.

    ``force_x_n``, ...: a non-zero one the machine has no coordinate for is refused by name.
    """
    from fpm_sim.sim.rollout import RolloutError, RolloutMachine

    coords = machine.coordinates if isinstance(machine, RolloutMachine) else ("x", "y", "phi")
    names = {"x": "force_x_n", "y": "force_y_n", "z": "force_z_n", "phi": "moment_z_nm"}
    for c, n in names.items():
        if values.get(n, 0.0) != 0.0 and c not in coords:
            raise RolloutError(
                f"the machine has no task coordinate {c} (its coordinates: {', '.join(coords)}), so no {what} along it",
                parameter=n,
                value=values[n],
                hint=f"drop {n}",
            )
    return [float(values.get(names[c], 0.0)) for c in coords]


@overload
def modes(
    config: Manipulator | Description | ImportedDescription | None = None,
    pose: Pose | TaskPose | None = None,
    *,
    q: dict[str, float] | None = None,
    options: ModelOptions | None = None,
    n_modes: int | None = 10,
    method: Literal["transition_fd", "constrained"] = "transition_fd",
) -> ModalResult: ...


@overload
def modes(
    config: Manipulator | Description | ImportedDescription | None = None,
    pose: Pose | TaskPose | None = None,
    *,
    q: dict[str, float] | None = None,
    options: ModelOptions | None = None,
    n_modes: int | None = 10,
    method: Literal["both"],
) -> ModalComparison: ...


@overload
def modes(
    config: ImportedDescription,
    pose: None = None,
    *,
    q: Sequence[dict[str, float]],
    options: ModelOptions | None = None,
    n_modes: int | None = 10,
    method: str = "transition_fd",
) -> list[ModalResult | ModalComparison]: ...


def modes(
    config: Manipulator | Description | ImportedDescription | None = None,
    pose: Pose | TaskPose | None = None,
    *,
    q: dict[str, float] | Sequence[dict[str, float]] | None = None,
    options: ModelOptions | None = None,
    n_modes: int | None = 10,
    method: str = "transition_fd",
) -> ModalResult | ModalComparison | list[ModalResult | ModalComparison]:
    """Natural frequencies (Hz), damping ratios and mode shapes of the manipulator at ``pose`` (``fpm-sim modes``).

    Parameters
    ----------
    config
        Manipulator description: the 3RRR's (:class:`fpm_sim.config.Manipulator`; ``None``: the embedded study
        prototype) or any described architecture (:class:`fpm_sim.architecture.Description`,
        ``fs.load_description``), or an imported MuJoCo model with links made flexible
        (:class:`fpm_sim.architecture.imported.ImportedDescription`, ``fs.load_imported``; ``fpm-sim import``).
    pose
        End-effector pose: a :class:`fpm_sim.kinematics.Pose` (m, m, rad; ``None``: ``(0, 0, 0)``) for the 3RRR,
        a :class:`fpm_sim.architecture.TaskPose` in the architecture's task coordinates for a described one
        (``None``: its first check pose). An imported model is posed by ``q``, or by a
        :class:`~fpm_sim.architecture.TaskPose` of its end-effector site where its description names one
        (``[end_effector]``; :class:`~fpm_sim.model.imported_pose.ImportedKinematics`, ``q`` then the joints kept
        fixed).
    q
        An imported model's joint values, ``{joint name: value}`` in SI: rad for a hinge, m for a slide (MuJoCo's
        joint coordinates; joints not named stay at the model's reference). Only for an imported model. A list of
        such mappings: the modes at each of those joint-space poses (a list of results, in order).
    options
        Model options; ``None``: ``ModelOptions()`` (standard resolution, gravity, axial springs).
    n_modes
        Number of physical modes returned (lowest first; ``None``: all).
    method
        ``"transition_fd"`` (``mjd_transitionFD``), ``"constrained"`` (constrained eigen-solve) or ``"both"``
        (a :class:`fpm_sim.linear.analysis.ModalComparison` of the two at one equilibrium).

    Returns
    -------
    ModalResult or ModalComparison
        ``.frequencies_hz``, ``.damping_ratios``, ``.modes``; ``.to_dict()``, ``.table()``, ``.plot()``.
    """
    from fpm_sim.architecture.imported import ImportedDescription
    from fpm_sim.linear.analysis import analyse

    if isinstance(config, ImportedDescription):
        from fpm_sim.model.imported import build_imported

        if pose is not None:
            from fpm_sim.architecture import TaskPose
            from fpm_sim.model.imported_pose import ImportedKinematics

            if not isinstance(pose, TaskPose) or isinstance(q, Sequence):
                raise TypeError("an imported model's task pose is an fs.TaskPose, with q a mapping of fixed joints")
            q = ImportedKinematics(config).solve(pose, fixed=q)
        if isinstance(q, Sequence):
            from fpm_sim.batch.joint_sweep import modes_at_joint_poses

            return modes_at_joint_poses(config, q, options=_options(options), n_modes=n_modes, method=method)
        return analyse(build_imported(config, q, _options(options)), method, n_modes)
    if q is not None:
        from fpm_sim.errors import FpmSimError

        raise FpmSimError("joint values are for an imported model", parameter="q", hint="give a pose instead")
    return analyse(_built(config, pose, options), method, n_modes)


def rig_modes(
    config: Manipulator | None = None,
    rig: str = "cantilever",
    *,
    angle_deg: float = 180.0,
    piece: RigConfig | None = None,
    options: ModelOptions | None = None,
    n_modes: int | None = 10,
    method: str = "transition_fd",
    damping_beta_s: float = 0.0,
) -> ModalResult:
    """Modes of one of the study's subsystem rigs (``"free-free"``, ``"cantilever"``, ``"chain"``; ``fpm-sim rig``).

    Parameters
    ----------
    config
        Description whose ``[rig]`` table gives the test piece; ``None``: the embedded one.
    rig
        The rig.
    angle_deg
        Chain hinge interior angle (degrees; 180 = straight).
    piece
        Test piece overriding the config's (lengths in m).
    options
        Model options (as :func:`modes`).
    n_modes, method
        As :func:`modes` (``"transition_fd"`` or ``"constrained"``).
    damping_beta_s
        Rig stiffness-proportional damping (s).
    """
    from fpm_sim.linear.analysis import rig_modes as _rig_modes

    return _rig_modes(
        config,
        rig,
        angle_deg=angle_deg,
        piece=piece,
        options=_options(options),
        n_modes=n_modes,
        method=method,  # type: ignore[arg-type]
        damping_beta_s=damping_beta_s,
    )


def _sweep_joints(config: ImportedDescription, poses: Sequence[Any] | None, options: ModelOptions | None) -> JointSweep:
    """:func:`sweep` of an imported model: its poses are ``{joint: value}`` mappings."""
    from fpm_sim.architecture import TaskPose
    from fpm_sim.batch.joint_sweep import sweep_joints

    joint_poses = [p for p in poses or [] if isinstance(p, dict)]
    task_poses = [p for p in poses or [] if isinstance(p, TaskPose)]
    if task_poses and len(task_poses) == len(poses or []):  # task space: solved with continuation
        from fpm_sim.model.imported_pose import joint_poses_of

        joint_poses = joint_poses_of(config, task_poses)
    if not joint_poses or len(joint_poses) != len(poses or []):
        raise TypeError(
            "an imported model is swept over joint-space poses, fs.sweep(desc, poses=[{'joint': 0.1}]), or over "
            "task poses of its end effector, fs.sweep(desc, poses=[fs.TaskPose(...)])"
        )
    return sweep_joints(config, joint_poses, options=_options(options, stacklevel=4))


def _sweep_described(
    config: Description,
    grid: str,
    poses: Sequence[Any] | None,
    step_mm: float,
    phi_rad: float,
    z_mm: float | None,
    options: ModelOptions | None,
    workers: int,
) -> TaskSweep:
    """:func:`sweep` of a described architecture: over its dense task grid, or ``poses`` (task poses)."""
    from fpm_sim.architecture import TaskPose
    from fpm_sim.batch.task_sweep import sweep_task, task_grid

    if grid == "dense":
        home = config.check_poses[0] if config.check_poses else {}
        held = {"z": z_mm * 1e-3 if z_mm is not None else home.get("z", 0.0), "phi": phi_rad}
        task_poses, _, _ = task_grid(config, step_mm=step_mm, held=held)
    else:
        task_poses = [p for p in poses or [] if isinstance(p, TaskPose)]
        if len(task_poses) != len(poses or []) or not task_poses:
            raise TypeError("a described architecture's poses are fs.TaskPose values (grid='poses')")
    return sweep_task(config, task_poses, options=options, workers=workers, grid=grid, step_mm=step_mm)


def sweep(
    config: Manipulator | Description | ImportedDescription | None = None,
    *,
    grid: str = "dense",
    poses: Sequence[Pose] | Sequence[TaskPose] | Sequence[dict[str, float]] | None = None,
    step_mm: float = 10.0,
    phi_rad: float = 0.0,
    z_mm: float | None = None,
    reading: str = "x+",
    options: ModelOptions | None = None,
    backend: str = "cpu",
    workers: int = 1,
    progress: bool = False,
) -> WorkspaceSweep | TaskSweep | JointSweep:
    """First three natural frequencies (Hz) over the workspace, the study's 25 poses or given poses.

    The ``fpm-sim sweep`` command.

    Parameters
    ----------
    config
        Manipulator description; ``None``: the embedded one. A described architecture
        (:class:`fpm_sim.architecture.Description`) is swept by its own pose loop
        (:func:`fpm_sim.batch.task_sweep.sweep_task`; ``grid`` ``"dense"`` or ``"poses"``, the result a
        :class:`fpm_sim.batch.task_sweep.TaskSweep`). An imported model's ``poses`` are ``{joint: value}`` mappings
        (:func:`fpm_sim.batch.joint_sweep.sweep_joints`, a :class:`fpm_sim.batch.joint_sweep.JointSweep`).
    grid
        ``"dense"`` (a square grid of ``step_mm`` at rotation ``phi_rad``), ``"paper"`` (the study's poses) or
        ``"poses"`` (``poses``).
    poses
        The poses of ``grid="poses"`` (:class:`fpm_sim.architecture.TaskPose` for a described architecture).
    z_mm
        Height of a spatial architecture's dense grid (mm; ``None``: its first check pose's).
    step_mm
        Dense grid spacing (mm).
    phi_rad
        Platform rotation of the dense grid (rad).
    reading
        How the study's table maps to poses (``"x+"``, ``"x-"``, ``"y+"``, ``"y-"``; paper grid).
    options
        Pose-loop model options; ``None``: :func:`fpm_sim.batch.pose_loop.fast_options` (standard resolution,
        inextensible links, gravity off: its prestress moves f1 by less than 1e-5 relative at (0, 0, 0)).
    backend, workers
        Pose-loop backend (``"cpu"`` or a batched JAX one) and processes (cpu).
    progress
        Show a progress bar.
    """
    from fpm_sim.architecture import Description
    from fpm_sim.architecture.imported import ImportedDescription

    if isinstance(config, ImportedDescription):  # joint-space poses
        return _sweep_joints(config, poses, options)
    if isinstance(config, Description):
        return _sweep_described(config, grid, poses, step_mm, phi_rad, z_mm, _options(options), workers)
    from fpm_sim.kinematics import Pose
    from fpm_sim.study.poses import parse_reading
    from fpm_sim.study.sweep import sweep_workspace

    if poses is not None and not all(isinstance(p, Pose) for p in poses):
        raise TypeError("the 3RRR's poses are fs.Pose values (x_m, y_m, phi_rad)")
    return sweep_workspace(
        _config(config),
        grid=grid,
        poses=[p for p in poses if isinstance(p, Pose)] if poses is not None else None,
        step_mm=step_mm,
        phi_rad=phi_rad,
        reading=parse_reading(reading),
        options=_options(options),
        backend=backend,
        workers=workers,
        progress=progress,
    )


def design(
    config: Manipulator | Description | ImportedDescription | None = None,
    *,
    poses: Sequence[Pose] | Sequence[TaskPose] | Sequence[dict[str, float]] | None = None,
    vary: dict[str, Sequence[float]] | None = None,
    designs: Sequence[dict[str, float]] | None = None,
    n_modes: int = 3,
    f_min_hz: float | None = None,
    options: ModelOptions | None = None,
    workers: int = 1,
) -> DesignResult:
    """Lowest ``n_modes`` frequencies for every design x pose (``fpm-sim design``).

    Parameters
    ----------
    config
        The base description; ``None``: the embedded one. A described architecture
        (:class:`fpm_sim.architecture.Description`, read from its file) varies dotted paths into its file
        (``sections.bar.height_m``, ``chains.left.proximal.length_m``: docs/architectures.md). An imported model
        (:class:`fpm_sim.architecture.imported.ImportedDescription`, ``fs.load_imported``) varies dotted paths into its
        file too (``materials.steel.young_pa``; docs/import.md).
    poses
        The poses, the same for every design (e.g. ``fs.sweep``'s grids, or
        :func:`fpm_sim.study.sweep.dense_grid`); a described architecture's are
        :class:`fpm_sim.architecture.TaskPose` values, ``None``: its check poses. The 3RRR needs them, and so does an
        imported model: ``{joint: value}`` mappings, or task poses where it names an ``[end_effector]``.
    vary
        ``{dotted field: values}`` (SI units, as the field names say): the full factorial.
    designs
        Instead of ``vary``: a list of ``{field: value}`` designs.
    n_modes
        Modes per pose.
    f_min_hz
        Threshold of the summary's workspace share (Hz).
    options
        Pose-loop model options; ``None``: as :func:`sweep`.
    workers
        Processes of a described architecture's pose loop (the 3RRR's runs on the Dask engine's default).
    """
    from fpm_sim.architecture import Description, TaskPose
    from fpm_sim.architecture.imported import ImportedDescription
    from fpm_sim.batch.engine import EngineOptions
    from fpm_sim.designs import DesignError, design_study

    machine: Any = config
    engine = None
    if isinstance(config, Description):
        home = [TaskPose.from_coordinates(p) for p in config.check_poses]
        chosen: Sequence[Any] = home if poses is None else poses
        engine = EngineOptions(workers=workers)
    elif poses is None and isinstance(config, ImportedDescription):
        raise DesignError(
            "an imported model states no check poses",
            parameter="poses",
            hint="give {joint: value} poses, or fs.TaskPose values where it names an [end_effector]",
        )
    elif poses is None:
        raise DesignError("the 3RRR's design study needs poses", parameter="poses", hint="e.g. dense_grid(config)")
    else:
        chosen = poses
        machine = config if isinstance(config, ImportedDescription) else _config(config)
    return design_study(
        machine,
        poses=chosen,
        vary=vary,
        designs=designs,
        n_modes=n_modes,
        f_min_hz=f_min_hz,
        options=_options(options),
        engine=engine,
    )


def reduce(
    config: Manipulator | Description | ImportedDescription | None = None,
    pose: Pose | TaskPose | None = None,
    *,
    q: dict[str, float] | None = None,
    n_modes: int | None = None,
    band_hz: float | None = None,
    error_bound: float | None = None,
    static_correction: bool = True,
    accel_fraction: float = 0.5,
    options: ModelOptions | None = None,
) -> ReducedModel:
    """Reduced-order state-space model (modal truncation) at ``pose`` (``fpm-sim reduce``).

    Parameters
    ----------
    config, pose
        As :func:`modes` (the 3RRR, a described architecture, or an imported model: its wrench inputs and
        displacement outputs at its ``[end_effector]`` site, else at its last flexible body's beam end).
    q
        An imported model's joint values (as :func:`modes`; a single pose).
    n_modes, band_hz, error_bound
        Modes kept: a count, every mode up to ``band_hz`` (Hz), or the fewest with a relative static
        truncation error <= ``error_bound`` (exactly one of them; none: 6 modes).
    static_correction
        Feedthrough for the truncated modes.
    accel_fraction
        Accelerometer outputs at this fraction (0..1 from the link's start: the elbow) of each accelerometer link:
        the 3RRR's distal links, a described machine's last flexible link of each chain, an imported model's
        flexible bodies' beams.
    options
        Model options (as :func:`modes`).
    """
    from fpm_sim.rom.reduction import reduce_model

    if n_modes is None and band_hz is None and error_bound is None:
        n_modes = 6
    return reduce_model(
        _built(config, pose, options, q),
        n_modes=n_modes,
        band_hz=band_hz,
        error_bound=error_bound,
        static_correction=static_correction,
        accel_fraction=accel_fraction,
    )


def frf(
    config: Manipulator | Description | None = None,
    pose: Pose | TaskPose | None = None,
    *,
    excitation: LinkPoint | None = None,
    response: LinkPoint | None = None,
    quantity: str = "accelerance",
    f_min_hz: float = 1.0,
    f_max_hz: float = 500.0,
    df_hz: float = 0.1,
    damping_ratio: float | Sequence[float] | None = None,
    n_modes: int | None = None,
    options: ModelOptions | None = None,
) -> FrequencyResponse:
    """Frequency response function of the linearised manipulator at ``pose`` (``fpm-sim frf``).

    By modal superposition of the constrained modes.

    Parameters
    ----------
    config, pose
        As :func:`modes` (the 3RRR or a described architecture).
    excitation
        Force input point and direction (``fs.LinkPoint``); default the model's test point
        (:func:`fpm_sim.response.default_point`): mid-span of ``distal_0`` along z on the 3RRR, mid-span of the
        first chain's last flexible link along the link frame's z on a described machine.
    response
        Response point and axis; default the excitation (a driving-point FRF).
    quantity
        ``"accelerance"`` (m/s^2/N), ``"mobility"`` (m/s/N) or ``"receptance"`` (m/N).
    f_min_hz, f_max_hz, df_hz
        Frequency band and step (Hz); the natural frequencies inside it are added to the grid.
    damping_ratio
        ``None``: the model's modal damping; a number: for every mode; a sequence: per mode.
    n_modes
        Sum over the lowest ``n_modes`` modes only (default all).
    options
        Model options (as :func:`modes`; the links must be flexible).
    """
    from fpm_sim.response import FrfError, default_point, frf_grid, modal_frf
    from fpm_sim.rom.reduction import modal_system

    if options is not None and options.link_model == "rigid":
        raise FrfError(
            "an FRF needs flexible links: with rigid links and locked motors nothing moves",
            parameter="link_model",
            value=options.link_model,
            hint="use 'segments'",
        )
    built = _built(config, pose, options)
    exc = excitation or default_point(built)
    resp = response or exc
    exc.check(built, "input")
    resp.check(built, "output")
    system = modal_system(built)
    return modal_frf(
        system,
        excitation=exc,
        response=resp,
        freq_hz=frf_grid(f_min_hz, f_max_hz, df_hz, system.frequencies_hz),
        quantity=quantity,
        damping_ratio=damping_ratio,
        n_modes=n_modes,
    )


def rollout(
    config: Manipulator | Description | ImportedDescription | None = None,
    pose: Pose | TaskPose | None = None,
    *,
    q: dict[str, float] | None = None,
    duration_s: float = 0.2,
    output_step_s: float = 1e-4,
    force_x_n: float = 0.0,
    force_y_n: float = 0.0,
    force_z_n: float = 0.0,
    moment_z_nm: float = 0.0,
    motor_torque_nm: Sequence[float] | None = None,
    motors: str = "locked",
    accel_fraction: float | None = 0.5,
    options: ModelOptions | None = None,
    progress: bool = False,
    integrator: str = "discrete",
    band_hz: float | None = None,
    step_s: float | None = None,
) -> RolloutResult:
    """Nonlinear simulation of the full manipulator from its static equilibrium (``fpm-sim rollout``).

    Under constant loads. The model is built here from ``(config, pose, options)`` (timestep rounded down to divide
    ``output_step_s``), so the rollout always matches its description.

    Parameters
    ----------
    config, pose, q
        As :func:`modes` (a described architecture: its task coordinates are recorded, :mod:`fpm_sim.sim.task`; an
        imported model: its ``[end_effector]`` site's, which it must name; no ``pose`` or ``q``: its reference).
    duration_s
        Simulated time (s).
    output_step_s
        Sample period of the recorded signals (s).
    force_x_n, force_y_n, force_z_n, moment_z_nm
        Constant end-effector force (N) and moment about z (N m); a described architecture takes a force along
        each of its translational task coordinates and a moment where it has ``phi`` (others refused by name;
        the 3RRR has no ``force_z_n``).
    motor_torque_nm
        Constant motor torques (N m, N on a prismatic joint), one per motor (the 3RRR: three, needs servo motors in
        ``config``; a described architecture: one per actuated joint, needs ``motors="servo"``); ``None``: none.
    motors
        A described architecture's actuated joints or an imported model's motors (the joints an ``<actuator>``
        drives, ``servo_joints``): ``"locked"`` (default) or ``"servo"`` (its ``[servos]`` gains,
        :class:`fpm_sim.architecture.description.ServoGains`); the 3RRR's come from ``config.motors``.
    accel_fraction
        Record accelerations at this fraction (0..1) of each distal link (the 3RRR); ``None``: none (a described
        architecture or an imported model records none).
    options
        Model options (as :func:`modes`).
    progress
        Show a progress bar.
    integrator, band_hz, step_s
        ``"discrete"`` (default) at the step of the band ``band_hz`` (Hz; default 5 x f1) or at ``step_s`` (s;
        ``fpm-sim rollout --timestep-s``), or ``"explicit"``: the model's own step
        (:func:`fpm_sim.sim.stepping.choose_stepping`).
    """
    from fpm_sim.rom.reduction import accel_site_names
    from fpm_sim.sim.rollout import RolloutMachine, constant
    from fpm_sim.sim.rollout import rollout as _rollout

    machine, built = _aligned(config, pose, options, output_step_s, motors, q)
    wrench = _task_load(
        machine, dict(force_x_n=force_x_n, force_y_n=force_y_n, force_z_n=force_z_n, moment_z_nm=moment_z_nm)
    )
    torque = _motor_torques(machine, motor_torque_nm)
    general = isinstance(machine, RolloutMachine)
    return _rollout(
        built,
        machine,
        duration_s=duration_s,
        output_step_s=output_step_s,
        ee_wrench=constant(*wrench) if any(wrench) else None,
        motor_torque=constant(*torque) if any(torque) else None,
        accel_sites=accel_site_names(built, accel_fraction) if accel_fraction is not None and not general else [],
        progress=progress,
        integrator=integrator,
        band_hz=band_hz,
        step_s=step_s,
    )


def _motor_torques(machine: Manipulator | RolloutMachine, torques: Sequence[float] | None) -> list[float]:
    """One torque per motor (the 3RRR's three, a described architecture's actuated joints); the count checked."""
    from fpm_sim.sim.rollout import RolloutError, RolloutMachine

    names = machine.motor_names if isinstance(machine, RolloutMachine) else ("0", "1", "2")
    if torques is None:
        return [0.0] * len(names)
    values = [float(v) for v in torques]
    if len(values) != len(names):
        raise RolloutError(
            f"needs {len(names)} values, one per actuated joint ({', '.join(names)}), got {len(values)}",
            parameter="motor_torque_nm",
            value=values,
            hint=f"give {len(names)} torques",
        )
    return values


def batched_rollouts(
    config: Manipulator | Description | None = None,
    pose: Pose | TaskPose | None = None,
    *,
    wrenches: Sequence[Sequence[float]],
    duration_s: float = 0.2,
    output_step_s: float = 1e-4,
    threads: int = 1,
    options: ModelOptions | None = None,
    integrator: str = "discrete",
    band_hz: float | None = None,
) -> BatchedRollouts:
    """Many constant end-effector loads on one model, stepped in ``mujoco.rollout``'s threads.

    Each row of ``wrenches`` (``F_x, F_y`` in N, ``M_z`` in N m; a described architecture: a force per
    translational task coordinate and a moment about z for ``phi``, in its task order) is one rollout from the
    static equilibrium under gravity, as :func:`rollout` with that constant load (:mod:`fpm_sim.sim.batched`); no
    command of its own.

    Parameters
    ----------
    config, pose
        As :func:`modes`.
    wrenches
        ``(n, 3)`` constant end-effector loads (a described architecture: ``(n, len(task))``), one rollout each.
    duration_s, output_step_s
        Simulated time (s) and sample period (s).
    threads
        Threads of the rollout pool.
    options
        Model options (as :func:`rollout`).
    integrator, band_hz
        As :func:`rollout`.

    Returns
    -------
    BatchedRollouts
        ``.to_xarray()`` (``ee_disp`` over ``rollout`` x ``time`` x ``axis``), ``.to_dict()``, ``.table()``,
        ``.plot()``.
    """
    from fpm_sim.sim.batched import BatchedRollouts
    from fpm_sim.sim.batched import batched_rollouts as _batched

    machine, built = _aligned(config, pose, options, output_step_s)
    ds = _batched(
        built,
        machine,
        wrenches,
        duration_s=duration_s,
        output_step_s=output_step_s,
        threads=threads,
        integrator=integrator,
        band_hz=band_hz,
    )
    return BatchedRollouts(ds)


def move(
    config: Manipulator | Description | ImportedDescription | None = None,
    pose: Pose | TaskPose | None = None,
    *,
    end: Pose | TaskPose | None = None,
    move_s: float = 0.3,
    profile: str = "minimum-jerk",
    path_csv: str | Path | None = None,
    shaper: str = "none",
    settle_s: float = 0.3,
    settle_tol_m: float | None = None,
    output_step_s: float = 1e-4,
    options: ModelOptions | None = None,
    integrator: str = "discrete",
    band_hz: float | None = None,
    progress: bool = False,
) -> MoveResult:
    """Simulate a point-to-point move of the end effector tracked by the motor servos (``fpm-sim move``).

    The full flexible model follows the commanded path; reported: tracking error, link deflection, residual
    vibration after the move (peak, settling time, dominant frequency against the modal f1 at the end pose),
    motor torques (:mod:`fpm_sim.sim.trajectory`). Servos: the 3RRR's stated defaults; a described architecture's or
    imported model's ``[servos]`` (:mod:`fpm_sim.sim.task`, :mod:`fpm_sim.sim.imported_move`).

    Parameters
    ----------
    config
        As :func:`modes`.
    pose, end
        Start and end pose (m, m, rad); ``None``: ``(0, 0, 0)`` and ``(30 mm, 0, 0)``. A described architecture:
        :class:`fpm_sim.architecture.TaskPose` s; ``None``: its first check pose (an imported model: its site's
        reference pose), and that pose 30 mm further along x.
    move_s, profile
        Move time (s) and motion profile (``"trapezoidal"``, ``"s-curve"``, ``"minimum-jerk"``).
    path_csv
        A commanded path ``t_s, x_mm, y_mm, phi_rad`` (a described architecture: ``t_s`` and its task columns,
        ``x_mm, y_mm[, z_mm][, phi_rad]``) instead of a profile move (then no ``pose``/``end``).
    shaper
        Input shaper for the end pose's dominant in-plane mode: ``"none"``, ``"zv"`` or ``"zvd"``.
    settle_s, settle_tol_m, output_step_s
        Simulated time after the move (s), settling tolerance on the in-plane residual (m; ``None``: 20 um), sample
        period (s).
    options
        Model options; ``None``: the standard resolution, inextensible links.
    integrator, band_hz
        As :func:`rollout` (default band: 5 x f1 at the end pose).
    progress
        Show a progress bar.
    """
    from fpm_sim.architecture import Description, TaskPose
    from fpm_sim.architecture.imported import ImportedDescription
    from fpm_sim.kinematics import Pose
    from fpm_sim.sim import trajectory as tj

    if path_csv is not None and (pose is not None or end is not None):
        raise tj.MoveError(
            "a sampled path sets its own start and end poses",
            parameter="path_csv",
            value=str(path_csv),
            hint="give either a path CSV or the start and end poses",
        )
    kw: dict[str, Any] = dict(
        settle_s=settle_s,
        options=_options(options),
        output_step_s=output_step_s,
        shaper_kind=shaper,
        settle_tol_m=tj.DEFAULT_SETTLE_TOL_M if settle_tol_m is None else settle_tol_m,
        integrator=integrator,
        band_hz=band_hz,
        progress=progress,
    )
    if isinstance(config, Description | ImportedDescription):
        return _task_move(config, pose, end, move_s, profile, path_csv, kw)
    if isinstance(pose, TaskPose) or isinstance(end, TaskPose):
        raise TypeError("the 3RRR takes fs.Pose s (x_m, y_m, phi_rad)")
    if path_csv is not None:
        path = tj.MovePath.from_csv(path_csv)
    else:
        path = tj.MovePath(_pose(pose), Pose.from_mm(30.0, 0.0, 0.0) if end is None else end, move_s, kind=profile)
    return tj.simulate_move(_config(config), path, **kw)


def _task_move(
    desc: Description | ImportedDescription,
    pose: Pose | TaskPose | None,
    end: Pose | TaskPose | None,
    move_s: float,
    profile: str,
    path_csv: str | Path | None,
    kw: dict[str, Any],
) -> MoveResult:
    """:func:`move` on a described architecture or an imported model (:func:`fpm_sim.sim.task.simulate_task_move`)."""
    import dataclasses

    from fpm_sim.sim.task import TaskPath, mover_of, pose_vector, simulate_task_move

    mover = mover_of(desc)  # an imported model without an end effector or motors: refused here
    task = mover.task
    if path_csv is not None:
        path = TaskPath.from_csv(path_csv, task)
    else:
        start = _move_start(desc, mover, pose)
        stop = _move_start(desc, mover, end) if end is not None else dataclasses.replace(start, x_m=start.x_m + 0.03)
        path = TaskPath(task, pose_vector(start, task), pose_vector(stop, task), move_s, kind=profile)
    return simulate_task_move(mover, path, **kw)


def _move_start(desc: Description | ImportedDescription, mover: Any, pose: Pose | TaskPose | None) -> TaskPose:
    """Return ``pose`` (a :class:`~fpm_sim.architecture.TaskPose`), a move's start or end.

    ``None``: a described architecture's first check pose, an imported model's reference pose
    (:meth:`fpm_sim.sim.imported_move.ImportedMover.reference_pose`).
    """
    from fpm_sim.architecture import Description, TaskPose

    if isinstance(desc, Description):
        return _task_pose(desc, pose)
    if pose is not None and not isinstance(pose, TaskPose):
        raise TypeError("an imported model takes a fs.TaskPose (x_m, y_m, z_m, phi_rad)")
    return pose if pose is not None else mover.reference_pose()


def impact(
    config: Manipulator | Description | ImportedDescription | None = None,
    pose: Pose | TaskPose | None = None,
    *,
    q: dict[str, float] | None = None,
    setup: ImpactSetup | None = None,
    options: ModelOptions | None = None,
    progress: bool = False,
) -> ImpactTestResult:
    """Virtual impact (hammer) test (``fpm-sim impact``).

    Rollouts of the full model under half-sine hits, the H1 FRF and its peaks.

    Parameters
    ----------
    config, pose
        As :func:`modes` (the 3RRR, a described architecture or an imported model).
    q
        An imported model's joint values (as :func:`modes`; a single pose).
    setup
        Hammer, accelerometer, pulse, record, noise, ... (:class:`fpm_sim.sim.impact.ImpactSetup`; ``None``:
        the study's set-up with hammer and accelerometer at the model's test point: the study's on the 3RRR,
        mid-span of the first chain's last flexible link along the link frame's z on a described machine,
        mid-span of the first flexible body's beam along its z on an imported model).
    options
        Model options (as :func:`modes`; the links must be flexible).
    progress
        Show a progress bar over the impacts.
    """
    from fpm_sim.sim.impact import virtual_impact_test

    return virtual_impact_test(_built(config, pose, options, q), setup, progress=progress)


def transient(
    config: Manipulator | None = None,
    pose: Pose | None = None,
    *,
    thickness_m: float | None = None,
    force_n: float | None = None,
    duration_s: float | None = None,
    output_step_s: float | None = None,
    band_hz: float | None = None,
    n_modes: int | None = None,
    options: ModelOptions | None = None,
    progress: bool = False,
    integrator: str = "discrete",
    step_band_hz: float | None = None,
) -> TransientResult:
    """Run the study's transient, or a variant of it (``fpm-sim transient``).

    The full nonlinear rollout against the reduced model under a step force. Every ``None`` takes the
    study's value (:mod:`fpm_sim.study.transient`).

    Parameters
    ----------
    config
        Manipulator description; ``None``: the embedded one (motors as configured; the study: locked).
    pose
        Pose of the test (m, m, rad); ``None``: the study's, (0, 0, 0).
    thickness_m
        Link in-plane thickness (m); ``None``: the study's 5 mm.
    force_n, duration_s, output_step_s
        Step force (N), simulated time (s), sample period (s).
    band_hz, n_modes
        Modes the reduced model keeps: all up to ``band_hz`` (Hz; default 500) or the lowest ``n_modes``.
    options
        Model options; only ``segments`` (resolved from ``fidelity``) and ``axial`` are used; ``None``: the
        study transient's 6 segments, inextensible links.
    progress
        Show progress bars.
    integrator, step_band_hz
        How the full model is stepped: ``"discrete"`` (default) at the step of the band ``step_band_hz`` (Hz;
        default 5 x f1), or ``"explicit"`` (as :func:`rollout`'s ``integrator``, ``band_hz``).
    """
    from fpm_sim.model.options import resolve_segments
    from fpm_sim.study import transient as tr

    opts = _options(options)
    return tr.study_transient(
        _config(config),
        pose=tr.STUDY_POSE if pose is None else pose,
        thickness_m=tr.STUDY_THICKNESS_M if thickness_m is None else thickness_m,
        force_n=tr.STUDY_FORCE_N if force_n is None else force_n,
        duration_s=tr.STUDY_DURATION_S if duration_s is None else duration_s,
        output_step_s=tr.STUDY_OUTPUT_STEP_S if output_step_s is None else output_step_s,
        segments=tr.DEFAULT_SEGMENTS
        if opts is None
        else resolve_segments(segments=opts.segments, link_model=opts.link_model),
        axial=False if opts is None else opts.axial,
        band_hz=tr.DEFAULT_BAND_HZ if band_hz is None and n_modes is None else band_hz,
        n_modes=n_modes,
        progress=progress,
        integrator=integrator,
        step_band_hz=step_band_hz,
    )


def readability(
    config: Manipulator | None = None,
    *,
    point: LinkPoint | None = None,
    row_is: str = "x",
    phi_sign: int = 1,
    f_max_hz: float = 500.0,
    damping_ratio: float | None = None,
    poses: Sequence[Pose] | None = None,
    options: ModelOptions | None = None,
    progress: bool = False,
) -> ReadabilityTable:
    """Mode-1 readability at the study's 25 poses (``fpm-sim readability``).

    For a driving-point hammer test at ``point`` (or at other ``poses``).

    Parameters
    ----------
    config
        Manipulator description; ``None``: the embedded one.
    point
        Hammer point and direction; ``None``: the study's (mid-span of ``distal_0`` along z).
    row_is, phi_sign
        How the study's table maps to poses (rows along ``"x"`` or ``"y"``; sign of its rotation).
    f_max_hz
        Top of the FRF band (Hz).
    damping_ratio
        ``None``: the model's modal damping; else for every mode.
    poses
        Other poses than the study's.
    options
        Model options; ``None``: 6 segments, inextensible links.
    progress
        Show a progress bar.
    """
    from fpm_sim.sim.impact import STUDY_IMPACT_POINT
    from fpm_sim.study.readability import readability_table

    return readability_table(
        _config(config),
        options=_options(options),
        point=STUDY_IMPACT_POINT if point is None else point,
        row_is=row_is,
        phi_sign=phi_sign,
        f_max_hz=f_max_hz,
        damping_ratio=damping_ratio,
        poses=None if poses is None else list(poses),
        progress=progress,
    )


def atlas(
    config: Manipulator | Description | ImportedDescription | None = None,
    *,
    x_m: Sequence[float],
    y_m: Sequence[float],
    phi_rad: Sequence[float] = (0.0,),
    z_m: float | None = None,
    n_modes: int = 6,
    n_extra: int = 4,
    options: ModelOptions | None = None,
    progress: bool = False,
) -> ModalAtlas:
    """Build a modal atlas: reduced models on a pose grid with their modes tracked (``fpm-sim atlas build``).

    Query it with ``atlas(...).query(pose)`` (``fpm-sim atlas query``: an interpolated
    :class:`fpm_sim.rom.reduction.ReducedModel`); ``.save(path)`` and
    :func:`fpm_sim.rom.atlas.load_atlas` store it.

    Parameters
    ----------
    config
        Manipulator description; ``None``: the embedded one; or a described architecture
        (:class:`fpm_sim.architecture.Description`: the grid in its task coordinates, queried at a ``fs.TaskPose``);
        or an imported model that names an ``[end_effector]``
        (:class:`fpm_sim.architecture.imported.ImportedDescription`: the grid in that site's task coordinates, at its
        reference height).
    x_m, y_m, phi_rad
        The grid (m, m, rad); ``phi_rad`` only on a machine that sets phi.
    z_m
        A spatial architecture's height (m; default its first check pose's): the atlas is a horizontal slice.
    n_modes, n_extra
        Tracked (kept) modes and extra candidates for the tracking.
    options
        Model options; ``None``: the standard resolution, inextensible links.
    progress
        Show a progress bar.
    """
    from fpm_sim.architecture import Description
    from fpm_sim.architecture.imported import ImportedDescription
    from fpm_sim.rom.atlas import build_atlas

    return build_atlas(
        config if isinstance(config, (Description, ImportedDescription)) else _config(config),
        x_m=x_m,
        y_m=y_m,
        phi_rad=phi_rad,
        z_m=z_m,
        options=_options(options),
        n_modes=n_modes,
        n_extra=n_extra,
        progress=progress,
    )


def ema(
    path: str | Path,
    *,
    f_lower_hz: float,
    f_upper_hz: float,
    n_modes: int = 3,
    pol_order: int = 40,
    window_tau_s: float | None = None,
) -> list[ModalEstimate]:
    """Experimental modal analysis of measured FRFs, CSV or UFF 58 (``fpm-sim ema``).

    Natural frequencies and damping ratios by LSCF, one estimate per FRF in the file.

    Parameters
    ----------
    path
        The FRF file (as :func:`fpm_sim.study.identify.ema.read_frfs` reads it).
    f_lower_hz, f_upper_hz
        Band of the fit (Hz).
    n_modes
        Modes estimated (the stable poles nearest the FRF's highest peaks).
    pol_order
        Highest polynomial order of the stabilisation chart.
    window_tau_s
        Decay constant (s) of an exponential window to remove from the damping; ``None``: the file's, if any.
    """
    from fpm_sim.study.identify.ema import estimate_modes, read_frfs

    return [
        estimate_modes(
            frf,
            f_lower_hz=f_lower_hz,
            f_upper_hz=f_upper_hz,
            n_modes=n_modes,
            pol_order=pol_order,
            window_tau_s=window_tau_s,
        )
        for frf in read_frfs(path)
    ]


def _measured_data(
    measured: Sequence[str | Path],
    subsystems: str | Path | None,
    free: Sequence[str],
    reading: str | None,
    sigma_pct: float | None,
) -> tuple[list[Observation], list[SubsystemTest], list[str]]:
    """Read the data of :func:`identify` and :func:`calibrate`.

    Returns the observations of the measured CSV files, the rig tests and the free groups (``rig`` added when
    rig tests are given).
    """
    from fpm_sim.study import identify as idf
    from fpm_sim.study.poses import parse_reading

    rd = parse_reading(reading) if reading else None
    sigma = idf.DEFAULT_SIGMA_PCT if sigma_pct is None else sigma_pct
    datasets = [idf.read_measured_csv(p, reading=rd, sigma_pct=sigma) for p in measured]
    tests = idf.read_subsystems_csv(subsystems) if subsystems is not None else []
    groups = list(free) + (["rig"] if tests and "rig" not in free else [])
    return [o for ds in datasets for o in ds.observations], tests, groups


def identify(
    config: Manipulator | None = None,
    *,
    measured: Sequence[str | Path] = (),
    subsystems: str | Path | None = None,
    free: Sequence[str] = ("geometry", "hardware"),
    reading: str | None = None,
    sigma_pct: float | None = None,
    subsystem_sigma_pct: float = 1.0,
    workspace: Sequence[Pose] = (),
    min_singularity: float = 0.05,
    settings: IdentifyOptions | None = None,
    progress: bool = False,
) -> Identification:
    """Identify the description's free parameters (model updating; ``fpm-sim identify``).

    From measured natural frequencies and rig tests.

    Parameters
    ----------
    config
        The starting description; ``None``: the embedded one.
    measured
        Measured-frequency CSV files (:func:`fpm_sim.study.identify.read_measured_csv`).
    subsystems
        Rig tests CSV (frees the ``rig`` group).
    free
        Parameter groups fitted (:data:`fpm_sim.study.identify.GROUPS`).
    reading
        How ``row_mm,col_mm`` files map to poses (``"x+"``, ...).
    sigma_pct
        Relative std (%) of a measured frequency where the file gives none; ``None``: the default (2 %).
    subsystem_sigma_pct
        Relative std (%) of a rig test.
    workspace, min_singularity
        Poses the machine is known to reach, and the smallest singularity measure accepted there.
    settings
        Search settings and the fitted model's resolution (:class:`fpm_sim.study.identify.IdentifyOptions`).
    progress
        Show progress lines.
    """
    from fpm_sim.study import identify as idf

    start = _config(config)
    observations, tests, groups = _measured_data(measured, subsystems, free, reading, sigma_pct)
    problem = idf.Problem(
        idf.parameter_set(start, groups),
        observations,
        tests,
        subsystem_sigma_pct=subsystem_sigma_pct,
        workspace=list(workspace),
        min_singularity=min_singularity,
    )
    return idf.identify(problem, options=settings, progress=progress)


def calibrate(
    config: Manipulator | Description | ImportedDescription | None = None,
    *,
    priors: str | Path | None = None,
    measured: Sequence[str | Path] = (),
    subsystems: str | Path | None = None,
    free: Sequence[str] | None = None,
    reading: str | None = None,
    sigma_pct: float | None = None,
    segments: int = 4,
    sampler: SamplerOptions | None = None,
    progress: bool = False,
) -> Calibration:
    """Bayesian calibration of the description's free parameters by nested sampling (``fpm-sim calibrate``).

    Parameters
    ----------
    config
        The base description the free parameters are applied to; ``None``: the embedded one. A described
        architecture (:class:`~fpm_sim.architecture.description.Description` read from its file) is calibrated by
        dotted paths into its file (:mod:`fpm_sim.study.calibrate.described`: one measured file in its task
        coordinates, each ``fK_hz`` compared with its K-th lowest elastic mode, one class); an imported model
        (:class:`~fpm_sim.architecture.imported.ImportedDescription`) likewise, its measured file in joint space (one
        column per joint) or in its ``[end_effector]``'s task coordinates, solved to joint values once
        (:func:`~fpm_sim.study.identify.described.read_joint_measured_csv`).
    priors
        The priors TOML file (one distribution and reason per free parameter; e.g.
        ``fpm_sim/data/study_priors.toml``); required on the 3RRR. On a described architecture its
        ``[parameters."PATH"]`` tables name dotted paths.
    measured, subsystems, reading, sigma_pct
        The data, as :func:`identify` reads them (the ``rig`` group is freed when rig tests are given). A described
        architecture takes one measured file and no rig tests or reading.
    free
        Parameter groups sampled (:data:`fpm_sim.study.identify.GROUPS`; ``None``: geometry, hardware,
        section-height); on a described architecture dotted paths, ``PATH`` (its prior in ``priors``) or
        ``PATH=lo:hi`` (uniform between them); ``None``: every path ``priors`` names.
    segments
        Resolution (spring locations per link) of the likelihood's model.
    sampler
        The sampler (nested sampling, or the two-stage tempered SMC of :mod:`fpm_sim.study.calibrate.smc`), its
        live points or particles, stopping, workers, seed, independent runs per elbow-branch class and the
        between-run check's tolerances (:class:`fpm_sim.study.calibrate.SamplerOptions`; the check is
        ``result.runs_check``).
    progress
        Show dynesty's progress line.
    """
    from fpm_sim.architecture import Description
    from fpm_sim.architecture.imported import ImportedDescription
    from fpm_sim.study import identify as idf
    from fpm_sim.study.calibrate import CalibrationError, CalibrationProblem, read_priors, run_calibration

    if isinstance(config, Description | ImportedDescription):
        problem = _described_calibration(config, priors, measured, subsystems, free, reading, sigma_pct, segments)
        return run_calibration(problem, sampler, progress=progress)
    if priors is None:
        raise CalibrationError(
            "give the priors TOML file", parameter="priors", hint="e.g. fpm_sim/data/study_priors.toml"
        )
    start = _config(config)
    free = ("geometry", "hardware", "section-height") if free is None else free
    observations, tests, groups = _measured_data(measured, subsystems, free, reading, sigma_pct)
    names = idf.parameter_set(start, groups).names
    problem = CalibrationProblem(
        start,
        tuple(groups),
        read_priors(priors, names),
        tuple(observations),
        tuple(tests),
        segments=segments,
    )
    return run_calibration(problem, sampler, progress=progress)


def _described_calibration(
    desc: Description | ImportedDescription,
    priors: str | Path | None,
    measured: Sequence[str | Path],
    subsystems: str | Path | None,
    free: Sequence[str] | None,
    reading: str | None,
    sigma_pct: float | None,
    segments: int,
) -> Any:
    """:func:`calibrate`'s problem on a described architecture.

    See :func:`fpm_sim.study.calibrate.described.described_problem`.
    """
    from fpm_sim.architecture.imported import ImportedDescription
    from fpm_sim.study import identify as idf
    from fpm_sim.study.calibrate import CalibrationError
    from fpm_sim.study.calibrate.described import described_problem
    from fpm_sim.study.identify.described import read_joint_measured_csv, read_task_measured_csv

    for name, given in (("subsystems", subsystems), ("reading", reading)):
        if given is not None:
            raise CalibrationError("is the 3RRR's (its rig tests, its table's reading)", parameter=name, hint="drop it")
    if len(measured) != 1:
        raise CalibrationError(
            "give one measured file (its task coordinates' columns, f1_hz, ...)", parameter="measured"
        )
    sigma = idf.DEFAULT_SIGMA_PCT if sigma_pct is None else sigma_pct
    if isinstance(desc, ImportedDescription):
        data = read_joint_measured_csv(measured[0], desc, sigma_pct=sigma)
    else:
        data = read_task_measured_csv(measured[0], desc, sigma_pct=sigma)
    return described_problem(
        desc, data, priors=priors, free=None if free is None else ",".join(free), segments=segments
    )


def reproduce(
    config: Manipulator | None = None,
    *,
    reading: str = "x+",
    options: ModelOptions | None = None,
    backend: str = "cpu",
    workers: int = 1,
    subsystems: bool = True,
    readability: bool = True,
    progress: bool = False,
) -> StudyReproduction:
    """Reproduce the study's subsystem tests and its 25 poses against COMSOL (``fpm-sim reproduce``).

    Parameters
    ----------
    config
        Manipulator description (its ``[rig]`` table gives the test pieces); ``None``: the embedded one.
    reading
        How the study's table maps to poses: ``"x+"``, ``"x-"``, ``"y+"`` or ``"y-"``.
    options
        Pose-loop model options; ``None``: as :func:`sweep`.
    backend, workers
        Pose-loop backend and processes.
    subsystems, readability
        Also solve the subsystem rigs; also tabulate mode-1 readability.
    progress
        Show progress bars.
    """
    from fpm_sim.study.poses import parse_reading
    from fpm_sim.study.reproduce import reproduce_study

    return reproduce_study(
        _config(config),
        reading=parse_reading(reading),
        options=_options(options),
        backend=backend,
        workers=workers,
        progress=progress,
        subsystems=subsystems,
        readability=readability,
    )


def export_mjcf(
    config: Manipulator | Description | None = None,
    pose: Pose | TaskPose | None = None,
    *,
    rig: str | None = None,
    angle_deg: float = 180.0,
    piece: RigConfig | None = None,
    options: ModelOptions | None = None,
) -> str:
    """Generate the MJCF (XML text) of the manipulator at ``pose`` or of a rig (``fpm-sim export-mjcf``).

    Parameters
    ----------
    config, pose
        As :func:`modes`.
    rig
        ``None``: the manipulator; else the rig (``"free-free"``, ``"cantilever"``, ``"chain"``; no pose).
    angle_deg, piece
        The rig's chain hinge angle (degrees) and test piece (as :func:`rig_modes`).
    options
        Model options (as :func:`modes`).
    """
    if rig is None:
        return _built(config, pose, options).to_xml()
    from fpm_sim.architecture import Description
    from fpm_sim.model.rigs import RigSetup, build_rig, rig_piece

    if isinstance(config, Description):
        raise TypeError("the rigs are the study's test pieces: export a described architecture with rig=None")
    cfg = _config(config)
    built = build_rig(
        RigSetup(rig, angle_deg=angle_deg), piece or rig_piece(cfg), _options(options), compliance=cfg.compliance
    )
    return built.to_xml()


# ----------------------------------------------------------------------------------------------- predictions with bands

if TYPE_CHECKING:
    from pathlib import Path

    from fpm_sim.study.planning import PlanResult, Target
    from fpm_sim.study.posterior import Posterior, PredictiveBands


def predict_bands(
    posterior: Posterior | str | Path,
    poses: Pose | TaskPose | Sequence[Pose] | Sequence[TaskPose] | None = None,
    *,
    draws: int | None = 100,
    n_modes: int = 3,
    options: ModelOptions | None = None,
    workers: int | None = None,
    seed: int = 0,
) -> PredictiveBands:
    """Predictions with bands: frequencies at ``poses`` over the draws of a posterior, and their quantiles.

    The posterior is ``posterior.nc`` of ``fpm-sim calibrate``; the result holds every draw's frequencies and
    their median and 5/25/75/95 % quantiles per pose (:class:`fpm_sim.study.posterior.PredictiveBands`).
    A posterior is a set of descriptions (one per draw): it stands where the other entry points take the
    description, and its poses where they take the pose.

    Parameters
    ----------
    posterior
        A :class:`fpm_sim.study.posterior.Posterior` or the path of its file.
    poses
        One pose or several (default: the origin). A described machine's posterior (``fpm-sim calibrate --config
        machine.toml``) takes :class:`fpm_sim.architecture.TaskPose` values (default: its first check pose).
    draws
        Posterior draws to use (a seeded random subset; ``None``: all).
    n_modes
        Modes per pose.
    options
        Pose-loop model options; default: the posterior's own resolution (that of its likelihood), inextensible
        links, gravity off (the pose loop's).
    workers
        Local Dask workers of the pose loop (default: the CPU count; small runs stay in this process).
    seed
        Which draws (:meth:`fpm_sim.study.posterior.Posterior.draws`).
    """
    from fpm_sim.architecture import Description, TaskPose
    from fpm_sim.batch.engine import EngineOptions
    from fpm_sim.kinematics import Pose
    from fpm_sim.model.options import ModelOptions
    from fpm_sim.study import posterior as study_posterior

    post = (
        posterior
        if isinstance(posterior, study_posterior.Posterior)
        else study_posterior.Posterior.from_netcdf(posterior)
    )
    opts = _options(options) or ModelOptions(segments=post.segments, axial=False, gravity=False)
    base = post.base
    pose_list: list[Pose | TaskPose]
    if poses is None:
        pose_list = [_task_pose(base, None) if isinstance(base, Description) else _pose(None)]
    else:
        pose_list = [poses] if isinstance(poses, Pose | TaskPose) else list(poses)
    return study_posterior.predict_bands(
        post, pose_list, n_draws=draws, seed=seed, n_modes=n_modes, options=opts, engine=EngineOptions(workers=workers)
    )


def plan_tests(
    posterior: Posterior | str | Path | None = None,
    *,
    candidates: str | Sequence[Pose] | Sequence[TaskPose] | None = None,
    quantities: Sequence[str] = ("f1", "f1+f2", "f1..f3"),
    target: Target | Sequence[Pose] | None = None,
    k: int = 3,
    sigma_rel: float | None = None,
    draws: int | None = 200,
    outcomes: int = 64,
    seed: int = 0,
    options: ModelOptions | None = None,
    workers: int | None = None,
) -> PlanResult:
    """Plan the next tests: rank candidate measurements by the target's expected band after each, choose ``k``.

    Each candidate's value is how much it is expected to narrow the target's band under the posterior; ``k`` are
    chosen greedily (:mod:`fpm_sim.study.plan`).

    Parameters
    ----------
    posterior
        A :class:`fpm_sim.study.posterior.Posterior` or the path of its file (default: the embedded default's).
    candidates
        ``"study"`` (the study's 25 cells; the 3RRR's only), ``"grid"`` (the workspace every 50 mm) or poses of your
        own (:class:`fpm_sim.architecture.TaskPose` values for a described machine's posterior); ``None``:
        ``"study"`` for the 3RRR, ``"grid"`` for a described machine.
    quantities
        What each candidate pose measures: any of ``"f1"``, ``"f1+f2"``, ``"f1..f3"`` (labelled modes), or
        ``"read:LINK@POS:AXIS"``: the first clear peak of a hammer test at that accelerometer point and axis, its
        mode unlabelled (e.g. ``"read:distal_0@0.5:z"``; the 3RRR's readout model,
        :func:`fpm_sim.study.planning.read_point`).
    target
        Where predictions matter: a :class:`fpm_sim.study.planning.Target` (e.g. a requirement's, with its level),
        poses (f1's band there), or ``None``: f1 over the workspace every 50 mm (a described machine: over the
        posterior median's task grid).
    k
        Measurements to choose.
    sigma_rel
        The planned measurement's sd relative to the frequency (default: the posterior's data's).
    draws, outcomes, seed
        Posterior draws used, simulated outcomes per set, and their seed.
    options
        Pose-loop model options (default: the posterior's own resolution).
    workers
        Local Dask workers of the pose loop.
    """
    from fpm_sim.batch.engine import EngineOptions
    from fpm_sim.model.options import ModelOptions
    from fpm_sim.study import planning
    from fpm_sim.study import posterior as study_posterior

    if posterior is None:
        posterior = study_posterior.default_posterior_path()
        if posterior is None:
            raise study_posterior.PosteriorError(
                "no posterior shipped", parameter="posterior", hint="give posterior.nc"
            )
    post = (
        posterior
        if isinstance(posterior, study_posterior.Posterior)
        else study_posterior.Posterior.from_netcdf(posterior)
    )
    cands = planning.candidates_from(post, candidates, quantities)
    tgt = planning.target_from(post, target)
    opts = _options(options) or ModelOptions(segments=post.segments, axial=False, gravity=False)
    return planning.plan_tests(
        post,
        cands,
        tgt,
        k=k,
        sigma_rel=sigma_rel,
        n_draws=draws,
        outcomes=outcomes,
        seed=seed,
        options=opts,
        engine=EngineOptions(workers=workers),
    )
