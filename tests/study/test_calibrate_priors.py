"""Priors of fpm-sim calibrate: parsing, refusals naming the key, and the unit-cube transform against
scipy.stats' own quantile functions (an independent implementation)."""

import numpy as np
import pytest
from scipy import stats

from fpm_sim.study.calibrate import PriorError, read_priors

NAMES = ["section.height_m", "hardware.platform.mass_kg"]
OK = """
[parameters."section.height_m"]
dist = "loguniform"
lower = 0.005
upper = 0.03
reason = "assumed: bar stock"

[parameters."hardware.platform.mass_kg"]
dist = "truncnormal"
mean = 1.0
sd = 0.5
lower = 0.2
upper = 3.0
reason = "assumed: a plate"

[likelihood.discrepancy_rel]
dist = "loguniform"
lower = 0.005
upper = 0.5
reason = "assumed: model error"

[statements.singular_at_phi0]
enabled = false

[statements.measured_poses_clear]
enabled = true
min_measure = 0.04
reason = "study: usable poses"
"""


def test_the_file_parses_in_the_free_parameters_order():
    pr = read_priors("p.toml", list(reversed(NAMES)), text=OK)
    assert [p.name for p in pr.parameters] == list(reversed(NAMES))
    assert pr.names == [*reversed(NAMES), "likelihood.discrepancy_rel"]
    assert pr.singular_at_phi0 is None  # enabled = false switches it off
    assert pr.measured_poses_clear is not None
    assert pr.measured_poses_clear.min_measure == 0.04
    assert not pr.sample_branches


