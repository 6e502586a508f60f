"""Writing an identification: ``config.toml``, ``identify.json``, ``report.md`` and figures, atomically.

The folder is written with :func:`fpm_sim.outputs.atomic_dir`: a temporary sibling renamed into place
when complete, so a reader never sees a mix of two runs or a half-written one.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import spearmanr

from fpm_sim.config import Manipulator, config_to_toml
from fpm_sim.outputs import atomic_dir
from fpm_sim.results import to_jsonable
from fpm_sim.study.identify.engine import CrossValidation, Identification, variance_scale
from fpm_sim.study.identify.problem import workspace_measures

__all__ = ["identified_config", "identified_provenance", "provenance_key", "render_report", "write_identification"]


def provenance_key(name: str) -> str:
    """The description field (dotted, as in the TOML) that a free parameter sets."""
    n = name.split("[")[0]
    mapping = {
        "geometry.base_rotation_deg": "geometry.base_angles_deg",
        "geometry.platform_rotation_deg": "geometry.platform_angles_deg",
        "geometry.base_angle_deg": "geometry.base_angles_deg",
        "geometry.platform_angle_deg": "geometry.platform_angles_deg",
        # the as-built group's per-chain deviations set the per-chain lists
        "geometry.base_angle_dev_deg": "geometry.base_angles_deg",
        "geometry.platform_angle_dev_deg": "geometry.platform_angles_deg",
        "geometry.proximal_length_dev_rel": "geometry.proximal_length_m",
        "geometry.distal_length_dev_rel": "geometry.distal_length_m",
    }
    if n in mapping:
        return mapping[n]
    if n.startswith("compliance.log10_"):
        return "compliance." + n[len("compliance.log10_") :]
    return n


def _fmt(v: float) -> str:
    return f"{v:.4g}"


def identified_provenance(provenance: dict[str, str], parts: Sequence[tuple[str, str]], source: str) -> dict[str, str]:
    """``provenance`` with every field that the parameters of ``parts`` (``(parameter name, its text)``) set marked
    ``identified: <source>; <text>; <text> ...`` (several parameters can set one field: a rotation and each chain's
    deviation), and each identified mass's inertia ``identified: scaled with the identified mass``."""
    prov = dict(provenance)
    by_key: dict[str, list[str]] = {}
    for name, text in parts:
        by_key.setdefault(provenance_key(name), []).append(text)
    for key, texts in by_key.items():
        prov[key] = f"identified: {source}; " + "; ".join(texts)
        if key.startswith(("hardware.", "rig.chain_hinge.")) and key.endswith(".mass_kg"):
            prov[key.replace("mass_kg", "inertia_kg_m2")] = "identified: scaled with the identified mass"
    return prov


def identified_config(result: Identification, *, data_note: str, method_note: str) -> Manipulator:
    """``result.config`` with each identified field's provenance ``identified: <data, method>; value +- std``."""
    cfg = result.config
    parts = []
    for name, v, s in zip(result.names, result.values, result.std):
        unit = "log10(N m/rad)" if "log10_" in name else name.rsplit("_", 1)[-1].split("[")[0]
        parts.append((name, f"{name} = {_fmt(v)} +- {_fmt(s)} {unit}"))
    prov = identified_provenance(cfg.provenance, parts, f"{data_note}, {method_note}")
    for key in {provenance_key(n) for n in result.at_bound} & {provenance_key(n) for n, _ in parts}:
        at_bound = [n for n in result.at_bound if provenance_key(n) == key]
        prov[key] += f" (at its bound: {', '.join(at_bound)}; the std is then not a confidence interval)"
    start_branch = result.start_elbow_branch or result.problem.parameters.start.geometry.elbow_branch
    if start_branch != cfg.geometry.elbow_branch:
        prov["geometry.elbow_branch"] = f"identified: {data_note}, the elbow-branch class of the best global-search fit"
    return cfg.replace(provenance=prov)


def _stats(pred: np.ndarray, meas: np.ndarray) -> dict[str, float]:
    ok = np.isfinite(pred) & np.isfinite(meas)
    if not ok.any():
        return {"n": 0}
    e = 100.0 * (pred[ok] / meas[ok] - 1.0)
    rho = float(spearmanr(pred[ok], meas[ok]).statistic) if ok.sum() > 2 else math.nan
    return {
        "n": int(ok.sum()),
        "mean_abs_pct": float(np.mean(np.abs(e))),
        "median_abs_pct": float(np.median(np.abs(e))),
        "max_abs_pct": float(np.max(np.abs(e))),
        "rms_pct": float(np.sqrt(np.mean(e**2))),
        "spearman": rho,
    }


