"""A bed of nails: the study's posterior, on the dominant orbit's class, has many optima, each only a few degrees wide
in the two rotations (issue 31; docs/identification.md, "Two mode families"). Compass searches of the two-family
emulator (fitted to segment-model runs at stage 1's particles, as a calibration run fits it) from many starts find
them; each optimum is checked on the segment model, and its width along the platform's rotation measured with and
without the as-built tolerances (1 deg at each joint circle, 1 % of each link, per chain) propagated into the
likelihood as a model error.

    python studies/calibration_nails.py --starts 64 256
    python studies/calibration_nails.py --starts 256 --split geometry.base_rotation_deg 2 --part 0   # motors < 0

The starts are stage 1's particles (the prior times the study's statements) chosen far apart (greedily by the
emulated log-likelihood, each at least 0.25 from those before it in the unit cube). A compass search (pattern search,
Kolda, Lewis & Torczon 2003) tries +-step along every coordinate, moves to the best neighbour if it improves, else
halves its step (0.05 down to 1e-4), vectorised over the starts.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from fpm_sim.kinematics import GeometryArrays, assemble_batch
from fpm_sim.study.calibrate import SamplerOptions
from fpm_sim.study.calibrate import sampler as S
from fpm_sim.study.calibrate import smc as SM
from fpm_sim.study.calibrate import vectorised as V
from fpm_sim.study.calibrate.problem import study_problem
from fpm_sim.study.inplane_surrogate import inplane_batch
from fpm_sim.study.outofplane_surrogate import outofplane_batch

Evaluate = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class CompassSettings:
    """A compass search's settings (unit-cube lengths)."""

    step: float = 0.05
    """The first step along each coordinate."""
    min_step: float = 1e-4
    """A start stops when its step falls below this (0.036 deg of a whole-turn angle)."""
    max_iter: int = 300
    """At most this many iterations (each start moves or halves its step once per iteration)."""
    spacing: float = 0.25
    """:func:`spread_starts`' least distance between starts."""


def _distance(a: np.ndarray, b: np.ndarray, periodic: tuple[int, ...]) -> np.ndarray:
    """Unit-cube distances from the rows of ``a`` ``(n, d)`` to ``b`` ``(d,)``, whole-turn coordinates the shorter
    way round."""
    diff = np.abs(a - b)
    if periodic:
        per = list(periodic)
        diff[:, per] = np.minimum(diff[:, per], 1.0 - diff[:, per])
    out: np.ndarray = np.sqrt(np.sum(diff**2, axis=1))
    return out


def spread_starts(
    u: np.ndarray, log_l: np.ndarray, n: int, *, spacing: float, periodic: tuple[int, ...] = ()
) -> np.ndarray:
    """At most ``n`` rows of ``u`` (``log_l``: their log-likelihood), greedily by ``log_l``: each at least
    ``spacing`` from those chosen before it; where fewer than ``n`` are that far apart, the best of the rest fill
    up. Rows with ``log_l = -inf`` are never chosen."""
    order = [int(i) for i in np.argsort(-log_l) if np.isfinite(log_l[i])]
    chosen: list[int] = []
    for i in order:
        if len(chosen) == n:
            break
        if not chosen or np.min(_distance(u[chosen], u[i], periodic)) >= spacing:
            chosen.append(i)
    rest = [i for i in order if i not in set(chosen)]
    chosen += rest[: n - len(chosen)]
    out: np.ndarray = u[chosen]
    return out


