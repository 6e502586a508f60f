"""Accuracy and cost of the link models (segments, cable, flex) against theory and the converged chain.

Writes its tables into ``docs/link_models.md`` (between the ``tables`` markers; the text around
them is kept). For each model and resolution:

1. the ENGINE_NOTES probe bar (steel, 10 x 10 x 228 mm, nothing clamped): first three in-plane
   bending frequencies of the free-free and the cantilever bar against Euler-Bernoulli;
2. the chain rig at 60, 90 and 180 degrees: first three frequencies against the converged segment
   chain (``--ref-segments``, constrained eigen-solve);
3. the manipulator at three poses: first three frequencies against the converged segment chain,
   and the wall time per pose (build + ``mjd_transitionFD`` linearisation at the equilibrium).

The chain rig uses the configuration's ``rig`` piece and the manipulator the configuration itself
(``--config``, default: the embedded default). docs/link_models.md was generated with
``nice python studies/link_model_study.py --config tests/data/symmetric_3rrr.toml`` (about 10 min on
2 cores); ``--quick`` for a smoke run.
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np
from tqdm import tqdm

from fpm_sim.beam_theory import euler_bernoulli_hz
from fpm_sim.config import Manipulator, Material, RigConfig, Section, default_config, load_config
from fpm_sim.kinematics import Pose
from fpm_sim.linear.solvers import modes_constrained, modes_transition_fd
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import ModelOptions
from fpm_sim.model.rigs import RigSetup, build_rig

MODELS = ("segments", "cable", "flex")
BEGIN, END = "<!-- tables:begin (studies/link_model_study.py) -->", "<!-- tables:end -->"
POSES = {
    "(0, 0, 0)": Pose.from_mm(0.0, 0.0, 0.0),
    "(50, 50, 0)": Pose.from_mm(50.0, 50.0, 0.0),
    "(0, -80, 0.2 rad)": Pose.from_mm(0.0, -80.0, 0.2),
}


def _in_plane(freqs: np.ndarray, n: int = 3) -> np.ndarray:
    """The square bar's bending modes come in degenerate in/out-of-plane pairs: one of each pair."""
    return freqs[0 : 2 * n : 2]


def _pct(x: np.ndarray, ref: np.ndarray) -> str:
    return " / ".join(f"{100 * (a / b - 1):+.2f}" for a, b in zip(x, ref))


PROBE_BAR = RigConfig(length_m=0.228, section=Section(0.010, 0.010), material=Material(200e9, 0.3, 7850.0))
"""The ENGINE_NOTES probe bar: steel 10 x 10 x 228 mm, nothing held in a clamp."""

CONFIG: Manipulator = default_config()
"""The configuration of the chain rig and the manipulator (``--config``)."""


def bar_study(resolutions: dict[str, list[int]]) -> list[str]:
    piece = PROBE_BAR
    lines = []
    for boundary in ("cantilever", "free-free"):
        eb = euler_bernoulli_hz(boundary, length_m=piece.length_m, section=piece.section, material=piece.material)
        lines += [
            f"\n### {boundary} bar (EB {eb[0]:.2f} / {eb[1]:.2f} / {eb[2]:.2f} Hz)\n",
            "| model | n | nv | f1 / f2 / f3 (Hz) | error vs EB (%) | build + transitionFD (s) |",
            "|---|---|---|---|---|---|",
        ]
        for lm in MODELS:
            for n in tqdm(resolutions[lm], desc=f"{boundary} {lm}", leave=False):
                t0 = time.perf_counter()
                built = build_rig(RigSetup(boundary), piece, ModelOptions(link_model=lm, segments=n))
                f = _in_plane(modes_transition_fd(built, n_modes=6).frequencies_hz)
                dt = time.perf_counter() - t0
                freqs = " / ".join(f"{x:.2f}" for x in f)
                lines.append(f"| {lm} | {n} | {built.model.nv} | {freqs} | {_pct(f, eb)} | {dt:.3f} |")
    return lines


