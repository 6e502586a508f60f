"""Modal atlas: MAC, matching and Procrustes alignment, tracking through a crossing of an in-plane and an
out-of-plane mode, interpolated reduced models against direct computations, file round trip, errors."""

import numpy as np
import pytest

from fpm_sim.kinematics import Pose
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import ModelOptions
from fpm_sim.model.passive import dof_stiffness
from fpm_sim.rom.atlas import (
    ATLAS_ERROR_WARN,
    AtlasAccuracyWarning,
    AtlasError,
    align_modes,
    build_atlas,
    load_atlas,
    mac_matrix,
    track_modes,
)
from fpm_sim.rom.reduction import modal_system, reduce_model
from tests.helpers.jitter import JITTER_SEEDS

OPTS = ModelOptions(segments=3, axial=False)
PAPER_GRID_M = np.array([-100.0, -50.0, 0.0, 50.0, 100.0]) * 1e-3
MIDPOINTS_MM = [-75.0, -25.0, 25.0, 75.0]
INTERP_TOL = 0.02
"""The issue's target: interpolated f1..f3 within 2 % of a direct computation at the midpoints of the
paper grid (50 mm spacing). Measured on this 3-segment model: 0.73 % worst with cubic interpolation
(2.4 % with multilinear, which is why 'auto' picks cubic on a 5 x 5 grid)."""


def test_mac_matrix():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(20, 3))
    m = mac_matrix(a, np.column_stack([-2.0 * a[:, 1], a[:, 0]]))
    assert m[1, 0] == pytest.approx(1.0)  # scale and sign do not matter
    assert m[0, 1] == pytest.approx(1.0)
    q, _ = np.linalg.qr(a)
    assert mac_matrix(q[:, :1], q[:, 1:2])[0, 0] == pytest.approx(0.0, abs=1e-20)


def test_align_recovers_order_signs_and_a_rotated_repeated_pair():
    rng = np.random.default_rng(1)
    p, _ = np.linalg.qr(rng.normal(size=(30, 4)))
    c, s = np.cos(0.7), np.sin(0.7)
    rot = np.array([[c, -s], [s, c]])
    # candidates: the pair (1, 2) rotated within its plane (a repeated frequency's arbitrary basis), then
    # everything permuted and sign-flipped, plus an unrelated extra mode
    pair = p[:, 1:3] @ rot
    extra = rng.normal(size=(30, 1))
    extra -= p @ (p.T @ extra)
    cand = np.column_stack([-p[:, 3], pair[:, 1], p[:, 0], extra[:, 0], -pair[:, 0]])
    al = align_modes(p, cand)
    assert set(al.index) == {0, 1, 2, 4}  # the unrelated mode takes no label
    np.testing.assert_allclose(al.basis, p, atol=1e-12)


def _out_of_plane_share(system, v):
    k = dof_stiffness(system.built.model)
    kinds = np.array(system.built.dof_kinds)
    e = k * v**2
    return e[(kinds == "bend_out") | (kinds == "twist")].sum() / e.sum()


def test_tracking_keeps_labels_through_a_crossing(symmetric_manip):
    """Raise the links' out-of-plane height: out-of-plane bending stiffens (f ~ height) while in-plane
    bending does not (EI and mass both scale with height), so out-of-plane modes climb through in-plane
    ones. Gravity off: the planes decouple exactly, so these are true crossings, not veerings."""
    pose = Pose(0.05, -0.05, 0.1)
    heights = np.linspace(0.010, 0.024, 15)
    opts = ModelOptions(segments=3, axial=False, gravity=False)
    systems = [modal_system(build_manipulator(symmetric_manip.with_section(height_m=h), pose, opts)) for h in heights]
    al = track_modes(systems, n_modes=4, n_extra=4)
    share = np.array([[_out_of_plane_share(s, s.phi[:, i]) for i in a.index] for s, a in zip(systems, al)])
    # the sweep does contain crossings: label 1 (out of plane) ends as the 2nd mode, label 4 (in plane) as the 1st
    assert al[0].index[0] == 0
    assert al[-1].index[0] == 1
    assert al[0].index[3] == 3
    assert al[-1].index[3] == 0
    # every label keeps its character along the sweep (a wrong swap would flip the share to ~0 or ~1)
    start = share[0] > 0.5
    assert np.all((share > 0.5) == start)
    assert np.all(np.abs(share - 0.5) > 0.45)  # the planes decouple: shares are 0 or 1
    assert min(a.mac.min() for a in al[1:]) > 0.9
    # negative control: labelling by sorted order changes character at the crossing
    naive = np.array([_out_of_plane_share(s, s.phi[:, 0]) for s in systems])
    assert naive[0] > 0.5
    assert naive[-1] < 0.5


