"""``fpm-sim atlas build|query``: reduced models on a pose grid, tracked by MAC, interpolated between."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

from fpm_sim.cli.common import (
    CliError,
    add_config_args,
    add_output_args,
    add_pose_args,
    add_resolution_args,
    check_output_file,
    count_arg,
    emit,
    load_machine,
    model_options,
    pose_of,
    read_input_file,
    resolution_line,
    with_resolution,
)
from fpm_sim.cli.main import PLOT_SUFFIXES, save_figure

__all__ = ["register"]

PAPER_GRID_MM = [-100.0, -50.0, 0.0, 50.0, 100.0]  # study.poses.GRID_MM (a test checks), kept light for --help
DESCRIBED_HALF_WIDTH_MM = 20.0
"""A described architecture's default grid: its first check pose and +-20 mm in x and y (3 x 3 poses, the fewest
with an interpolation error estimate)."""


def _grid(args: argparse.Namespace, machine: Any) -> tuple[list[float], list[float], list[float]]:
    """The grid (m, m, rad) of the options, or the default: the study's 5 x 5 paper grid at phi 0 for the 3RRR,
    the first check pose and +-20 mm for a described architecture (its phi where it sets one)."""
    from fpm_sim.architecture import Description
    from fpm_sim.architecture.imported import ImportedDescription

    if isinstance(machine, ImportedDescription):
        return _imported_grid(args, machine)
    if isinstance(machine, Description):
        home = machine.check_poses[0] if machine.check_poses else {}
        h = DESCRIBED_HALF_WIDTH_MM
        xs = [home.get("x", 0.0) * 1e3 + d for d in (-h, 0.0, h)]
        ys = [home.get("y", 0.0) * 1e3 + d for d in (-h, 0.0, h)]
        phis = [home.get("phi", 0.0)]
    else:
        xs, ys, phis = PAPER_GRID_MM, PAPER_GRID_MM, [0.0]
    x_mm = args.x_mm if args.x_mm is not None else xs
    y_mm = args.y_mm if args.y_mm is not None else ys
    return [v * 1e-3 for v in x_mm], [v * 1e-3 for v in y_mm], args.phi_rad if args.phi_rad is not None else phis


def _imported_grid(args: argparse.Namespace, desc: Any) -> tuple[list[float], list[float], list[float]]:
    """An imported model's grid (m, m, rad): ``--x-mm`` and ``--y-mm`` as given (it states no reach or check pose to
    centre a default on; refused naming them when absent), ``--phi-rad`` or, where its task coordinates hold phi, its
    end-effector site's phi at the model's reference."""
    if args.x_mm is None or args.y_mm is None:
        missing = " and ".join(f for f, v in (("--x-mm", args.x_mm), ("--y-mm", args.y_mm)) if v is None)
        raise CliError(
            f"{missing}: an imported model states no reach or check pose to centre a default grid on; give the grid's "
            "values in its end-effector site's x and y (mm), e.g. --x-mm -20 0 20 --y-mm 230 250 270"
        )
    phis = args.phi_rad
    if phis is None:
        phis = [0.0]
        if "phi" in desc.task:
            from fpm_sim.model.imported_pose import ImportedKinematics

            phis = [ImportedKinematics(desc).reference_pose().phi_rad]
    return [v * 1e-3 for v in args.x_mm], [v * 1e-3 for v in args.y_mm], phis


def cmd_atlas_build(args: argparse.Namespace) -> int:
    import numpy as np

    from fpm_sim.model.options import warn_if_coarse
    from fpm_sim.outputs import atomic_file
    from fpm_sim.rom.atlas import build_atlas

    check_output_file(args.out, "--out", (".npz",))
    check_output_file(args.plot, "--plot", PLOT_SUFFIXES)
    opts = model_options(args)
    machine = load_machine(args, "atlas")
    x_m, y_m, phi_rad = _grid(args, machine)
    warn_if_coarse(opts)
    atlas = build_atlas(
        machine,
        x_m=x_m,
        y_m=y_m,
        phi_rad=phi_rad,
        z_m=None if args.z_mm is None else args.z_mm * 1e-3,
        options=opts,
        n_modes=args.modes,
        n_extra=args.extra,
        progress=not args.json,
    )
    with atomic_file(args.out) as tmp:
        atlas.save(tmp)
    if args.plot:
        save_figure(args.plot, atlas.plot)
    payload = with_resolution(atlas.to_dict(), opts)
    payload["out"] = str(args.out)
    weak = atlas.weak_links()
    text = (
        f"atlas of {int(np.prod(atlas.grid_shape))} poses ({' x '.join(map(str, atlas.grid_shape))}), "
        f"{atlas.n_modes} tracked modes; tracked frequency (Hz) per label, (#n) = sorted position where it moved:\n"
        + atlas.table()
        + f"\n{len(atlas.label_changes())} label changes (a mode's shape MAC with the parent pose below 0.5: its "
        "per-label frequency is unreliable there)"
        + f"\n{len(weak)} weak links (aligned basis MAC with the parent pose below 0.8: interpolated models unreliable "
        f"there); lowest aligned MAC {float(atlas.nodes['mac_aligned'].min()):.3f}"
        + "\n"
        + resolution_line(opts)
        + f"\nwrote {args.out}"
        + (f"\nwrote {args.plot}" if args.plot else "")
    )
    emit(args, payload, text)
    return 0


def cmd_atlas_query(args: argparse.Namespace) -> int:
    import numpy as np

    from fpm_sim.model.options import ModelOptions
    from fpm_sim.outputs import atomic_file
    from fpm_sim.rom.atlas import AtlasError, load_atlas, mac_matrix, model_at
    from fpm_sim.rom.reduction import modal_system

    check_output_file(args.out, "--out", (".mat", ".npz"))
    atlas = read_input_file(args.atlas, "atlas", load_atlas, "an atlas written by 'fpm-sim atlas build --out FILE.npz'")
    pose, pose_label = _query_pose(args, atlas)
    rom = atlas.query(pose, method=args.method)
    if args.out:
        with atomic_file(args.out) as tmp:
            rom.save(tmp)
    o = atlas.parameters.get("options", {})
    opts = ModelOptions(
        **{k: o[k] for k in ("link_model", "segments", "axial", "rotary_inertia", "gravity", "timestep_s") if k in o}
    )
    payload = with_resolution(rom.to_dict(), opts)
    payload["atlas"] = str(args.atlas)
    lines = [f"interpolated reduced model at {pose_label} from {args.atlas} ({args.method}):"]
    if args.direct:
        manip = load_machine(args, "atlas")
        if manip.name != atlas.parameters.get("config"):
            raise AtlasError(
                f"the atlas was built for config {atlas.parameters.get('config')!r}, not {manip.name!r}; "
                "pass its --config"
            )
        system = modal_system(model_at(manip, pose, opts))
        # each interpolated mode against the direct mode of the most similar shape (MAC), which need not
        # be the same sorted position: the atlas keeps the tracked modes, not always the lowest ones
        mac = mac_matrix(rom.mode_shapes, system.phi)
        match = np.argmax(mac, axis=1)
        direct = system.frequencies_hz[match]
        rel = rom.frequencies_hz / direct - 1.0
        payload["direct_frequencies_hz"] = direct.tolist()
        payload["direct_mode_index"] = (match + 1).tolist()
        payload["mac"] = mac[np.arange(len(match)), match].tolist()
        payload["relative_difference"] = rel.tolist()
        payload["lowest_direct_frequencies_hz"] = system.frequencies_hz[: rom.n_modes].tolist()
        lines.append(
            f"{'mode':>4}  {'atlas (Hz)':>11}  {'direct (Hz)':>11}  {'direct #':>8}  {'MAC':>6}  {'diff %':>8}  "
            f"{'damping':>8}"
        )
        for i, (f, d, j, r, z) in enumerate(zip(rom.frequencies_hz, direct, match, rel, rom.damping_ratios), 1):
            lines.append(
                f"{i:>4}  {f:>11.3f}  {d:>11.3f}  {j + 1:>8}  {mac[i - 1, j]:>6.3f}  {r * 100:>8.3f}  {z:>8.4f}"
            )
        q = rom.parameters.get("atlas_query", {})
        est, node = q.get("error_estimate"), q.get("error_estimate_node")
        worst = float(np.max(np.abs(rel)))
        if est is not None and node is not None and est > 2 * worst:
            lines.append(
                f"atlas vs direct here: at most {100 * worst:.2f} %, well below the estimated {100 * est:.1f} %: the "
                f"estimate is the worst leave-one-out error near the pose (at the grid node ({node[0] * 1e3:g}, "
                f"{node[1] * 1e3:g}) mm), a worst case for the region; this direct comparison is the error at this pose"
            )
        lines.append("resolution (the atlas's): " + resolution_line(opts).removeprefix("resolution: "))
    else:
        lines.append(rom.table())  # ends with the atlas's resolution
    if args.out:
        lines.append(f"wrote {args.out}")
    emit(args, payload, "\n".join(lines))
    return 0


def _query_pose(args: argparse.Namespace, atlas: Any) -> tuple[Any, str]:
    """The query's pose: the 3RRR's (:func:`pose_of`), or a described architecture's task pose in the atlas's task
    coordinates (an option for another coordinate refused by name; one not given takes the atlas's root node, z
    its height), and its label."""
    from fpm_sim.architecture import TaskPose

    machine = atlas.parameters.get("architecture")
    if machine is None:
        pose = pose_of(args)
        return pose, pose.label()
    task = machine["task"]
    given = {"x": args.x_mm, "y": args.y_mm, "z": args.z_mm, "phi": args.phi_rad}
    for c, v in given.items():
        flag = "--phi-rad" if c == "phi" else f"--{c}-mm"
        if v is not None and c not in task:
            raise CliError(
                f"{flag}: the atlas's machine ({atlas.parameters.get('config')}) has no task coordinate {c} (its task "
                f"coordinates are {', '.join(task)}); drop {flag}"
            )
        if v is not None and not math.isfinite(v):
            raise CliError(f"{flag}: must be a finite number, got {v}")
    root = [float(a[i]) for a, i in zip((atlas.x_m, atlas.y_m, atlas.phi_rad), atlas.root)]
    scale = {"x": 1e-3, "y": 1e-3, "phi": 1.0}
    x, y, phi = (r if given[c] is None else given[c] * scale[c] for c, r in zip(("x", "y", "phi"), root))
    z = float(machine["z_m"]) if given["z"] is None else given["z"] * 1e-3
    task_pose = TaskPose(x, y, z, phi)
    return task_pose, task_pose.label(tuple(task))


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "atlas",
        help="modal atlas: reduced models on a pose grid tracked by MAC, interpolated at poses in between",
        description=(
            "build: modal systems on an x/y/phi grid (default the study's 5 x 5 grid, phi 0), modes tracked from the "
            "central pose by MAC and aligned by Procrustes rotations, saved to .npz; on a described architecture "
            "(--config with [[chains]]) the grid is in its task coordinates (x, y; phi where it sets it; a spatial "
            "one at one --z-mm); on an imported model that names an [end_effector] (kind = 'imported') the grid is in "
            "that site's task coordinates and must be given (--x-mm and --y-mm: it states no reach), at its reference "
            "height and phi unless --z-mm, --phi-rad. query: the interpolated reduced model at a pose (optionally "
            "compared with a direct computation, --direct, which needs the atlas's --config; exported with --out); a "
            "described architecture's coordinates not given take the atlas's central pose."
        ),
    )
    sp = p.add_subparsers(dest="atlas_command", required=True)
    b = sp.add_parser("build", help="build and save an atlas")
    b.add_argument(
        "--x-mm",
        type=float,
        nargs="+",
        default=None,
        help="grid x values (mm; default the study's -100..100 step 50 on the 3RRR, the first check pose +-20 mm on "
        "a described architecture; an imported model: required)",
    )
    b.add_argument("--y-mm", type=float, nargs="+", default=None, help="grid y values (mm; default as --x-mm)")
    b.add_argument(
        "--phi-rad",
        type=float,
        nargs="+",
        default=None,
        help="grid rotations (rad, default 0; a described architecture that sets phi: its first check pose's)",
    )
    b.add_argument(
        "--z-mm",
        type=float,
        default=None,
        help="a spatial architecture's height (mm; default its first check pose's): the atlas is a horizontal slice",
    )
    b.add_argument("--modes", type=count_arg("--modes"), default=6, help="tracked modes (default 6)")
    b.add_argument(
        "--extra", type=count_arg("--extra", low=0), default=4, help="extra candidate modes per pose (default 4)"
    )
    add_resolution_args(b, axial=False)
    b.add_argument("--out", type=Path, required=True, help="atlas file (.npz)")
    b.add_argument("--plot", type=Path, help="tracked f1..f3 over the grid (.png, .pdf, .svg)")
    add_config_args(b)
    add_output_args(b)
    b.set_defaults(func=cmd_atlas_build)
    q = sp.add_parser("query", help="interpolated reduced model at a pose")
    q.add_argument("atlas", type=Path, help="atlas file from 'atlas build'")
    q.add_argument("--method", choices=("auto", "linear", "cubic"), default="auto", help="interpolation (default auto)")
    q.add_argument(
        "--direct",
        action=argparse.BooleanOptionalAction,
        default=False,
        help="compare with a direct computation at the pose (default off)",
    )
    q.add_argument("--out", type=Path, help="export the reduced model (.mat or .npz)")
    add_pose_args(q)
    add_config_args(q)
    add_output_args(q)
    q.set_defaults(func=cmd_atlas_query)