def summary(result: Identification, cv: CrossValidation | None) -> dict[str, Any]:
    """In-sample and cross-validated error statistics per data source."""
    p = result.problem
    n_obs = len(p.observations)
    sources = [o.source for o in p.observations]
    out: dict[str, Any] = {}
    for s in sorted(set(sources)):
        m = np.array([x == s for x in sources])
        out[s] = {"in_sample": _stats(result.predicted[:n_obs][m], result.measured[:n_obs][m])}
        if cv is not None:
            out[s]["cross_validated"] = _stats(cv.predicted[m], cv.measured[m])
    if p.subsystem_tests:
        out["subsystems"] = {"in_sample": _stats(result.predicted[n_obs:], result.measured[n_obs:])}
    return out


def workspace_check(result: Identification) -> dict[str, Any] | None:
    """The workspace prior (``Problem.workspace``) at the optimum: poses, threshold, smallest measure and
    the poses below the threshold (``None`` without a workspace)."""
    ws = result.problem.workspace
    if not ws:
        return None
    m = workspace_measures(result.problem, result.config)
    m_min = result.problem.min_singularity
    below = [ws[i].label() for i in range(len(ws)) if not (m[i] >= m_min)]
    return {
        "poses": len(ws),
        "min_singularity": m_min,
        "smallest_measure": float(np.nanmin(m)) if np.isfinite(m).any() else math.nan,
        "unreachable": int(np.sum(~np.isfinite(m))),
        "below_threshold": below,
    }


def render_report(
    result: Identification,
    cv: CrossValidation | None,
    *,
    command: str,
    data_files: Sequence[str],
    extra: str = "",
) -> str:
    """The Markdown report."""
    lines = _header_lines(result, command=command, data_files=data_files)
    lines += diagnosis_lines(result)
    lines += _statistics_lines(result, cv)
    lines += _parameter_lines(result)
    lines += _residual_lines(result, cv)
    lines += competing_optima_lines(result)
    if extra:
        lines += ["", extra]
    lines += ["", "Figures: `measured_vs_predicted.png`, `residuals_workspace.png`."]
    return "\n".join(lines) + "\n"


def _jacobian_note(result: Identification) -> str:
    """How the local steps' Jacobian was computed, in words."""
    if result.options.jacobian == "exact":
        return (
            "exact Jacobian of the frequencies from the eigen-solve's sensitivities, geometry included "
            "(fpm_sim.study.identify.sensitivity); rig tests and the workspace prior by finite differences"
        )
    return "forward finite-difference Jacobian of the frequencies in bound-normalised parameters"


def _header_lines(result: Identification, *, command: str, data_files: Sequence[str]) -> list[str]:
    """The command, the data, the search and the workspace prior."""
    lines = [
        "# fpm-sim identify",
        "",
        f"Command: `{command}`",
        "",
        f"Data: {', '.join(data_files)}. Free parameters: {len(result.names)}; observations: "
        f"{len(result.measured)}; residual degrees of freedom {result.dof}; chi^2/dof {result.chi2_per_dof:.3g}.",
        "",
        f"Search: global `{result.options.global_method}` (seed {result.options.seed}"
        + (
            f"; {result.options.staged_starts} starts, each freeing its parameters in stages with exact derivatives"
            if result.options.global_method == "staged"
            else ""
        )
        + "), then bounded least squares "
        f"(trust-region reflective, {_jacobian_note(result)}); {result.options.segments} spring "
        f"locations per link. {result.history[-1].evaluations} model evaluations, {result.seconds:.0f} s.",
        "",
    ]
    ws = workspace_check(result)
    if ws is not None:
        lines += [
            f"Workspace prior: {ws['poses']} poses the machine works at; a singularity measure below "
            f"{ws['min_singularity']:g} or an unreachable pose is penalised. At the optimum the smallest measure "
            f"is {ws['smallest_measure']:.3g}"
            + (f"; below the threshold: {', '.join(ws['below_threshold'])}." if ws["below_threshold"] else "."),
            "",
        ]
    return lines


