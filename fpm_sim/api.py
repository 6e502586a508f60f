"""The public entry points, one per capability (re-exported lazily by :mod:`fpm_sim`).

Every function takes the description first (``config``: a :class:`fpm_sim.config.Manipulator`, ``None``
for the embedded study prototype), then the pose where there is one (a :class:`fpm_sim.kinematics.Pose`
in m, m, rad; ``None`` for ``(0, 0, 0)``), and everything else keyword-only. The model is always built
here from ``(config, pose)``, so a result cannot mix a description with another model. The resolution
is ``fidelity`` (``"fast"``, ``"standard"``, ``"fine"``) or ``segments`` per link (overrides), the one
policy of :mod:`fpm_sim.model.options`; every result states it and its estimated discretisation error.

Every result has ``.to_dict()`` (JSON-ready), ``.table()`` (text) and ``.plot(ax=None)`` (a
``matplotlib.figure.Figure``). These are thin functions over the library: no computation of their own.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import ArrayLike

    from fpm_sim.config import Manipulator, RigConfig
    from fpm_sim.frf import FrequencyResponse, LinkPoint
    from fpm_sim.kinematics import Pose
    from fpm_sim.linear.modal import ModalResult
    from fpm_sim.model.options import ModelOptions
    from fpm_sim.rom.reduction import ReducedModel
    from fpm_sim.sim.rollout import RolloutResult
    from fpm_sim.study.reproduce import StudyReproduction
    from fpm_sim.study.sweep import WorkspaceSweep

__all__ = ["frf", "frf_grid", "model_options", "modes", "reduce", "reproduce", "rig_modes", "rollout", "sweep"]


def model_options(
    *,
    fidelity: str | None = None,
    segments: int | None = None,
    link_model: str = "segments",
    axial: bool = True,
    gravity: bool = True,
    rotary_inertia: bool = False,
    timestep_s: float | None = None,
) -> ModelOptions:
    """Build the model options of every entry point (see :class:`fpm_sim.model.options.ModelOptions`).

    Parameters
    ----------
    fidelity
        ``"fast"`` (8 segments per link), ``"standard"`` (12, the default) or ``"fine"`` (24).
    segments
        Resolution per link; overrides ``fidelity``.
    link_model
        ``"segments"``, ``"rigid"``, ``"cable"`` or ``"flex"``.
    axial
        Axial springs (extensible links).
    gravity
        Gravity (9.81 m/s^2) along the motor axes.
    rotary_inertia
        Section rotary inertia (Rayleigh beam).
    timestep_s
        Simulation step (s); ``None``: automatic.

    Warns
    -----
    fpm_sim.model.options.ResolutionWarning
        When the estimated discretisation error of the first frequency passes 1 %.
    """
    from fpm_sim.model.options import ModelOptions, warn_if_coarse

    opts = ModelOptions(
        link_model=link_model,
        segments=segments,
        fidelity=None if segments is not None else fidelity,
        axial=axial,
        gravity=gravity,
        rotary_inertia=rotary_inertia,
        timestep_s=timestep_s,
    )
    warn_if_coarse(opts, stacklevel=3)
    return opts


def _config(config: Manipulator | None) -> Manipulator:
    from fpm_sim.config import default_config

    return config if config is not None else default_config()


def _pose(pose: Pose | None) -> Pose:
    from fpm_sim.kinematics import Pose

    return pose if pose is not None else Pose(0.0, 0.0, 0.0)


def modes(
    config: Manipulator | None = None,
    pose: Pose | None = None,
    *,
    fidelity: str | None = None,
    segments: int | None = None,
    link_model: str = "segments",
    axial: bool = True,
    gravity: bool = True,
    rotary_inertia: bool = False,
    n_modes: int | None = 10,
    method: str = "transition_fd",
) -> ModalResult:
    """Natural frequencies (Hz), damping ratios and mode shapes of the manipulator at ``pose``.

    Parameters
    ----------
    config
        Manipulator description; ``None``: the embedded study prototype.
    pose
        End-effector pose (m, m, rad); ``None``: ``(0, 0, 0)``.
    fidelity, segments, link_model, axial, gravity, rotary_inertia
        Model options (:func:`model_options`).
    n_modes
        Number of physical modes returned (lowest first; ``None``: all).
    method
        ``"transition_fd"`` (``mjd_transitionFD``) or ``"constrained"`` (constrained eigen-solve).

    Returns
    -------
    ModalResult
        ``.frequencies_hz``, ``.damping_ratios``, ``.modes``; ``.to_dict()``, ``.table()``, ``.plot()``.
    """
    from fpm_sim.linear.analysis import manipulator_modes

    opts = model_options(
        fidelity=fidelity,
        segments=segments,
        link_model=link_model,
        axial=axial,
        gravity=gravity,
        rotary_inertia=rotary_inertia,
    )
    return manipulator_modes(_pose(pose), config=_config(config), options=opts, n_modes=n_modes, method=method)  # type: ignore[arg-type]


def rig_modes(
    config: Manipulator | None = None,
    rig: str = "cantilever",
    *,
    angle_deg: float = 180.0,
    piece: RigConfig | None = None,
    fidelity: str | None = None,
    segments: int | None = None,
    link_model: str = "segments",
    axial: bool = True,
    gravity: bool = True,
    n_modes: int | None = 10,
    method: str = "transition_fd",
    damping_beta_s: float = 0.0,
) -> ModalResult:
    """Modes of one of the study's subsystem rigs (``"free-free"``, ``"cantilever"``, ``"chain"``).

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
    fidelity, segments, link_model, axial, gravity
        Model options (:func:`model_options`).
    n_modes, method
        As :func:`modes`.
    damping_beta_s
        Rig stiffness-proportional damping (s).
    """
    from fpm_sim.linear.analysis import rig_modes as _rig_modes

    opts = model_options(fidelity=fidelity, segments=segments, link_model=link_model, axial=axial, gravity=gravity)
    return _rig_modes(
        rig,
        angle_deg=angle_deg,
        piece=piece,
        config=_config(config),
        options=opts,
        n_modes=n_modes,
        method=method,  # type: ignore[arg-type]
        damping_beta_s=damping_beta_s,
    )


def sweep(
    config: Manipulator | None = None,
    *,
    grid: str = "dense",
    step_mm: float = 10.0,
    phi_rad: float = 0.0,
    reading: str = "x+",
    fidelity: str | None = None,
    segments: int | None = None,
    axial: bool = False,
    backend: str = "cpu",
    workers: int = 1,
    progress: bool = False,
) -> WorkspaceSweep:
    """First three natural frequencies (Hz) over the workspace or at the study's 25 poses.

    Parameters
    ----------
    config
        Manipulator description; ``None``: the embedded one.
    grid
        ``"dense"`` (a square grid of ``step_mm`` at rotation ``phi_rad``) or ``"paper"`` (the study's poses).
    step_mm
        Dense grid spacing (mm).
    phi_rad
        Platform rotation of the dense grid (rad).
    reading
        How the study's table maps to poses (``"x+"``, ``"x-"``, ``"y+"``, ``"y-"``; paper grid).
    fidelity, segments, axial
        Resolution (:func:`model_options`); the pose loop solves with gravity off (its prestress moves f1
        by less than 1e-5 relative at (0, 0, 0)).
    backend, workers
        Pose-loop backend (``"cpu"`` or a batched JAX one) and processes (cpu).
    progress
        Show a progress bar.
    """
    from fpm_sim.study.poses import parse_reading
    from fpm_sim.study.sweep import sweep_workspace

    opts = model_options(fidelity=fidelity, segments=segments, axial=axial, gravity=False)
    return sweep_workspace(
        _config(config),
        grid=grid,
        step_mm=step_mm,
        phi_rad=phi_rad,
        reading=parse_reading(reading),
        options=opts,
        backend=backend,
        workers=workers,
        progress=progress,
    )


def reduce(
    config: Manipulator | None = None,
    pose: Pose | None = None,
    *,
    n_modes: int | None = None,
    band_hz: float | None = None,
    error_bound: float | None = None,
    static_correction: bool = True,
    accel_fraction: float = 0.5,
    fidelity: str | None = None,
    segments: int | None = None,
    link_model: str = "segments",
    axial: bool = True,
    gravity: bool = True,
) -> ReducedModel:
    """Reduced-order state-space model (modal truncation) at ``pose``.

    Parameters
    ----------
    config, pose
        As :func:`modes`.
    n_modes, band_hz, error_bound
        Modes kept: a count, every mode up to ``band_hz`` (Hz), or the fewest with a relative static
        truncation error <= ``error_bound`` (exactly one of them; none: 6 modes).
    static_correction
        Feedthrough for the truncated modes.
    accel_fraction
        Accelerometer outputs at this fraction (0..1 from the elbow) of each distal link.
    fidelity, segments, link_model, axial, gravity
        Model options (:func:`model_options`).
    """
    from fpm_sim.model.manipulator import build_manipulator
    from fpm_sim.rom.reduction import reduce_model

    if n_modes is None and band_hz is None and error_bound is None:
        n_modes = 6
    opts = model_options(fidelity=fidelity, segments=segments, link_model=link_model, axial=axial, gravity=gravity)
    built = build_manipulator(_config(config), _pose(pose), opts)
    return reduce_model(
        built,
        n_modes=n_modes,
        band_hz=band_hz,
        error_bound=error_bound,
        static_correction=static_correction,
        accel_fraction=accel_fraction,
    )


def frf_grid(f_min_hz: float, f_max_hz: float, df_hz: float, modal_freq_hz: ArrayLike) -> np.ndarray:
    """Make a frequency grid (Hz) from ``f_min_hz`` to ``f_max_hz`` by ``df_hz``, plus the natural frequencies.

    The natural frequencies inside the band are added so that every resonance peak is sampled at its top.
    """
    import numpy as np

    from fpm_sim.frf import FrfError

    if not (0.0 <= f_min_hz < f_max_hz) or not df_hz > 0:
        raise FrfError("need 0 <= f_min_hz < f_max_hz and df_hz > 0 (--f-min-hz, --f-max-hz, --df-hz)")
    if (f_max_hz - f_min_hz) / df_hz > 1e6:
        raise FrfError("the band holds more than 1e6 frequencies (--f-min-hz, --f-max-hz, --df-hz); use a larger df_hz")
    freq = np.arange(f_min_hz, f_max_hz + df_hz / 2, df_hz)
    fm = np.asarray(modal_freq_hz, float)
    return np.unique(np.concatenate([freq, fm[(fm >= freq[0]) & (fm <= freq[-1])]]))


def frf(
    config: Manipulator | None = None,
    pose: Pose | None = None,
    *,
    excitation: LinkPoint | None = None,
    response: LinkPoint | None = None,
    quantity: str = "accelerance",
    f_min_hz: float = 1.0,
    f_max_hz: float = 500.0,
    df_hz: float = 0.1,
    damping_ratio: float | Sequence[float] | None = None,
    n_modes: int | None = None,
    fidelity: str | None = None,
    segments: int | None = None,
    link_model: str = "segments",
    axial: bool = True,
    gravity: bool = True,
) -> FrequencyResponse:
    """Frequency response function of the linearised manipulator at ``pose`` (modal superposition).

    Parameters
    ----------
    config, pose
        As :func:`modes`.
    excitation
        Force input point and direction (:class:`fpm_sim.frf.LinkPoint`); default mid-span of
        ``distal_0`` along z.
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
    fidelity, segments, link_model, axial, gravity
        Model options (:func:`model_options`).
    """
    from fpm_sim.frf import FrfError, LinkPoint, modal_frf
    from fpm_sim.model.manipulator import build_manipulator
    from fpm_sim.rom.reduction import modal_system

    if link_model == "rigid":
        raise FrfError(
            "an FRF needs flexible links: with rigid links and locked motors nothing moves; use link_model "
            "'segments' (--link-model)"
        )
    opts = model_options(fidelity=fidelity, segments=segments, link_model=link_model, axial=axial, gravity=gravity)
    built = build_manipulator(_config(config), _pose(pose), opts)
    exc = excitation or LinkPoint("distal_0", 0.5, "z")
    resp = response or exc
    exc.check(built)
    resp.check(built)
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
    config: Manipulator | None = None,
    pose: Pose | None = None,
    *,
    duration_s: float = 0.2,
    output_step_s: float = 1e-4,
    force_x_n: float = 0.0,
    force_y_n: float = 0.0,
    moment_z_nm: float = 0.0,
    motor_torque_nm: Sequence[float] = (0.0, 0.0, 0.0),
    accel_fraction: float | None = 0.5,
    fidelity: str | None = None,
    segments: int | None = None,
    link_model: str = "segments",
    axial: bool = True,
    gravity: bool = True,
    progress: bool = False,
) -> RolloutResult:
    """Nonlinear simulation of the full manipulator from its static equilibrium under constant loads.

    The model is built here from ``(config, pose)`` (timestep rounded down to divide ``output_step_s``),
    so the rollout always matches its description.

    Parameters
    ----------
    config, pose
        As :func:`modes`.
    duration_s
        Simulated time (s).
    output_step_s
        Sample period of the recorded signals (s).
    force_x_n, force_y_n, moment_z_nm
        Constant end-effector force (N) and moment (N m).
    motor_torque_nm
        Constant motor torques (N m; needs servo motors in ``config``).
    accel_fraction
        Record accelerations at this fraction (0..1) of each distal link; ``None``: none.
    fidelity, segments, link_model, axial, gravity
        Model options (:func:`model_options`).
    progress
        Show a progress bar.
    """
    from fpm_sim.model.manipulator import build_manipulator
    from fpm_sim.rom.reduction import accel_site_names
    from fpm_sim.sim.rollout import aligned_options, constant
    from fpm_sim.sim.rollout import rollout as _rollout

    manip, p = _config(config), _pose(pose)
    opts = model_options(fidelity=fidelity, segments=segments, link_model=link_model, axial=axial, gravity=gravity)
    built = build_manipulator(manip, p, aligned_options(manip, p, opts, output_step_s))
    wrench = (force_x_n, force_y_n, moment_z_nm)
    return _rollout(
        built,
        manip,
        duration_s=duration_s,
        output_step_s=output_step_s,
        ee_wrench=constant(*wrench) if any(wrench) else None,
        motor_torque=constant(*motor_torque_nm) if any(motor_torque_nm) else None,
        accel_sites=accel_site_names(built, accel_fraction) if accel_fraction is not None else [],
        progress=progress,
    )


def reproduce(
    config: Manipulator | None = None,
    *,
    reading: str = "x+",
    fidelity: str | None = None,
    segments: int | None = None,
    axial: bool = False,
    backend: str = "cpu",
    workers: int = 1,
    subsystems: bool = True,
    readability: bool = True,
    progress: bool = False,
) -> StudyReproduction:
    """Reproduce the study's subsystem tests and its 25 poses against COMSOL.

    Parameters
    ----------
    config
        Manipulator description (its ``[rig]`` table gives the test pieces); ``None``: the embedded one.
    reading
        How the study's table maps to poses: ``"x+"``, ``"x-"``, ``"y+"`` or ``"y-"``.
    fidelity, segments, axial
        Pose-loop resolution (:func:`model_options`; gravity off, as :func:`sweep`).
    backend, workers
        Pose-loop backend and processes.
    subsystems, readability
        Also solve the subsystem rigs; also tabulate mode-1 readability.
    progress
        Show progress bars.
    """
    from fpm_sim.study.poses import parse_reading
    from fpm_sim.study.reproduce import reproduce_study

    opts = model_options(fidelity=fidelity, segments=segments, axial=axial, gravity=False)
    return reproduce_study(
        _config(config),
        reading=parse_reading(reading),
        options=opts,
        backend=backend,
        workers=workers,
        progress=progress,
        subsystems=subsystems,
        readability=readability,
    )


# ----------------------------------------------------------------------------------------------- predictions with bands

if TYPE_CHECKING:
    from pathlib import Path

    from fpm_sim.study.posterior import Posterior, PredictiveBands

__all__ += ["predict_bands"]  # appended beside the function (the list above is left as it is)


def predict_bands(
    posterior: Posterior | str | Path,
    poses: Pose | Sequence[Pose] | None = None,
    *,
    draws: int | None = 100,
    n_modes: int = 3,
    fidelity: str | None = None,
    segments: int | None = None,
    workers: int | None = None,
    seed: int = 0,
) -> PredictiveBands:
    """Predictions with bands: frequencies at ``poses`` over the draws of a posterior, and their quantiles.

    The posterior is ``posterior.nc`` of ``fpm-sim calibrate``; the result holds every draw's frequencies and
    their median and 5/25/75/95 % quantiles per pose (:class:`fpm_sim.study.posterior.PredictiveBands`).

    Parameters
    ----------
    posterior
        A :class:`fpm_sim.study.posterior.Posterior` or the path of its file.
    poses
        One pose or several (default: the origin).
    draws
        Posterior draws to use (a seeded random subset; ``None``: all).
    n_modes
        Modes per pose.
    fidelity, segments
        Pose-loop resolution; default: the posterior's own (the resolution of its likelihood).
    workers
        Local Dask workers of the pose loop (default: the CPU count; small runs stay in this process).
    seed
        Which draws (:meth:`fpm_sim.study.posterior.Posterior.draws`).
    """
    from fpm_sim.batch.engine import EngineOptions
    from fpm_sim.kinematics import Pose
    from fpm_sim.study import posterior as study_posterior

    post = (
        posterior
        if isinstance(posterior, study_posterior.Posterior)
        else study_posterior.Posterior.from_netcdf(posterior)
    )
    if fidelity is None and segments is None:
        segments = post.segments
    opts = model_options(fidelity=fidelity, segments=segments, axial=False, gravity=False)
    pose_list = [_pose(None)] if poses is None else [poses] if isinstance(poses, Pose) else list(poses)
    return study_posterior.predict_bands(
        post, pose_list, n_draws=draws, seed=seed, n_modes=n_modes, options=opts, engine=EngineOptions(workers=workers)
    )
