"""Every figure's basic facts, at tiny resolutions: no text outside the canvas (titles, labels, legends, cell
numbers), axis labels on every data axes, and the plotted data equal to the table the figure claims to show
(for the design trade-off: the plotted values against the ``summary.csv`` column its y axis names)."""

import csv
import math
from pathlib import Path

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")

import matplotlib.pyplot as plt
from matplotlib.text import Text

from fpm_sim.batch.engine import EngineOptions
from fpm_sim.batch.frequencies import pose_frequencies
from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.designs import design_study
from fpm_sim.figures import text_colour, wrap_title
from fpm_sim.kinematics import Pose
from fpm_sim.model.options import ResolutionWarning
from fpm_sim.study.poses import TableReading, study_poses
from fpm_sim.study.reproduce import StudyReproduction, subsystem_frequencies
from fpm_sim.study.sweep import sweep_workspace

SEG = 3
"""Segments per link: the figures' layout and data paths do not depend on the resolution."""
SLACK_PX = 1.0
"""A text may touch the canvas edge by a pixel (antialiasing of the bounding box)."""


def _outside(b, width: float, height: float) -> bool:
    return b.x0 < -SLACK_PX or b.y0 < -SLACK_PX or b.x1 > width + SLACK_PX or b.y1 > height + SLACK_PX


def texts_outside(fig) -> list[str]:
    """What leaves the canvas as drawn at save time: every visible, non-empty text (titles, labels, legends,
    annotations, cell numbers) by its own tight bounding box, and the tick labels through the figure's tight
    bounding box (it counts only the ticks drawn; matplotlib keeps undrawn ones outside the view limits)."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    width, height = fig.canvas.get_width_height()
    ticks = set()
    for a in fig.axes:
        for axis in (a.xaxis, a.yaxis, *([a.zaxis] if hasattr(a, "zaxis") else [])):
            ticks.update(axis.get_ticklabels(minor=False))
            ticks.update(axis.get_ticklabels(minor=True))
            ticks.add(axis.get_offset_text())
    out = []
    for t in fig.findobj(Text):
        if t in ticks or not t.get_visible() or not t.get_text().strip():
            continue
        if t.axes is not None and not t.axes.get_visible():
            continue
        b = t.get_window_extent(renderer)
        if _outside(b, width, height):
            out.append(f"{t.get_text()[:60]!r} at {b.x0:.0f}..{b.x1:.0f} x {b.y0:.0f}..{b.y1:.0f} of {width}x{height}")
    tight = fig.get_tightbbox(renderer).transformed(fig.dpi_scale_trans)
    if _outside(tight, width, height):
        out.append(f"tick labels: the figure's tight box {tight.bounds} exceeds {width}x{height}")
    return out


def _drawn_labels(a) -> list:
    """Title, axis labels and the tick labels drawn (those at ticks inside the view limits) of axes ``a``."""
    out = [a.title, a._left_title, a._right_title]
    for axis in (a.xaxis, a.yaxis):
        out.append(axis.label)
        lo, hi = sorted(axis.get_view_interval())
        span = hi - lo
        for loc, label in zip(axis.get_majorticklocs(), axis.get_majorticklabels()):
            if lo - 1e-9 * span <= loc <= hi + 1e-9 * span:
                out.append(label)
    return [t for t in out if t.get_visible() and t.get_text().strip()]


def overlapping_labels(fig) -> list[str]:
    """Pairs of labels (titles, axis labels, tick labels) of different axes whose boxes overlap: e.g. a colour
    bar's tick labels over the next panel's y label."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    axes = [a for a in fig.axes if a.get_visible() and a.name != "3d"]
    boxes = [[(t, t.get_window_extent(renderer)) for t in _drawn_labels(a)] for a in axes]
    out = []
    for i in range(len(axes)):
        for j in range(i + 1, len(axes)):
            for ti, bi in boxes[i]:
                for tj, bj in boxes[j]:
                    if bi.overlaps(bj):
                        out.append(f"{ti.get_text()!r} / {tj.get_text()!r}")
    return out


def data_axes(fig) -> list:
    """The axes that show data (not colour bars, not switched off)."""
    return [a for a in fig.axes if a.get_visible() and a.axison and a.get_label() != "<colorbar>"]


def check_figure(fig) -> None:
    """Texts inside the canvas; every data axes labelled on x and y (and z in 3D)."""
    assert texts_outside(fig) == []
    assert overlapping_labels(fig) == []
    for a in data_axes(fig):
        assert a.get_xlabel().strip(), a
        assert a.get_ylabel().strip(), a
        if a.name == "3d":
            assert a.get_zlabel().strip(), a


