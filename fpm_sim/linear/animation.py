"""Mode shapes you can watch: an animated GIF of one mode of any built model, the deformed links moving over
the undeformed ones for one period.

The points drawn are the ones :class:`fpm_sim.linear.modes.ModalResult` gives (its ``point_positions`` and
``point_displacements``: the sites along every link of :attr:`fpm_sim.model.spec.BuiltModel.links`), so the 3RRR
and every described architecture animate alike: one colour per leg (the links hanging from one another in the
model's tree), the platform (end effector) through the link ends that move with it. The axes are 3D when the
machine is spatial or the mode leaves the machine's plane, else 2D in that plane. Frames are rendered by
matplotlib's Agg renderer into a figure that belongs to no window (no ``pyplot``, no display, no OpenGL) and
written by matplotlib's Pillow writer, so it runs on a headless machine.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import mujoco
import numpy as np

from fpm_sim.errors import FpmSimError

__all__ = [
    "AMPLITUDE_FRACTION",
    "OUT_OF_PLANE_SHARE",
    "AnimationError",
    "ModeMotion",
    "animate_mode",
    "frame_figure",
    "mode_motion",
]

AMPLITUDE_FRACTION = 0.15
"""Drawn length of the largest point displacement, as a fraction of the model's size (the largest span of the
point positions along x, y or z)."""

OUT_OF_PLANE_SHARE = 0.05
"""A planar machine's mode is drawn in 3D when more than this share of its squared point displacements is
normal to the machine's plane."""

PLANAR_TOLERANCE = 0.02
"""A machine is planar when its points span at most this fraction of its size along one world axis."""

END_EFFECTOR_SITES = ("platform_center", "end_effector_site")
"""Sites at the end effector (the 3RRR's platform; a described architecture's end effector)."""

LEG_COLOURS = ("C0", "C1", "C2", "C3", "C4", "C5", "C6", "C8", "C9")
"""One colour per leg: matplotlib's cycle without its grey (C7), which would read as the equilibrium."""

DPI = 80
FIGSIZE_IN = (5.0, 4.8)
MAX_FRAMES = 240
MAX_FPS = 50


class AnimationError(FpmSimError):
    """An animation that cannot be made: a mode beyond those found, too few frames, a frame rate out of range, a
    drawn length that is not positive, a file that is not a ``.gif``."""


class AnimatedModes(Protocol):
    """What the animation reads of a modal result (:class:`fpm_sim.linear.modes.ModalResult` has it)."""

    built: Any
    qpos: np.ndarray
    modes: list[Any]

    def point_positions(self) -> dict[str, np.ndarray]: ...

    def point_displacements(self, index: int) -> dict[str, np.ndarray]: ...


@dataclass(frozen=True)
class ModeMotion:
    """One mode as drawn: the points at equilibrium and their displacement at the drawn amplitude.

    Attributes
    ----------
    positions
        Link name -> points along it at equilibrium, ``(n, 3)`` (m).
    displacements
        Link name -> the points' displacement at the peak of the motion, ``(n, 3)`` (m, already scaled).
    platform
        The platform's outline through the link ends that move with it, ``(k, 3)`` (m; closed when ``k >= 3``,
        empty when the model has no end effector site or fewer than two distinct link ends move with it).
    platform_displacement
        The outline's displacement at the peak, ``(k, 3)`` (m).
    axes
        The world axes drawn: ``(0, 1, 2)`` in 3D, or the two axes of the machine's plane.
    amplitude_m
        Drawn length of the largest point displacement (m).
    size_m
        The model's size: the largest span of the point positions along x, y or z (m).
    out_of_plane
        Share of the squared point displacements normal to the machine's plane (1 for a spatial machine).
    planar
        Whether the machine lies in a plane of the world's axes.
    legs
        Link name -> its leg (0, 1, ...): a link hanging from another one in the model's tree is in that one's leg.
    """

    positions: dict[str, np.ndarray]
    displacements: dict[str, np.ndarray]
    platform: np.ndarray
    platform_displacement: np.ndarray
    axes: tuple[int, ...]
    amplitude_m: float
    size_m: float
    out_of_plane: float
    planar: bool
    legs: dict[str, int]


