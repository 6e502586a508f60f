import dataclasses
import math

import numpy as np
import pytest

from fpm_sim.config import Material, Section
from fpm_sim.identification import Parameter, fit, identify_link
from fpm_sim.study_comparison import subsystem_frequencies
from fpm_sim.study_data import SubsystemTest


def test_fit_recovers_known_parameters_of_an_analytic_model():
    # two-parameter model with three data: f_i = a * x_i^b, noise-free
    xs = np.array([1.0, 2.0, 3.0])
    truth = (40.0, 0.5)

    def model(theta):
        return theta[0] * xs ** theta[1]

    res = fit(model, model(np.array(truth)), [Parameter("a", 10.0, 1.0, 100.0), Parameter("b", 1.5, 0.0, 3.0)])
    # least_squares stops at ftol 1e-8 on the cost: parameters to ~1e-6 relative
    assert res.values == pytest.approx(truth, rel=1e-5)
    assert np.all(np.abs(res.residual_pct) < 1e-4)
    assert res.correlation.shape == (2, 2) and res.correlation[0, 0] == pytest.approx(1.0)


def test_link_identification_recovers_synthetic_length_and_clamp(default_manip):
    truth_len, truth_clamp = 0.21, 0.03
    seg = 4  # the same discretisation generates and fits the data: recovery is exact up to the solver tolerance
    rig = dataclasses.replace(
        default_manip.rig,
        length_m=truth_len,
        clamped_length_m=truth_clamp,
        section=Section(0.01, 0.01),
        material=Material(200e9, 0.3, 7850.0),
    )
    truth_cfg = default_manip.replace(rig=rig)
    tests = [
        SubsystemTest("free-free", 180.0, math.nan, math.nan, "ff"),
        SubsystemTest("cantilever", 180.0, math.nan, math.nan, "cl"),
    ]
    synth = [r.ours_hz for r in subsystem_frequencies(truth_cfg, segments=seg, tests=tests)]
    data = [dataclasses.replace(t, experimental_hz=f) for t, f in zip(tests, synth)]
    start = default_manip.replace(rig=dataclasses.replace(rig, length_m=0.24, clamped_length_m=0.01))
    res, cfg = identify_link(start, tests=data, segments=seg)
    assert res.values == pytest.approx([truth_len, truth_clamp], rel=1e-4)
    assert cfg.rig.length_m == pytest.approx(truth_len, rel=1e-4)