REPEATED_RTOL = 1e-8
"""Modes closer than this (relative frequency) count as one repeated cluster, whose basis an eigen-solver may return
in any rotation: the symmetric pose's pairs are 5e-10 apart here (MuJoCo's round-off in the assembly), exactly
repeated on a machine that rounds the assembly exactly symmetric."""


def _rotate_repeated(system, seed):
    """``system`` with each cluster of repeated modes (:data:`REPEATED_RTOL`) in a random orthonormal basis of its
    span (seeded): another machine's equally valid answer for the same modes. Returns it and the widest cluster's
    relative frequency spread (how far the rotated shapes are from eigenvectors)."""
    import dataclasses

    f, phi = system.frequencies_hz, system.phi.copy()
    rng, spread, i = np.random.default_rng(seed), 0.0, 0
    while i < f.size:
        j = i + 1
        while j < f.size and f[j] / f[i] - 1.0 < REPEATED_RTOL:
            j += 1
        if j - i > 1:
            q, _ = np.linalg.qr(rng.standard_normal((j - i, j - i)))
            phi[:, i:j] = phi[:, i:j] @ q
            spread = max(spread, f[j - 1] / f[i] - 1.0)
        i = j
    return dataclasses.replace(system, phi=phi), spread


@pytest.mark.parametrize("seed", JITTER_SEEDS)
def test_atlas_does_not_depend_on_the_basis_of_the_roots_repeated_pairs(symmetric_manip, monkeypatch, seed):
    """The root (0, 0, 0) of the symmetric manipulator has repeated pairs (modes 2-3 and 4-5), whose basis is the
    eigen-solver's arbitrary choice (issue 32: under OPENBLAS_CORETYPE=Sandybridge the flex cantilever's exactly
    repeated pair came out in another basis than under SkylakeX). Tracking, the aligned basis's consistency and the
    interpolated frequencies must not depend on it: the Procrustes alignment carries the root's rotation to every
    node, so the interpolated modal stiffness is conjugated by it and keeps its eigenvalues. (The per-label MACs and
    the stored matrices do change: by up to 0.7 and 3e5 rad^2/s^2 here; the interpolated frequencies by 2e-10.)"""
    from fpm_sim.rom import atlas as atlas_module

    grid = dict(x_m=[-0.05, 0.0, 0.05], y_m=[0.0], options=OPTS, n_modes=6)
    queries = [Pose.from_mm(-25.0, 0.0, 0.0), Pose.from_mm(40.0, 0.0, 0.0)]
    base = build_atlas(symmetric_manip, **grid)
    spreads = []
    solve = atlas_module.modal_system

    def rotated(built, **kw):
        system, spread = _rotate_repeated(solve(built, **kw), seed)
        spreads.append(spread)
        return system

    monkeypatch.setattr(atlas_module, "modal_system", rotated)
    other = build_atlas(symmetric_manip, **grid)
    assert max(spreads) > 0.0  # the root's pairs were rotated
    assert other.weak_links() == base.weak_links() == []
    np.testing.assert_array_equal(
        np.sort(other.nodes["label_index"], axis=-1), np.sort(base.nodes["label_index"], axis=-1)
    )
    for pose in queries:
        # the rotated shapes are eigenvectors only to within the clusters' spread (< REPEATED_RTOL), so the
        # interpolated frequencies agree to that
        np.testing.assert_allclose(
            other.query(pose).frequencies_hz, base.query(pose).frequencies_hz, rtol=REPEATED_RTOL, atol=0
        )


@pytest.fixture(scope="module")
def atlas(symmetric_manip):
    return build_atlas(symmetric_manip, x_m=PAPER_GRID_M, y_m=PAPER_GRID_M, options=OPTS, n_modes=6)


def test_atlas_reproduces_its_grid_poses(symmetric_manip, atlas):
    compared_io = 0
    for pose in (
        Pose(0.0, 0.0, 0.0),
        Pose(-0.05, 0.0, 0.0),
        Pose(0.0, -0.05, 0.0),
        Pose(0.05, -0.1, 0.0),
        Pose(-0.1, 0.1, 0.0),
    ):
        rom = atlas.query(pose)
        system = modal_system(build_manipulator(symmetric_manip, pose, OPTS))
        node = (int(np.argmin(np.abs(atlas.x_m - pose.x_m))), int(np.argmin(np.abs(atlas.y_m - pose.y_m))), 0)
        tracked = np.sort(atlas.nodes["label_index"][node].astype(int))
        # the atlas keeps the tracked modes, which far from the root need not be the lowest six
        np.testing.assert_allclose(rom.frequencies_hz, system.frequencies_hz[tracked], rtol=1e-9)
        if np.array_equal(tracked, np.arange(6)):
            compared_io += 1
            direct = reduce_model(system, n_modes=6)
            # same modes, same static correction: the same input-output map (a basis-free comparison)
            np.testing.assert_allclose(rom.static_gain(), direct.static_gain(), rtol=1e-6, atol=1e-12)
            f = np.array([30.0, 95.0, 140.0])
            h_a, h_d = rom.frequency_response(f), direct.frequency_response(f)
            np.testing.assert_allclose(h_a, h_d, rtol=1e-6, atol=1e-9 * np.abs(h_d).max())
    assert compared_io >= 3