def _check(n_modes: int, mode: int, scale_m: float | None, frames: int = 2, fps: int = 1) -> None:
    if isinstance(mode, bool) or not isinstance(mode, (int, np.integer)) or not 1 <= mode <= n_modes:
        raise AnimationError(
            f"must be one of the {n_modes} physical modes found (1-based)",
            parameter="mode",
            value=mode,
            hint=f"choose 1..{n_modes}" if n_modes else "there is no mode to draw",
        )
    if isinstance(frames, bool) or not isinstance(frames, (int, np.integer)) or not 2 <= frames <= MAX_FRAMES:
        raise AnimationError(f"must be a whole number in 2..{MAX_FRAMES}", parameter="frames", value=frames)
    if isinstance(fps, bool) or not isinstance(fps, (int, np.integer)) or not 1 <= fps <= MAX_FPS:
        raise AnimationError(f"must be a whole number of frames per second in 1..{MAX_FPS}", parameter="fps", value=fps)
    if scale_m is not None and not (math.isfinite(scale_m) and scale_m > 0):
        raise AnimationError("must be a positive length (m)", parameter="scale_m", value=scale_m)


def _plane_normal(points: np.ndarray, size: float) -> int | None:
    """The world axis normal to the machine's plane, or ``None`` for a spatial machine."""
    spans = np.ptp(points, axis=0)
    k = int(np.argmin(spans))
    return k if spans[k] <= PLANAR_TOLERANCE * size else None


def _platform(result: AnimatedModes, index: int) -> tuple[np.ndarray, np.ndarray]:
    """The platform outline and its (unit-shape) displacement of mode ``index``: the link ends that move with the
    end effector body (jointed to it: their point's Jacobian equals the end effector's at that point on every
    motion the loop closures admit), ordered around their centre in their best-fit plane. Empty when the model has
    no end effector site or fewer than two distinct link ends move with it."""
    from fpm_sim.linear.nullspace import constraint_rank

    model = result.built.model
    sites = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, s) for s in END_EFFECTOR_SITES]
    if max(sites) < 0:
        return np.zeros((0, 3)), np.zeros((0, 3))
    data = mujoco.MjData(model)
    data.qpos[:] = result.qpos
    mujoco.mj_forward(model, data)
    body = int(model.site_bodyid[max(sites)])
    admissible = constraint_rank(model, data, warn=False).basis  # (nv, free motions)
    shape = result.modes[index].shape
    js, je = np.zeros((3, model.nv)), np.zeros((3, model.nv))
    ends, moves = [], []
    for names in result.built.links.values():
        sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, names[-1])
        p = data.site_xpos[sid].copy()
        mujoco.mj_jacSite(model, data, js, None, sid)
        mujoco.mj_jac(model, data, je, None, p, body)
        ref = max(np.linalg.norm(js @ admissible, 2), np.linalg.norm(je @ admissible, 2))
        if ref > 0 and np.linalg.norm((js - je) @ admissible, 2) <= 1e-6 * ref:
            ends.append(p)
            moves.append(js @ shape)
    pts, disp = _distinct(ends, moves)
    if len(pts) < 2:
        return np.zeros((0, 3)), np.zeros((0, 3))
    if len(pts) >= 3:
        centred = pts - pts.mean(axis=0)
        _, _, vt = np.linalg.svd(centred)
        order = np.argsort(np.arctan2(centred @ vt[1], centred @ vt[0]))
        pts, disp = pts[[*order, order[0]]], disp[[*order, order[0]]]
    return pts, disp


