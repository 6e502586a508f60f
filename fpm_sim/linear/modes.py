"""The result of a modal analysis: the modes of one model by one method, their strain-energy character,
tables, JSON, 3D plots and animated GIFs (:mod:`fpm_sim.linear.animation`) of the mode shapes (the methods
that compute them: :mod:`fpm_sim.linear.solvers`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from fpm_sim.model.spec import BuiltModel

__all__ = [
    "ModalResult",
    "Mode",
    "real_shape",
    "strain_energy_character",
]


@dataclass
class Mode:
    """One physical mode.

    Attributes
    ----------
    frequency_hz
        Undamped natural frequency.
    damping_ratio
        Viscous damping ratio.
    shape
        Generalised shape (one entry per degree of freedom), real, max-abs normalised to 1.
    character
        Fraction of the mode's strain energy in each spring kind (bend_in, bend_out, twist, ...).
    constraint_ratio
        Loop-closure violation of the shape (``|J v| / (|J|_2 |v|)``).
    """

    frequency_hz: float
    damping_ratio: float
    shape: np.ndarray
    character: dict[str, float]
    constraint_ratio: float

    @property
    def dominant(self) -> str:
        return max(self.character, key=self.character.__getitem__) if self.character else "-"


@dataclass
class ModalResult:
    """Modes of one model by one method, with what was dropped and why."""

    method: str
    built: BuiltModel
    qpos: np.ndarray
    modes: list[Mode]
    dropped: dict[str, int] = field(default_factory=dict)

    @property
    def frequencies_hz(self) -> np.ndarray:
        return np.array([m.frequency_hz for m in self.modes])

    @property
    def damping_ratios(self) -> np.ndarray:
        return np.array([m.damping_ratio for m in self.modes])

    def point_displacements(self, index: int) -> dict[str, np.ndarray]:
        """Cartesian displacement (m per unit generalised amplitude) of points along each link.

        Returns link name -> array (n_points, 3), points from the link's start to its end.
        """
        model = self.built.model
        data = mujoco.MjData(model)
        data.qpos[:] = self.qpos
        mujoco.mj_forward(model, data)
        v = self.modes[index].shape
        jacp = np.zeros((3, model.nv))
        out: dict[str, np.ndarray] = {}
        for link, sites in self.built.links.items():
            pts = []
            for s in sites:
                sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, s)
                mujoco.mj_jacSite(model, data, jacp, None, sid)
                pts.append(jacp @ v)
            out[link] = np.array(pts)
        return out

    def point_positions(self) -> dict[str, np.ndarray]:
        """Positions (m) of the same points at the equilibrium."""
        model = self.built.model
        data = mujoco.MjData(model)
        data.qpos[:] = self.qpos
        mujoco.mj_forward(model, data)
        return {link: np.array([data.site(s).xpos.copy() for s in sites]) for link, sites in self.built.links.items()}

    def to_dict(self, n_modes: int | None = None) -> dict[str, Any]:
        """JSON-ready modes (frequency Hz, damping ratio, character), what was dropped, the resolution."""
        from fpm_sim.model.options import resolution_of_parameters

        modes = self.modes[:n_modes] if n_modes else self.modes
        return {
            "method": self.method,
            "modes": [
                {
                    "frequency_hz": m.frequency_hz,
                    "damping_ratio": m.damping_ratio,
                    "dominant": m.dominant,
                    "character": {k: round(v, 4) for k, v in m.character.items()},
                }
                for m in modes
            ],
            "dropped": dict(self.dropped),
            "resolution": resolution_of_parameters(self.built.parameters),
            "parameters": self.built.parameters,
        }

    def table(self, n_modes: int | None = None) -> str:
        """A plain-text table of the modes, ending with the model's resolution (segments per link and the
        estimated discretisation error of f1) where the model records it."""
        from fpm_sim.model.options import resolution_footer

        modes = self.modes[:n_modes] if n_modes else self.modes
        lines = [f"{'mode':>4}  {'freq (Hz)':>11}  {'damping':>8}  {'character':<30}"]
        for i, m in enumerate(modes, 1):
            top = sorted(m.character.items(), key=lambda kv: -kv[1])[:2]
            char = ", ".join(f"{k} {v:.0%}" for k, v in top if v > 0.005)
            lines.append(f"{i:>4}  {m.frequency_hz:>11.3f}  {m.damping_ratio:>8.4f}  {char:<30}")
        footer = resolution_footer(self.built.parameters)
        return "\n".join([*lines, footer] if footer else lines)

    def plot(self, ax: Any = None, *, index: int | None = None, n_modes: int = 1, scale_m: float = 0.03) -> Any:
        """Draw mode shapes in 3D over the equilibrium shape (matplotlib); returns the ``Figure``.

        Parameters
        ----------
        ax
            A 3D axes (``projection="3d"``) to draw mode ``index`` (default 0) on; ``None`` makes a new
            figure with the first ``n_modes`` modes side by side (or mode ``index`` alone).
        index
            The mode to draw (0-based).
        n_modes
            Modes drawn on a new figure when ``index`` is not given.
        scale_m
            Drawn length of the largest point displacement (m); out-of-plane modes show along z.
        """
        import matplotlib.pyplot as plt

        if ax is not None:
            self._plot_mode(ax, 0 if index is None else index, scale_m)
            return ax.figure
        indices = [index] if index is not None else list(range(max(1, min(n_modes, len(self.modes)))))
        fig = plt.figure(figsize=(4.5 * len(indices), 4.5))
        for k, i in enumerate(indices):
            self._plot_mode(fig.add_subplot(1, len(indices), k + 1, projection="3d"), i, scale_m)
        fig.tight_layout()
        return fig

    def animate(
        self,
        path: str | Path,
        *,
        mode: int = 1,
        frames: int = 24,
        fps: int = 12,
        scale_m: float | None = None,
    ) -> Path:
        """Write an animated GIF of one mode shape: the deformed links over the undeformed ones for one period,
        in 3D where the mode leaves the machine's plane, with its frequency in the title
        (:func:`fpm_sim.linear.animation.animate_mode`). Headless: matplotlib's Agg renderer and Pillow writer.

        Parameters
        ----------
        path
            The ``.gif`` file to write (atomically).
        mode
            The mode to draw, 1-based (1 .. the number of modes found).
        frames
            Frames per period (2..240); the GIF loops.
        fps
            Frames per second of the GIF (1..50).
        scale_m
            Drawn length of the largest point displacement (m); ``None``: 15 % of the model's size.

        Returns
        -------
        Path
            The file written.

        Raises
        ------
        fpm_sim.linear.animation.AnimationError
            ``mode`` beyond the modes found (``parameter="mode"``), bad ``frames``, ``fps`` or ``scale_m``.
        """
        from fpm_sim.linear.animation import animate_mode

        return animate_mode(self, path, mode=mode, frames=frames, fps=fps, scale_m=scale_m)

    def _plot_mode(self, ax: Any, index: int, scale_m: float) -> None:
        pos = self.point_positions()
        disp = self.point_displacements(index)
        peak = max(float(np.max(np.linalg.norm(d, axis=1))) for d in disp.values()) or 1.0
        ends, ends0 = [], []
        for k, (link, p) in enumerate(pos.items()):
            ax.plot(p[:, 0], p[:, 1], p[:, 2], color="0.55", lw=1, ls="--", label="equilibrium" if k == 0 else None)
            q = p + disp[link] * (scale_m / peak)
            label = f"mode shape (largest displacement drawn {scale_m * 1e3:g} mm)" if k == 0 else None
            ax.plot(q[:, 0], q[:, 1], q[:, 2], lw=2, color="C0", label=label)
            if link.startswith("distal"):
                ends.append(q[-1])
                ends0.append(p[-1])
        if len(ends) == 3:  # the platform triangle through the platform joints, deformed and at equilibrium
            tri0 = np.array(ends0 + ends0[:1])
            ax.plot(tri0[:, 0], tri0[:, 1], tri0[:, 2], color="0.55", lw=1, ls="--")
            tri = np.array(ends + ends[:1])
            ax.plot(tri[:, 0], tri[:, 1], tri[:, 2], color="k", lw=1.5, label="platform")
        ax.legend(fontsize=7, loc="upper left")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_zlabel("z (m)")
        from matplotlib.ticker import MaxNLocator

        for axis in (ax.xaxis, ax.yaxis, ax.zaxis):  # a few ticks each: a 2 m arm's labels otherwise run together
            axis.set_major_locator(MaxNLocator(nbins=5))
        points = np.concatenate(list(pos.values()))
        span = max(float(np.ptp(points, axis=0).max()), 1e-3)  # a planar machine's: its x-y extent
        mid = 0.5 * (points.min(axis=0) + points.max(axis=0))
        ax.set_zlim(mid[2] - span / 2, mid[2] + span / 2)
        if np.ptp(points[:, 2]) > np.ptp(points[:, :2], axis=0).max():  # a machine standing up (an imported arm)
            half = span / 2 + scale_m
            ax.set_xlim(mid[0] - half, mid[0] + half)
            ax.set_ylim(mid[1] - half, mid[1] + half)
            ax.set_zlim(mid[2] - half, mid[2] + half)
        m = self.modes[index]
        ax.set_title(f"mode {index + 1}: {m.frequency_hz:.2f} Hz, {m.dominant}")


def strain_energy_character(shape: np.ndarray, k_dof: np.ndarray, kinds: list[str]) -> dict[str, float]:
    energy = 0.5 * k_dof * shape**2
    total = float(energy.sum())
    out: dict[str, float] = {}
    if total <= 0.0:
        return out
    for kind, e in zip(kinds, energy):
        if e > 0:
            out[kind] = out.get(kind, 0.0) + float(e) / total
    return out


def real_shape(v: np.ndarray) -> np.ndarray:
    """Rotate a complex shape to its dominant real form, max-abs normalised with a positive peak."""
    k = int(np.argmax(np.abs(v)))
    if abs(v[k]) == 0.0:
        return np.real(v)
    r = np.real(v * np.conj(v[k]) / abs(v[k]))
    normalised: np.ndarray = r / r[k]
    return normalised
