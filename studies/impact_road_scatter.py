"""The scatter behind the bounds of tests/study/test_identify_impact_road.py: the same rollouts, many noise draws.

Simulates the test's impacts once per pose and axis without noise (``virtual_impact_test``, the test's truth,
poses and settings), then for each seed adds accelerometer noise, forms H1 as ``fpm-sim impact`` does, writes
UFF 58, and runs ``fpm-sim ema`` and ``fpm-sim identify`` as the test does. Prints, per seed, the EMA frequency
error against the truth's modal frequency (first mode of the test's kind) and the identified section values
against the truth (relative error and in reported standard deviations); then the ranges. Every seed is analysed
twice: with the exponential window's decay removed by the EMA (the UFF records carry its time constant, as
``fpm-sim impact --uff`` writes them) and without (``fpm-sim ema --exp-window-tau-s inf``), so the window's bias
shows as the difference.

    python studies/impact_road_scatter.py [--seeds 12] [--noise-m-s2 0.01] [--record-s 0.5]

(A study: it takes the test's truth, poses and settings from ``tests/helpers/truths.py``, shared with the test,
so run it from a source checkout.)
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

import fpm_sim  # noqa: F401  (single-threaded BLAS)
from fpm_sim.batch.frequencies import pose_frequencies
from fpm_sim.cli.main import main as cli_main
from fpm_sim.config.schema import config_to_toml
from fpm_sim.kinematics import Pose
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import ModelOptions
from fpm_sim.response import FrequencyResponse, LinkPoint
from fpm_sim.sim.impact import (
    ImpactRecord,
    ImpactSetup,
    exp_window_tau_s,
    h1_estimate,
    virtual_impact_test,
    write_uff58,
)

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the source checkout: tests/helpers
from tests.helpers import truths as road  # the road test's truth, poses and settings

WINDOW_END = ImpactSetup.window_end
"""The exponential window at the record's end: fpm-sim impact's default."""


def _cli(*argv: str) -> dict:
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(io.StringIO()):
        rc = cli_main([*argv, "--json"])
    if rc != 0:
        raise SystemExit(f"fpm-sim {argv[0]} failed: {buf.getvalue()[-2000:]}")
    return json.loads(buf.getvalue())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=12)
    ap.add_argument("--noise-m-s2", type=float, default=road.NOISE_M_S2)
    ap.add_argument("--record-s", type=float, default=0.5)
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    start = road.reference_config()
    truth = start.with_section(**road.TRUTH_SECTION_M)
    opts = ModelOptions(segments=road.SEGMENTS, axial=False, gravity=False)
    pf = pose_frequencies(truth, [Pose.from_mm(*p) for p in road.POSES_MM], n_modes=6, options=opts)
    records, target, steps = {}, {}, {}
    for i, pose_mm in enumerate(road.POSES_MM):
        built = build_manipulator(truth, Pose.from_mm(*pose_mm), opts)
        in_plane = pf.in_plane[i] > 0.5
        for axis, kind in road.AXES.items():
            p = LinkPoint("distal_0", 0.5, axis)
            setup = ImpactSetup(impact=p, accelerometer=p, record_s=args.record_s, n_impacts=1, f_max_hz=400.0)
            res = virtual_impact_test(built, setup)
            records[(pose_mm, axis)] = res.records[0]
            steps[(pose_mm, axis)] = res.discrete_step_s
            target[(pose_mm, kind)] = pf.frequencies_hz[i][in_plane if kind == "in_plane" else ~in_plane][0]
    ways = {"window removed": (), "window kept": ("--exp-window-tau-s", "inf")}
    ema_err = {(w, k): [] for w in ways for k in road.AXES.values()}
    fit: dict[tuple[str, str], list[tuple[float, float]]] = {(w, n): [] for w in ways for n in road.TRUTH_SECTION_M}
    for seed in range(args.seeds):
        rng = np.random.default_rng(seed)
        with tempfile.TemporaryDirectory() as tmp:
            d = Path(tmp)
            (d / "start.toml").write_text(config_to_toml(start))
            files: dict[str, list[str]] = {axis: [] for axis in road.AXES}
            for axis in road.AXES:
                for pose_mm in road.POSES_MM:
                    r = records[(pose_mm, axis)]
                    noisy = r.accel_m_s2 + rng.normal(0.0, args.noise_m_s2, r.accel_m_s2.size)
                    f, h, _ = h1_estimate(
                        [ImpactRecord(r.t_s, r.force_n, noisy, r.peak_force_n, 0.0)], pad_s=8.0, window_end=WINDOW_END
                    )
                    frf = FrequencyResponse(f, h, "accelerance", "m/s^2/N", "hammer", "accel")
                    tau_s = exp_window_tau_s(float(r.t_s[-1]), WINDOW_END)
                    uff = write_uff58(
                        frf,
                        d / f"{pose_mm}_{axis}.uff",
                        pose_mm_rad=pose_mm,
                        window_tau_s=tau_s,
                        discrete_step_s=steps[(pose_mm, axis)],
                    )
                    files[axis].append(str(uff))
            row = []
            for way, extra in ways.items():
                measured = []
                for axis, kind in road.AXES.items():
                    band = ("--f-lower-hz", "20", "--f-upper-hz", "400", "--n-modes", "1", *extra)
                    out_dir = d / f"{kind}_{len(extra)}"
                    out = _cli("ema", *files[axis], *band, "--mode-label", kind, "--out", str(out_dir))
                    for e in out["estimates"]:
                        ema_err[(way, kind)].append(e["freq_hz"][0] / target[(tuple(e["pose_mm_rad"]), kind)] - 1.0)
                    measured += ["--measured", f"{out_dir / 'modes.csv'},sigma_pct={road.SIGMA_PCT}"]
                res = _cli(
                    "identify",
                    "--config",
                    str(d / "start.toml"),
                    "--free",
                    "section",
                    "--global",
                    "none",
                    *measured,
                    "--segments",
                    str(road.SEGMENTS),
                    "--quiet",
                    "--out",
                    str(d / f"id_{len(extra)}"),
                )
                for name, value in road.TRUTH_SECTION_M.items():
                    p = res["result"]["parameters"][f"section.{name}"]
                    fit[(way, name)].append((p["value"] / value - 1.0, (p["value"] - value) / p["std"]))
                    rel, nstd = fit[(way, name)][-1]
                    row.append(f"{way}: {name} {100 * rel:+.3f} % ({nstd:+.2f} std)")
        print(f"seed {seed}: " + "; ".join(row))
    for (way, kind), errs in ema_err.items():
        print(f"{way}: EMA f / modal f - 1, {kind}: {100 * min(errs):+.3f} .. {100 * max(errs):+.3f} %")
    for (way, name), rows in fit.items():
        a = np.array(rows)
        print(
            f"{way}: {name}: {100 * a[:, 0].min():+.3f} .. {100 * a[:, 0].max():+.3f} %, |error| / std up to "
            f"{np.abs(a[:, 1]).max():.2f}"
        )


if __name__ == "__main__":
    main()
