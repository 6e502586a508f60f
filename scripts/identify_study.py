"""Identify what the study does not state, step by step, and print the evidence.

    nice python scripts/identify_study.py --out out/identification [--seeds 1] [--quick]

1. link: rig length and clamped length from the free-free and cantilever tests;
2. chain: hinge hardware mass and the hinge tilt compliance from the chain tests;
3. geometry screening: for each reading of the table and each elbow-branch class, a global search
   (differential evolution) on the in-plane surrogate, scale-free; the table of best fits is the
   evidence for the reading;
4. rotation sign: at the poses written (x, 0), the singularity measure at phi = 0 and at +-0.2 rad
   for the best geometry of each reading (the study turned the platform to move away from a
   singularity);
5. refinement of the best combination on the segment model (geometry and platform mass).

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
from fpm_sim.config import Section, default_config
from fpm_sim.fast_frequencies import fast_options
from fpm_sim.identification import (
    ELBOW_BRANCH_CLASSES,
    geometry_from,
    identify_manipulator,
    identify_subsystems,
    screen_geometry,
)
from fpm_sim.kinematics import Pose, UnreachablePoseError, inverse_kinematics
from fpm_sim.study_data import subsystem_tests
from fpm_sim.study_poses import READINGS, ROTATION_RAD, study_poses


def rotation_evidence(cfg, reading) -> dict:  # noqa: ANN001
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
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    args.out.mkdir(parents=True, exist_ok=True)
    report: dict = {}
    base = default_config()

    # 1-2: subsystems -------------------------------------------------------------------------
    t0 = time.time()
    tests = subsystem_tests()
    link_tests = [t for t in tests if t.rig != "chain"]
    chain_tests = [t for t in tests if t.rig == "chain"]
    init = {"rig.length_m": 0.2295, "rig.clamped_length_m": 0.04}
    r_link, cfg = identify_subsystems(base, list(init), tests=link_tests, initial=init)
    print("step 1, link\n" + r_link.table(), f"\n({time.time() - t0:.0f} s)\n", flush=True)
    report["link"] = r_link.to_dict()
    t0 = time.time()
    init = {"rig.chain_hinge.mass_kg": 0.3, "compliance.passive_joint_tilt_nm_per_rad": 500.0}
    r_chain, cfg = identify_subsystems(cfg, list(init), tests=chain_tests, initial=init)
    print("step 2, chain\n" + r_chain.table(), f"\n({time.time() - t0:.0f} s)\n", flush=True)
    report["chain"] = r_chain.to_dict()

    # the manipulator: links 10 mm in-plane x 30 mm, hinge hardware as identified on the chain
    hinge = cfg.rig.chain_hinge
    cfg = cfg.replace(
        section=Section(0.010, 0.030),
        hardware=dataclasses.replace(cfg.hardware, elbow_joint=hinge, platform_joint=hinge),
    )

    # 3: screening ------------------------------------------------------------------------------
    screens = []
    maxiter = 30 if args.quick else 300
    for rd in READINGS:
        sp = study_poses(rd)
        poses, comsol = [p.pose for p in sp], [p.comsol_hz for p in sp]
        for br in ELBOW_BRANCH_CLASSES:
            for seed in range(args.seeds):
                t0 = time.time()
                s = screen_geometry(cfg, poses, comsol, elbow_branch=br, reading=rd.name, seed=seed, maxiter=maxiter)
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

    # 5: refinement -------------------------------------------------------------------------------
    best = min(screens, key=lambda s: s.rms_log)
    rd = [r for r in READINGS if r.name == best.reading][0]
    sp = study_poses(rd)
    t0 = time.time()
    res, final = identify_manipulator(
        cfg,
        [p.pose for p in sp],
        [p.comsol_hz for p in sp],
        initial=[*best.values, cfg.hardware.platform.mass_kg],
        elbow_branch=best.elbow_branch,
        options=fast_options(segments=4),
        max_nfev=30 if args.quick else 80,
    )
    print(f"step 5, refinement ({rd.name}, branch {best.elbow_branch})\n" + res.table(), f"({time.time() - t0:.0f} s)")
    report["manipulator"] = {"reading": rd.name, "elbow_branch": best.elbow_branch, "fit": res.to_dict()}
    (args.out / "identification.json").write_text(json.dumps(report, indent=1, default=float))
    print(f"wrote {args.out / 'identification.json'}")
    _ = np.nan


if __name__ == "__main__":
    main()