def chain_study(resolutions: dict[str, list[int]], ref_n: int) -> list[str]:
    piece = CONFIG.rig
    lines = [
        f"\n### chain rig (reference: segments n = {ref_n}, constrained eigen-solve)\n",
        "| angle | model | n | nv | f1 / f2 / f3 (Hz) | error vs reference (%) | dropped (transitionFD) |",
        "|---|---|---|---|---|---|---|",
    ]
    for angle in (60.0, 90.0, 180.0):
        ref_b = build_rig(RigSetup("chain", angle_deg=angle), piece, ModelOptions(segments=ref_n))
        ref = modes_constrained(ref_b, n_modes=3).frequencies_hz
        lines.append(
            f"| {angle:g} | reference | {ref_n} | {ref_b.model.nv} | {' / '.join(f'{x:.2f}' for x in ref)} | | |"
        )
        for lm in MODELS:
            for n in tqdm(resolutions[lm], desc=f"chain {angle:g} {lm}", leave=False):
                built = build_rig(RigSetup("chain", angle_deg=angle), piece, ModelOptions(link_model=lm, segments=n))
                res = modes_transition_fd(built, n_modes=3)
                f = res.frequencies_hz
                lines.append(
                    f"| {angle:g} | {lm} | {n} | {built.model.nv} | {' / '.join(f'{x:.2f}' for x in f)} | "
                    f"{_pct(f, ref)} | {res.dropped} |"
                )
    return lines