@pytest.fixture(scope="module")
def reproduction(default_manip):
    reading = TableReading()
    poses = study_poses(reading)
    opts = fast_options(segments=SEG)
    freqs = pose_frequencies(default_manip, [p.pose for p in poses], n_modes=3, options=opts)
    subs = subsystem_frequencies(default_manip, segments=SEG)
    return StudyReproduction(default_manip, reading, poses, freqs, subs, opts)


def test_the_checker_sees_a_clipped_title():
    """The check can fail: a title wider than its figure is caught, and wrapping it fixes that."""
    fig, ax = plt.subplots(figsize=(3, 2))
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    title = "a title much wider than the three inch figure it sits on " * 2
    ax.set_title(title)
    assert texts_outside(fig)
    ax.set_title(wrap_title(title, fig, 10, fraction=0.6), fontsize=10)
    fig.set_layout_engine("constrained")
    assert texts_outside(fig) == []
    plt.close(fig)
    # and colour-bar tick labels over the next panel's y label (three panels, no layout engine)
    fig, axes = plt.subplots(1, 3, figsize=(12.6, 3.8))
    for a in axes:
        fig.colorbar(a.scatter([-100, 100], [-100, 100], c=[0.0, 30.0]), ax=a, shrink=0.8)
        a.set_ylabel("y (mm)")
        a.set_aspect("equal")
    assert overlapping_labels(fig)
    plt.close(fig)


def test_heatmaps_show_the_table_with_readable_numbers(reproduction):
    fig = reproduction.plot_heatmaps()
    check_figure(fig)
    ours = fig.axes[0]
    image = ours.get_images()[0]
    _, _, z = reproduction.grid(reproduction.f1_hz)
    np.testing.assert_array_equal(np.asarray(image.get_array()), np.ma.masked_invalid(z))
    # every cell number is its cell's f1 as the table rounds it, in the colour that reads on the cell
    shown = {t.get_text() for t in ours.texts}
    assert {f"{v:.1f}" for v in reproduction.f1_hz} <= shown
    for t in ours.texts:
        if t.get_text() != "-":
            assert t.get_color() == text_colour(image, float(t.get_text()))
    assert {t.get_color() for t in ours.texts} == {"k", "w"}  # dark and light cells both present
    plt.close(fig)


def test_a_variant_the_study_tables_do_not_describe_shows_no_comsol_difference(reproduction):
    thin = reproduction.config.with_section(thickness_m=0.005)
    rep = StudyReproduction(
        thin, reproduction.reading, reproduction.poses, reproduction.frequencies, [], reproduction.options
    )
    assert not rep.comparable
    fig = rep.plot_heatmaps()
    check_figure(fig)
    assert len(data_axes(fig)) == 1
    assert "not comparable" in fig.get_suptitle()
    header = next(line for line in rep.table().splitlines() if line.split()[:2] == ["row", "col"])
    assert "COMSOL" not in header
    assert "diff %" not in rep.table()
    plt.close(fig)


def test_subsystem_legend_covers_no_bar(reproduction):
    fig = reproduction.plot_subsystems()
    check_figure(fig)
    renderer = fig.canvas.get_renderer()
    (legend,) = fig.legends
    box = legend.get_window_extent(renderer)
    for a in fig.axes:
        for bar in a.patches:
            assert not box.overlaps(bar.get_window_extent(renderer))
    plt.close(fig)


def test_paper_sweep_title_names_both_rotations(default_manip):
    sw = sweep_workspace(default_manip, grid="paper", options=fast_options(segments=SEG), workers=1)
    fig = sw.plot()
    check_figure(fig)
    title = fig.axes[0].get_title()
    assert "0 rad at 20 poses" in title
    assert "0.2 rad at 5 poses" in title
    plotted = fig.axes[0].collections[0].get_array()
    np.testing.assert_allclose(plotted, [r["f1_hz"] for r in sw.rows()])
    plt.close(fig)


@pytest.fixture(scope="module")
def design(default_manip, tmp_path_factory):
    # six ordinary poses and the default's near-singular (-100, 50) mm, where min_f1_hz and min_f1_ok_hz part
    poses = [*(Pose(x, y, 0.0) for x in (-0.05, 0.0, 0.05) for y in (-0.05, 0.05)), Pose(-0.1, 0.05, 0.0)]
    vary = {"section.thickness_m": [0.01, 0.02, 0.03, 0.04, 0.05], "hardware.payload.mass_kg": [0.0, 1.0, 2.0]}
    res = design_study(
        default_manip, poses=poses, vary=vary, f_min_hz=30.0, options=fast_options(segments=2),
        engine=EngineOptions(scheduler="serial"),
    )  # fmt: skip
    out = tmp_path_factory.mktemp("design")
    res.write(out, figures=False)
    return res, out