def compass_search(
    evaluate: Evaluate, starts: np.ndarray, settings: CompassSettings, *, periodic: tuple[int, ...] = ()
) -> tuple[np.ndarray, np.ndarray, int]:
    """Maximise ``log L_a + log L_b`` from each row of ``starts`` ``(S, d)`` on the unit cube (whole-turn
    coordinates ``periodic`` wrapped, the others clipped): each iteration every active start tries ``+-step`` along
    every coordinate, moves to the best neighbour if it improves, else halves its step. Returns ``(optima (S, d),
    their log L (S,), evaluations)``."""
    x = np.array(starts, float)
    s, d = x.shape
    la, lb = evaluate(x)
    with np.errstate(invalid="ignore"):
        fx = la + lb
    fx = np.where(np.isnan(fx), -np.inf, fx)
    step = np.full(s, settings.step)
    dirs = np.concatenate([np.eye(d), -np.eye(d)])  # (2d, d)
    per = list(periodic)
    calls = s
    for _ in range(settings.max_iter):
        active = np.flatnonzero((step >= settings.min_step) & np.isfinite(fx))
        if active.size == 0:
            break
        raw = x[active, None, :] + step[active, None, None] * dirs[None]  # (a, 2d, d)
        trial = np.clip(raw, 0.0, 1.0)
        if per:
            trial[..., per] = np.mod(raw[..., per], 1.0)
        la, lb = evaluate(trial.reshape(-1, d))
        calls += trial.shape[0] * trial.shape[1]
        with np.errstate(invalid="ignore"):
            ft = (la + lb).reshape(len(active), 2 * d)
        ft = np.where(np.isnan(ft), -np.inf, ft)
        best = np.argmax(ft, axis=1)
        gain = ft[np.arange(len(active)), best]
        better = gain > fx[active]
        moved = active[better]
        x[moved] = trial[better, best[better]]
        fx[moved] = gain[better]
        step[active[~better]] *= 0.5
    return x, fx, calls


