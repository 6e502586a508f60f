"""The small, typed Python API: one call per question a user asks."""

from __future__ import annotations

from dataclasses import dataclass

import mujoco

from fpm_sim.config import Manipulator, RigConfig, default_config
from fpm_sim.errors import FpmSimError
from fpm_sim.kinematics import Pose
from fpm_sim.linear.equilibrium import static_equilibrium
from fpm_sim.linear.modal import Method, ModalResult, modes_constrained, modes_transition_fd
from fpm_sim.linear.threads import blas_threads
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import BuiltModel, ModelOptions
from fpm_sim.model.rigs import RigSetup, build_rig, rig_piece

__all__ = ["ModalComparison", "analyse", "compare_methods", "manipulator_modes", "rig_modes"]


@dataclass
class ModalComparison:
    """The same model analysed by both methods."""

    transition_fd: ModalResult
    constrained: ModalResult

    def relative_differences(self, n_modes: int) -> list[float]:
        """``f_transition_fd / f_constrained - 1`` for the first ``n_modes`` modes."""
        a, b = self.transition_fd.frequencies_hz, self.constrained.frequencies_hz
        n = min(n_modes, len(a), len(b))
        return [float(a[i] / b[i] - 1.0) for i in range(n)]


def analyse(built: BuiltModel, method: Method | str, n_modes: int | None) -> ModalResult | ModalComparison:
    """Modes of ``built`` by ``"transition_fd"``, ``"constrained"`` or ``"both"``, with the static
    equilibrium solved once (floating models are linearised at ``qpos0`` by each method)."""
    if method not in ("transition_fd", "constrained", "both"):
        raise FpmSimError(
            "unknown method", parameter="method", value=method, hint="choose 'transition_fd', 'constrained' or 'both'"
        )
    qpos = None if built.floating else static_equilibrium(built.model, mujoco.MjData(built.model))
    with blas_threads():  # one BLAS thread around the dense eigen-solves (fpm_sim.linear.threads)
        if method == "transition_fd":
            return modes_transition_fd(built, n_modes=n_modes, qpos=qpos)
        if method == "constrained":
            return modes_constrained(built, n_modes=n_modes, qpos=qpos)
        return ModalComparison(
            modes_transition_fd(built, n_modes=n_modes, qpos=qpos),
            modes_constrained(built, n_modes=n_modes, qpos=qpos),
        )


def compare_methods(built: BuiltModel, *, n_modes: int | None = 10) -> ModalComparison:
    """Analyse ``built`` by both methods at one shared equilibrium."""
    out = analyse(built, "both", n_modes)
    assert isinstance(out, ModalComparison)
    return out


def manipulator_modes(
    pose: Pose,
    *,
    config: Manipulator | None = None,
    options: ModelOptions | None = None,
    n_modes: int | None = 10,
    method: Method = "transition_fd",
) -> ModalResult:
    """Natural frequencies, damping ratios and mode shapes of the manipulator at ``pose``.

    Parameters
    ----------
    pose
        End-effector pose (m, m, rad).
    config
        Manipulator description; the embedded default if omitted.
    options
        Discretisation and simulation options.
    n_modes
        Number of physical modes to return (lowest first).
    method
        ``"transition_fd"`` (``mjd_transitionFD``) or ``"constrained"`` (constrained eigen-solve).
    """
    built = build_manipulator(config or default_config(), pose, options)
    result = analyse(built, method, n_modes)
    assert isinstance(result, ModalResult)
    return result


def rig_modes(
    rig: str,
    *,
    angle_deg: float = 180.0,
    piece: RigConfig | None = None,
    config: Manipulator | None = None,
    options: ModelOptions | None = None,
    n_modes: int | None = 10,
    method: Method = "transition_fd",
    damping_beta_s: float = 0.0,
) -> ModalResult:
    """Modes of one of the study's subsystem rigs (``free-free``, ``cantilever``, ``chain``).

    ``damping_beta_s`` is the rig's stiffness-proportional damping (s); 0 by default: the study's
    rigs report frequencies only, and the manipulator's assumed structural damping (1 % at 60 Hz)
    would give the bar's kHz modes damping ratios of 0.2 to 0.9.
    """
    cfg = config or default_config()
    setup = RigSetup(rig, angle_deg=angle_deg, damping_beta_s=damping_beta_s)
    built = build_rig(setup, piece or rig_piece(cfg), options, compliance=cfg.compliance)
    result = analyse(built, method, n_modes)
    assert isinstance(result, ModalResult)
    return result