def test_aligned_basis_is_consistent_on_the_paper_grid(atlas):
    """Labels may change character between 50 mm neighbours (modes 2-6 mix near the symmetric pose), but the
    tracked six-mode subspace does not turn: every aligned basis vector keeps a MAC above 0.8 (measured 0.89)
    with its parent's, which is what makes the matrix interpolation work."""
    assert atlas.weak_links() == []
    assert len(atlas.label_changes()) > 0  # the raw per-mode identity does change: the diagnostic sees it


@pytest.mark.parametrize("x_mm", MIDPOINTS_MM)
def test_interpolated_frequencies_at_paper_grid_midpoints(symmetric_manip, atlas, x_mm):
    for y_mm in MIDPOINTS_MM:
        pose = Pose.from_mm(x_mm, y_mm, 0.0)
        rom = atlas.query(pose)
        direct = modal_system(build_manipulator(symmetric_manip, pose, OPTS)).frequencies_hz[:3]
        assert np.max(np.abs(rom.frequencies_hz[:3] / direct - 1.0)) < INTERP_TOL, (x_mm, y_mm)


def test_interpolated_model_is_close_in_input_output_terms(symmetric_manip, atlas):
    """Static gain (end-effector compliance) at a midpoint: interpolated vs direct reduced model."""
    pose = Pose.from_mm(25.0, -25.0, 0.0)
    rom = atlas.query(pose)
    direct = reduce_model(modal_system(build_manipulator(symmetric_manip, pose, OPTS)), n_modes=6)
    g_i, g_d = rom.static_gain()[:3, :3], direct.static_gain()[:3, :3]
    # the in-plane compliance changes by tens of percent over 50 mm near the centre; a consistent basis keeps
    # the interpolated gain within a few percent (measured below 1 %); an inconsistent one (sign flips) gives
    # O(1) errors
    assert np.linalg.norm(g_i - g_d) / np.linalg.norm(g_d) < 0.05


def test_save_load_round_trip(atlas, tmp_path):
    p = atlas.save(tmp_path / "atlas.npz")
    back = load_atlas(p)
    pose = Pose.from_mm(-25.0, 75.0, 0.0)
    np.testing.assert_allclose(back.query(pose).a, atlas.query(pose).a)
    assert back.parameters["options"]["segments"] == 3
    assert back.table() == atlas.table()


def test_queries_outside_the_grid_are_refused(atlas):
    with pytest.raises(AtlasError, match="outside"):
        atlas.query(Pose.from_mm(120.0, 0.0, 0.0))
    with pytest.raises(AtlasError, match="single value"):
        atlas.query(Pose.from_mm(0.0, 0.0, 0.1))
    with pytest.raises(AtlasError, match="method"):
        atlas.query(Pose(0.0, 0.0, 0.0), method="spline")


def test_bad_grids_are_refused(symmetric_manip):
    with pytest.raises(AtlasError, match="x_m"):
        build_atlas(symmetric_manip, x_m=[0.0, 0.0], y_m=[0.0], options=OPTS)
    with pytest.raises(AtlasError, match="root"):
        build_atlas(symmetric_manip, x_m=[0.0, 0.05], y_m=[0.0], options=OPTS, root=Pose(0.01, 0.0, 0.0))
    for kwargs, name in (({"n_modes": 0}, "n_modes"), ({"n_modes": 2.5}, "n_modes"), ({"n_extra": -1}, "n_extra")):
        with pytest.raises(AtlasError, match=name):
            build_atlas(symmetric_manip, x_m=[0.0, 0.05], y_m=[0.0], options=OPTS, **kwargs)


