"""The study's reduced-model validation transient: full nonlinear rollout against the reduced model.

The study (Segura, c. 2021) validated its reduced model at pose (0, 0) with all links 5 mm thick
and the motors locked: a constant force on the end effector in x, then in y, 0.2 s simulated at a
0.1 ms step, end-effector displacement from link bending compared between the full and the reduced
model (full model 4 min 32 s in COMSOL; reduced "instantaneous"). The study gives no force
magnitude; :data:`STUDY_FORCE_N` is assumed (see there).

Here both models share one discretisation (the check is reduction error, not discretisation error):
the full model is the segment-chain MuJoCo model (default: the standard resolution, 12 segments, no axial
springs), stepped nonlinearly from its static equilibrium under gravity; the reduced model is
:func:`fpm_sim.rom.reduction.reduce_model` at the same equilibrium. The displacement is measured along the
loaded axis, relative to the equilibrium.

The rollout runs on MuJoCo's ``discrete`` integrator at the step of :mod:`fpm_sim.sim.stepping` (band 5 x f1
unless ``step_band_hz`` is given; here f1 is 5.9 Hz, so the step is the 0.1 ms output step): 12 segments take
seconds a load axis instead of the explicit reference's minutes (0.81 us steps), with the same displacement to
0.1-0.2 % NRMS (measured, ``scripts/benchmark_transient.py``). ``integrator="explicit"``: the model's own
integrator and automatic step, rounded down so that 0.1 ms is a whole number of steps.
Error measure: normalised RMS ``rms(d_full - d_rom) / rms(d_full)`` per load axis.
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fpm_sim.config import Manipulator, default_config
from fpm_sim.kinematics import Pose
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import DEFAULT_SEGMENTS, ModelOptions
from fpm_sim.model.spec import BuiltModel
from fpm_sim.results import to_jsonable
from fpm_sim.rom.reduction import ReducedModel, reduce_model
from fpm_sim.sim.rollout import RolloutError, aligned_options, constant, rollout
from fpm_sim.sim.stepping import DEFAULT_INTEGRATOR, Stepping

__all__ = [
    "STUDY_DURATION_S",
    "STUDY_FORCE_N",
    "STUDY_FULL_MODEL_WALL_S",
    "STUDY_OUTPUT_STEP_S",
    "STUDY_THICKNESS_M",
    "TransientCase",
    "TransientResult",
    "nrms_error",
    "study_transient",
]

STUDY_FORCE_N = 10.0
"""Force magnitude (N). Assumed: the study gives none. 10 N deflects the 5 mm-link manipulator by
about 1.1 mm statically (2 mm at the first peak), under 1 % of the 228 mm links: the small-deflection
range a linear reduced model is meant for, yet large enough that geometric nonlinearity shows
(at 1 N the full-vs-reduced error falls ~10 times, measured)."""
STUDY_THICKNESS_M = 0.005
STUDY_DURATION_S = 0.2
STUDY_OUTPUT_STEP_S = 1e-4
STUDY_FULL_MODEL_WALL_S = 4 * 60 + 32
"""The study's full COMSOL model: 4 min 32 s for this transient (its hardware)."""
STUDY_POSE = Pose(0.0, 0.0, 0.0)
ANISOTROPY_TOL = 0.01
"""Peak ratios within 1 % of one are reported as equal: the nonlinear full model alone differs by
~0.1 % between x and y at 10 N (measured), and the assumed geometry is 3-fold symmetric, which makes
the linear in-plane static compliance at (0, 0) isotropic."""
DEFAULT_BAND_HZ = 500.0


def nrms_error(full: np.ndarray, reduced: np.ndarray) -> float:
    """``rms(full - reduced) / rms(full)``."""
    full, reduced = np.asarray(full, float), np.asarray(reduced, float)
    return float(np.sqrt(np.mean((full - reduced) ** 2)) / np.sqrt(np.mean(full**2)))


@dataclass
class TransientCase:
    """One load axis: full and reduced displacement along it (m), and the wall times (s)."""

    axis: str
    force_n: float
    t_s: np.ndarray
    disp_full_m: np.ndarray
    disp_rom_m: np.ndarray
    wall_full_s: float
    wall_rom_s: float

    @property
    def nrms(self) -> float:
        return nrms_error(self.disp_full_m, self.disp_rom_m)

    @property
    def peak_full_m(self) -> float:
        return float(np.max(np.abs(self.disp_full_m)))

    @property
    def peak_rom_m(self) -> float:
        return float(np.max(np.abs(self.disp_rom_m)))


