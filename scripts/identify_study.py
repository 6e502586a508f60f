"""Identify what the study does not state, step by step, and print the evidence.

    nice python scripts/identify_study.py --out out/identification [--seeds 1] [--quick]

1-2. link and chain tests together: rig length, clamped length, the test piece's second dimension
   and the chain hinge's mass;
3. geometry screening: for each reading of the table and each elbow-branch class, a global search
   (differential evolution) on the in-plane surrogate, scale-free; the table of best fits is the
   evidence for the reading;
4. rotation sign: at the poses written (x, 0), the singularity measure at phi = 0 and at +-0.2 rad
   for the best geometry of each reading (the study turned the platform to move away from a
   singularity);
5. refinement of the best combination on the segment model (platform mass, then geometry with it),
   and the final geometry evaluated under all four readings.

Writes ``identification.json`` into ``--out``. Long (tens of minutes on 2 busy cores): run it with
``nice``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
import warnings
from pathlib import Path

import numpy as np

import fpm_sim  # noqa: F401
from fpm_sim.batch.frequencies import first_frequencies
from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.config import Section, default_config
from fpm_sim.kinematics import Pose, UnreachablePoseError, inverse_kinematics
from fpm_sim.study.identification import (
    ELBOW_BRANCH_CLASSES,
    Screening,
    geometry_from,
    identify_manipulator,
    identify_subsystems,
    screen_geometry,
)
from fpm_sim.study.poses import READINGS, ROTATION_RAD, parse_reading, study_poses
from fpm_sim.study.reproduce import error_stats
from fpm_sim.study.tables import subsystem_tests


def rotation_evidence(cfg, reading) -> dict:
    """Singularity measure at the poses written (x, 0): phi = 0, +0.2, -0.2."""
    out = {}
    for p in study_poses(reading):
        if p.col_mm != 0:
            continue
        row = {}
        for phi in (0.0, ROTATION_RAD, -ROTATION_RAD):
            try:
                asm = inverse_kinematics(cfg.geometry, Pose(p.pose.x_m, p.pose.y_m, phi), check_singularity=False)
                row[f"{phi:+.1f}"] = asm.singularity.value
            except UnreachablePoseError:
                row[f"{phi:+.1f}"] = None
        out[f"({p.row_mm:g}, {p.col_mm:g})"] = row
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("out/identification"))
    ap.add_argument("--seeds", type=int, default=1, help="differential-evolution seeds per combination")
    ap.add_argument("--quick", action="store_true", help="small searches (a smoke run, not a result)")
    ap.add_argument(
        "--start",
        help="skip the screening: refine from this geometry, 'READING;B1,B2,B3;R,r,L1,L2,rot_deg,off_deg' "
        "(the embedded default: 'x+;-1,-1,-1;0.1569,0.0942,0.1553,0.1553,59.3143,30.5384')",
    )
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    args.out.mkdir(parents=True, exist_ok=True)
    report: dict = {}
    base = default_config()

    # 1-2: subsystems: all five tests at once -------------------------------------------------
    t0 = time.time()
    init = {
        "rig.length_m": 0.2295,
        "rig.clamped_length_m": 0.037,
        "rig.section.height_m": 0.0091,
        "rig.chain_hinge.mass_kg": 0.42,
    }
    r_sub, cfg = identify_subsystems(base, list(init), tests=subsystem_tests(), initial=init)
    print("steps 1-2, link and chain tests\n" + r_sub.table(), f"\n({time.time() - t0:.0f} s)\n", flush=True)
    report["subsystems"] = r_sub.to_dict()

    # the manipulator: links 30 mm in-plane (the study) x the test pieces' identified plate, joint
    # hardware as identified on the chain
    hinge = cfg.rig.chain_hinge
    cfg = cfg.replace(
        section=Section(0.030, cfg.rig.section.height_m),
        hardware=dataclasses.replace(cfg.hardware, elbow_joint=hinge, platform_joint=hinge),
    )

    if args.start:
        rd_text, br_text, x_text = args.start.split(";")
        start_reading = parse_reading(rd_text)
        start_branch = tuple(int(v) for v in br_text.split(","))
        start_values = np.array([float(v) for v in x_text.split(",")])
        screens = [Screening(start_reading.name, start_branch, start_values, float("nan"), float("nan"), float("nan"))]
    else:
        # 3: screening ------------------------------------------------------------------------------
        screens = []
        maxiter = 30 if args.quick else 300
        for rd in READINGS:
            sp = study_poses(rd)
            poses, comsol = [p.pose for p in sp], [p.comsol_hz for p in sp]
            for br in ELBOW_BRANCH_CLASSES:
                for seed in range(args.seeds):
                    t0 = time.time()
                    s = screen_geometry(
                        cfg, poses, comsol, elbow_branch=br, reading=rd.name, seed=seed, maxiter=maxiter
                    )
                    screens.append(s)
                    print(
                        f"step 3, {rd.name:>15} branch {br}: rms(ln f) {s.rms_log:.4f}, Spearman {s.spearman:.3f} "
                        f"({time.time() - t0:.0f} s)",
                        flush=True,
                    )
        report["screening"] = [
            {
                "reading": s.reading,
                "elbow_branch": s.elbow_branch,
                "values": s.values.tolist(),
                "rms_log": s.rms_log,
                "spearman": s.spearman,
            }
            for s in screens
        ]
        best_by_reading = {}
        for s in screens:
            if s.reading not in best_by_reading or s.rms_log < best_by_reading[s.reading].rms_log:
                best_by_reading[s.reading] = s

        # 4: rotation sign ----------------------------------------------------------------------------
        report["rotation"] = {}
        for rd in READINGS:
            s = best_by_reading[rd.name]
            g_cfg = cfg.replace(geometry=geometry_from(s.values, s.elbow_branch))
            report["rotation"][rd.name] = rotation_evidence(g_cfg, rd)
            print(f"step 4, {rd.name}: singularity measure at (x, 0) poses", report["rotation"][rd.name], flush=True)

    # 5: refinement: level (platform mass) first, then geometry and level ----------------------
    best = screens[0] if args.start else min(screens, key=lambda s: s.rms_log)
    rd = next(r for r in READINGS if r.name == best.reading)
    sp = study_poses(rd)
    poses, comsol = [p.pose for p in sp], [p.comsol_hz for p in sp]
    opts = fast_options(segments=4)
    t0 = time.time()
    lvl, _ = identify_manipulator(
        cfg,
        poses,
        comsol,
        initial=[*best.values, 1.0],
        elbow_branch=best.elbow_branch,
        options=opts,
        geometry_free=False,
        max_nfev=20,
    )
    res, final = identify_manipulator(
        cfg,
        poses,
        comsol,
        initial=[*best.values, float(lvl.values[0])],
        elbow_branch=best.elbow_branch,
        options=opts,
        span=0.25,
        span_deg=20.0,
        max_nfev=30 if args.quick else 60,
    )
    print(f"step 5, refinement ({rd.name}, branch {best.elbow_branch})\n" + res.table(), f"({time.time() - t0:.0f} s)")
    report["manipulator"] = {"reading": rd.name, "elbow_branch": best.elbow_branch, "fit": res.to_dict()}
    readings = {}
    for other in READINGS:
        osp = study_poses(other)
        f = first_frequencies(final, [p.pose for p in osp])[:, 0]
        readings[other.name] = error_stats(f, np.array([p.comsol_hz for p in osp]))
        st = readings[other.name]
        print(
            f"  {other.name}: mean {st['mean_abs_pct']:.2f} %, max {st['max_abs_pct']:.2f} %, "
            f"Spearman {st['spearman']:.3f}"
        )
    report["readings_with_final_geometry"] = readings
    report["rotation_final"] = {r.name: rotation_evidence(final, r) for r in READINGS if r.row_is == rd.row_is}
    print("singularity measure at the (x, 0) poses, phi 0 / +0.2 / -0.2:", report["rotation_final"][rd.name])
    (args.out / "identification.json").write_text(json.dumps(report, indent=1, default=float))
    print(f"wrote {args.out / 'identification.json'}")


if __name__ == "__main__":
    main()