def test_rotation_axis_and_mixed_orders(symmetric_manip):
    """A grid in x (4 values: cubic under 'auto') and phi (2 values: linear), queried between rotations."""
    xs = np.array([-0.075, -0.025, 0.025, 0.075])
    at = build_atlas(symmetric_manip, x_m=xs, y_m=[0.025], phi_rad=[0.0, 0.2], options=OPTS, n_modes=6)
    pose = Pose(0.0, 0.025, 0.1)
    direct = modal_system(build_manipulator(symmetric_manip, pose, OPTS)).frequencies_hz[:3]
    auto = at.query(pose).frequencies_hz[:3]
    # 0.1 rad and 25 mm from the nearest nodes; measured 0.07 %
    assert np.max(np.abs(auto / direct - 1.0)) < INTERP_TOL
    assert not np.allclose(auto, at.query(pose, method="linear").frequencies_hz[:3], rtol=1e-9)
    with pytest.raises(AtlasError, match="cubic"):
        at.query(pose, method="cubic")


def _worst_actual_error(manip, rom, pose):
    """Worst relative error of the interpolated frequencies against the nearest directly computed ones (the
    atlas keeps the tracked modes, which need not be the lowest six)."""
    direct = modal_system(build_manipulator(manip, pose, OPTS)).frequencies_hz
    return max(float(np.min(np.abs(direct / f - 1.0))) for f in rom.frequencies_hz)


QUERIES_MM = [(-75.0, -75.0), (25.0, 50.0), (50.0, 50.0), (75.0, -75.0)]


def test_error_estimate_is_an_upper_bound_without_warning_on_the_paper_grid(symmetric_manip, atlas):
    import warnings

    for x_mm, y_mm in QUERIES_MM:
        pose = Pose.from_mm(x_mm, y_mm, 0.0)
        with warnings.catch_warnings():
            warnings.simplefilter("error", AtlasAccuracyWarning)
            rom = atlas.query(pose)
        est = rom.parameters["atlas_query"]["error_estimate"]
        # measured 1.5 % estimated against <= 0.7 % actual: below the 2 % warning threshold, above the truth
        assert _worst_actual_error(symmetric_manip, rom, pose) <= est < ATLAS_ERROR_WARN


def test_error_estimate_warns_on_a_coarse_grid(symmetric_manip):
    coarse = np.array([-100.0, 0.0, 100.0]) * 1e-3
    at = build_atlas(symmetric_manip, x_m=coarse, y_m=coarse, options=OPTS, n_modes=6)
    for x_mm, y_mm in QUERIES_MM:
        pose = Pose.from_mm(x_mm, y_mm, 0.0)
        with pytest.warns(AtlasAccuracyWarning, match="estimated interpolation error"):
            rom = at.query(pose)
        # measured: 4.3 % estimated, 1.5..4.2 % actual at these poses (the interpolation really is poor here)
        assert _worst_actual_error(symmetric_manip, rom, pose) <= rom.parameters["atlas_query"]["error_estimate"]


def test_no_error_estimate_on_a_two_point_grid_warns(symmetric_manip):
    at = build_atlas(symmetric_manip, x_m=[-0.05, 0.05], y_m=[0.0], options=OPTS, n_modes=3)
    with pytest.warns(AtlasAccuracyWarning, match="no interpolation error estimate"):
        rom = at.query(Pose(0.0, 0.0, 0.0))
    assert rom.parameters["atlas_query"]["error_estimate"] is None


@pytest.mark.slow
def test_interpolated_frequencies_at_six_segments(symmetric_manip):
    """The CLI's default resolution (6 segments): measured 0.79 % worst over the 16 midpoints."""
    opts = ModelOptions(segments=6, axial=False)
    at = build_atlas(symmetric_manip, x_m=PAPER_GRID_M, y_m=PAPER_GRID_M, options=opts, n_modes=6)
    worst = 0.0
    for x_mm in MIDPOINTS_MM:
        for y_mm in MIDPOINTS_MM:
            pose = Pose.from_mm(x_mm, y_mm, 0.0)
            direct = modal_system(build_manipulator(symmetric_manip, pose, opts)).frequencies_hz[:3]
            worst = max(worst, float(np.max(np.abs(at.query(pose).frequencies_hz[:3] / direct - 1.0))))
    assert worst < INTERP_TOL


def test_files_that_are_not_atlases_are_refused(tmp_path):
    fake = tmp_path / "fake.npz"
    fake.write_bytes(b"not a zip archive")
    with pytest.raises(AtlasError, match="not a readable atlas file"):
        load_atlas(fake)
    other = tmp_path / "other.npz"
    np.savez(other, x_m=np.zeros(2))
    with pytest.raises(AtlasError, match="missing node_lam"):
        load_atlas(other)
    single = tmp_path / "single.npz"
    np.save(tmp_path / "single.npy", np.zeros(3))
    (tmp_path / "single.npy").rename(single)
    with pytest.raises(AtlasError, match="not an atlas file"):
        load_atlas(single)