def manipulator_study(resolutions: dict[str, list[int]], ref_n: int) -> list[str]:
    cfg = CONFIG
    lines = [
        f"\n### manipulator (default configuration; reference: segments n = {ref_n}, constrained eigen-solve)\n",
        "| pose | model | n | nv | f1 / f2 / f3 (Hz) | error vs reference (%) | time per pose (s) "
        "| time / segments' at the same n | dropped |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    seg_time: dict[tuple[str, int], float] = {}
    for label, pose in POSES.items():
        ref_b = build_manipulator(cfg, pose, ModelOptions(segments=ref_n))
        ref = modes_constrained(ref_b, n_modes=3).frequencies_hz
        lines.append(
            f"| {label} | reference | {ref_n} | {ref_b.model.nv} | {' / '.join(f'{x:.2f}' for x in ref)} | | | | |"
        )
        for lm in MODELS:
            for n in tqdm(resolutions[lm], desc=f"manip {label} {lm}", leave=False):
                t0 = time.perf_counter()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")  # flex's Section/DampingWarning: reported in the text
                    built = build_manipulator(cfg, pose, ModelOptions(link_model=lm, segments=n))
                    res = modes_transition_fd(built, n_modes=3)
                dt = time.perf_counter() - t0
                if lm == "segments":
                    seg_time[(label, n)] = dt
                ratio = dt / seg_time[(label, n)] if (label, n) in seg_time else float("nan")
                f = res.frequencies_hz
                lines.append(
                    f"| {label} | {lm} | {n} | {built.model.nv} | {' / '.join(f'{x:.2f}' for x in f)} | "
                    f"{_pct(f, ref)} | {dt:.2f} | {ratio:.2f} | {res.dropped} |"
                )
    return lines


def with_flex_limits(built, *, torsion: bool, inplane: bool):
    """The segment chain with what the 1D flex lacks, to explain its gap: ``torsion`` removes the
    twist springs (1e-6 of their stiffness: a flex has none), ``inplane`` gives the in-plane bending
    springs the out-of-plane (weaker) stiffness, as the flex's single bending stiffness does."""
    m = built.model
    kinds = np.array(built.dof_kinds)
    for j in range(m.njnt):
        kind = kinds[m.jnt_dofadr[j]]
        scale = 1.0
        if torsion and kind == "twist":
            scale = 1e-6
        if inplane and kind == "bend_in":
            sec = CONFIG.section
            scale = sec.i_outofplane_m4 / sec.i_inplane_m4
        # stiffness and its proportional damping together
        m.jnt_stiffness[j] *= scale
        m.dof_damping[m.jnt_dofadr[j]] *= scale
    return built


def flex_gap_study(n: int) -> list[str]:
    """Manipulator first modes at (0, 0, 0): flex against the segment chain stripped of torsion and
    of its in-plane section (the flex's two limitations), at the same resolution."""
    cfg = CONFIG
    pose = POSES["(0, 0, 0)"]
    lines = [
        f"\n### cause of the flex gap on the manipulator at (0, 0, 0), n = {n} (constrained eigen-solve, "
        "gravity off)\n",
        "| model | f1 / f2 / f3 (Hz) |",
        "|---|---|",
    ]
    rows = [
        ("segments", {}),
        ("segments without torsion", {"torsion": True, "inplane": False}),
        ("segments with the weak-axis I in plane", {"torsion": False, "inplane": True}),
        ("segments with both (what the flex can represent)", {"torsion": True, "inplane": True}),
    ]
    for label, limits in rows:
        # gravity off: without torsion the chain is nearly a mechanism and sags without bound; all
        # rows are linearised at the unloaded assembly
        built = build_manipulator(cfg, pose, ModelOptions(segments=n, gravity=False))
        if limits:
            with_flex_limits(built, **limits)
        # without torsion stiffness, the pieces' twist inertia gives local twist modes at any
        # frequency; a flex has no twist freedom at all, so modes whose strain energy is mostly
        # twist are left out
        modes = [md for md in modes_constrained(built, n_modes=None).modes if md.character.get("twist", 0.0) < 0.5]
        f = np.array([md.frequency_hz for md in modes[:3]])
        lines.append(f"| {label} | {' / '.join(f'{x:.2f}' for x in f)} |")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        built = build_manipulator(cfg, pose, ModelOptions(link_model="flex", segments=n, gravity=False))
    f = modes_constrained(built, n_modes=3).frequencies_hz
    lines.append(f"| flex | {' / '.join(f'{x:.2f}' for x in f)} |")
    return lines


def square_section_study(n: int) -> list[str]:
    """Manipulator at (0, 0, 0) with square 10 x 10 mm links, which the flex can represent in bending:
    what remains of its gap is the missing torsion."""
    import dataclasses

    from fpm_sim.config import Section

    cfg = dataclasses.replace(CONFIG, section=Section(0.010, 0.010))
    lines = [
        f"\n### manipulator at (0, 0, 0) with 10 x 10 mm links, n = {n} (constrained eigen-solve)\n",
        "| model | f1 / f2 / f3 / f4 (Hz) | dominant strain energy |",
        "|---|---|---|",
    ]
    for lm in MODELS:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = modes_constrained(
                build_manipulator(cfg, POSES["(0, 0, 0)"], ModelOptions(link_model=lm, segments=n)), n_modes=4
            )
        freqs = " / ".join(f"{x:.2f}" for x in res.frequencies_hz)
        lines.append(f"| {lm} | {freqs} | {', '.join(md.dominant for md in res.modes)} |")
    return lines


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="two resolutions per model (smoke run)")
    p.add_argument("--out", type=Path, default=Path("docs/link_models.md"))
    p.add_argument("--config", type=Path, help="manipulator TOML for the chain rig and the manipulator")
    args = p.parse_args()
    global CONFIG
    if args.config is not None:
        CONFIG = load_config(args.config)
    if args.quick:
        bars = {m: [4, 8] for m in MODELS}
        rig = {m: [4, 8] for m in MODELS}
        manip = {m: [4] for m in MODELS}
        ref_rig, ref_manip = 16, 8
    else:
        bars = {m: [4, 8, 12, 16, 32] for m in MODELS}
        rig = {m: [4, 8, 12, 16] for m in MODELS}
        manip = {m: [4, 8, 12] for m in MODELS}
        ref_rig, ref_manip = 32, 24
    flags = (" --quick" if args.quick else "") + (f" --config {args.config}" if args.config else "")
    lines = [f"Generated by `python studies/link_model_study.py{flags}`."]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    text = args.out.read_text() if args.out.exists() else f"# Link models\n\n{BEGIN}\n{END}\n"
    if BEGIN not in text or END not in text:
        raise SystemExit(f"{args.out} lacks the markers {BEGIN} / {END} between which the tables go")
    head, rest = text.split(BEGIN, 1)
    tail = rest.split(END, 1)[1]
    for part in (
        lambda: bar_study(bars),
        lambda: chain_study(rig, ref_rig),
        lambda: manipulator_study(manip, ref_manip),
        lambda: flex_gap_study(8 if args.quick else 16),
        lambda: square_section_study(8),
    ):
        new = part()
        lines += new
        print("\n".join(new), flush=True)
        # written after every part, so that a failure late in the run keeps what was measured
        args.out.write_text(f"{head}{BEGIN}\n" + "\n".join(lines) + f"\n{END}{tail}")


if __name__ == "__main__":
    main()