def test_design_tradeoff_plots_the_column_its_axis_names(design):
    res, out = design
    with open(out / "summary.csv") as fh:
        rows = list(csv.DictReader(fh))
    fig = res.plot_tradeoff()
    check_figure(fig)
    ax = fig.axes[0]
    assert "ok poses" in ax.get_ylabel()
    xy = ax.collections[0].get_offsets()
    column = [float(r["min_f1_ok_hz"]) if r["min_f1_ok_hz"] else math.nan for r in rows]
    np.testing.assert_allclose(xy[:, 1], column, rtol=1e-6)
    np.testing.assert_allclose(xy[:, 0], [float(r["moving_mass_kg"]) for r in rows], rtol=1e-6)
    # the column the label names differs from the all-poses minimum here, so the check can tell them apart
    assert not np.allclose(column, [float(r["min_f1_hz"]) for r in rows], equal_nan=True)
    plt.close(fig)


def test_design_maps_say_how_many_designs_they_show(design):
    res, _ = design
    fig = res.plot_maps()
    check_figure(fig)
    assert len(data_axes(fig)) == 12
    assert "1-12 of 15" in fig.get_suptitle()
    plt.close(fig)
    fig = res.plot()
    check_figure(fig)
    plt.close(fig)


def test_modes_plot_has_a_legend_and_the_equilibrium_shape():
    import fpm_sim as fs

    with pytest.warns(ResolutionWarning):  # 3 segments: coarse on purpose (the layout does not depend on it)
        res = fs.modes(
            fs.default_config(), fs.Pose.from_mm(50, -50, 0.0), options=fs.ModelOptions(segments=SEG), n_modes=2
        )
    fig = res.plot(n_modes=2)
    check_figure(fig)
    for a in fig.axes:
        labels = [t.get_text() for t in a.get_legend().get_texts()]
        assert labels[0] == "equilibrium"
        assert labels[1].startswith("mode shape")
    plt.close(fig)


def test_mode_animation_frames_keep_their_texts_inside():
    """A frame of ``modes --animate``: 3D for the out-of-plane mode 1, 2D for the in-plane mode 2 at (0, 0, 0)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    import fpm_sim as fs
    from fpm_sim.linear.animation import frame_figure

    with pytest.warns(ResolutionWarning):
        res = fs.modes(None, None, options=fs.ModelOptions(segments=SEG), n_modes=2)
    for mode, name in ((1, "3d"), (2, "rectilinear")):
        fig = frame_figure(res, mode=mode)
        FigureCanvasAgg(fig)  # a figure of no window: the checker measures texts through an Agg canvas
        check_figure(fig)
        assert [a.name for a in fig.axes] == [name]
        assert fig.get_suptitle().startswith(f"mode {mode}: ")
        assert "Hz" in fig.get_suptitle()
    five_bar = fs.load_description(Path(__file__).resolve().parents[1] / "examples" / "architectures" / "five_bar.toml")
    res = fs.modes(five_bar, None, options=fs.ModelOptions(segments=SEG, gravity=False), n_modes=1)
    fig = frame_figure(res, mode=1)  # a wide planar machine, out of plane: 3D
    FigureCanvasAgg(fig)
    check_figure(fig)


def test_readability_panels_do_not_overlap(default_manip):
    from fpm_sim.model.options import ModelOptions
    from fpm_sim.study.readability import readability_table

    cells = study_poses(TableReading())[:4]
    tab = readability_table(default_manip, options=ModelOptions(segments=SEG, axial=False, gravity=False), poses=cells)
    axes = tab.plot()
    fig = np.atleast_1d(axes)[0].figure
    check_figure(fig)
    for k, a in enumerate(data_axes(fig)):
        np.testing.assert_allclose(a.collections[0].get_array(), [r.metrics[k].prominence_db for r in tab.rows])
    plt.close(fig)


def test_atlas_figure_and_the_node_behind_its_estimate(default_manip):
    from fpm_sim.model.options import ModelOptions
    from fpm_sim.rom.atlas import build_atlas

    grid = [-0.05, 0.0, 0.05]
    atlas = build_atlas(default_manip, x_m=grid, y_m=grid, phi_rad=[0.0], options=ModelOptions(segments=SEG), n_modes=2)
    axes = atlas.plot(labels=(1, 2))
    fig = np.atleast_1d(axes)[0].figure
    check_figure(fig)
    assert "red x" in fig.get_suptitle()
    plt.close(fig)
    # the estimate is a quarter of the leave-one-out error at the node it names
    pose = Pose(0.025, 0.025, 0.0)
    node = atlas.error_estimate_node(pose)
    axes_values = (atlas.x_m, atlas.y_m, atlas.phi_rad)
    index = tuple(int(np.argmin(np.abs(np.asarray(v) - n))) for v, n in zip(axes_values, node))
    assert atlas.error_estimate(pose) == pytest.approx(np.nanmax(atlas.loo_errors()[index]) / 4.0)
