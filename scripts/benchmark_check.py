"""``check_requirements`` of a 10-requirement file on the 10 mm dense grid against the sweeps it needs.

The file's ten requirements (six over the reachable workspace without payload, four with a 1 kg payload, of
kinds min_frequency and band_exclusion, modes 1..6) need two sweeps of the workspace: one per payload, with
six modes. The floor is those two sweeps run directly (``pose_frequencies``, the same poses, modes and
resolution); the check runs with a fresh cache. Both run in one process, interleaved ``--repeat`` times (a
load change on the shared machine hits both alike); printed: the median wall and CPU time of each and
their ratios. Target (issue 22): <= 1.2x.

    nice python scripts/benchmark_check.py [--segments 6] [--repeat 3]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from fpm_sim.batch.frequencies import pose_frequencies
from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.config import default_config
from fpm_sim.study.requirements import (
    PoseSpec,
    SweepCache,
    check_requirements,
    load_requirements,
    with_payload,
)

WORKSPACE = 'poses = { grid = "dense", step_mm = 10, phi_rad = 0.0 }'


def requirements_text(segments: int) -> str:
    reqs = [f"[settings]\nsegments = {segments}\n"]
    for i, (mode, bound) in enumerate([(1, 5.0), (2, 10.0), (3, 20.0)]):
        reqs.append(
            f'[[requirement]]\nname = "f{mode} no payload {i}"\nkind = "min_frequency"\nmode = {mode}\n'
            f"at_least_hz = {bound}\n{WORKSPACE}\n"
        )
    for i, band in enumerate([(300.0, 310.0), (400.0, 420.0), (500.0, 505.0)]):
        reqs.append(
            f'[[requirement]]\nname = "band no payload {i}"\nkind = "band_exclusion"\nband_hz = [{band[0]}, '
            f"{band[1]}]\nn_modes = 6\n{WORKSPACE}\n"
        )
    for i, mode in enumerate([1, 2]):
        reqs.append(
            f'[[requirement]]\nname = "f{mode} with 1 kg {i}"\nkind = "min_frequency"\nmode = {mode}\n'
            f"at_least_hz = 5.0\npayload_kg = [0.0, 1.0]\n{WORKSPACE}\n"
        )
    for i, band in enumerate([(300.0, 310.0), (450.0, 460.0)]):
        reqs.append(
            f'[[requirement]]\nname = "band with 1 kg {i}"\nkind = "band_exclusion"\nband_hz = [{band[0]}, '
            f"{band[1]}]\nn_modes = 6\npayload_kg = 1.0\n{WORKSPACE}\n"
        )
    return "\n".join(reqs)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--segments", type=int, default=6, help="resolution per link (default 6)")
    ap.add_argument("--repeat", type=int, default=3, help="interleaved runs of each (default 3)")
    args = ap.parse_args()
    config = default_config()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "fpm-requirements.toml"
        path.write_text(requirements_text(args.segments))
        reqs = load_requirements(path)
    assert len(reqs.requirements) == 10
    poses = PoseSpec(step_mm=10.0).resolve(config, "benchmark")
    opts = fast_options(segments=args.segments)
    floor_s, check_s, floor_cpu, check_cpu = [], [], [], []
    for _ in range(args.repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        for payload in (None, 1.0):  # the two sweeps the file needs
            cfg = config if payload is None else with_payload(config, payload)
            pose_frequencies(cfg, poses, n_modes=6, options=opts)
        floor_s.append(time.perf_counter() - t0)
        floor_cpu.append(time.process_time() - c0)
        t0, c0 = time.perf_counter(), time.process_time()
        cache = SweepCache()
        report = check_requirements(reqs, config, cache=cache)
        check_s.append(time.perf_counter() - t0)
        check_cpu.append(time.process_time() - c0)
        assert report.sweeps == 2, report.sweeps
    f, c = statistics.median(floor_s), statistics.median(check_s)
    fc, cc = statistics.median(floor_cpu), statistics.median(check_cpu)
    print(f"{len(poses)} reachable poses on the 10 mm grid, {args.segments} segments per link, 10 requirements")
    print(f"the two sweeps directly: median {f:.2f} s  ({', '.join(f'{t:.2f}' for t in floor_s)})")
    print(f"check_requirements:      median {c:.2f} s  ({', '.join(f'{t:.2f}' for t in check_s)})")
    print(f"ratio: {c / f:.3f}x wall (target <= 1.2x); sweeps run by the check: {report.sweeps}")
    print(
        f"CPU time of this process (less sensitive to a shared machine): sweeps {fc:.2f} s, check {cc:.2f} s, "
        f"ratio {cc / fc:.3f}x"
    )


if __name__ == "__main__":
    main()
