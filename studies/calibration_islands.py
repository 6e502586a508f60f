"""One SMC island of the study's calibration at a time (issue 31; docs/identification.md, "Islands, subspace moves and
importance sampling"): the dominant class with the as-built model, each island given as ``SEED,I`` (the stream
``numpy.random.default_rng([SEED, I])``, or ``SEED`` alone for ``I = 0``: island ``I`` of run ``SEED`` of
``fpm-sim calibrate --islands``), run in the order given in this process. An island's ln Z is a function of its own
stream: the same whatever ran before it.

    python studies/calibration_islands.py 0,1 2,3 0,5 0,6 2,5 2,6
    python studies/calibration_islands.py --cheap-particles 10000 3,1 3,2 3,3 3,4
"""

from __future__ import annotations

import argparse
import dataclasses
import time
import warnings

import numpy as np

from fpm_sim.study.calibrate import SamplerOptions
from fpm_sim.study.calibrate import sampler as smc_sampler
from fpm_sim.study.calibrate.problem import study_problem


def island(text: str) -> tuple[int, int]:
    """``"SEED,I"`` or ``"SEED"`` as ``(SEED, I)``."""
    try:
        parts = [int(v) for v in text.split(",")]
    except ValueError:
        parts = []
    if len(parts) not in (1, 2) or min(parts) < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: give SEED,I (two integers >= 0, e.g. 0,1) or SEED")
    return parts[0], parts[1] if len(parts) == 2 else 0


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("islands", nargs="+", type=island, help="SEED,I of each island, in order")
    p.add_argument("--branch", type=int, nargs=3, default=[-1, -1, 1])
    p.add_argument("--particles", type=int, default=500, help="the data stage's (default 500)")
    p.add_argument("--cheap-particles", type=int, default=1500, help="the statements stage's (default 1500)")
    a = p.parse_args()
    warnings.simplefilter("ignore")
    prob = study_problem(model="segments", branch=tuple(a.branch), as_built=(1.0, 0.01))
    smc_sampler._init_worker(prob)
    opts = SamplerOptions(
        sampler="smc", particles=a.particles, cheap_particles=a.cheap_particles, emulator=500, moves=10, jumps=0.2
    )
    one, two = (dataclasses.replace(x, periodic=smc_sampler._periodic(None)) for x in opts.smc_settings())
    for seed, i in a.islands:
        rng = np.random.default_rng(seed if i == 0 else [seed, i])
        emu = smc_sampler._SegmentEmulator(klass=None, part=None, n=opts.emulator, pool=None, rng=rng)
        t = time.time()
        out = smc_sampler._smc_island(None, None, one, two, rng, opts, emu=emu, pool=None, modes=None)
        z, e = float(out["logz"][-1]), float(out["logzerr"][-1])
        print(f"island {seed},{i}: ln Z {z:.4f} +- {e:.3f} ({time.time() - t:.0f} s)", flush=True)


if __name__ == "__main__":
    main()