def _polar(ga: GeometryArrays) -> dict[str, np.ndarray]:
    def split(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return np.linalg.norm(p, axis=2), np.arctan2(p[..., 1], p[..., 0])

    br, ba = split(ga.base_points)
    pr, pa = split(ga.platform_local)
    return {
        "base_radius_m": br,
        "base_angles_rad": ba,
        "platform_radius_m": pr,
        "platform_angles_rad": pa,
        "proximal_m": ga.proximal_m.copy(),
        "distal_m": ga.distal_m.copy(),
        "elbow_branch": ga.elbow_branch,
    }


def tolerance_rel(problem: object, thetas: np.ndarray, angle_deg: float = 1.0, length_rel: float = 0.01) -> np.ndarray:
    """``(n, n_obs)`` the relative sd of f1 that per-chain as-built deviations (each joint circle's angle by
    ``angle_deg``, each link by ``length_rel``) give, to first order on the two surrogates (the lower family)."""
    d, _ = V._described(problem, thetas)  # type: ignore[arg-type]
    xyz, oi = problem.measured_pose_array, problem.observation_pose_index  # type: ignore[attr-defined]

    def f1(desc: object) -> np.ndarray:
        m = assemble_batch(desc.geometry, xyz[:, 0], xyz[:, 1], xyz[:, 2])  # type: ignore[attr-defined]
        fi = inplane_batch(V._inplane(desc), xyz, assembled=m)  # type: ignore[arg-type]
        fo = outofplane_batch(V._outofplane(desc), xyz, assembled=m)  # type: ignore[arg-type]
        out: np.ndarray = np.fmin(fi, fo)[:, oi]
        return out

    f0, p0 = f1(d), _polar(d.geometry)
    var = np.zeros_like(f0)
    steps = {
        "base_angles_rad": np.radians(angle_deg),
        "platform_angles_rad": np.radians(angle_deg),
        "proximal_m": length_rel,
        "distal_m": length_rel,
    }
    for key, step in steps.items():
        for chain in range(3):
            p = {k: v.copy() for k, v in p0.items()}
            p[key][:, chain] = p[key][:, chain] * (1 + step) if key.endswith("_m") else p[key][:, chain] + step
            f = f1(dataclasses.replace(d, geometry=GeometryArrays.from_polar(**p)))
            var += np.nan_to_num(f - f0, nan=0.0) ** 2  # a deviation that leaves a pose unreachable: left out
    out: np.ndarray = np.sqrt(var) / f0
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--branch", type=int, nargs=3, default=[-1, -1, 1])
    p.add_argument("--starts", type=int, nargs="+", default=[64, 256])
    p.add_argument("--runs", type=int, default=500, help="segment-model runs the emulator is fitted to")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--check", type=int, default=6, help="optima checked on the segment model")
    p.add_argument("--split", nargs=2, metavar=("NAME", "N"), help="search one part of this split prior (--part)")
    p.add_argument("--part", type=int, default=0, help="the part of --split searched (from 0)")
    a = p.parse_args()
    warnings.simplefilter("ignore")
    prob = study_problem(model="segments", branch=tuple(a.branch))
    S._init_worker(prob)
    rng = np.random.default_rng(a.seed)
    split = None if a.split is None else (a.split[0], int(a.split[1]))
    opts = SamplerOptions(
        sampler="smc", particles=1000, cheap_particles=2000, emulator=a.runs, seed=a.seed, split=split
    )
    part = S._parts(prob, opts)[a.part if split else 0]
    per = S._periodic(part)
    one_s = dataclasses.replace(opts.smc_settings()[0], periodic=per)
    d = prob.ndim
    t0 = time.time()
    first = SM._stage_one(lambda u: S._smc_cheap(u, None, part), d, one_s, rng)
    assert not isinstance(first, SM.SmcRun), "no prior draw reaches every measured pose"
    one = first[0].u
    with S._pool(prob, a.workers) as pool:
        emu = S._SegmentEmulator(klass=None, part=part, n=a.runs, pool=pool, rng=rng)
        evaluate = emu.train(one)
    assert emu.fitted is not None
    print(
        f"stage 1 and {a.runs} segment-model runs: {time.time() - t0:.0f} s; emulator held-out rms per pose "
        f"{np.round(emu.fitted.held_out_rms_per_obs, 4)}"
    )
    la, lb = evaluate(one)
    for n in a.starts:
        t0 = time.time()
        start = spread_starts(one, la + lb, n, spacing=CompassSettings().spacing, periodic=per)
        x, fx, calls = compass_search(evaluate, start, CompassSettings(), periodic=per)
        top = np.argsort(-fx)[: a.check]
        th = S._class_thetas(x[top], None, part)
        f = np.array([prob.predict(t) for t in th])
        ea, eb = V.split_log_likelihood_batch(prob, th, f, V.cheap_log_likelihood_batch(prob, th))
        arrays, _ = V.inplane_arrays(prob, th)
        xyz = prob.measured_pose_array
        measure = assemble_batch(arrays.geometry, xyz[:, 0], xyz[:, 1], xyz[:, 2]).singularity.min(axis=1)
        print(f"{n} starts: {calls} emulated calls, {time.time() - t0:.0f} s")
        print(f"  best optima, emulated log L (data + statements): {np.round(fx[top], 2)}")
        print(f"  the same on the segment model:                   {np.round(ea + eb, 2)}")
        print(f"  least singularity measure at a measured pose:    {np.round(measure, 3)}")
        print(f"  motors' / platform's rotation (deg): {np.round(th[:, 4], 1)} / {np.round(th[:, 5], 1)}")
        _widths(prob, x[top[0]], part)


def _widths(prob: object, u0: np.ndarray, part: S.Part) -> None:
    """The best optimum's log L along the platform's rotation, with and without the as-built tolerances."""
    for h in (1e-3, 3e-3, 1e-2, 3e-2):
        u = np.array([u0, u0])
        u[0, 5], u[1, 5] = (u0[5] + h) % 1.0, (u0[5] - h) % 1.0
        th = S._class_thetas(u, None, part)
        f = np.array([prob.predict(t) for t in th])  # type: ignore[attr-defined]
        c = V.cheap_log_likelihood_batch(prob, th)  # type: ignore[arg-type]
        a0, b0 = V.split_log_likelihood_batch(prob, th, f, c)  # type: ignore[arg-type]
        tol = tolerance_rel(prob, th)  # one row at a time: the library's model error is one value per datum
        rows = [slice(i, i + 1) for i in range(len(th))]
        with_tol = [V.split_log_likelihood_batch(prob, th[r], f[r], c[r], model_error_rel=tol[r][0]) for r in rows]  # type: ignore[arg-type]
        a1, b1 = (np.concatenate(v) for v in zip(*with_tol))
        print(
            f"    platform rotation +-{360 * h:.2f} deg: log L {np.round(a0 + b0, 2)}, with the tolerances "
            f"{np.round(a1 + b1, 2)}"
        )


if __name__ == "__main__":
    main()