def _distinct(points: list[np.ndarray], moves: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The points (and their displacements) with coincident ones (closer than 0.1 mm) kept once."""
    keep: list[int] = []
    for k, p in enumerate(points):
        if all(np.linalg.norm(p - points[j]) > 1e-4 for j in keep):
            keep.append(k)
    return np.array([points[k] for k in keep]).reshape(-1, 3), np.array([moves[k] for k in keep]).reshape(-1, 3)


def _legs(built: Any) -> dict[str, int]:
    """Link name -> leg number: walking up the model's body tree from a link's first point, the first body that
    carries another link's points puts the link in that link's leg; a link with none above it starts a leg."""
    model = built.model
    body_of: dict[int, str] = {}
    for link, sites in built.links.items():
        for s in sites:
            body_of.setdefault(int(model.site_bodyid[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, s)]), link)
    above: dict[str, str | None] = {}
    for link, sites in built.links.items():
        b = int(model.site_bodyid[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, sites[0])])
        while b > 0 and body_of.get(b, link) == link:
            b = int(model.body_parentid[b])
        above[link] = body_of.get(b) if b > 0 else None
    tops: dict[str, int] = {}
    legs: dict[str, int] = {}
    for link in built.links:
        top = link
        while (up := above[top]) is not None:
            top = up
        legs[link] = tops.setdefault(top, len(tops))
    return legs


def mode_motion(result: AnimatedModes, index: int, *, scale_m: float | None = None) -> ModeMotion:
    """The points of mode ``index`` (0-based) of ``result`` as drawn, the largest point displacement scaled to
    ``scale_m`` (m; ``None``: :data:`AMPLITUDE_FRACTION` of the model's size)."""
    pos = result.point_positions()
    disp = result.point_displacements(index)
    every_p = np.concatenate(list(pos.values()))
    every_d = np.concatenate(list(disp.values()))
    size = max(float(np.ptp(every_p, axis=0).max()), 1e-3)
    peak = float(np.max(np.linalg.norm(every_d, axis=1))) or 1.0
    amplitude = AMPLITUDE_FRACTION * size if scale_m is None else float(scale_m)
    factor = amplitude / peak
    normal = _plane_normal(every_p, size)
    total = float(np.sum(every_d**2))
    out = 1.0 if normal is None else (float(np.sum(every_d[:, normal] ** 2)) / total if total > 0 else 0.0)
    axes = (0, 1, 2) if normal is None or out > OUT_OF_PLANE_SHARE else tuple(a for a in range(3) if a != normal)
    platform, platform_d = _platform(result, index)
    return ModeMotion(
        positions=pos,
        displacements={k: v * factor for k, v in disp.items()},
        platform=platform,
        platform_displacement=platform_d * factor,
        axes=axes,
        amplitude_m=amplitude,
        size_m=size,
        out_of_plane=out,
        planar=normal is not None,
        legs=_legs(result.built),
    )


def _limits(motion: ModeMotion) -> list[tuple[float, float]]:
    """Axis limits (mm) holding every frame, each axis at least 40 % of the model's size (equal scales)."""
    every_p = np.concatenate(list(motion.positions.values())) * 1e3
    pad = motion.amplitude_m * 1e3 * 1.1
    lo, hi = every_p.min(axis=0) - pad, every_p.max(axis=0) + pad
    least = 0.4 * motion.size_m * 1e3
    mid, half = (lo + hi) / 2, np.maximum((hi - lo) / 2, least / 2)
    return [(float(mid[a] - half[a]), float(mid[a] + half[a])) for a in motion.axes]


def _character(mode: Any) -> str:
    top = sorted(mode.character.items(), key=lambda kv: -kv[1])[:2]
    return ", ".join(f"{k} {v:.0%}" for k, v in top if v > 0.005) or "-"


def _figure(result: AnimatedModes, index: int, motion: ModeMotion) -> tuple[Any, Any]:
    """The figure (no window) and its axes: 3D or 2D, equal scales, the title and the caption."""
    from matplotlib.figure import Figure

    from fpm_sim.figures import wrap_title

    fig = Figure(figsize=FIGSIZE_IN, dpi=DPI)
    spatial = len(motion.axes) == 3
    ax: Any = fig.add_subplot(projection="3d") if spatial else fig.add_subplot()
    limits = _limits(motion)
    for a, (lo, hi) in enumerate(limits):  # the axes' own x, y (z) hold the world axes drawn
        getattr(ax, f"set_{'xyz'[a]}lim")(lo, hi)
        getattr(ax, f"set_{'xyz'[a]}label")(f"{'xyz'[motion.axes[a]]} (mm)", fontsize=9)
    ax.tick_params(labelsize=8)
    ax.locator_params(nbins=5)
    if spatial:
        ax.set_box_aspect([hi - lo for lo, hi in limits], zoom=0.9)
        for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
            axis.set_pane_color((1.0, 1.0, 1.0, 0.0))
        fig.subplots_adjust(left=0.0, right=0.93, bottom=0.1, top=0.95)
    else:
        ax.set_aspect("equal")
        fig.subplots_adjust(left=0.14, right=0.97, bottom=0.14, top=0.9)
    m = result.modes[index]
    title = f"mode {index + 1}: {m.frequency_hz:.2f} Hz, {_character(m)}"
    fig.suptitle(wrap_title(title, fig, 12), fontsize=12)
    caption = f"grey: equilibrium; largest displacement drawn {motion.amplitude_m * 1e3:.3g} mm (exaggerated)"
    if spatial and motion.planar:
        caption += f"; out of plane {motion.out_of_plane:.0%}"
    fig.text(0.5, 0.015, wrap_title(caption, fig, 8), fontsize=8, ha="center", va="bottom", color="0.25")
    return fig, ax


def _xyz(points: np.ndarray, axes: tuple[int, ...]) -> list[np.ndarray]:
    return [points[:, a] * 1e3 for a in axes]


def _draw(ax: Any, motion: ModeMotion) -> list[tuple[Any, np.ndarray, np.ndarray]]:
    """The undeformed links (light grey, fixed) and the moving ones, one colour per leg, joints as dots, points
    that never move (the base joints) as dark grey triangles; returns (line, points, displacement) of what moves."""
    moving = []
    for link, p in motion.positions.items():
        d = motion.displacements[link]
        ax.plot(*_xyz(p, motion.axes), color="0.72", lw=1.5)
        colour = LEG_COLOURS[motion.legs[link] % len(LEG_COLOURS)]
        style = {"lw": 2.2, "marker": "o", "ms": 3.5, "markevery": [0, len(p) - 1], "solid_capstyle": "round"}
        (line,) = ax.plot(*_xyz(p, motion.axes), color=colour, **style)
        moving.append((line, p, d))
        still = [k for k in (0, len(p) - 1) if np.linalg.norm(d[k]) <= 1e-9 * motion.amplitude_m]
        if still:
            ax.plot(*_xyz(p[still], motion.axes), ls="none", marker="^", ms=7, color="0.35")
    if len(motion.platform):
        ax.plot(*_xyz(motion.platform, motion.axes), color="0.72", lw=1.5)
        (line,) = ax.plot(*_xyz(motion.platform, motion.axes), color="k", lw=1.6)
        moving.append((line, motion.platform, motion.platform_displacement))
    return moving


def animate_mode(
    result: AnimatedModes,
    path: str | Path,
    *,
    mode: int = 1,
    frames: int = 24,
    fps: int = 12,
    scale_m: float | None = None,
) -> Path:
    """Write an animated GIF of mode ``mode`` (1-based) of ``result``: one period in ``frames`` frames at
    ``fps`` frames per second, looping; the largest point displacement drawn ``scale_m`` long (m; ``None``:
    :data:`AMPLITUDE_FRACTION` of the model's size). The file is written atomically; returns its path.

    Raises
    ------
    AnimationError
        ``mode`` is not one of the modes found, ``frames`` not in 2..240, ``fps`` not in 1..50, ``scale_m`` not
        positive, or ``path`` does not end in ``.gif``.
    fpm_sim.outputs.OutputError
        ``path`` cannot be written.
    """
    from matplotlib.animation import PillowWriter

    from fpm_sim.outputs import atomic_file

    path = Path(path)
    if path.suffix.lower() != ".gif":
        raise AnimationError("the animation is a GIF", parameter="path", value=str(path), hint="end the name in .gif")
    _check(len(result.modes), mode, scale_m, frames, fps)
    fig, moving, axes = _scene(result, mode - 1, scale_m)
    writer = PillowWriter(fps=fps)
    with atomic_file(path) as tmp, writer.saving(fig, str(tmp), dpi=DPI):
        for k in range(frames):
            # a quarter frame off the peak: no two frames alike (Pillow would merge neighbours), frame 0 the peak
            _move(moving, axes, math.cos(2.0 * math.pi * (k + 0.25) / frames))
            writer.grab_frame()
    return path


def frame_figure(result: AnimatedModes, *, mode: int = 1, phase: float = 1.0, scale_m: float | None = None) -> Any:
    """One frame of :func:`animate_mode` as a ``matplotlib.figure.Figure`` (belonging to no window): mode ``mode``
    (1-based) at ``phase`` of its peak displacement (-1..1; 1: the peak), the largest point displacement drawn
    ``scale_m`` long (m; ``None``: :data:`AMPLITUDE_FRACTION` of the model's size)."""
    _check(len(result.modes), mode, scale_m)
    fig, moving, axes = _scene(result, mode - 1, scale_m)
    _move(moving, axes, phase)
    return fig


def _scene(result: AnimatedModes, index: int, scale_m: float | None) -> tuple[Any, list[Any], tuple[int, ...]]:
    motion = mode_motion(result, index, scale_m=scale_m)
    fig, ax = _figure(result, index, motion)
    return fig, _draw(ax, motion), motion.axes


def _move(moving: list[tuple[Any, np.ndarray, np.ndarray]], axes: tuple[int, ...], phase: float) -> None:
    """The moving lines at ``phase`` of the peak displacement."""
    for line, p, d in moving:
        xyz = _xyz(p + phase * d, axes)
        if len(xyz) == 3:
            line.set_data_3d(*xyz)
        else:
            line.set_data(*xyz)