def diagnosis_lines(result: Identification) -> list[str]:
    """Whether the fit found the machine (:mod:`fpm_sim.study.identify.diagnosis`): the verdict, the chi-squared
    test, what the data determine and the troubled poses."""
    d = result.diagnosis
    if d is None:
        return []
    f = d.floor
    lines = [
        "## Did the fit find the machine?",
        "",
        f"**{d.summary()}**",
        "",
        f"Noise floor: chi2 = sum((model - measured) / sigma)^2 = {f.chi2:.4g} over {f.n_data} data with their stated "
        f"sigmas, {f.n_parameters} free parameters, {f.dof} degrees of freedom: chi2/dof = {f.ratio:.3g}, p-value "
        f"{f.p_value:.3g} (at the floor when p >= 0.001).",
        "",
        "Posterior sd with the stated sigmas (Gauss-Newton, (J'J)^-1), and whether the data determine each parameter "
        "(an undetermined one lies along a direction whose sd exceeds a quarter of the bounds' width):",
        "",
        "| parameter | posterior sd | determined |",
        "|---|---|---|",
    ]
    det = d.determination
    for n, s, ok in zip(det.names, det.posterior_sd, det.determined):
        lines.append(f"| {n} | {s:.3g} | {'yes' if ok else 'no'} |")
    lines += ["", *[f"- {x}" for x in d.lines()[1:]], ""]
    return lines


