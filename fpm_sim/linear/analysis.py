"""Internal: the modal analysis behind :func:`fpm_sim.modes` and :func:`fpm_sim.rig_modes`.

Not a public surface: users call the facade (``import fpm_sim as fs``; :mod:`fpm_sim.api`). The functions
here take the built model or, like the facade, the description first (``config``, then the pose or rig).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from fpm_sim.config import Manipulator, RigConfig, default_config
from fpm_sim.errors import FpmSimError
from fpm_sim.kinematics import Pose
from fpm_sim.linear.equilibrium import static_equilibrium
from fpm_sim.linear.modes import ModalResult
from fpm_sim.linear.solvers import Method, modes_constrained, modes_transition_fd
from fpm_sim.linear.threads import blas_threads
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import ModelOptions
from fpm_sim.model.rigs import RigSetup, build_rig, rig_piece
from fpm_sim.model.spec import BuiltModel

__all__ = ["ModalComparison", "analyse", "compare_methods", "manipulator_modes", "rig_modes"]


@dataclass
class ModalComparison:
    """The same model analysed by both methods."""

    transition_fd: ModalResult
    constrained: ModalResult

    def relative_differences(self, n_modes: int | None = None) -> list[float]:
        """``f_transition_fd / f_constrained - 1`` for the first ``n_modes`` modes (``None``: all)."""
        a, b = self.transition_fd.frequencies_hz, self.constrained.frequencies_hz
        n = min(len(a), len(b)) if n_modes is None else min(n_modes, len(a), len(b))
        return [float(a[i] / b[i] - 1.0) for i in range(n)]

    def to_dict(self, n_modes: int | None = None) -> dict[str, Any]:
        """The transitionFD result's dictionary with the constrained modes and the relative differences
        under ``cross_check``."""
        payload = self.transition_fd.to_dict(n_modes)
        payload["cross_check"] = {
            "method": "constrained",
            "modes": self.constrained.to_dict(n_modes)["modes"],
            "relative_difference": self.relative_differences(n_modes),
        }
        return payload

    def table(self, n_modes: int | None = None) -> str:
        """Both methods' frequencies side by side, their relative difference and the damping ratio."""
        a, b = self.transition_fd.modes, self.constrained.modes
        lines = [f"{'mode':>4}  {'transitionFD (Hz)':>17}  {'constrained (Hz)':>16}  {'diff':>8}  {'damping':>8}"]
        for i, d in enumerate(self.relative_differences(n_modes)):
            lines.append(
                f"{i + 1:>4}  {a[i].frequency_hz:>17.3f}  {b[i].frequency_hz:>16.3f}  {d:>8.2e}  "
                f"{a[i].damping_ratio:>8.4f}"
            )
        from fpm_sim.model.options import resolution_footer

        footer = resolution_footer(self.transition_fd.built.parameters)
        return "\n".join([*lines, footer] if footer else lines)

    def plot(self, ax: Any = None) -> Any:
        """Relative difference ``|f_transition_fd / f_constrained - 1|`` per mode (log scale); returns the
        ``Figure``."""
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(figsize=(5.5, 3.5), constrained_layout=True)
        diff = np.abs(np.asarray(self.relative_differences(), float))
        ax.semilogy(np.arange(1, len(diff) + 1), np.maximum(diff, 1e-16), "o-")
        ax.set_xticks(np.arange(1, len(diff) + 1))
        ax.set_xlabel("mode")
        ax.set_ylabel("|f transitionFD / f constrained - 1|")
        ax.set_title("the two linearisations of the same model")
        ax.grid(True, which="both", alpha=0.3)
        return ax.figure


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
    config: Manipulator | None,
    pose: Pose,
    *,
    options: ModelOptions | None = None,
    n_modes: int | None = 10,
    method: Method = "transition_fd",
) -> ModalResult:
    """Natural frequencies, damping ratios and mode shapes of the manipulator at ``pose``.

    Parameters
    ----------
    config
        Manipulator description; ``None``: the embedded default.
    pose
        End-effector pose (m, m, rad).
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
    config: Manipulator | None,
    rig: str,
    *,
    angle_deg: float = 180.0,
    piece: RigConfig | None = None,
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
