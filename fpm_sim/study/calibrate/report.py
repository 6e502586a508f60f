"""``report.md`` and figures of a calibration: diagnostics, marginals against priors, the discrepancy,
a corner plot, predicted-vs-measured with 50/90 % bands and per-datum coverage."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from fpm_sim.outputs import atomic_file
from fpm_sim.study.calibrate.priors import BRANCH_PARAMETER, DISCREPANCY_PARAMETER
from fpm_sim.study.calibrate.sampler import Calibration
from fpm_sim.study.identify.problem import ELBOW_BRANCHES
from fpm_sim.study.readout import setup_weights

__all__ = ["corner_figure", "render_report", "write_report"]


CORNER_MAX_PANELS = 12
"""Above this many continuous coordinates the corner leaves out the per-chain ones (names ending in ``[i]``, such
as the ``as-built`` group's deviations): 23 panels a side make every label unreadable, and report.md's marginals
give them all."""


def corner_figure(cal: Calibration, *, max_points: int = 1500) -> Any:
    """Pairwise scatter of the continuous coordinates (diagonal: histograms), the draws coloured by branch class;
    with more than :data:`CORNER_MAX_PANELS` of them, the per-chain ones are left out and the title says so."""
    import matplotlib.pyplot as plt

    names = [n for n in cal.names if n != BRANCH_PARAMETER]
    left_out = [n for n in names if n.endswith("]")] if len(names) > CORNER_MAX_PANELS else []
    names = [n for n in names if n not in left_out]
    idx = [cal.names.index(n) for n in names]
    d = cal.draws[: min(max_points, len(cal.draws))]
    colour = d[:, cal.names.index(BRANCH_PARAMETER)] if BRANCH_PARAMETER in cal.names else np.zeros(len(d))
    k = len(names)
    fig, axes = plt.subplots(k, k, figsize=(1.35 * k + 1, 1.35 * k + 1), squeeze=False)
    for i in range(k):
        for j in range(k):
            ax = axes[i, j]
            if j > i:
                ax.set_visible(False)
                continue
            if i == j:
                ax.hist(d[:, idx[i]], bins=25, color="tab:blue", alpha=0.8)
                ax.set_yticks([])
            else:
                ax.scatter(d[:, idx[j]], d[:, idx[i]], s=2, c=colour, cmap="tab10", vmin=0, vmax=9, alpha=0.6)
            ax.tick_params(labelsize=5)
            if i == k - 1:
                ax.set_xlabel(names[j].replace("geometry.", "").replace("hardware.", ""), fontsize=6)
            else:
                ax.set_xticklabels([])
            if j == 0 and i > 0:
                ax.set_ylabel(names[i].replace("geometry.", "").replace("hardware.", ""), fontsize=6)
            elif j > 0:
                ax.set_yticklabels([])
    title = "posterior draws (colour: elbow-branch class)" if BRANCH_PARAMETER in cal.names else "posterior draws"
    if left_out:
        title += f"\n{len(left_out)} per-chain parameters left out (report.md's marginals give them)"
    fig.suptitle(title)
    fig.tight_layout()
    if BRANCH_PARAMETER in cal.names and k > 1:  # in the empty upper triangle's top right corner
        _class_legend(fig, axes[0, k - 1], colour)
    return fig


def _class_legend(fig: Any, anchor: Any, colour: np.ndarray) -> None:
    """A legend of the classes the corner's colours stand for (tab10 by class index), its top right corner at
    ``anchor``'s (an axes of the hidden upper triangle)."""
    import matplotlib
    from matplotlib.lines import Line2D

    cmap = matplotlib.colormaps["tab10"]
    classes = sorted({round(float(c)) for c in colour})
    handles = [Line2D([], [], ls="", marker="o", color=cmap(c / 9.0), label=str(ELBOW_BRANCHES[c])) for c in classes]
    x0, y0, w, h = anchor.get_position().bounds
    fig.legend(handles=handles, title="elbow branches", loc="upper right", fontsize=8, title_fontsize=8,
               bbox_to_anchor=(x0 + w, y0 + h), bbox_transform=fig.transFigure)  # fmt: skip


def _prior_of(cal: Calibration, name: str) -> str:
    pr = cal.problem.priors
    for p in pr.parameters:
        if p.name == name:
            return p.describe()
    for h in pr.hyperpriors:
        if h.name == name:
            return h.describe()
    return ""


def _sampler_line(cal: Calibration) -> str:
    """The diagnostics' lines on the sampler: its settings, cost, and the evidence with what its error covers."""
    o = cal.options
    runs = f"{getattr(o, 'runs', 1)} run(s) per class, first seed {o.seed}"
    split = getattr(o, "split", None)
    if split is not None:
        runs += f"; each class's prior of {split[0]} cut into {split[1]} parts of equal prior mass, sampled apart"
    if getattr(o, "sampler", "dynesty") == "smc":
        head = (
            f"- two-stage tempered SMC ({o.cheap_particles} particles for the prior times the statements, then "
            f"{o.particles} for the data, effective sample size kept at {o.ess_fraction:g} per step, "
            f"{getattr(o, 'cheap_moves', o.moves):g} / {o.moves:g} accepted moves per particle per step"
            f"{_extra_moves(o)}; {runs}): "
            f"{cal.n_iterations} tempering steps, "
            f"{cal.n_calls} likelihood calls, {cal.seconds:.0f} s"
        )
        err = "the error is the SMC's estimate from the particles' genealogy (Lee & Whiteley 2018)"
        if getattr(o, "importance", 0):
            head += (
                f"; each run's evidence and posterior by importance sampling, {o.importance} independent draws of "
                f"a Student-t mixture fitted to its final particles (each run's effective sample size and Pareto k "
                f"are in the run lines of the command's output)"
            )
            err = "the error is the independent importance draws' own"
        if getattr(o, "islands", 1) > 1:
            head += (
                f"; each run {o.islands} independent islands, its ln Z their mean and its error at least their "
                f"spread's (Verge et al. 2015)"
            )
            err += ", or the islands' spread where larger"
        if getattr(o, "emulator", 0):
            head += (
                f"; the data stage on an emulator of the segment model fitted to {o.emulator} segment-model runs (and "
                f"refitted at its particles), each run importance-weighted to the segment model (each run's weights' "
                f"effective sample size and Pareto k are in the run lines of the command's output; "
                f'docs/identification.md, "An emulator of the segment model")'
            )
            err += " plus the importance weights' variance"
    else:
        head = (
            f"- nested sampling (dynesty, {o.live_points} live points per run, {runs}, stop at dlogz {o.dlogz:g}, "
            f"proposal {o.sample}" + (f" with {o.walks} steps per walk" if o.walks else "") + f"): "
            f"{cal.n_iterations} iterations, {cal.n_calls} likelihood calls, {cal.seconds:.0f} s"
            + ("" if cal.converged else " -- stopped on the likelihood-call limit (max_calls): NOT converged")
        )
        err = "the error is nested sampling's statistical one"
    return (
        head + f"\n- log-evidence ln Z = {cal.log_evidence:.3f} +- {cal.log_evidence_err:.3f} ({err}; a mode no "
        "particle or live point entered is not in it)"
    )


def render_report(cal: Calibration, *, command: str, data_note: str) -> str:
    """The text of ``report.md``."""
    p = cal.problem
    q = cal.quantiles((0.05, 0.5, 0.95))
    lines = [
        "# fpm-sim calibrate: Bayesian model updating",
        "",
        f"Data: {data_note}. Free {'paths' if p.notes() else 'groups'}: {', '.join(p.groups)}; {p.segments} "
        "segments per link.",
        "",
        *[f"{k.replace('_', ' ').capitalize()}: {v}.\n" for k, v in p.notes().items()],
        f"Reproduce: `{command}`",
        "",
        "## Diagnostics",
        "",
        _sampler_line(cal),
        f"- best log-likelihood among the draws {np.max(cal.log_likelihood):.2f}; at the start description "
        f"(discrepancy at its best) {cal.start_log_likelihood:.2f}"
        + (
            " -- **the sampler missed the start's region: this posterior is incomplete; rerun with more particles "
            "(live points)**"
            if cal.missed_start
            else ""
        ),
        f"- effective sample size (Kish) of the weighted samples: {cal.ess_kish:.0f}; equal-weight draws written: "
        f"{len(cal.draws)} ({len(np.unique(cal.draws, axis=0))} distinct)",
        "",
        "## Marginals (5 / 50 / 95 %) and priors",
        "",
        "| parameter | 5 % | 50 % | 95 % | sd | prior |",
        "|---|---|---|---|---|---|",
    ]
    for i, n in enumerate(cal.names):
        if n == BRANCH_PARAMETER:
            continue
        lines.append(
            f"| `{n}` | {q[i, 0]:.4g} | {q[i, 1]:.4g} | {q[i, 2]:.4g} | {np.std(cal.draws[:, i]):.3g} | "
            f"{_prior_of(cal, n)} |"
        )
    if BRANCH_PARAMETER in cal.names:
        lines += _class_lines(cal)
    if DISCREPANCY_PARAMETER in cal.names:
        i = cal.names.index(DISCREPANCY_PARAMETER)
        lines += [
            "",
            f"Model discrepancy (relative sd of the model at a pose): median {100 * q[i, 1]:.2g} %, "
            f"90 % interval {100 * q[i, 0]:.2g}-{100 * q[i, 2]:.2g} % (prior {_prior_of(cal, DISCREPANCY_PARAMETER)}).",
        ]
    st = [s for s in (p.priors.singular_at_phi0, p.priors.measured_poses_clear) if s is not None]
    lines += ["", "Study statements in the likelihood: " + ("; ".join(s.reason for s in st) if st else "none") + "."]
    lo50, hi50 = cal.bands(0.5)
    lo90, hi90 = cal.bands(0.9)
    med = np.median(cal.f_pred, axis=0)
    c50, c90 = cal.coverage(0.5), cal.coverage(0.9)
    lines += [
        "",
        "## Predicted vs measured (posterior predictive of a new measurement: model, discrepancy and noise)",
        "",
        f"Coverage: {c50.sum()}/{len(c50)} measured values inside their 50 % band, {c90.sum()}/{len(c90)} inside "
        "their 90 % band (in-sample: these data shaped the posterior).",
        "",
        "| datum | measured (Hz) | model median (Hz) | 50 % band | 90 % band | in 90 % |",
        "|---|---|---|---|---|---|",
    ]
    for lab, y, m, a, b, c, d, ok in zip(p.labels, p.measured, med, lo50, hi50, lo90, hi90, c90):
        lines.append(f"| {lab} | {y:.4g} | {m:.4g} | {a:.4g}-{b:.4g} | {c:.4g}-{d:.4g} | {'yes' if ok else 'NO'} |")
    lines += _runs_lines(cal)
    lines += _read_lines(cal)
    lines += _loo_lines(cal)
    lines += ["", "Figures: `corner.png` (pairwise draws), `predicted_vs_measured.png`, `leave_one_out.png`.", ""]
    return "\n".join(lines)


def _class_lines(cal: Calibration) -> list[str]:
    """The elbow-branch classes: each sampled on its own, its evidence and weight, its share of the draws."""
    k = cal.names.index(BRANCH_PARAMETER)
    classes, counts = np.unique(np.round(cal.draws[:, k]).astype(int), return_counts=True)
    share = dict(zip(classes.tolist(), counts.tolist()))
    if not cal.classes:  # a run saved before the classes were enumerated
        lines = ["", "Elbow-branch classes (prior: uniform over the 8):", ""]
        for c, m in sorted(share.items(), key=lambda t: -t[1]):
            lines.append(f"- {ELBOW_BRANCHES[c]}: {100.0 * m / len(cal.draws):.1f} % of the draws")
        return lines
    orbits = any(c.size > 1 for c in cal.classes)
    lines = [
        "",
        "Elbow-branch classes (prior: uniform over the 8; each class's continuous posterior sampled on its own, "
        "the classes weighted by their evidences, `w_k = Z_k / sum Z`):",
        *(
            [
                "",
                "A class marked x3 stands for the three that a cyclic relabelling of the chains maps onto each other: "
                "with both rotations over a whole turn they hold the same machines, so one is sampled and its evidence "
                'counted three times (priors: `relabel = "cyclic"`; docs/identification.md).',
            ]
            if orbits
            else []
        ),
        "",
        "| class | reachable prior draws | ln Z (runs merged) | ln Z per run | weight | draws |",
        "|---|---|---|---|---|---|",
    ]
    for c in sorted(cal.classes, key=lambda c: -c.weight):
        if c.skipped:
            lines.append(f"| {c.label} | 0 of {c.probe_draws} | skipped (Z = 0) | | 0 | 0 |")
            continue
        runs = ", ".join(f"{z:.2f}" for z in c.run_log_evidence)
        n = share.get(-1 if c.klass is None else c.klass, 0)
        lines.append(
            f"| {c.label} | {100 * c.prior_mass:.0f} % of {c.probe_draws} | {c.log_evidence:.2f} +- "
            f"{c.log_evidence_err:.2f} | {runs} | {100 * c.weight:.1f} +- {100 * c.weight_sd:.1f} % | {n} |"
        )
    return lines


def _runs_lines(cal: Calibration) -> list[str]:
    """The independent runs side by side and the between-run check."""
    chk = cal.runs_check
    if chk is None:
        return ["", "## Independent runs", "", "One run: no between-run check (several independent runs give one)."]
    head = "| | " + " | ".join(f"seed {s}" for s in chk.seeds) + " | spread of 5/50/95 % over the runs (sd) |"
    lines = [
        "",
        "## Independent runs (between-run check)",
        "",
        ("**" + chk.summary_line() + "**") if not chk.passed else chk.summary_line(),
        "",
        f"Criteria: {chk.criteria()}.",
        "",
        head,
        "|---|" + "---|" * (len(chk.seeds) + 1),
        "| ln Z | "
        + " | ".join(f"{z:.2f} +- {e:.2f}" for z, e in zip(chk.log_evidence, chk.log_evidence_err))
        + " | |",
    ]
    for j, k in enumerate(chk.classes):
        if np.max(chk.class_weights[:, j]) > chk.class_threshold:
            label = cal.problem.class_label(k).removeprefix("the ")
            lines.append(
                f"| weight {label} | " + " | ".join(f"{100 * w:.1f} %" for w in chk.class_weights[:, j]) + " | |"
            )
    sp = chk.spread()
    for i, n in enumerate(chk.names):
        qs = " | ".join(f"{q[0]:.4g} / {q[1]:.4g} / {q[2]:.4g}" for q in chk.quantiles[:, i, :])
        flag = " **disagree**" if n in chk.bad_parameters else ""
        lines.append(f"| `{n}` 5/50/95 % | {qs} | {sp[i, 0]:.2f} / {sp[i, 1]:.2f} / {sp[i, 2]:.2f}{flag} |")
    return lines


def _read_lines(cal: Calibration) -> list[str]:
    """The latent-mode section: per measured pose, which mode the posterior thinks the first clear peak was, and
    which accelerometer setup."""
    resp = cal.read_responsibility()
    read = cal.problem.priors.mode_read
    if resp is None or read is None or cal.readouts is None:
        return []
    p = cal.problem
    n = len(p.observations)
    setups = np.mean([setup_weights(p.measured[:n], p.sigma[:n], f, pr, d) for f, pr, d in cal.readouts], axis=0)
    best = int(np.argmax(setups))
    lines = [
        "",
        "## Which mode was read (latent-mode model)",
        "",
        "Accelerometer setup (link and axis; the study does not state them), posterior: "
        + ", ".join(f"{pt.label()} {100 * w:.0f} %" for pt, w in sorted(zip(read.points, setups), key=lambda t: -t[1]))
        + f". Most probable: {read.points[best].label()}.",
        "",
        "| datum | measured (Hz) | " + " | ".join(f"P(mode {k + 1})" for k in range(read.modes)) + " |",
        "|---|---|" + "---|" * read.modes,
    ]
    for lab, y, r in zip(p.labels[:n], p.measured[:n], resp):
        lines.append(f"| {lab} | {y:.4g} | " + " | ".join(f"{v:.2f}" for v in r) + " |")
    return lines


def _loo_lines(cal: Calibration) -> list[str]:
    """The leave-one-out section: how the posterior predicts each measured pose it was not given."""
    if len(cal.problem.observations) < 2:
        return []
    loo = cal.leave_one_out()
    return [
        "",
        "## Leave-one-out predictions (PSIS-LOO: the posterior without each measured pose, by importance sampling)",
        "",
        loo.summary_line() + ".",
        "",
        "```",
        loo.table(summary=False),  # the paragraph above gives the summary line
        "```",
    ]


def _save(fig: Any, path: Path) -> None:
    import matplotlib.pyplot as plt

    with atomic_file(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def write_report(cal: Calibration, out: str | Path, *, command: str, data_note: str) -> None:
    """``report.md``, ``corner.png``, ``predicted_vs_measured.png`` and ``leave_one_out.png`` in ``out`` (each
    atomically)."""
    import matplotlib

    matplotlib.use("Agg")
    out = Path(out)
    _save(corner_figure(cal), out / "corner.png")
    _save(cal.plot(), out / "predicted_vs_measured.png")
    if len(cal.problem.observations) > 1:
        _save(cal.leave_one_out().plot(), out / "leave_one_out.png")
    with atomic_file(out / "report.md") as tmp:
        tmp.write_text(render_report(cal, command=command, data_note=data_note))


def _extra_moves(o: Any) -> str:
    """The data stage's jumps and its moves on the posterior after its last step, in words (``""``: neither)."""
    m, j = getattr(o, "final_moves", 0.0), getattr(o, "jumps", 0.0)
    out = f", a fraction {j:g} of the sweeps jumps from a mixture fitted to the particles" if j else ""
    return out + (f", then {m:g} on the posterior" if m else "")