def _statistics_lines(result: Identification, cv: CrossValidation | None) -> list[str]:
    """In-sample and cross-validated errors per data file."""
    lines = [
        "## Error statistics",
        "",
        "| data | n | in-sample mean abs % | in-sample max % | Spearman | CV mean abs % | CV max % | CV Spearman |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for s, st in summary(result, cv).items():
        i = st["in_sample"]
        c = st.get("cross_validated", {})
        lines.append(
            f"| {s} | {i.get('n', 0)} | {i.get('mean_abs_pct', math.nan):.2f} | {i.get('max_abs_pct', math.nan):.2f} | "
            f"{i.get('spearman', math.nan):.3f} | {c.get('mean_abs_pct', math.nan):.2f} | "
            f"{c.get('max_abs_pct', math.nan):.2f} | {c.get('spearman', math.nan):.3f} |"
        )
    if cv is not None:
        lines += [
            "",
            f"Cross-validation: {cv.folds}-fold over poses (every observation at a held-out pose, from every file, "
            f"left out together; each fold refitted from the full-data optimum); {cv.seconds:.0f} s.",
        ]
    return lines


def _parameter_lines(result: Identification) -> list[str]:
    """Each parameter's start, value, standard deviation and bounds; the correlations."""
    p = result.problem
    lines = ["", "## Parameters", "", "| parameter | start | value | std | bounds |", "|---|---|---|---|---|"]
    for fp, v, s in zip(p.parameters.parameters, result.values, result.std):
        flag = " (at bound)" if fp.name in result.at_bound else ""
        lines.append(f"| {fp.name} | {fp.start:.5g} | {v:.5g}{flag} | {s:.3g} | [{fp.lower:.4g}, {fp.upper:.4g}] |")
    lines += [
        "",
        "Standard deviations: Gauss-Newton covariance s^2 (J'J)^+ with s^2 = max(chi^2/dof, 1) (the residuals' own "
        "scale when the stated sigmas are too small). A parameter at its bound has no confidence interval.",
        "",
        "Correlations (rows and columns in the parameter order):",
        "",
        "```",
    ]
    for n, row in zip(result.names, result.correlation):
        lines.append(f"{n:<40}" + " ".join(f"{c:+.2f}" for c in row))
    lines.append("```")
    return lines


def _residual_lines(result: Identification, cv: CrossValidation | None) -> list[str]:
    """Every datum's measured, model and cross-validated value; the search history."""
    p = result.problem
    lines = [
        "",
        "## Residuals",
        "",
        "| data | measured Hz | sigma Hz | model Hz | error % | CV model Hz |",
        "|---|---|---|---|---|---|",
    ]
    n_obs = len(p.observations)
    for j, (lab, m, s, f) in enumerate(zip(p.labels, result.measured, p.sigma, result.predicted)):
        cvp = f"{cv.predicted[j]:.2f}" if cv is not None and j < n_obs else ""
        lines.append(f"| {lab} | {m:.2f} | {s:.2f} | {f:.2f} | {100 * (f / m - 1):+.2f} | {cvp} |")
    lines += ["", "## Search history", "", "| stage | evaluations | cost | seconds | note |", "|---|---|---|---|---|"]
    for h in result.history:
        lines.append(f"| {h.stage} | {h.evaluations} | {h.cost:.4g} | {h.seconds:.0f} | {h.note} |")
    return lines


def competing_optima_lines(result: Identification) -> list[str]:
    """The report's table of every local refinement's end, best first: its cost above the optimum's in units
    of ``s^2 = max(chi^2/dof, 1)`` (the scale of the standard deviations: an end within a few units fits the
    data about as well, so the data do not decide between them) and its parameter values."""
    if not result.candidates:
        return []
    s2 = variance_scale(result.chi2_per_dof)
    names = result.names
    lines = [
        "",
        "## Local refinements (competing optima)",
        "",
        "Every refinement's end, best first. Delta: its cost above the optimum's divided by "
        f"s^2 = {s2:.3g} (ends a few units apart fit the data about as well; their predictions elsewhere can "
        "differ by far more than the standard deviations above).",
        "",
        "| cost | delta | from | " + " | ".join(names) + " |",
        "|---|---|---|" + "---|" * len(names),
    ]
    ps = result.problem.parameters
    for c in sorted(result.candidates, key=lambda c: c.cost):
        vals = " | ".join(f"{v:.4g}" for v in ps.from_unit(c.z))
        lines.append(f"| {c.cost:.4g} | {(c.cost - result.cost) / s2:.2f} | {c.origin} | {vals} |")
    return lines


def plot_figures(result: Identification, cv: CrossValidation | None, folder: Path) -> None:
    """``measured_vs_predicted.png`` and ``residuals_workspace.png``."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    p = result.problem
    n_obs = len(p.observations)
    meas, pred = result.measured[:n_obs], result.predicted[:n_obs]
    fig = result.plot(cv=cv)
    fig.savefig(folder / "measured_vs_predicted.png", dpi=120)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(6, 5), constrained_layout=True)
    x = np.array([o.pose.x_m * 1e3 for o in p.observations])
    y = np.array([o.pose.y_m * 1e3 for o in p.observations])
    e = 100.0 * (pred / meas - 1.0)
    lim_e = float(np.nanmax(np.abs(e))) if np.any(np.isfinite(e)) else 1.0
    sc = ax.scatter(x, y, c=e, cmap="RdBu_r", vmin=-lim_e, vmax=lim_e, s=120, edgecolors="k")
    fig.colorbar(sc, ax=ax, label="model / measured - 1 (%), in-sample")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_aspect("equal")
    fig.savefig(folder / "residuals_workspace.png", dpi=120)
    plt.close(fig)


def write_identification(
    out: Path,
    result: Identification,
    cv: CrossValidation | None,
    *,
    command: str,
    data_files: Sequence[str],
    data_note: str,
    header: str = "",
    extra_report: str = "",
    extra_json: dict[str, Any] | None = None,
    figures: bool = True,
) -> Manipulator:
    """Write the folder atomically (see module docstring); returns the identified description."""
    with atomic_dir(out, overwrite=True) as tmp:  # the command checked --out / --overwrite before computing
        return _write_identification(
            tmp, result, cv, command=command, data_files=data_files, data_note=data_note, header=header,
            extra_report=extra_report, extra_json=extra_json, figures=figures,
        )  # fmt: skip


def _write_identification(
    tmp: Path,
    result: Identification,
    cv: CrossValidation | None,
    *,
    command: str,
    data_files: Sequence[str],
    data_note: str,
    header: str | None,
    extra_report: str,
    extra_json: dict[str, Any] | None,
    figures: bool,
) -> Manipulator:
    method_note = (
        f"fpm-sim identify ({result.options.global_method} global search, seed {result.options.seed}, then bounded "
        f"least squares, {result.options.segments} segments/link)"
    )
    cfg = identified_config(result, data_note=data_note, method_note=method_note)
    hdr = header or (
        f"fpm-sim identify: {command}\nEvery 'identified' value: +- one standard deviation (Gauss-Newton)."
    )
    (tmp / "config.toml").write_text(config_to_toml(cfg, header=hdr, default_source="start description"))
    doc = {
        "command": command,
        "data": list(data_files),
        "result": result.to_dict(),
        "cross_validation": cv.to_dict() if cv is not None else None,
        "summary": summary(result, cv),
        "workspace": workspace_check(result),
    }
    if extra_json:
        doc.update(extra_json)
    (tmp / "identify.json").write_text(json.dumps(to_jsonable(doc), indent=1))
    (tmp / "report.md").write_text(
        render_report(result, cv, command=command, data_files=data_files, extra=extra_report)
    )
    if figures:
        plot_figures(result, cv, tmp)
    return cfg
