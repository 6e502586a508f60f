"""Compare model structures by cross-validated prediction error, all refined from one identified optimum.

    nice python studies/compare_structures.py out/identify_study --out out/structures [--folds 4]

Each structure (a set of ``--free`` groups and model options) is fitted with ``fpm-sim identify --global
none`` from the same start, the optimum of a shipped identification run (``FOLDER/config.toml``), on the
same data with the same weights, and cross-validated with the same folds. Starting every structure from
one point removes the confound of a global search that lands in different basins for different
parameter sets (docs/identification.md). Prints a markdown table: parameters, chi^2/dof, in-sample and
cross-validated mean |error| against each data file, and the Akaike and Bayesian information criteria
(from the cost, which is chi^2 with the stated sigmas).
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import shlex
import sys
from pathlib import Path

from fpm_sim.cli.main import main as cli_main

STRUCTURES: list[tuple[str, str, list[str]]] = [
    ("geometry, hardware, section height (the shipped structure)", "geometry,hardware,section-height", []),
    ("+ in-plane thickness (the study states 30 mm)", "geometry,hardware,section", []),
    ("+ compliance (passive tilt, locked motor, motor mount)", "geometry,hardware,section-height,compliance", []),
    ("+ offsets (stacked links)", "geometry,hardware,section-height,offsets", []),
    ("+ hubs (rigid link ends)", "geometry,hardware,section-height,hubs", []),
    ("Timoshenko links", "geometry,hardware,section-height", ["--timoshenko"]),
    ("per-chain geometry instead of symmetric", "geometry-per-chain,hardware,section-height", []),
    (
        "+ compliance, offsets, hubs, Timoshenko",
        "geometry,hardware,section-height,compliance,offsets,hubs",
        ["--timoshenko"],
    ),
]


def _data_args(command: list[str]) -> list[str]:
    """The data, weights, reading and resolution of the shipped run (everything but the search)."""
    keep = {"--measured", "--subsystems", "--reading", "--segments", "--sigma-pct", "--subsystem-sigma-pct"}
    out = []
    for k, v in itertools.pairwise(command):
        if k in keep:
            out += [k, v]
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", type=Path, help="an fpm-sim identify output folder (its optimum is every start)")
    ap.add_argument("--out", type=Path, default=Path("out/structures"))
    ap.add_argument("--folds", type=int, default=4)
    ap.add_argument("--max-nfev", type=int, default=40)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--only", type=int, nargs="*", help="indices of STRUCTURES to run (default all)")
    args = ap.parse_args()
    doc = json.loads((args.folder / "identify.json").read_text())
    data = _data_args(shlex.split(doc["command"]))
    rows = []
    for i, (label, groups, extra) in enumerate(STRUCTURES):
        if args.only and i not in args.only:
            continue
        out = args.out / f"s{i}"
        cmd = [
            "identify",
            "--config",
            str(args.folder / "config.toml"),
            *data,
            "--free",
            groups,
            "--global",
            "none",
            "--max-nfev",
            str(args.max_nfev),
            "--folds",
            str(args.folds),
            "--workers",
            str(args.workers),
            "--out",
            str(out),
            "--overwrite",
            "--quiet",
            *extra,
        ]
        print("fpm-sim " + " ".join(shlex.quote(c) for c in cmd), flush=True)
        cli_main(cmd)
        res = json.loads((out / "identify.json").read_text())
        r, summ = res["result"], res["summary"]
        k = len(r["parameters"])
        n = len(r["residuals"])
        cost = r["cost"]
        row = {
            "label": label,
            "k": k,
            "chi2_dof": r["chi2_per_dof"],
            "aic": cost + 2 * k,
            "bic": cost + k * math.log(n),
        }
        for src, st in summ.items():
            row[src] = (st["in_sample"]["mean_abs_pct"], (st.get("cross_validated") or {}).get("mean_abs_pct"))
        rows.append(row)
    sources = [s for s in rows[0] if s.endswith(".csv")] if rows else []
    head = "| structure | k | chi2/dof | AIC | BIC | " + " | ".join(f"{s} in-sample / CV" for s in sources) + " |"
    print("\n" + head + "\n|" + "---|" * (5 + len(sources)))
    for row in rows:
        cells = [f"{row[s][0]:.1f} % / {row[s][1]:.1f} %" for s in sources]
        print(
            f"| {row['label']} | {row['k']} | {row['chi2_dof']:.1f} | {row['aic']:.0f} | {row['bic']:.0f} | "
            + " | ".join(cells)
            + " |"
        )
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "structures.json").write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
