"""Predictions with bands from a posterior (fpm_sim.study.posterior): a tiny synthetic posterior.nc written with
ArviZ in the calibration's format (six perturbed copies of the default description), read back and pushed
through the pose loop; the bands are checked against the draws computed one by one."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fpm_sim.batch.engine import EngineOptions
from fpm_sim.batch.frequencies import pose_frequencies
from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.config import default_config
from fpm_sim.kinematics import Pose
from fpm_sim.study.identify.parameters import parameter_set
from fpm_sim.study.posterior import QUANTILES, Posterior, PosteriorError, predict_bands, study_bands
from tests.helpers.posterior import GROUPS, HEIGHTS_M, PLATFORM_KG, SEGMENTS, write_posterior

POSES = [Pose.from_mm(0.0, 0.0, 0.0), Pose.from_mm(40.0, -30.0, 0.1), Pose.from_mm(5000.0, 0.0, 0.0)]
"""Two reachable poses and one that no draw reaches (5 m away)."""


@pytest.fixture(scope="module")
def posterior_file(tmp_path_factory):
    return write_posterior(tmp_path_factory.mktemp("post") / "posterior.nc")


@pytest.fixture(scope="module")
def posterior(posterior_file):
    return Posterior.from_netcdf(posterior_file)


@pytest.fixture(scope="module")
def bands(posterior):
    return predict_bands(posterior, POSES, n_draws=None, n_modes=2, engine=EngineOptions(scheduler="serial"))


def test_reads_the_format(posterior):
    assert posterior.n_draws == 6
    assert posterior.groups == GROUPS
    assert posterior.segments == SEGMENTS
    assert posterior.names == parameter_set(default_config(), list(GROUPS)).names
    assert posterior.elbow_branch is None
    np.testing.assert_array_equal(posterior.likelihood["likelihood.discrepancy_rel"], np.linspace(0.02, 0.04, 6))


def test_a_draws_config_has_exactly_the_draws_values(posterior):
    configs = posterior.configs()
    assert len(configs) == 6
    base = default_config()
    for i, c in enumerate(configs):
        assert c.section.height_m == HEIGHTS_M[i]
        assert c.hardware.platform.mass_kg == PLATFORM_KG[i]
        # everything the draw does not hold is the base's
        assert c.section.thickness_m == base.section.thickness_m
        assert c.geometry == base.geometry
        assert c.hardware.elbow_joint.mass_kg == pytest.approx(base.hardware.elbow_joint.mass_kg, rel=1e-12)
    med = posterior.median_config()
    assert med.section.height_m == np.median(HEIGHTS_M)
    assert med.hardware.platform.mass_kg == np.median(PLATFORM_KG)


def test_thinning_is_a_seeded_subset_without_repeats(posterior):
    a = posterior.draws(4, seed=1)
    assert len(set(a.tolist())) == 4
    assert list(a) == sorted(a)
    np.testing.assert_array_equal(a, posterior.draws(4, seed=1))
    np.testing.assert_array_equal(posterior.draws(None), np.arange(6))
    np.testing.assert_array_equal(posterior.draws(60), np.arange(6))
    with pytest.raises(PosteriorError, match="n_draws: must be >= 1, got 0"):
        posterior.draws(0)


def test_elbow_branches_replace_the_base_ones(tmp_path):
    branch = np.ones((6, 3), int)
    branch[2] = (1, -1, 1)
    branch[4] = (1, -1, 1)
    branch[5] = (1, -1, 1)
    post = Posterior.from_netcdf(write_posterior(tmp_path / "p.nc", branch=branch))
    assert post.config(2).geometry.elbow_branch == (1, -1, 1)
    assert post.config(0).geometry.elbow_branch == (1, 1, 1)
    assert post.median_config().geometry.elbow_branch == (1, -1, 1)  # the most frequent combination


def test_the_band_brackets_each_draws_own_frequency(posterior, bands):
    # two draws computed directly with the pose loop at the same resolution: their frequencies are the band's
    # draws bit for bit (the same solve), and each lies within the band's 0-100 % range
    for i in (1, 4):
        own = pose_frequencies(posterior.config(i), POSES, n_modes=2, options=fast_options(segments=SEGMENTS))
        np.testing.assert_array_equal(bands.frequencies_hz[i], own.frequencies_hz)
        assert np.isnan(own.frequencies_hz[2]).all()  # nobody reaches the far pose
        f = own.frequencies_hz[:2]
        assert np.all((f >= bands.frequencies_hz[:, :2].min(axis=0)) & (f <= bands.frequencies_hz[:, :2].max(axis=0)))
    # the median lies inside both bands, the 50 % band inside the 90 % band
    q = bands.quantiles_hz[:, :2]
    assert np.all(np.diff(q, axis=0) >= 0)
    # the draws differ (height 14.5-16 mm, platform 4.0-4.8 kg): the parameters' 90 % band of f1 is 8.7 % of
    # the median at the centre, the predictive one (with the fixture's 2-4 % discrepancy) 15.1 % (measured at 4
    # segments; the bounds only say the band is neither empty nor absurd)
    q = bands.parameter_quantiles_hz[:, 0, 0]
    assert 0.05 < (q[4] - q[0]) / q[2] < 0.15
    assert 0.10 < bands.relative_width[0, 0] < 0.20


def test_quantiles_equal_numpys_over_the_draws(bands):
    f = bands.frequencies_hz[:, :2, :]  # the two reachable poses: every draw computed
    q = bands.parameter_quantiles_hz[:, :2, :]
    np.testing.assert_allclose(q, np.quantile(f, QUANTILES, axis=0), rtol=0, atol=0)
    np.testing.assert_array_equal(q[2], np.median(f, axis=0))


def test_predictive_bands_hold_the_model_discrepancy(bands):
    from scipy import stats

    assert bands.discrepancy_rel is not None  # the fixture's posterior has likelihood.discrepancy_rel
    # one draw: the predictive quantiles are f (1 + d z_q) exactly (scipy's normal quantiles)
    one = dataclasses.replace(
        bands, draw_index=bands.draw_index[:1], frequencies_hz=bands.frequencies_hz[:1], status=bands.status[:1],
        discrepancy_rel=np.array([0.1]),
    )  # fmt: skip
    f = one.frequencies_hz[0, :2, :]
    expect = f[None] * (1 + 0.1 * stats.norm.ppf(np.array(QUANTILES)))[:, None, None]
    np.testing.assert_allclose(one.quantiles_hz[:, :2, :], expect, rtol=1e-9)  # bisection to round-off
    # all draws: against a large Monte Carlo sample of the same mixture (1e5 per draw; sampling error ~0.3 %)
    rng = np.random.default_rng(0)
    d = np.asarray(bands.discrepancy_rel)
    f0 = bands.frequencies_hz[:, 0, 0]
    sample = (f0[:, None] * (1 + d[:, None] * rng.standard_normal((len(f0), 100_000)))).ravel()
    np.testing.assert_allclose(bands.quantiles_hz[:, 0, 0], np.quantile(sample, QUANTILES), rtol=3e-3)
    # the predictive band is wider than the parameters' spread alone
    assert np.all(bands.quantiles_hz[4, :2] - bands.quantiles_hz[0, :2] > bands.parameter_quantiles_hz[4, :2]
                  - bands.parameter_quantiles_hz[0, :2])  # fmt: skip
    assert "predictive" in bands.table()


def test_a_gaussian_process_discrepancy_shifts_and_narrows_each_draws_prediction(bands):
    """Per draw and pose f (1 + shift + sd z): the quantiles of that mixture against a Monte Carlo of it."""
    rng = np.random.default_rng(1)
    n = bands.n_draws
    shift = rng.uniform(-0.1, 0.1, (n, 3))
    sd = rng.uniform(0.02, 0.08, (n, 3))
    gp = dataclasses.replace(bands, discrepancy_rel=sd, discrepancy_shift=shift)
    f0 = bands.frequencies_hz[:, 1, 0]
    z = rng.standard_normal((n, 100_000))
    sample = (f0[:, None] * (1 + shift[:, 1, None] + sd[:, 1, None] * z)).ravel()
    # 6e5 samples: the quantiles' sampling error is below 0.1 %
    np.testing.assert_allclose(gp.quantiles_hz[:, 1, 0], np.quantile(sample, QUANTILES), rtol=3e-3)
    p = gp.meet_probability(float(np.median(f0)), mode=1)[:, 1]
    np.testing.assert_allclose(p, (f0[:, None] * (1 + shift[:, 1, None] + sd[:, 1, None] * z) >= np.median(f0)).mean(1),
                               atol=5e-3)  # fmt: skip
    assert "Gaussian process" in gp.kind_line()


def test_unreachable_draws_are_counted_not_banded(bands):
    np.testing.assert_array_equal(bands.computed_fraction, [1.0, 1.0, 0.0])
    np.testing.assert_array_equal(bands.unreachable_fraction, [0.0, 0.0, 1.0])
    assert np.isnan(bands.quantiles_hz[:, 2]).all()
    rows = bands.rows()
    assert rows[2]["unreachable_fraction"] == 1.0
    assert rows[0]["f1_q50_hz"] == bands.median_hz[0, 0]
    assert bands.probability_above(0.0).tolist() == [1.0, 1.0, 0.0]


def test_partly_unreachable_pose_uses_the_reaching_draws(bands):
    masked = dataclasses.replace(bands, status=bands.status.copy(), frequencies_hz=bands.frequencies_hz.copy())
    masked.status[:2, 1] = "unreachable"
    masked.frequencies_hz[:2, 1] = np.nan
    assert masked.computed_fraction[1] == pytest.approx(4 / 6)
    np.testing.assert_array_equal(
        masked.parameter_quantiles_hz[:, 1, 0], np.quantile(bands.frequencies_hz[2:, 1, 0], QUANTILES)
    )


def test_result_outputs(bands, tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    d = bands.to_dict()
    assert d["n_draws"] == 6
    assert d["quantiles"] == list(QUANTILES)
    assert len(d["bands"]) == 3
    assert d["frequencies_hz"][0][2] == [None, None]
    table = bands.table()
    assert "5-95 %" in table
    assert "0/6" in table  # the unreachable pose
    ds = bands.dataset
    assert ds["freq_hz"].dims == ("draw", "pose", "mode")
    assert set(ds["x_mm"].dims) == {"pose"}
    assert bands.plot().axes
    assert bands.plot_map().axes
    assert bands.widest() in (0, 1)


def test_bad_posterior_files_say_what_is_wrong(tmp_path):
    with pytest.raises(PosteriorError, match=r"posterior: file not found, got '.*nope\.nc'") as missing:
        Posterior.from_netcdf(tmp_path / "nope.nc")
    # the error contract: the library's parameter and the value (the command line shows its --posterior option)
    assert (missing.value.parameter, missing.value.value) == ("posterior", str(tmp_path / "nope.nc"))
    junk = tmp_path / "junk.nc"
    junk.write_text("not a netcdf file")
    with pytest.raises(PosteriorError, match=r"junk\.nc: not an ArviZ") as unreadable:
        Posterior.from_netcdf(junk)
    # not a posterior at all: the error names the parameter (the command line's --posterior) and the file
    assert unreadable.value.parameter == "posterior"
    assert str(junk) in str(unreadable.value)
    with pytest.raises(PosteriorError, match=r"fpm_sim_segments: must be an integer, got 'four'") as seg:
        Posterior.from_netcdf(write_posterior(tmp_path / "s.nc", attrs={"fpm_sim_segments": "four"}))
    assert (seg.value.parameter, seg.value.file) == ("fpm_sim_segments", str(tmp_path / "s.nc"))
    with pytest.raises(PosteriorError, match=r"lacks the attribute.*fpm_sim_free_groups"):
        Posterior.from_netcdf(write_posterior(tmp_path / "a.nc", attrs={"fpm_sim_free_groups": None}))
    with pytest.raises(PosteriorError, match=r"unknown: section\.width_m"):
        Posterior.from_netcdf(write_posterior(tmp_path / "b.nc", draws={"section.width_m": np.ones(6)}))
    with pytest.raises(PosteriorError, match=r"missing: hardware\.elbow_joint\.mass_kg"):
        Posterior.from_netcdf(write_posterior(tmp_path / "c.nc", drop=("hardware.elbow_joint.mass_kg",)))
    with pytest.raises(PosteriorError, match="unknown parameter group"):
        Posterior.from_netcdf(write_posterior(tmp_path / "d.nc", attrs={"fpm_sim_free_groups": "bogus"}))
    bad = write_posterior(tmp_path / "e.nc", draws={"section.height_m": -HEIGHTS_M})
    with pytest.raises(PosteriorError, match="draw 0 is not a valid description"):
        Posterior.from_netcdf(bad).config(0)


def test_study_bands_cover_the_measured_poses_and_predict_the_withheld(posterior):
    from fpm_sim.study.tables import measured_table, withheld_cells

    sb = study_bands(posterior, n_draws=None, engine=EngineOptions(scheduler="serial"))
    n_measured = sum(m.readable for m in measured_table())
    assert n_measured == 12
    assert len(withheld_cells()) == 6
    assert sb.withheld.tolist() == [False] * 12 + [True] * 6
    assert np.isnan(sb.measured_hz[12:]).all()  # never a value at the withheld poses
    # coverage counted by hand from the quantiles
    q = sb.bands.quantiles_hz[:, :12, 0]
    f = sb.measured_hz[:12]
    c = sb.coverage()
    assert c["measured_poses"] == 12
    assert c["in_90_band"] == np.mean((f >= q[0]) & (f <= q[4]))
    assert c["in_50_band"] == np.mean((f >= q[1]) & (f <= q[3]))
    assert "withheld poses (predictions only)" in sb.table()
    d = sb.to_dict()
    assert [r["measured_hz"] is None for r in d["poses"]] == [False] * 12 + [True] * 6


@pytest.mark.filterwarnings("ignore:coarse resolution")
def test_api_entry_point_gives_the_same_bands(posterior_file, bands):
    import fpm_sim as fs

    res = fs.predict_bands(posterior_file, POSES[:2], draws=None, n_modes=2, workers=1)
    np.testing.assert_array_equal(res.frequencies_hz, bands.frequencies_hz[:, :2])
    assert res.options.segments == SEGMENTS  # the posterior's resolution by default
    one = fs.predict_bands(Posterior.from_netcdf(posterior_file), POSES[0], draws=3, n_modes=1, workers=1)
    assert one.frequencies_hz.shape == (3, 1, 1)


def test_measure_here_next_prefers_poses_every_draw_reaches_away_from_singularities(bands):
    two = dataclasses.replace(bands, status=bands.status.copy(), frequencies_hz=bands.frequencies_hz.copy())
    assert two.widest() == int(np.argmax(two.relative_width[:2, 0]))
    w = 1 - two.widest()  # make the other reachable pose the widest, through one near-singular draw
    two.frequencies_hz[0, w, 0] = 1.0
    two.status[0, w] = "near_singular"
    assert np.nanargmax(two.relative_width[:, 0]) == w
    assert two.widest() == 1 - w  # not there: the widest band among the poses all draws reach as ok
    assert set(two.dataset["status"].dims) == {"draw", "pose"}


def test_the_shipped_posteriors_headline_numbers():
    """Issue 23's numbers for the embedded default's posterior (100 seeded draws, its 4 segments; ~4 s), pinned
    so that a change cannot move them silently. The posterior is issue 31's (as built, 4 islands of 10 000
    statements particles, 3 runs that pass the between-run check; docs/identification.md). Measured: 12/12
    measured f1 inside the 90 % predictive band (the target, >= 11, is met in-sample), 9/12 inside the 50 % band,
    a posterior median 12.0 % off (target 8 %: missed), 90 % bands 0.974 of the median wide at the measured poses
    (a half-width of 49 %; target 12 %: missed); leave-one-out 11/12 inside the 90 % band, half-width 57.6 %,
    median 18.0 % off (the earlier one-run posterior: 8/12, 19.7 %, 0.875; 11/12, 44.6 %, 20.5 %)."""
    from importlib import resources

    from fpm_sim.study.posterior import Posterior, study_bands

    post = Posterior.from_netcdf(str(resources.files("fpm_sim.data") / "default_posterior.nc"))
    sb = study_bands(post, n_draws=100)
    c = sb.coverage()
    assert c["measured_poses"] == 12
    assert c["in_90_band"] >= 11 / 12
    # a calibrated 50 % band holds about half: 3..9 of 12 is the binomial's central 96 %; measured 9/12
    assert 3 / 12 <= c["in_50_band"] <= 9 / 12
    assert c["median_error_pct"] == pytest.approx(12.0, abs=0.5)  # seeded draws: deterministic up to BLAS
    width = sb.bands.relative_width[~np.asarray(sb.withheld), 0]
    assert np.median(width) == pytest.approx(0.974, abs=0.03)
    # leave-one-out (PSIS over the file's 200 draws; deterministic): issue 23's targets are >= 11/12 inside the
    # 90 % band (met: 11), a median half-width <= 12 % (missed: 57.6 %) and a mean error <= 8 % (missed: 18.0 %)
    loo = sb.loo
    assert loo is not None
    assert int(loo.inside(0.9).sum()) == 11
    assert float(np.median(loo.half_width)) == pytest.approx(0.576, abs=0.005)
    assert loo.mean_abs_error == pytest.approx(0.180, abs=0.005)


def test_read_predictive_is_the_weighted_mixture_over_draws_and_modes(bands):
    """read_quantiles_hz: f_k (1 + sqrt(d^2 + noise^2) z) with the read weights, against a Monte Carlo of it."""
    rng = np.random.default_rng(2)
    n = bands.n_draws
    f = rng.uniform(30, 70, (n, 3, 3))
    w = rng.dirichlet(np.ones(3), size=(n, 3))
    d = np.full(n, 0.1)
    rb = dataclasses.replace(bands, read_freq_hz=f, read_weight=w, discrepancy_rel=d, read_noise_rel=0.02)
    q = rb.read_quantiles_hz
    assert q is not None
    sd = np.sqrt(0.1**2 + 0.02**2)
    m = 200_000
    draw = rng.integers(0, n, m)
    mode = (rng.random(m)[:, None] > np.cumsum(w[draw, 1], axis=1)).sum(axis=1).clip(max=2)
    sample = f[draw, 1, mode] * (1 + sd * rng.standard_normal(m))
    # 2e5 samples: quantile sampling error ~0.2 % of the value
    np.testing.assert_allclose(q[:, 1], np.quantile(sample, QUANTILES), rtol=5e-3)
    assert bands.read_quantiles_hz is None  # without the latent-mode model there is nothing to read


def test_the_likelihoods_resolution_is_inside_the_bands():
    """Issue 23: the calibration samples at 4 segments per link; the shipped resolution is 12. Over 20 draws of
    the shipped posterior at its 12 measured poses, f1 at 4 segments is 1.2 % above f1 at 12 (median; max 1.8 %,
    measured), 25 times less than the 90 % band's half-width there (44.6 %)."""
    import warnings
    from importlib import resources

    from fpm_sim.kinematics import Pose
    from fpm_sim.model.options import DEFAULT_SEGMENTS
    from fpm_sim.study.identify import Observation
    from fpm_sim.study.identify.engine import predict_observations
    from fpm_sim.study.posterior import Posterior

    post = Posterior.from_netcdf(str(resources.files("fpm_sim.data") / "default_posterior.nc"))
    d = post.data
    assert d is not None
    obs = [Observation(Pose(x, y, p), 1, 1.0, 1.0, None, "r") for x, y, p in zip(d.x_m, d.y_m, d.phi_rad)]
    diff = []
    for i in post.draws(20, seed=0):
        cfg = post.config(int(i))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            f4 = predict_observations(cfg, obs, options=fast_options(segments=4))
            f_ship = predict_observations(cfg, obs, options=fast_options(segments=DEFAULT_SEGMENTS))
        diff.append(f4 / f_ship - 1)
    diff = np.abs(np.array(diff))
    assert DEFAULT_SEGMENTS == 12
    assert diff.max() < 0.025  # measured 1.8 %: discretisation, second order in 1/segments
    loo = post.leave_one_out()
    assert loo is not None
    assert diff.max() < 0.1 * float(np.median(loo.half_width))


