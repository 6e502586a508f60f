"""A virtual impact-hammer modal test on the full nonlinear model.

The study measured the manipulator's first frequency as a laboratory does: a hammer impact "along the
axis of an accelerometer on the second link", three impacts averaged into one FRF, the first frequency
read from the FRF peaks. This module repeats that procedure on the MuJoCo model.

Procedure (:func:`virtual_impact_test`), per impact, from rest at the static equilibrium under gravity:

1. a half-sine force pulse ``F(t) = F_peak sin(pi t / T)`` for ``0 <= t <= T`` (default ``T = 1 ms``,
   :data:`PULSE_S`; a steel-tipped PCB 208C02-class hammer on steel gives pulses of a fraction of a
   millisecond to ~1 ms, whose spectrum is flat within 3 dB up to about ``0.6 / T``, here 600 Hz, well
   above the band of the first modes) at the impact point, along the impact axis (the axis follows
   the link as it moves), applied at every integrator step (``mj_applyFT`` into ``qfrc_applied``);
2. the full nonlinear model is stepped (``mj_step``; integrator and step below) for ``record_s``, and the
   accelerometer signal (the material point's acceleration along its axis,
   gravity excluded) and the hammer force are sampled every ``sample_s``;
3. optional Gaussian noise of standard deviation ``noise_m_s2`` is added to the accelerometer signal.

The impacts differ in peak force (``F_peak (1 + force_spread u)``, ``u`` uniform in [-1, 1], seeded)
and in noise. Both signals get the same exponential window (decaying to ``window_end`` of its initial
value at the end of the record: the standard response window of impact testing, which adds the known
damping ``ln(1 / window_end) / (2 pi f record_s)`` to every mode without shifting its peak) and are
zero-padded to ``pad_s`` before the FFT. The FRF estimate is H1: ``sum conj(F_i) A_i / sum |F_i|^2``
over the impacts, with its ordinary coherence. The first frequency is the lowest peak of ``|H1|`` above
``f_min_hz`` with a prominence of at least ``min_prominence_db`` (:func:`fpm_sim.response.pick_peaks`).

Study set-up, as assumed here (the study does not say which chain or where along the link): the
accelerometer at mid-span of chain 0's distal link (the "second link"), the hammer hitting the same
point along the accelerometer axis (a driving-point FRF). The default axis is ``z`` (out of the base
plane): with the default (assumed) geometry, 30 mm in-plane by 10 mm out-of-plane links, the model's
first mode at every study pose is out-of-plane bending, which an in-plane impact does not excite at
all (the structure is symmetric about its plane, so in-plane and out-of-plane motions decouple but for
the small coupling of the gravity sag). Choose ``axis="normal"`` for an in-plane test.

Integration step. By default the rollouts run on MuJoCo's ``discrete`` integrator (springs, dampers and the
loop-closing welds implicit in one solve, stable at any step) at the step of :mod:`fpm_sim.sim.stepping`: from
the band ``ImpactSetup.band_hz`` (default 5 x f1: numerical damping at most 2 % at its top), at most a tenth of
the pulse, dividing ``sample_s``; ``ImpactSetup.timestep_s`` gives the step instead. The step damps a mode at
``f`` by ``zeta_num ~ pi f h`` and lengthens its period by ``~ (2 pi f h)^2 / 3``, both known exactly
(:func:`fpm_sim.sim.stepping.discrete_pole`): :attr:`ImpactTestResult.identified_damping_ratio` subtracts it as
it subtracts the window's, and :func:`write_uff58` writes the step into the UFF record, from which ``fpm-sim
ema`` inverts it exactly (:func:`fpm_sim.sim.stepping.remove_integrator_effect`). ``integrator="explicit"``: the
model's own ``implicitfast`` integrator and automatic step (explicit springs: 5-7 us at 3 segments, 0.3-0.8 us at
12, about 50 times slower), the reference. Measured at pose (0, 0, 0.2) with ``h = 20 us``
(``scripts/benchmark_impact_timestep.py``): 12 segments run 46-54x faster, 3 segments 2.4-2.9x, and the EMA
reads the same frequencies from both FRFs to 0.04 % (12 segments, 0.1 s records) and 0.005 % (3 segments,
0.5 s records).

Modal reference: :func:`fpm_sim.rom.reduction.modal_system` of the *same* compiled model (same
discretisation and timestep) at the same equilibrium.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from fpm_sim.errors import FpmSimWarning
from fpm_sim.linear.equilibrium import static_equilibrium
from fpm_sim.model.spec import BuiltModel
from fpm_sim.response import (
    DEFAULT_MIN_PROMINENCE_DB,
    FrequencyResponse,
    FrfError,
    LinkPoint,
    default_point,
    half_power_damping,
    material_point,
    modal_frf,
)
from fpm_sim.rom.reduction import ModalSystem, modal_system
from fpm_sim.sim.stepping import (
    DEFAULT_INTEGRATOR,
    Stepping,
    SteppingError,
    apply_stepping,
    choose_stepping,
    reraise_as,
)

__all__ = [
    "PEAK_FORCE_N",
    "PULSE_S",
    "STUDY_IMPACT_POINT",
    "UFF_POSE_TAG",
    "ImpactRecord",
    "ImpactSetup",
    "ImpactTestResult",
    "exp_window_tau_s",
    "h1_estimate",
    "point_acceleration",
    "virtual_impact_test",
    "write_uff58",
]

PULSE_S = 1e-3
"""Half-sine pulse duration (s); see the module docstring."""
PEAK_FORCE_N = 20.0
"""Peak hammer force (N). Assumed: a light tap. Its impulse, ``2 F T / pi`` = 0.013 N s, sets mode 1
ringing at the driving point with an amplitude of about ``impulse * r_1 / omega_1`` ~ 10 um (``r_1`` ~ 0.3
1/kg the modal constant, ``omega_1`` ~ 445 rad/s): the linear range of 228 mm links."""
STUDY_IMPACT_POINT = LinkPoint("distal_0", 0.5, "z")
"""Assumed study impact and accelerometer point (see the module docstring)."""


@dataclass(frozen=True)
class ImpactSetup:
    """How the virtual test is run (SI units; see the module docstring).

    Parameters
    ----------
    impact, accelerometer
        Hammer point/direction and accelerometer point/axis (default both :data:`STUDY_IMPACT_POINT`).
    pulse_s, peak_force_n
        Half-sine pulse duration (s) and peak force (N).
    n_impacts
        Impacts averaged (the study: 3).
    record_s
        Record length per impact (s).
    sample_s
        Sampling interval (s); rounded to a whole number of model timesteps.
    pad_s
        Zero-padded length for the FFT (s); the spectral line spacing is ``1 / pad_s``.
    window_end
        Exponential window value at the end of the record (1 = no window).
    noise_m_s2
        Standard deviation of the accelerometer noise (m/s^2).
    force_spread
        Relative spread of the peak force between impacts.
    seed
        Random seed for the force spread and the noise.
    f_min_hz, f_max_hz
        Band searched for peaks (Hz).
    min_prominence_db
        Prominence a peak needs (dB).
    timestep_s
        Discrete integrator step of the rollouts (s) instead of the band's (module docstring); at most
        ``sample_s`` and ``pulse_s / 10``.
    integrator
        ``"discrete"`` (default) or ``"explicit"`` (the model's own step; the reference).
    band_hz
        Band (Hz) the discrete step is chosen for (default 5 x f1; :mod:`fpm_sim.sim.stepping`).
    """

    impact: LinkPoint = STUDY_IMPACT_POINT
    accelerometer: LinkPoint = STUDY_IMPACT_POINT
    pulse_s: float = PULSE_S
    peak_force_n: float = PEAK_FORCE_N
    n_impacts: int = 3
    record_s: float = 0.5
    sample_s: float = 1e-4
    pad_s: float = 8.0
    window_end: float = 0.01
    noise_m_s2: float = 0.0
    force_spread: float = 0.1
    seed: int = 0
    f_min_hz: float = 5.0
    f_max_hz: float = 1000.0
    min_prominence_db: float = DEFAULT_MIN_PROMINENCE_DB
    timestep_s: float | None = None
    integrator: str = DEFAULT_INTEGRATOR
    band_hz: float | None = None

    def check(self) -> None:
        positive = ("pulse_s", "peak_force_n", "record_s", "sample_s", "pad_s", "f_max_hz")
        for name in positive:
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise FrfError("must be positive", parameter=name, value=v)
        if not (isinstance(self.n_impacts, int) and self.n_impacts >= 1):
            raise FrfError("must be an integer >= 1", parameter="n_impacts", value=self.n_impacts)
        if not (0.0 < self.window_end <= 1.0):
            raise FrfError("must lie in (0, 1]", parameter="window_end", value=self.window_end)
        if not self.noise_m_s2 >= 0.0:
            raise FrfError("must be >= 0", parameter="noise_m_s2", value=self.noise_m_s2)
        if not 0.0 <= self.force_spread < 1.0:
            raise FrfError("must lie in [0, 1)", parameter="force_spread", value=self.force_spread)
        if self.pulse_s >= self.record_s:
            raise FrfError(f"pulse_s ({self.pulse_s:g} s) must be shorter than record_s ({self.record_s:g} s)")
        if self.pad_s < self.record_s:
            raise FrfError(f"pad_s ({self.pad_s:g} s) must be at least record_s ({self.record_s:g} s)")
        if self.integrator == "explicit" and self.timestep_s is not None:
            raise FrfError(
                "sets the discrete integrator's step",
                parameter="timestep_s",
                value=self.timestep_s,
                hint="drop it with the explicit integrator (it runs at the model's own step)",
            )
        if self.timestep_s is not None:
            h = self.timestep_s
            if not (math.isfinite(h) and h > 0):
                raise FrfError(f"timestep_s must be positive, got {h!r}")
            if h > self.sample_s * (1 + 1e-9):
                raise FrfError(f"timestep_s ({h:g} s) must not exceed sample_s ({self.sample_s:g} s)")
            if h > self.pulse_s / 10:
                raise FrfError(
                    f"timestep_s ({h:g} s) must resolve the pulse: at most pulse_s / 10 = {self.pulse_s / 10:g} s"
                )
        if self.f_max_hz > 0.5 / self.sample_s:
            raise FrfError(
                f"f_max_hz ({self.f_max_hz:g} Hz) is above the Nyquist frequency {0.5 / self.sample_s:g} Hz of "
                "sample_s; lower f_max_hz or sample_s"
            )


@dataclass
class ImpactRecord:
    """One impact: sampled time (s), hammer force (N) and accelerometer signal (m/s^2)."""

    t_s: np.ndarray
    force_n: np.ndarray
    accel_m_s2: np.ndarray
    peak_force_n: float
    wall_s: float


def point_acceleration(
    model: mujoco.MjModel, data: mujoco.MjData, body_id: int, point: np.ndarray, res6: np.ndarray | None = None
) -> np.ndarray:
    """World linear acceleration (m/s^2, gravity excluded) of a material point of a body.

    Needs ``mj_forward`` and ``mj_rnePostConstraint`` done. ``a_p = a_o + alpha x r + w x (w x r)``
    with ``o`` the body frame origin (``mj_objectAcceleration`` / ``mj_objectVelocity`` of the
    ``XBODY``) and ``r = p - o``.
    """
    acc = np.zeros(6) if res6 is None else res6
    vel = np.zeros(6)
    mujoco.mj_objectAcceleration(model, data, mujoco.mjtObj.mjOBJ_XBODY, body_id, acc, 0)
    mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_XBODY, body_id, vel, 0)
    r = point - data.xpos[body_id]
    w = vel[:3]
    # cacc carries -gravity (accelerometer convention): add gravity back for the kinematic acceleration
    return acc[3:] + model.opt.gravity + _cross(acc[:3], r) + _cross(w, _cross(w, r))


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """3-vector cross product (``np.cross`` costs ~20 us a call; this runs twice per sample)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _one_impact(
    built: BuiltModel,
    q_eq: np.ndarray,
    setup: ImpactSetup,
    peak_force_n: float,
    n_sub: int,
    n_samples: int,
) -> ImpactRecord:
    model = built.model
    data = mujoco.MjData(model)
    data.qpos[:] = q_eq
    data.qvel[:] = 0.0
    mujoco.mj_forward(model, data)
    h = float(model.opt.timestep)
    force = np.zeros(n_samples)
    accel = np.zeros(n_samples)
    res6 = np.zeros(6)
    torque0 = np.zeros(3)
    n_pulse_steps = math.ceil(setup.pulse_s / h) + 1
    hammer = material_point(built, setup.impact)
    sensor = material_point(built, setup.accelerometer)
    start = time.perf_counter()
    step = 0
    for k in range(n_samples):
        t_k = k * n_sub * h
        # sample: the state at t_k with the force applied at t_k (so the acceleration includes it)
        f_k = peak_force_n * math.sin(math.pi * t_k / setup.pulse_s) if t_k <= setup.pulse_s else 0.0
        data.qfrc_applied[:] = 0.0
        if f_k:
            p_i, e_i = hammer.world(data)
            mujoco.mj_applyFT(model, data, f_k * e_i, torque0, p_i, hammer.body_id, data.qfrc_applied)
        mujoco.mj_forward(model, data)
        mujoco.mj_rnePostConstraint(model, data)
        p_a, e_a = sensor.world(data)
        accel[k] = e_a @ point_acceleration(model, data, sensor.body_id, p_a, res6)
        force[k] = f_k
        if k == n_samples - 1:
            break
        if step < n_pulse_steps:
            for _ in range(n_sub):  # the pulse is applied at every integrator step
                t = step * h
                data.qfrc_applied[:] = 0.0
                if t <= setup.pulse_s:
                    p_i, e_i = hammer.world(data)
                    f = peak_force_n * math.sin(math.pi * t / setup.pulse_s)
                    mujoco.mj_applyFT(model, data, f * e_i, torque0, p_i, hammer.body_id, data.qfrc_applied)
                mujoco.mj_step(model, data)
                step += 1
        else:
            data.qfrc_applied[:] = 0.0
            mujoco.mj_step(model, data, nstep=n_sub)
            step += n_sub
        if not np.all(np.isfinite(data.qpos)):
            raise FrfError(f"the impact simulation diverged at t = {data.time:.4g} s; lower peak_force_n")
    wall = time.perf_counter() - start
    t_s = np.arange(n_samples) * n_sub * h
    return ImpactRecord(t_s, force, accel, peak_force_n, wall)


def exp_window_tau_s(record_s: float, window_end: float) -> float:
    """Time constant (s) of the exponential window ``exp(-t / tau)`` that falls to ``window_end`` of its initial
    value at ``t = record_s`` (``inf`` for ``window_end = 1``: no window)."""
    return record_s / math.log(1.0 / window_end) if window_end < 1.0 else math.inf


def h1_estimate(
    records: list[ImpactRecord], *, pad_s: float, window_end: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """H1 FRF ``sum conj(F) A / sum |F|^2`` and coherence from impact records (module docstring).

    Returns frequency (Hz), complex H1 (m/s^2/N) and the ordinary coherence.
    """
    t = records[0].t_s
    dt = float(t[1] - t[0])
    n = len(t)
    n_fft = int(2 ** math.ceil(math.log2(max(pad_s / dt, n))))
    tau = exp_window_tau_s(float(t[-1]), window_end)
    win = np.exp(-t / tau)
    sff = np.zeros(n_fft // 2 + 1)
    saa = np.zeros(n_fft // 2 + 1)
    sfa = np.zeros(n_fft // 2 + 1, complex)
    for r in records:
        f_spec = np.fft.rfft(r.force_n * win, n_fft) * dt
        a_spec = np.fft.rfft(r.accel_m_s2 * win, n_fft) * dt
        sff += np.abs(f_spec) ** 2
        saa += np.abs(a_spec) ** 2
        sfa += np.conj(f_spec) * a_spec
    freq = np.fft.rfftfreq(n_fft, dt)
    with np.errstate(invalid="ignore", divide="ignore"):
        h1 = sfa / sff
        coh = np.abs(sfa) ** 2 / (sff * saa)
    return freq, h1, np.nan_to_num(coh)


@dataclass
class ImpactTestResult:
    """Outcome of :func:`virtual_impact_test` (SI units)."""

    frf: FrequencyResponse
    records: list[ImpactRecord]
    first_peak_hz: float
    modal_f1_hz: float
    modal_freq_hz: np.ndarray
    damping_half_power: float
    window_damping: float
    window_tau_s: float
    """Time constant (s) of the exponential response window (``inf``: none); give it to ``fpm-sim ema`` (it
    travels in the UFF record written by :func:`write_uff58`) so that the EMA removes the window's decay."""
    setup: ImpactSetup
    parameters: dict[str, Any] = field(default_factory=dict)
    modal_constants: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """Per mode of the linear model: ``(c phi_r)(phi_r' b)`` (1/kg), hammer force in, acceleration out."""
    excitation: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """Per mode: ``|phi_r' b|``, how strongly the hammer excites it (1/sqrt(kg))."""
    observation: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """Per mode: ``|c phi_r|``, how strongly the accelerometer sees it (1/sqrt(kg))."""

    def mode1_note(self) -> str:
        """In words: which mode the first FRF peak is and, when it is not mode 1, why mode 1 was not seen (its
        modal constant at this hammer/accelerometer pair against the seen mode's, split into how strongly the
        hammer excites it and how strongly the accelerometer sees it); '' when the first peak is mode 1."""
        k = self.first_peak_mode
        if k == 1:
            return ""
        f1 = self.modal_f1_hz
        if k == 0:
            return f"no FRF peak in the band: mode 1 ({f1:.4g} Hz) and the others are not seen at this set-up"
        text = (
            f"the first FRF peak ({self.first_peak_hz:.4g} Hz) is mode {k} ({self.modal_freq_hz[k - 1]:.4g} Hz); "
            f"mode 1 ({f1:.4g} Hz) is not seen"
        )
        if self.modal_constants.size >= k:
            r = np.abs(self.modal_constants)
            ex, ob = self.excitation, self.observation
            ratio = r[0] / r[k - 1] if r[k - 1] > 0 else math.inf
            text += (
                f": at hammer {self.setup.impact.label()} and accelerometer {self.setup.accelerometer.label()} mode "
                f"1's modal constant is {ratio:.2g} of mode {k}'s (the hammer excites mode 1 "
                f"{ex[0] / ex[k - 1]:.2g}x as strongly as mode {k}, the accelerometer sees it {ob[0] / ob[k - 1]:.2g}x "
                "as strongly), so its peak is too small to stand out; move the hammer or the accelerometer (e.g. "
                "another axis: fpm-sim readability ranks the points)"
            )
        return text

    stepping: Stepping | None = None
    """How the rollouts were stepped; its ``step_s`` travels in the UFF record (``discrete_step_s``)."""

    @property
    def numerical_damping(self) -> float:
        """Damping ratio the integrator adds at the first peak (0 for the explicit reference)."""
        if self.stepping is None or not math.isfinite(self.first_peak_hz):
            return 0.0
        return self.stepping.damping_at(self.first_peak_hz)

    @property
    def discrete_step_s(self) -> float | None:
        """The discrete integrator's step (s), or ``None`` (explicit reference): what the EMA must invert."""
        return self.stepping.step_s if self.stepping is not None and self.stepping.integrator == "discrete" else None

    @property
    def first_peak_mode(self) -> int:
        """1-based index of the model's mode nearest the first peak (1: the test reads mode 1; more: mode 1
        is not seen at this hammer/accelerometer set-up). 0 when there is no peak."""
        if not math.isfinite(self.first_peak_hz):
            return 0
        return int(np.argmin(np.abs(self.modal_freq_hz - self.first_peak_hz))) + 1

    @property
    def identified_damping_ratio(self) -> float:
        """Damping ratio of the first mode identified from the test: the half-power reading minus the damping
        the exponential window and the integrator add (pass it to :func:`fpm_sim.response.modal_frf` or ``fpm-sim frf
        --damping-ratio``)."""
        return self.damping_half_power - self.window_damping - self.numerical_damping

    @property
    def relative_error(self) -> float:
        """``first_peak_hz / modal_f1_hz - 1``."""
        return self.first_peak_hz / self.modal_f1_hz - 1.0

    def to_dict(self) -> dict[str, Any]:
        peaks = self.frf.peaks(min_prominence_db=self.setup.min_prominence_db, f_min_hz=self.setup.f_min_hz)
        band = self.frf.freq_hz <= self.setup.f_max_hz
        return {
            "first_peak_hz": self.first_peak_hz,
            "modal_f1_hz": self.modal_f1_hz,
            "first_peak_mode": self.first_peak_mode,
            "first_peak_note": self.mode1_note(),
            "relative_error": self.relative_error,
            "modal_freq_hz": self.modal_freq_hz[:8].tolist(),
            "peaks": [
                {"freq_hz": p.freq_hz, "prominence_db": p.prominence_db}
                for p in peaks
                if p.freq_hz <= self.setup.f_max_hz
            ][:8],
            "damping_ratio_half_power": self.damping_half_power,
            "window_added_damping_at_first_peak": self.window_damping,
            "window_tau_s": self.window_tau_s if math.isfinite(self.window_tau_s) else None,
            "numerical_damping_at_first_peak": self.numerical_damping,
            "discrete_step_s": self.discrete_step_s,
            "stepping": self.stepping.to_dict() if self.stepping is not None else None,
            "identified_damping_ratio": self.identified_damping_ratio,
            "min_coherence_in_band": float(np.min(self.frf.coherence[band & (self.frf.freq_hz >= self.setup.f_min_hz)]))
            if self.frf.coherence.size
            else None,
            "impacts": [{"peak_force_n": r.peak_force_n, "wall_s": r.wall_s} for r in self.records],
            "setup": {
                **{k: v for k, v in asdict(self.setup).items() if k not in ("impact", "accelerometer")},
                "impact": self.setup.impact.label(),
                "accelerometer": self.setup.accelerometer.label(),
            },
            "parameters": self.parameters,
        }

    def table(self) -> str:
        d = self.to_dict()
        lines = [
            f"virtual impact test: hammer {d['setup']['impact']}, accelerometer {d['setup']['accelerometer']}, "
            f"{len(self.records)} impacts of {self.setup.pulse_s * 1e3:g} ms, record {self.setup.record_s:g} s",
            f"  first FRF peak   {self.first_peak_hz:10.3f} Hz",
            f"  modal f1         {self.modal_f1_hz:10.3f} Hz   (difference {self.relative_error * 100:+.3f} %)",
            "  first peak is mode 1" if self.first_peak_mode == 1 else f"  {self.mode1_note()}",
            f"  half-power zeta  {self.damping_half_power:10.4f}     (includes {self.window_damping:.4f} from the "
            f"exponential window and {self.numerical_damping:.4f} from the integrator: identified "
            f"{self.identified_damping_ratio:.4f})",
            *([f"  {self.stepping.line()}"] if self.stepping is not None else []),
            f"{'peak':>6}  {'freq (Hz)':>10}  {'prominence (dB)':>16}",
        ]
        for i, p in enumerate(d["peaks"], 1):
            lines.append(f"{i:>6}  {p['freq_hz']:>10.3f}  {p['prominence_db']:>16.1f}")
        return "\n".join(lines)

    def plot(self, ax: Any = None, *, axes: Any = None) -> Any:
        """H1 magnitude and phase with the modal frequencies marked, and the coherence; returns the ``Figure``.

        ``ax``: one axes for the H1 magnitude alone; ``axes``: three (magnitude, phase, coherence); default a
        new figure.
        """
        import matplotlib.pyplot as plt

        if ax is None and axes is None:
            _, axes = plt.subplots(3, 1, figsize=(8, 7), sharex=True, gridspec_kw={"height_ratios": [2, 1, 1]})
        band = (self.frf.freq_hz >= self.setup.f_min_hz) & (self.frf.freq_hz <= self.setup.f_max_hz)
        sub = FrequencyResponse(
            self.frf.freq_hz[band],
            self.frf.h[band],
            self.frf.quantity,
            self.frf.unit,
            self.frf.excitation,
            self.frf.response,
            modal_freq_hz=self.modal_freq_hz,
        )
        if ax is not None:
            sub.plot(ax=ax, label=f"H1, {len(self.records)} impacts")
            ax.axvline(self.first_peak_hz, color="r", ls="--", lw=0.8)
            return ax.figure
        sub.plot(axes=axes[:2], label=f"H1, {len(self.records)} impacts")
        axes[1].set_xlabel("")
        axes[0].axvline(self.first_peak_hz, color="r", ls="--", lw=0.8)
        axes[2].plot(self.frf.freq_hz[band], self.frf.coherence[band], lw=1.0)
        axes[2].set_ylabel("coherence")
        axes[2].set_ylim(0, 1.05)
        axes[2].set_xlabel("frequency (Hz)")
        return axes[0].figure


def virtual_impact_test(
    built: BuiltModel,
    setup: ImpactSetup | None = None,
    *,
    system: ModalSystem | None = None,
    progress: bool = False,
) -> ImpactTestResult:
    """Run the virtual impact test on ``built`` (see the module docstring).

    Parameters
    ----------
    built
        The full model; a copy runs on the ``discrete`` integrator unless ``setup.integrator`` is ``"explicit"``
        (``built`` is not changed). ``sample_s`` is rounded to a whole number of steps.
    setup
        Test settings (default: :class:`ImpactSetup` with the hammer and the accelerometer at the model's test
        point, :func:`fpm_sim.response.default_point`: the study's :data:`STUDY_IMPACT_POINT` on the 3RRR).
    system
        The modal system of ``built`` if already computed (else computed here).
    progress
        Show a tqdm progress bar over the impacts.
    """
    setup = setup or ImpactSetup(impact=default_point(built), accelerometer=default_point(built))
    setup.check()
    setup.impact.check(built)
    setup.accelerometer.check(built)
    q_eq = static_equilibrium(built.model, mujoco.MjData(built.model)) if system is None else system.qpos
    system = system or modal_system(built, qpos=q_eq)
    stepping = _impact_stepping(built, setup, float(system.frequencies_hz[0]))
    rollout = apply_stepping(built, stepping)
    h = float(rollout.model.opt.timestep)
    n_sub = max(1, round(setup.sample_s / h))
    dt = n_sub * h
    n_samples = round(setup.record_s / dt) + 1
    records = _impacts(rollout, q_eq, setup, n_sub, n_samples, progress=progress)
    freq, h1, coh = h1_estimate(records, pad_s=setup.pad_s, window_end=setup.window_end)
    frf = FrequencyResponse(
        freq_hz=freq,
        h=h1,
        quantity="accelerance",
        unit="m/s^2/N",
        excitation=setup.impact.label(),
        response=setup.accelerometer.label(),
        modal_freq_hz=system.frequencies_hz,
        coherence=coh,
    )
    first, zeta, tau, window_zeta = _first_peak(frf, setup, dt * (n_samples - 1))
    # the linear model's modal constants at this set-up: why a mode is (not) seen
    constants, hammer, sensor = _modal_constants(system, setup)
    result = ImpactTestResult(
        frf=frf,
        records=records,
        first_peak_hz=first,
        modal_f1_hz=float(system.frequencies_hz[0]),
        modal_freq_hz=system.frequencies_hz,
        damping_half_power=zeta,
        window_damping=window_zeta,
        window_tau_s=tau,
        setup=setup,
        stepping=stepping,
        parameters={
            **built.parameters,
            "sample_s": dt,
            "steps_per_sample": n_sub,
            "rollout_timestep_s": h,
            "rollout_integrator": mujoco.mjtIntegrator(rollout.model.opt.integrator).name,
        },
        modal_constants=np.asarray(constants),
        excitation=np.sqrt(np.abs(hammer)),  # driving point: (phi' b)^2
        observation=np.sqrt(np.abs(sensor)),  # driving point at the accelerometer: (c phi)^2
    )
    if result.first_peak_mode != 1:
        warnings.warn(result.mode1_note(), FpmSimWarning, stacklevel=2)
    return result


UFF_POSE_TAG = "fpm-sim pose"
"""Prefix of the UFF 58 ``id4`` record that carries the pose (``fpm-sim pose x_mm=.. y_mm=.. phi_rad=..``)."""
UFF_WINDOW_TAG = "fpm-sim exp-window"
"""Prefix of the UFF 58 ``id5`` record that carries the exponential window (``fpm-sim exp-window tau_s=..``)."""
UFF_STEP_TAG = "discrete-step_s"
"""Key of the discrete integrator's step in the UFF 58 ``id5`` record (``discrete-step_s=..``)."""


def _first_peak(frf: FrequencyResponse, setup: ImpactSetup, record_s: float) -> tuple[float, float, float, float]:
    """The first peak of the H1 below ``f_max_hz`` (Hz; NaN if none), its half-power damping ratio, the exponential
    window's time constant (s) over a record of ``record_s`` and the damping ratio that window adds at the peak."""
    keep = frf.freq_hz <= setup.f_max_hz
    peaks = [
        p
        for p in frf.peaks(min_prominence_db=setup.min_prominence_db, f_min_hz=setup.f_min_hz)
        if p.freq_hz <= setup.f_max_hz
    ]
    first = peaks[0].freq_hz if peaks else math.nan
    zeta = half_power_damping(frf.freq_hz[keep], np.abs(frf.h[keep]), first) if peaks else math.nan
    tau = exp_window_tau_s(record_s, setup.window_end)
    window_zeta = 1.0 / (tau * 2.0 * math.pi * first) if peaks and math.isfinite(tau) else 0.0
    return first, zeta, tau, window_zeta


def _impact_stepping(built: BuiltModel, setup: ImpactSetup, f1_hz: float) -> Stepping:
    """The rollouts' integrator and step: from the set-up's band, dividing the sample interval, at least ten steps
    per hammer pulse (:func:`fpm_sim.sim.stepping.choose_stepping`)."""
    try:
        stepping = choose_stepping(
            built,
            integrator=setup.integrator,
            band_hz=setup.band_hz,
            step_s=setup.timestep_s,
            divides_s=setup.sample_s,
            max_step_s=setup.pulse_s / 10,
            f1_hz=f1_hz,
        )
    except SteppingError as e:
        raise reraise_as(FrfError, e) from None
    return stepping


def _impacts(
    rollout: BuiltModel, q_eq: np.ndarray, setup: ImpactSetup, n_sub: int, n_samples: int, *, progress: bool
) -> list[ImpactRecord]:
    """``setup.n_impacts`` hammer hits of random amplitude (``force_spread``), each recorded with sensor noise."""
    rng = np.random.default_rng(setup.seed)
    amps = setup.peak_force_n * (1.0 + setup.force_spread * rng.uniform(-1.0, 1.0, setup.n_impacts))
    it = range(setup.n_impacts)
    if progress:
        from tqdm import tqdm

        it = tqdm(it, desc="impacts", unit="impact", leave=False)
    records = []
    for i in it:
        rec = _one_impact(rollout, q_eq, setup, float(amps[i]), n_sub, n_samples)
        if setup.noise_m_s2 > 0:
            rec.accel_m_s2 = rec.accel_m_s2 + rng.normal(0.0, setup.noise_m_s2, rec.accel_m_s2.size)
        records.append(rec)
    return records


def _modal_constants(system: ModalSystem, setup: ImpactSetup) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The linear model's modal constants at this set-up (why a mode is, or is not, seen): hammer to sensor,
    hammer driving point, sensor driving point."""
    one_hz = np.array([1.0])
    constants = modal_frf(system, excitation=setup.impact, response=setup.accelerometer, freq_hz=one_hz).residues
    hammer = modal_frf(system, excitation=setup.impact, response=setup.impact, freq_hz=one_hz).residues
    sensor = modal_frf(system, excitation=setup.accelerometer, response=setup.accelerometer, freq_hz=one_hz).residues
    return constants, hammer, sensor


def write_uff58(
    frf: FrequencyResponse,
    path: str | Path,
    *,
    pose_mm_rad: tuple[float, float, float] | None = None,
    response_node: int = 1,
    reference_node: int = 1,
    response_dir: int = 3,
    reference_dir: int = 3,
    description: str = "fpm-sim virtual impact test",
    window_tau_s: float | None = None,
    discrete_step_s: float | None = None,
) -> Path:
    """Write an FRF as a Universal File Format type-58 record (ASCII) with :mod:`pyuff`.

    Function type 4 (FRF), complex ordinate, even abscissa spacing (``frf.freq_hz`` must be evenly
    spaced), SI units as they are (accelerance m/s^2/N). ``pose_mm_rad`` (x_mm, y_mm, phi_rad) is
    written into ``id4`` so that :func:`fpm_sim.study.identify.ema.read_frfs` knows where the test was;
    directions follow UFF (1 = x, 2 = y, 3 = z; negative for the opposite sense). ``window_tau_s`` (s), the
    time constant of the exponential window the FRF was computed with, is written into ``id5``, so that
    ``fpm-sim ema`` removes the decay it added (None or ``inf``: no window); ``discrete_step_s`` (s), the discrete
    integrator's step of the rollouts, joins it there (``discrete-step_s=..``) so that the EMA inverts the step's
    numerical damping and period error (None: explicit reference, nothing to invert). Overwrites ``path``.
    """
    import pyuff

    p = Path(path)
    f = np.asarray(frf.freq_hz, float)
    if f.size < 2 or not np.allclose(np.diff(f), f[1] - f[0], rtol=1e-6, atol=1e-9):
        raise FrfError(f"UFF 58 needs an evenly spaced frequency axis; {p} not written")
    if p.exists():
        p.unlink()
    id4 = (
        "NONE"
        if pose_mm_rad is None
        else (f"{UFF_POSE_TAG} x_mm={pose_mm_rad[0]:.6g} y_mm={pose_mm_rad[1]:.6g} phi_rad={pose_mm_rad[2]:.6g}")
    )
    windowed = window_tau_s is not None and math.isfinite(window_tau_s)
    parts = [f"{UFF_WINDOW_TAG} tau_s={window_tau_s:.9g}"] if windowed else []
    if discrete_step_s is not None:
        parts.append(f"fpm-sim {UFF_STEP_TAG}={discrete_step_s:.9g}")
    id5 = " ".join(parts) or "NONE"
    ds = pyuff.prepare_58(
        binary=0,
        id1=description[:80],
        id2=f"{frf.quantity} ({frf.unit})"[:80],
        id3=f"excitation {frf.excitation}, response {frf.response}"[:80],
        id4=id4[:80],
        id5=id5[:80],
        func_type=4,
        rsp_node=response_node,
        rsp_dir=response_dir,
        ref_node=reference_node,
        ref_dir=reference_dir,
        data=np.asarray(frf.h, complex),
        x=f,
        abscissa_spacing=1,
        abscissa_spec_data_type=18,
        ordinate_spec_data_type=12,
        orddenom_spec_data_type=13,
    )
    pyuff.UFF(str(p)).write_sets(ds, mode="overwrite")
    return p