@dataclass
class TransientResult:
    """Both load axes of the transient, the reduced model used, and how it was set up."""

    cases: list[TransientCase]
    rom: ReducedModel
    wall_rom_build_s: float
    parameters: dict[str, Any] = field(default_factory=dict)
    stepping: Stepping | None = None
    """How the full model was stepped (:mod:`fpm_sim.sim.stepping`)."""

    def case(self, axis: str) -> TransientCase:
        return next(c for c in self.cases if c.axis == axis)

    def summary(self) -> dict[str, Any]:
        out: dict[str, Any] = {"cases": {}}
        for c in self.cases:
            out["cases"][c.axis] = {
                "force_n": c.force_n,
                "nrms_error": c.nrms,
                "peak_full_m": c.peak_full_m,
                "peak_rom_m": c.peak_rom_m,
                "final_full_m": float(c.disp_full_m[-1]),
                "final_rom_m": float(c.disp_rom_m[-1]),
                "mean_full_m": float(np.mean(c.disp_full_m)),
                "wall_full_s": c.wall_full_s,
                "wall_rom_simulation_s": c.wall_rom_s,
            }
        if {"x", "y"} <= {c.axis for c in self.cases}:
            x, y = self.case("x"), self.case("y")
            out["y_over_x_peak_full"] = y.peak_full_m / x.peak_full_m
            out["y_over_x_peak_rom"] = y.peak_rom_m / x.peak_rom_m
            out["y_larger_than_x"] = bool(y.peak_full_m > x.peak_full_m)
            ratio = out["y_over_x_peak_full"]
            gain = self.rom.static_gain()
            out["static_compliance_m_per_n"] = {"x": float(gain[0, 0]), "y": float(gain[1, 1])}
            out["anisotropy_verdict"] = (
                f"y larger than x by more than {ANISOTROPY_TOL:.0%}"
                if ratio > 1 + ANISOTROPY_TOL
                else f"x larger than y by more than {ANISOTROPY_TOL:.0%}"
                if ratio < 1 - ANISOTROPY_TOL
                else f"x and y equal within {ANISOTROPY_TOL:.0%}"
            )
        wall_full = sum(c.wall_full_s for c in self.cases)
        wall_rom = self.wall_rom_build_s + sum(c.wall_rom_s for c in self.cases)
        out["wall_full_s"] = wall_full
        out["wall_rom_build_s"] = self.wall_rom_build_s
        out["wall_rom_total_s"] = wall_rom
        out["speedup_full_over_rom"] = wall_full / wall_rom
        out["study_full_model_wall_s"] = STUDY_FULL_MODEL_WALL_S
        out["rom"] = self.rom.to_dict()
        out["stepping"] = self.stepping.to_dict() if self.stepping is not None else None
        out["parameters"] = self.parameters
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: :meth:`summary` (per load axis: peaks, NRMS error, wall times; the reduced model)."""
        return to_jsonable(self.summary())

    def table(self) -> str:
        """Per load axis: force, peak displacements of both models, NRMS error, wall times."""
        s = self.summary()
        lines = [
            f"{'axis':>4}  {'force (N)':>9}  {'peak full (mm)':>14}  {'peak ROM (mm)':>13}  {'NRMS':>7}  "
            f"{'full (s)':>8}  {'ROM sim (s)':>11}"
        ]
        for c in self.cases:
            lines.append(
                f"{c.axis:>4}  {c.force_n:>9.3g}  {c.peak_full_m * 1e3:>14.4f}  {c.peak_rom_m * 1e3:>13.4f}  "
                f"{c.nrms:>7.2%}  {c.wall_full_s:>8.2f}  {c.wall_rom_s:>11.4f}"
            )
        if "y_larger_than_x" in s:
            lines.append(
                f"y peak / x peak: {s['y_over_x_peak_full']:.4f} (full), {s['y_over_x_peak_rom']:.4f} (ROM): "
                + s["anisotropy_verdict"]
                + f" (study: y larger than x); ROM static compliance x {s['static_compliance_m_per_n']['x']:.4g}, "
                f"y {s['static_compliance_m_per_n']['y']:.4g} m/N"
            )
        lines.append(
            f"wall time: full nonlinear {s['wall_full_s']:.2f} s, reduced model {s['wall_rom_total_s']:.3f} s "
            f"(build {s['wall_rom_build_s']:.3f} s) -> {s['speedup_full_over_rom']:.0f}x; the study's full COMSOL "
            f"model took {STUDY_FULL_MODEL_WALL_S} s (4 min 32 s, other hardware and model)"
        )
        p = self.parameters
        lines.append(
            f"model: {p['segments']} segments/link, axial={p['axial']}, nv={p['nv']}, "
            f"timestep {p['timestep_s']:.4g} s; "
            f"ROM {self.rom.n_modes} modes (<= {p['band_hz']} Hz), static correction {self.rom.static_correction}"
        )
        if self.stepping is not None:
            lines.append(self.stepping.line())
        return "\n".join(lines)

    def plot(self, ax: Any = None, *, axes: Any = None) -> Any:
        """Displacement of the full and the reduced model against time; returns the ``Figure``.

        ``ax``: one axes with every load axis; ``axes``: one per load axis; default a new figure.
        """
        import matplotlib.pyplot as plt

        if ax is not None:
            for c in self.cases:
                line = ax.plot(c.t_s, c.disp_full_m * 1e3, label=f"{c.axis}: full nonlinear", lw=1.5)[0]
                ax.plot(
                    c.t_s,
                    c.disp_rom_m * 1e3,
                    "--",
                    color=line.get_color(),
                    lw=1.2,
                    label=f"{c.axis}: reduced ({self.rom.n_modes} modes), NRMS {c.nrms:.2%}",
                )
            ax.set_ylabel("displacement along the load (mm)")
            ax.set_xlabel("t (s)")
            ax.legend(fontsize=8)
            return ax.figure
        if axes is None:
            _, axes = plt.subplots(len(self.cases), 1, figsize=(8, 3.2 * len(self.cases)), sharex=True)
        axes = np.atleast_1d(axes)
        for a, c in zip(axes, self.cases):
            a.plot(c.t_s, c.disp_full_m * 1e3, label="full nonlinear", lw=1.5)
            a.plot(c.t_s, c.disp_rom_m * 1e3, "--", label=f"reduced ({self.rom.n_modes} modes)", lw=1.2)
            a.set_ylabel(f"{c.axis} displacement (mm)")
            a.set_title(f"constant {c.force_n:g} N in {c.axis}: NRMS error {c.nrms:.2%}", fontsize=9)
            a.legend(fontsize=8)
        axes[-1].set_xlabel("t (s)")
        return axes[0].figure

    def save(self, out_dir: str | Path) -> dict[str, Path]:
        """Write ``transient.csv`` (``t_s,load_axis,disp_full_m,disp_rom_m``), ``transient.png``,
        ``summary.json`` and ``summary.txt`` into ``out_dir``."""
        d = Path(out_dir)
        d.mkdir(parents=True, exist_ok=True)
        csv = d / "transient.csv"
        with csv.open("w") as f:
            f.write("t_s,load_axis,disp_full_m,disp_rom_m\n")
            for c in self.cases:
                for t, a, b in zip(c.t_s, c.disp_full_m, c.disp_rom_m):
                    f.write(f"{t:.6g},{c.axis},{a:.10g},{b:.10g}\n")
        import matplotlib.pyplot as plt

        fig = self.plot()
        png = d / "transient.png"
        fig.tight_layout()
        fig.savefig(png, dpi=120)
        plt.close(fig)
        js = d / "summary.json"

        js.write_text(json.dumps(to_jsonable(self.summary()), indent=2))
        txt = d / "summary.txt"
        txt.write_text(self.table() + "\n")
        return {"csv": csv, "plot": png, "summary_json": js, "summary_txt": txt}


def study_transient(
    manip: Manipulator | None = None,
    *,
    pose: Pose = STUDY_POSE,
    thickness_m: float | None = STUDY_THICKNESS_M,
    force_n: float = STUDY_FORCE_N,
    axes: tuple[str, ...] = ("x", "y"),
    duration_s: float = STUDY_DURATION_S,
    output_step_s: float = STUDY_OUTPUT_STEP_S,
    segments: int = DEFAULT_SEGMENTS,
    axial: bool = False,
    band_hz: float | None = DEFAULT_BAND_HZ,
    n_modes: int | None = None,
    static_correction: bool = True,
    progress: bool = False,
    integrator: str = DEFAULT_INTEGRATOR,
    step_band_hz: float | None = None,
) -> TransientResult:
    """Run the study's transient (defaults) or a variant: full nonlinear rollout vs reduced model.

    Parameters
    ----------
    manip
        Manipulator (default: the embedded one); motors as configured (the study: locked).
    pose
        Pose of the test (m, m, rad).
    thickness_m
        Link in-plane thickness override (the study: 5 mm); ``None`` keeps the configuration's.
    force_n
        Constant force magnitude (N), switched on at ``t = 0`` from the equilibrium under gravity.
    axes
        Load axes, each ``"x"`` or ``"y"``, run one after the other.
    duration_s, output_step_s
        Simulated time and output step (s).
    segments, axial
        Discretisation shared by the full and the reduced model.
    band_hz, n_modes
        Modes kept in the reduced model (one of the two; see :func:`fpm_sim.rom.reduction.reduce_model`).
    integrator, step_band_hz
        How the full model is stepped: ``"discrete"`` at the step of the band ``step_band_hz`` (Hz; default 5 x
        f1) or ``"explicit"`` (:func:`fpm_sim.sim.stepping.choose_stepping`).

    Long because: its fourteen options take 28 lines of documentation; the steps (build, reduce, one load
    case per axis, :func:`_load_case`) are 60 lines.
    """
    manip = manip or default_config()
    if thickness_m is not None:
        manip = manip.with_section(thickness_m=thickness_m)
    for a in axes:
        if a not in ("x", "y"):
            raise ValueError(f"load axis must be 'x' or 'y', got {a!r}")
    opts = aligned_options(manip, pose, ModelOptions(segments=segments, axial=axial), output_step_s)
    built = build_manipulator(manip, pose, opts)
    t0 = time.perf_counter()
    rom = reduce_model(
        built, band_hz=None if n_modes is not None else band_hz, n_modes=n_modes, static_correction=static_correction
    )
    wall_build = time.perf_counter() - t0
    cases = []
    stepping: Stepping | None = None
    for a in axes:
        case, stepping = _load_case(
            built,
            manip,
            rom,
            a,
            force_n=force_n,
            duration_s=duration_s,
            output_step_s=output_step_s,
            progress=progress,
            integrator=integrator,
            step_band_hz=step_band_hz,
        )
        cases.append(case)
    params = {
        "pose": dataclasses.asdict(pose),
        "thickness_m": manip.section.thickness_m,
        "motors": manip.motors.mode,
        "force_n": force_n,
        "force_source": "assumed (the study gives no magnitude); see fpm_sim.transient.STUDY_FORCE_N",
        "duration_s": duration_s,
        "output_step_s": output_step_s,
        "segments": segments,
        "axial": axial,
        "nv": int(built.model.nv),
        "timestep_s": stepping.step_s if stepping is not None else built.timestep_s,
        "integrator": integrator,
        "band_hz": band_hz if n_modes is None else None,
        "gravity": True,
        "start": "static equilibrium under gravity; displacement measured from it",
        "error_measure": "rms(full - rom) / rms(full) along the loaded axis",
    }
    return TransientResult(cases=cases, rom=rom, wall_rom_build_s=wall_build, parameters=params, stepping=stepping)


def _load_case(
    built: BuiltModel,
    manip: Manipulator,
    rom: ReducedModel,
    axis: str,
    *,
    force_n: float,
    duration_s: float,
    output_step_s: float,
    progress: bool,
    integrator: str,
    step_band_hz: float | None,
) -> tuple[TransientCase, Stepping | None]:
    """One load axis: the full model's rollout under the constant force ``force_n`` (N) along ``axis`` and the
    reduced model's response to the same force (from the built manipulator ``built`` and its reduced model
    ``rom``); the full model's stepping."""
    k = "xy".index(axis)
    wrench = [0.0, 0.0, 0.0]
    wrench[k] = force_n
    try:
        full = rollout(
            built,
            manip,
            duration_s=duration_s,
            output_step_s=output_step_s,
            ee_wrench=constant(*wrench),
            qpos=rom.qpos,
            progress=progress,
            integrator=integrator,
            band_hz=step_band_hz,
            f1_hz=float(rom.frequencies_hz[0]),
        )
    except RolloutError as e:
        if e.parameter == "band_hz":  # the stepping's band is study_transient's step_band_hz
            e.parameter = "step_band_hz"
        raise
    u = np.zeros((len(full.t_s), len(rom.input_names)))
    u[:, k] = force_n
    t1 = time.perf_counter()
    y = rom.simulate(full.t_s, u)
    wall_rom = time.perf_counter() - t1
    case = TransientCase(
        axis=axis,
        force_n=force_n,
        t_s=full.t_s,
        disp_full_m=full.ee_disp[:, k],
        disp_rom_m=y[:, rom.output_index(("disp_x", "disp_y")[k])],
        wall_full_s=full.wall_s,
        wall_rom_s=wall_rom,
    )
    return case, full.stepping