@pytest.mark.parametrize(
    ("table", "frozen"),
    [
        ('dist = "uniform"\nlower = 2.0\nupper = 5.0', stats.uniform(2.0, 3.0)),
        ('dist = "loguniform"\nlower = 0.01\nupper = 2.0', stats.loguniform(0.01, 2.0)),
        ('dist = "normal"\nmean = 1.5\nsd = 0.3', stats.norm(1.5, 0.3)),
        ('dist = "lognormal"\nmedian = 0.8\nsigma_log = 0.6', stats.lognorm(0.6, scale=0.8)),
        (
            'dist = "truncnormal"\nmean = 1.0\nsd = 0.5\nlower = 0.2\nupper = 3.0',
            stats.truncnorm((0.2 - 1.0) / 0.5, (3.0 - 1.0) / 0.5, loc=1.0, scale=0.5),
        ),
    ],
)
def test_the_transform_is_the_stated_distributions_quantile_function(table, frozen):
    text = f'[parameters."x_m"]\n{table}\nreason = "assumed: test"\n'
    (prior,) = read_priors("p.toml", ["x_m"], text=text).parameters
    u = np.linspace(0.001, 0.999, 41)
    # the same inverse CDF to rounding (scipy's ppf is an independent implementation)
    np.testing.assert_allclose(prior.transform(u), frozen.ppf(u), rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize(
    ("text", "names", "needle"),
    [
        ('[parameters."nope_m"]\ndist = "uniform"\nlower = 0\nupper = 1\nreason = "r"', ["x_m"], "nope_m"),
        ("", ["x_m"], "no prior for the free parameter(s) x_m"),
        ('[parameters."x_m"]\ndist = "cauchy"\nreason = "r"', ["x_m"], "unknown distribution 'cauchy'"),
        ('[parameters."x_m"]\ndist = "uniform"\nlower = 1\nupper = 2', ["x_m"], "'reason'"),
        (
            '[parameters."x_m"]\ndist = "uniform"\nlower = 2\nupper = 1\nreason = "r"',
            ["x_m"],
            "lower (2) must be below",
        ),
        ('[parameters."x_m"]\ndist = "normal"\nmean = 1\nreason = "r"', ["x_m"], "missing 'sd'"),
        ('[parameters."x_m"]\ndist = "normal"\nmean = 1\nsd = 1\nwidth = 2\nreason = "r"', ["x_m"], "'width'"),
        ('[parameters."x_m"]\ndist = "loguniform"\nlower = 0\nupper = 1\nreason = "r"', ["x_m"], "lower > 0"),
        ("[priors]\nx = 1", ["x_m"], "unknown section(s) ['priors']"),
        ("[statements.wishful]\nenabled = true", [], "unknown statement(s) ['wishful']"),
        ("[statements.measured_poses_clear]\nmin_measure = 0.1", [], "measured_poses_clear]: give a 'reason'"),
        ("[statements.measured_poses_clear]\nthreshold = 0.1\nreason = 'r'", [], "'threshold'"),
        ("[likelihood]\nsigma = 2", [], "[likelihood]: unknown key(s) ['sigma']"),
        (
            '[likelihood.length_scale_m]\ndist = "uniform"\nlower = 0.1\nupper = 1\nreason = "r"',
            [],
            "a correlation length needs a discrepancy",
        ),
        (
            '[likelihood.discrepancy_rel]\nvalue = 0.1\nreason = "r"\n'
            '[likelihood.length_scale_m]\ndist = "uniform"\nlower = -0.1\nupper = 1\nreason = "r"',
            [],
            "must be > 0 over the whole prior",
        ),
        ('[parameters."geometry.elbow_branch"]\ndist = "uniform"\nreason = "r"', [], '"branches"'),
        ("[parameters", ["x_m"], "not valid TOML"),
    ],
)
def test_bad_priors_are_refused_naming_the_key(text, names, needle):
    with pytest.raises(PriorError) as exc:
        read_priors("bad.toml", names, text=text)
    assert needle in str(exc.value)
    assert "bad.toml" in str(exc.value)


def test_a_missing_file_is_named(tmp_path):
    with pytest.raises(PriorError, match="priors file not found"):
        read_priors(tmp_path / "none.toml", ["x_m"])


def test_the_shipped_study_priors_cover_the_study_groups(default_manip):
    from importlib.resources import files

    from fpm_sim.study.identify import parameter_set

    names = parameter_set(default_manip, ["geometry", "hardware", "section-height"]).names
    pr = read_priors("study_priors.toml", names, text=files("fpm_sim.data").joinpath("study_priors.toml").read_text())
    assert pr.sample_branches
    assert pr.singular_at_phi0 is not None
    assert pr.measured_poses_clear is not None
    assert all(p.reason.startswith(("assumed: ", "study: ")) for p in pr.parameters)
    # the default description's values lie inside their priors' support (the start is a possible machine)
    ps = parameter_set(default_manip, ["geometry", "hardware", "section-height"])
    for p, x in zip(pr.parameters, ps.x0):
        lo, hi = p.transform(0.0), p.transform(1.0)
        assert lo <= x <= hi, p.name


def test_the_shipped_as_built_priors_are_the_study_priors_and_the_as_built_group(default_manip):
    """``study_priors_as_built.toml`` (the shipped posterior's priors) is the study's priors with the as-built
    group's 1 deg / 1 % deviations and nothing else: parsed, the same distributions and statements as
    ``study_priors.toml`` plus ``as_built_priors(1.0, 0.01)``, each with its reason."""
    from importlib.resources import files

    from fpm_sim.study.calibrate.problem import as_built_priors
    from fpm_sim.study.identify import parameter_set

    data = files("fpm_sim.data")
    names = parameter_set(default_manip, ["geometry", "hardware", "section-height", "as-built"]).names
    shipped = read_priors("as_built", names, text=data.joinpath("study_priors_as_built.toml").read_text())
    study = data.joinpath("study_priors.toml").read_text()
    with_group = study.replace("[likelihood]", as_built_priors(1.0, 0.01) + "\n[likelihood]")
    built = read_priors("built", names, text=with_group)
    assert [p.describe() for p in shipped.parameters] == [p.describe() for p in built.parameters]
    assert [p.name for p in shipped.parameters] == [p.name for p in built.parameters]
    assert [h.describe() for h in shipped.hyperpriors] == [h.describe() for h in built.hyperpriors]
    assert shipped.singular_at_phi0 == built.singular_at_phi0
    assert shipped.measured_poses_clear == built.measured_poses_clear
    assert sum("_dev_" in p.name for p in shipped.parameters) == 12
    assert all(p.reason.startswith(("assumed: ", "study: ")) for p in shipped.parameters)
