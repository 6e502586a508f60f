"""Minimal reproduction: ``jit(mjx.kinematics)`` compiles in seconds, then one call runs for minutes.

Standalone (needs only ``mujoco``, ``mujoco-mjx`` and ``jax``; no fpm_sim), for an upstream report. Each
variant is a small MJCF chain; each runs in its own subprocess under a wall-clock limit (a variant that
hits it prints ``TIMEOUT``), and prints nbody, nv, the XLA compile time and the time of one call of the
compiled ``mjx.kinematics``, plus its largest deviation from C MuJoCo's ``mj_kinematics``.

Usage::

    python studies/repro_mjx_chain_rig.py                 # every variant, 120 s limit each
    python studies/repro_mjx_chain_rig.py --limit 60 --variants hinge_chain,jointless_leaf
    python studies/repro_mjx_chain_rig.py --one jointless_leaf --x64 0   # one variant in this process

Findings and numbers: ``docs/mjx_chain_rig.md``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time


def chain_xml(n_bodies: int, joints: str, *, root_joint: bool = True, leaf: bool = False, copies: int = 1) -> str:
    """A straight chain of ``n_bodies`` boxes along x, each child offset by 0.1 m.

    ``joints`` per body: ``h`` hinge z, ``y`` hinge y, ``x`` hinge x, ``s`` slide x (e.g. ``"hyx"``).
    ``root_joint=False`` gives the first body no joint (fixed to the world); ``leaf=True`` adds a
    jointless leaf body at the end (as a clamp or a tip mass would be). ``copies`` side-by-side identical
    chains from the world (MJX then batches the bodies of each tree level: arrays of width ``copies``).
    """
    axes = {"h": ("hinge", "0 0 1"), "y": ("hinge", "0 1 0"), "x": ("hinge", "1 0 0"), "s": ("slide", "1 0 0")}
    tree = ""
    for c in range(copies):
        tree += _one_chain(n_bodies, joints, axes, root_joint, leaf, prefix=f"c{c}", y=0.1 * c)
    return f'<mujoco><option><flag contact="disable"/></option><worldbody>{tree}</worldbody></mujoco>'


def _one_chain(n_bodies: int, joints: str, axes: dict, root_joint: bool, leaf: bool, prefix: str, y: float) -> str:
    body = ""
    closing = ""
    for i in range(n_bodies):
        pos = f"0 {y} 0" if i == 0 else "0.1 0 0"
        js = ""
        if i > 0 or root_joint:
            for k, c in enumerate(joints):
                typ, axis = axes[c]
                js += f'<joint name="{prefix}j{i}_{k}" type="{typ}" axis="{axis}" stiffness="100"/>'
        body += (
            f'<body name="{prefix}b{i}" pos="{pos}"><inertial pos="0.05 0 0" mass="0.1" diaginertia="1e-4 1e-4 1e-5"/>'
            f'{js}<geom type="box" size="0.05 0.005 0.005" pos="0.05 0 0" contype="0" conaffinity="0"/>'
        )
        closing += "</body>"
    if leaf:
        body += (
            f'<body name="{prefix}leaf" pos="0.1 0 0"><inertial mass="1e-4" pos="0 0 0" diaginertia="1e-9 1e-9 1e-9"/>'
            "</body>"
        )
    return body + closing


VARIANTS = {
    # control: every body has its joints
    "hinge_chain": lambda: chain_xml(4, "hyx"),
    # the chain rig's features, one at a time
    "jointless_root": lambda: chain_xml(4, "hyx", root_joint=False),
    "jointless_leaf": lambda: chain_xml(4, "hyx", leaf=True),
    "both_jointless": lambda: chain_xml(4, "hyx", root_joint=False, leaf=True),
    "single_hinge_leaf": lambda: chain_xml(2, "h", leaf=True),
    # the same chain twice side by side (as the manipulator's three legs): one vmap of width 2 per level
    "two_chains_leaf": lambda: chain_xml(4, "hyx", leaf=True, copies=2),
    # depth: hinges in series
    "hinge_chain_3": lambda: chain_xml(3, "hyx"),
    "hinge_chain_5": lambda: chain_xml(5, "hyx"),
}


def run_one(name: str, calls: int = 3) -> None:
    """Compile ``jit(mjx.kinematics)`` for one variant in this process, call it ``calls`` times; print two lines."""
    import jax

    jax.config.update("jax_enable_x64", os.environ.get("REPRO_X64", "1") == "1")
    import mujoco
    import numpy as np
    from mujoco import mjx

    m = mujoco.MjModel.from_xml_string(VARIANTS[name]())
    mx = mjx.put_model(m)
    d = mjx.make_data(mx)
    t0 = time.perf_counter()
    compiled = jax.jit(mjx.kinematics).lower(mx, d).compile()
    t1 = time.perf_counter()
    cost = compiled.cost_analysis()
    cost = cost[0] if isinstance(cost, list) else cost
    hlo = compiled.as_text()
    print(
        f"{name:<20} nbody {m.nbody:>3} nv {m.nv:>3} x64 {int(jax.config.jax_enable_x64)} "
        f"compile {t1 - t0:7.2f} s  XLA flops estimate {cost.get('flops', float('nan')):.3g}  "
        f"optimized HLO {len(hlo.splitlines())} lines",
        flush=True,
    )
    runs = []
    for _ in range(calls):
        t1 = time.perf_counter()
        out = jax.block_until_ready(compiled(mx, d))
        runs.append(time.perf_counter() - t1)
    ref = mujoco.MjData(m)
    mujoco.mj_kinematics(m, ref)
    err = float(np.abs(np.asarray(out.xpos) - ref.xpos).max())
    calls_s = ", ".join(f"{r:.3f}" for r in runs)
    print(f"{name:<20} calls of the compiled function: {calls_s} s  |xpos - C| {err:.1e}", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--variants", default=",".join(VARIANTS), help="comma-separated names")
    ap.add_argument("--limit", type=float, default=120.0, help="wall-clock limit per variant (s)")
    ap.add_argument("--x64", choices=("0", "1"), default="1", help="float64 (1, as fpm_sim) or float32 (0)")
    ap.add_argument("--one", help="run one variant in this process (no limit)")
    ap.add_argument("--print-xml", help="print the MJCF of one variant and exit")
    args = ap.parse_args()
    if args.print_xml:
        print(VARIANTS[args.print_xml]())
        return
    os.environ["REPRO_X64"] = args.x64
    if args.one:
        run_one(args.one)
        return
    import jax
    import mujoco

    print(f"mujoco {mujoco.__version__}, jax {jax.__version__}, backend {jax.default_backend()}", flush=True)
    for name in args.variants.split(","):
        cmd = [sys.executable, __file__, "--one", name, "--x64", args.x64]
        t0 = time.perf_counter()
        try:
            res = subprocess.run(cmd, capture_output=True, text=True, timeout=args.limit, check=False)
            out, err = res.stdout, res.stderr
        except subprocess.TimeoutExpired as exc:
            out = exc.stdout.decode() if isinstance(exc.stdout, bytes) else (exc.stdout or "")
            out += f"{name:<20} TIMEOUT after {time.perf_counter() - t0:.0f} s (compile + run)\n"
            err = ""
        lines = [ln for ln in out.splitlines() if ln.startswith(name)]
        print("\n".join(lines) if lines else f"{name:<20} failed: {err.strip().splitlines()[-1:]}", flush=True)


if __name__ == "__main__":
    main()
