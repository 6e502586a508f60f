"""Does marginalising the likelihood over as-built per-chain deviations flatten the calibration's nails (issue 31;
docs/identification.md, "Two mode families in the emulator, and a bed of nails")?

The segment model's log L (data and statements) of the study's problem, elbow branches (-1, -1, 1), at two points and
along the platform's rotation through them, against its mean over ``--draws`` as-built machines: each chain's joint
angles at the base and at the platform off by N(0, ``--angle-deg``), each link's length by N(0, ``--length-rel``), the
same draws at every point (common random numbers). The two points are the best particles of two runs of the motors'
negative half in the fourth session ("The second mode is a peak the emulator cannot see"): seed 2's, on a nail, and
seed 1's, on the broad part.

    python studies/calibration_marginal_tolerance.py
"""

from __future__ import annotations

import argparse
import dataclasses
import warnings
from multiprocessing import Pool

import numpy as np
from scipy.special import logsumexp

from fpm_sim.study.calibrate.problem import study_problem
from fpm_sim.study.identify.problem import fast_options, predict_observations

PROBLEM = study_problem(model="segments", branch=(-1, -1, 1))
POINTS = {
    # geometry (m, deg), the three masses (kg), the section's height (m), the discrepancy: PROBLEM.names
    "seed 2's best (a nail)": [0.34100565479369715, 0.05183945719350441, 0.18021154155438424, 0.32800050143583126,
                               -55.319402295559755, -174.76613409784483, 0.22425880376333512, 0.22439811744298718,
                               0.039061294479898555, 0.008954791384774426, 0.12165026084665079],
    "seed 1's best (broad)": [0.4627320614141938, 0.18546040806400024, 0.2528482494808245, 0.21328635767661933,
                              -73.35204972367222, 131.07635990341925, 0.23480631030264396, 0.16229832148986215,
                              0.032790133165734134, 0.008726672107788512, 0.194199699889267],
}  # fmt: skip
ROTATION = PROBLEM.names.index("geometry.platform_rotation_deg")


def log_l(job: tuple[np.ndarray, np.ndarray, float, float]) -> float:
    """The log L of the description at ``theta`` built with per-chain deviations ``dev`` (12 standard normals)."""
    warnings.simplefilter("ignore")
    theta, dev, angle_deg, length_rel = job
    cfg = PROBLEM.config(theta)
    g = cfg.geometry

    def per(v: object) -> np.ndarray:
        return np.broadcast_to(np.asarray(v, float), (3,)).copy()

    g2 = dataclasses.replace(
        g, base_angles_rad=tuple(per(g.base_angles_rad) + np.radians(angle_deg) * dev[0:3]),
        platform_angles_rad=tuple(per(g.platform_angles_rad) + np.radians(angle_deg) * dev[3:6]),
        proximal_length_m=tuple(per(g.proximal_length_m) * (1 + length_rel * dev[6:9])),
        distal_length_m=tuple(per(g.distal_length_m) * (1 + length_rel * dev[9:12])),
    )  # fmt: skip
    try:
        cfg2 = cfg.replace(geometry=g2)
        f = predict_observations(cfg2, list(PROBLEM.observations), options=fast_options(segments=PROBLEM.segments))
        v = PROBLEM.statements_log_likelihood(cfg2) + PROBLEM.data_log_likelihood(f, PROBLEM.discrepancy(theta), None)
    except ValueError:  # an as-built machine that cannot be assembled
        return -np.inf
    return float(v) if np.isfinite(v) else -np.inf  # NaN: a measured pose out of reach


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--draws", type=int, default=48)
    p.add_argument("--angle-deg", type=float, default=1.0)
    p.add_argument("--length-rel", type=float, default=0.01)
    p.add_argument("--workers", type=int, default=2)
    a = p.parse_args()
    dev = np.random.default_rng(123).standard_normal((a.draws, 12))
    with Pool(a.workers) as pool:
        for name, point in POINTS.items():
            for step_deg in (0.0, 1.08, -1.08, 3.6, -3.6):
                theta = np.array(point)
                theta[ROTATION] += step_deg
                jobs = [(theta, d, a.angle_deg, a.length_rel) for d in [np.zeros(12), *dev]]
                vals = np.array(pool.map(log_l, jobs))
                marginal = logsumexp(vals[1:]) - np.log(a.draws)
                print(f"{name}, platform rotation {step_deg:+.2f} deg: log L {vals[0]:.2f}, mean over {a.draws} "
                      f"as-built draws {marginal:.2f} ({np.isfinite(vals[1:]).sum()} of them reach every pose)",
                      flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