def test_a_draw_written_as_a_description_says_it_is_a_posterior_draw():
    """A draw of the shipped posterior (as built: per-chain deviations set the per-chain lists) written as TOML
    names the posterior draw as the source of every field its parameters set, not the base description's."""
    import tomllib
    from importlib import resources

    from fpm_sim.config import config_to_toml, parse_config
    from fpm_sim.study.identify.report import provenance_key
    from fpm_sim.study.posterior import DRAW_SOURCE, Posterior

    assert provenance_key("geometry.proximal_length_dev_rel[2]") == "geometry.proximal_length_m"
    assert provenance_key("geometry.base_angle_dev_deg[0]") == "geometry.base_angles_deg"
    post = Posterior.from_netcdf(str(resources.files("fpm_sim.data") / "default_posterior.nc"))
    cfg = post.config(7)
    for key in ("geometry.base_radius_m", "geometry.proximal_length_m", "geometry.base_angles_deg",
                "hardware.platform.mass_kg", "section.height_m", "geometry.elbow_branch"):  # fmt: skip
        assert cfg.provenance[key].startswith(f"identified: {DRAW_SOURCE}, draw 7 of default_posterior.nc"), key
    assert "geometry.proximal_length_dev_rel[1]" in cfg.provenance["geometry.proximal_length_m"]
    assert cfg.provenance["hardware.platform.inertia_kg_m2"] == "identified: scaled with the identified mass"
    # fields no parameter sets keep the base's source
    assert cfg.provenance["material.young_pa"] == post.base.provenance["material.young_pa"]
    again = parse_config(tomllib.loads(config_to_toml(cfg)))
    assert again.provenance["section.height_m"] == cfg.provenance["section.height_m"]
    assert again.geometry.proximal_length_m == cfg.geometry.proximal_length_m
