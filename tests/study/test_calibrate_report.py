"""The calibration report's figures: what a person reads."""

from __future__ import annotations

import types

import matplotlib
import numpy as np

matplotlib.use("Agg")


def _calibration(names: list[str]) -> types.SimpleNamespace:
    """The two attributes :func:`corner_figure` reads: parameter names and equal-weight draws."""
    rng = np.random.default_rng(0)
    return types.SimpleNamespace(names=names, draws=rng.normal(size=(200, len(names))))


def test_corner_leaves_out_per_chain_parameters_only_when_there_are_too_many():
    """The shipped posterior has 22 continuous coordinates, 12 of them per-chain deviations: 23 panels a side
    leave no label readable, so above CORNER_MAX_PANELS the per-chain ones go (and the title says so); below it,
    every coordinate is drawn."""
    import matplotlib.pyplot as plt

    from fpm_sim.study.calibrate.report import CORNER_MAX_PANELS, corner_figure

    collective = [f"geometry.p{i}" for i in range(10)] + ["likelihood.discrepancy_rel"]
    per_chain = [f"geometry.base_angle_dev_deg[{i}]" for i in range(3)]
    many = collective + [f"geometry.{n}_dev[{i}]" for i in range(3) for n in ("a", "b", "c", "d")]
    assert len(many) > CORNER_MAX_PANELS >= len(collective + per_chain[:1])

    fig = corner_figure(_calibration(many))
    assert np.asarray(fig.axes).size == len(collective) ** 2
    assert "12 per-chain parameters left out" in fig._suptitle.get_text()
    plt.close(fig)

    few = collective + per_chain[:1]
    fig = corner_figure(_calibration(few))
    assert np.asarray(fig.axes).size == len(few) ** 2
    assert "left out" not in fig._suptitle.get_text()
    plt.close(fig)


def test_corner_names_the_class_of_each_colour():
    """The draws are coloured by elbow-branch class: a legend names the classes present, in the colours drawn."""
    import matplotlib.pyplot as plt

    from fpm_sim.study.calibrate.priors import BRANCH_PARAMETER
    from fpm_sim.study.calibrate.report import corner_figure
    from fpm_sim.study.identify.problem import ELBOW_BRANCHES

    cal = _calibration(["geometry.p0", "geometry.p1", BRANCH_PARAMETER])
    cal.draws[:, 2] = np.where(np.arange(len(cal.draws)) % 3 == 0, 2.0, 5.0)
    fig = corner_figure(cal)
    (legend,) = fig.legends
    assert [t.get_text() for t in legend.get_texts()] == [str(ELBOW_BRANCHES[2]), str(ELBOW_BRANCHES[5])]
    fig.canvas.draw()  # the scatter maps its values to colours when drawn
    scatter = fig.axes[2].collections[0]  # row 1, column 0: the first scatter
    drawn = {tuple(np.round(c, 6)) for c in scatter.get_facecolors()[:, :3]}
    legend_colours = {tuple(np.round(h.get_color()[:3], 6)) for h in legend.legend_handles}
    assert legend_colours == drawn
    plt.close(fig)
