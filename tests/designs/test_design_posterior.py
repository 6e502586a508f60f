"""Designs over a posterior (fpm_sim.designs.robust, ``design --posterior``): every design applied to every draw;
P(min f1 >= f_min) checked against the draws solved one by one."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from fpm_sim.batch.engine import EngineOptions
from fpm_sim.batch.frequencies import pose_frequencies
from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.cli.main import main
from fpm_sim.designs import DesignError, apply_design
from fpm_sim.designs.robust import design_over_draws
from fpm_sim.study.poses import study_poses
from fpm_sim.study.posterior import Posterior
from tests.helpers.posterior import write_posterior

POSES = [p.pose for p in study_poses()][:6]
VARY = {"section.thickness_m": [0.02, 0.03]}


@pytest.fixture(scope="module")
def post_file(tmp_path_factory):
    return write_posterior(tmp_path_factory.mktemp("dpost") / "posterior.nc")


@pytest.fixture(scope="module")
def result(post_file):
    post = Posterior.from_netcdf(post_file)
    return post, design_over_draws(
        post.configs(),
        poses=POSES,
        f_min_hz=0.0,
        vary=VARY,
        options=fast_options(segments=4),
        engine=EngineOptions(scheduler="serial"),
    )


def test_each_design_and_draw_is_the_draw_with_the_design_applied(result):
    post, res = result
    assert res.frequencies_hz.shape == (2, 6, len(POSES), 1)
    for d, k in ((0, 1), (1, 4)):
        cfg = apply_design(post.config(k), {"section.thickness_m": VARY["section.thickness_m"][d]})
        own = pose_frequencies(cfg, POSES, n_modes=1, options=fast_options(segments=4))
        np.testing.assert_array_equal(res.frequencies_hz[d, k], own.frequencies_hz)
        ok = [s == "ok" for s in own.status]
        assert res.min_f1_ok_hz[d, k] == np.min(own.frequencies_hz[ok, 0])


def test_probability_is_the_share_of_draws_meeting_the_target(result):
    _, res0 = result
    m = res0.min_f1_ok_hz
    assert np.isfinite(m).all()
    # a target at the median of design 0's min f1: exactly half of its six draws reach it
    target = float(np.median(m[0]))
    res = dataclasses.replace(res0, f_min_hz=target)
    p = res.probability_meets
    assert p[0] == 0.5
    assert p[1] == np.mean(m[1] >= target)
    assert p[1] > p[0]  # thicker links are stiffer: more draws meet the target
    row = res.summary()[0]
    assert row["min_f1_ok_q50_hz"] == target
    assert "P(min f1>=" in res.table()


def test_bad_requests(post_file):
    post = Posterior.from_netcdf(post_file)
    with pytest.raises(DesignError, match="not both or neither"):
        design_over_draws(post.configs(2), poses=POSES, f_min_hz=10.0)
    with pytest.raises(DesignError, match=r"f_min_hz: must be >= 0, got -1\.0"):
        design_over_draws(post.configs(2), poses=POSES, f_min_hz=-1.0, vary=VARY)


def test_cli_design_with_a_posterior(post_file, tmp_path, capsys):
    out = tmp_path / "D"
    argv = ["design", "--posterior", str(post_file), "--vary", "section.thickness_m=0.02,0.03", "--draws", "3"]
    assert main([*argv, "--out", str(out)]) == 2
    assert "needs --f-min-hz" in capsys.readouterr().err
    assert main([*argv, "--f-min-hz", "5", "--poses", str(_poses_csv(tmp_path)), "--out", str(out), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["n_draws"] == 3
    assert [r["section.thickness_m"] for r in d["summary"]] == [0.02, 0.03]
    assert {p.name for p in out.iterdir()} == {"design_bands.csv", "design_bands.json", "design_bands.png"}


def _poses_csv(tmp_path):
    path = tmp_path / "poses.csv"
    path.write_text("x_mm,y_mm,phi_rad\n" + "".join(f"{p.x_m * 1e3},{p.y_m * 1e3},{p.phi_rad}\n" for p in POSES))
    return path
