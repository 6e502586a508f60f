"""Start-up time of the command line against its floor, ``python -c "import mujoco, scipy.linalg"``.

Runs each command N times in turn (interleaved, so that a load change on a shared machine hits all of
them alike) and prints the median wall time of each and its ratio to the floor. Target (issue 10): 1.3x.

    python scripts/benchmark_startup.py [-n 15]
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import subprocess
import sys
import time

FLOOR = [sys.executable, "-c", "import mujoco, scipy.linalg"]


def commands() -> dict[str, list[str]]:
    exe = shutil.which("fpm-sim")
    cli = [exe] if exe else [sys.executable, "-m", "fpm_sim.cli.main"]
    return {
        "import mujoco, scipy.linalg": FLOOR,
        "python -c 'import fpm_sim'": [sys.executable, "-c", "import fpm_sim"],
        "fpm-sim --help": [*cli, "--help"],
        "fpm-sim config": [*cli, "config"],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-n", type=int, default=15, help="runs per command (default 15)")
    n = ap.parse_args().n
    cmds = commands()
    times: dict[str, list[float]] = {k: [] for k in cmds}
    for _ in range(n):
        for name, argv in cmds.items():
            t0 = time.perf_counter()
            subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
            times[name].append(time.perf_counter() - t0)
    floor = statistics.median(times["import mujoco, scipy.linalg"])
    print(f"median of {n} runs each (interleaved); ratio to the floor 'import mujoco, scipy.linalg'")
    for name, ts in times.items():
        med = statistics.median(ts)
        print(f"  {name:<30} {med * 1e3:8.1f} ms   {med / floor:5.2f}x")


if __name__ == "__main__":
    main()
