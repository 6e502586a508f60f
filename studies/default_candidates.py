"""Issue 32 item 2: which one description should stand for the shipped posterior as the embedded default?

Candidates, each a single machine evaluated at the study's 12 measured poses (in-sample: the posterior saw them):

- ``median-parameters``: every free parameter at its posterior median (what ``calibrate`` writes as config.toml);
- ``medoid``: the posterior draw whose f1 at the study's 18 cells (12 measured, 6 withheld: their coordinates only)
  lies closest to the posterior's median prediction (mean |log ratio|): a machine the posterior holds whose
  predictions are the bands' centre. No measured value enters the choice.

and, for reference, the posterior's median prediction itself (not one machine) and the current default. Writes the
medoid's description (``--write PATH``) so that ``fpm-sim reproduce --config PATH`` evaluates it at the default
resolution.

    python studies/default_candidates.py --write out/default_medoid.toml
"""

from __future__ import annotations

import argparse
import dataclasses
import warnings
from importlib import resources
from pathlib import Path

import numpy as np


def _in_sample_pct(f_hz: np.ndarray, measured_hz: np.ndarray) -> float:
    """Mean |error| in percent of f against the measured values (NaN predictions count as missing)."""
    ok = np.isfinite(f_hz)
    return float(np.mean(np.abs(f_hz[ok] / measured_hz[ok] - 1.0)) * 100.0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--write", default=None, help="write the medoid draw's description here (TOML)")
    args = parser.parse_args()

    from fpm_sim.config import Manipulator
    from fpm_sim.study.posterior import Posterior, study_bands

    post = Posterior.from_netcdf(str(resources.files("fpm_sim.data") / "default_posterior.nc"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sb = study_bands(post, n_draws=None)
    f = sb.bands.frequencies_hz[:, :, 0]  # (draws, cells)
    measured = ~np.asarray(sb.withheld)
    median = np.nanmedian(f, axis=0)
    distance = np.nanmean(np.abs(np.log(f / median)), axis=1)
    distance[np.isnan(f).any(axis=1)] = np.inf  # a draw that cannot reach a cell is no default
    best = int(np.argmin(distance))
    meas_hz = sb.measured_hz[measured]
    typical = float(np.median(distance[np.isfinite(distance)]))
    print(f"draws: {len(f)}; the medoid is draw {int(sb.bands.draw_index[best])} (mean |log ratio| to the median "
          f"prediction {distance[best]:.4f}; the draws' median {typical:.4f})")  # fmt: skip
    print(f"in-sample mean |error| at the 12 measured poses ({sb.bands.options.segments} segments per link):")
    print(f"  posterior median prediction (not one machine): {_in_sample_pct(median[measured], meas_hz):6.2f} %")
    print(f"  medoid draw:                                    {_in_sample_pct(f[best, measured], meas_hz):6.2f} %")
    in_each = [_in_sample_pct(f[i, measured], meas_hz) for i in range(len(f)) if np.isfinite(distance[i])]
    print(f"  a posterior draw, 5/50/95 %:                    {np.percentile(in_each, 5):6.2f} / "
          f"{np.percentile(in_each, 50):.2f} / {np.percentile(in_each, 95):.2f} %")  # fmt: skip
    i = int(sb.bands.draw_index[best])
    cfg = post.config(i)
    assert isinstance(cfg, Manipulator)  # the study's posterior: the 3RRR
    print(f"the medoid's parameters (elbow branches {cfg.geometry.elbow_branch}):")
    for name, value in zip(post.names, post.values[i]):
        print(f"  {name:42s} {float(value):.5g}")
    if args.write:
        from fpm_sim.config.schema import config_to_toml

        head = f"the shipped posterior's draw {i}: its f1 at the study's 18 cells closest to the median prediction"
        Path(args.write).write_text(config_to_toml(cfg, header=head, default_source="start description"))
        # the same draw with every per-chain deviation at its prior mean, 0 (their posterior is their prior)
        values = np.where([n.endswith("]") for n in post.names], 0.0, post.values[i])
        base = post.base
        assert isinstance(base, Manipulator)  # the study's posterior: the 3RRR
        base = dataclasses.replace(
            base, geometry=dataclasses.replace(base.geometry, elbow_branch=cfg.geometry.elbow_branch)
        )
        symmetric = post._apply(values, base, f"draw {i}, per-chain deviations 0")
        sym_path = Path(args.write).with_name(Path(args.write).stem + "_symmetric.toml")
        sym_path.write_text(config_to_toml(symmetric, header=head + "; per-chain deviations 0"))
        print(f"wrote {args.write}, {sym_path}")


if __name__ == "__main__":
    main()
