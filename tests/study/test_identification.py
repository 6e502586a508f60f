import dataclasses
import math

import numpy as np
import pytest

from fpm_sim.config import Material, Section
from fpm_sim.study.identification import Parameter, fit, identify_link
from fpm_sim.study.reproduce import subsystem_frequencies
from fpm_sim.study.tables import SubsystemTest


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
    assert res.correlation.shape == (2, 2)
    assert res.correlation[0, 0] == pytest.approx(1.0)


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


@pytest.mark.slow
def test_manipulator_step_recovers_a_synthetic_platform_mass_and_geometry(default_manip):
    import dataclasses as dc

    from fpm_sim.batch.frequencies import first_frequencies
    from fpm_sim.batch.pose_loop import fast_options
    from fpm_sim.config import LumpedMass
    from fpm_sim.kinematics import Pose
    from fpm_sim.study.identification import identify_manipulator

    opts = fast_options(segments=2)  # generate and fit with the same model: recovery up to solver tolerance
    g = default_manip.geometry
    truth = [g.base_radius_m, g.platform_radius_m, g.proximal_length_m, g.distal_length_m]
    rot = math.degrees(g.base_angles_rad[0]) - 90.0
    off = math.degrees(g.platform_angles_rad[0] - g.base_angles_rad[0])
    true_mass = 1.3
    ratio = true_mass / default_manip.hardware.platform.mass_kg
    plat = LumpedMass(true_mass, tuple(v * ratio for v in default_manip.hardware.platform.inertia_kg_m2))
    truth_cfg = default_manip.replace(hardware=dc.replace(default_manip.hardware, platform=plat))
    poses = [Pose.from_mm(x, y, 0.0) for x in (-60, 0, 60) for y in (-60, 0, 60)]
    synth = first_frequencies(truth_cfg, poses, options=opts)[:, 0]
    # start the platform mass and the base radius away from the truth; fit both (7 free parameters, 9 data)
    start = [truth[0] * 1.08, *truth[1:], rot, off, 0.6 * default_manip.hardware.platform.mass_kg]
    res, _ = identify_manipulator(
        default_manip, poses, synth, initial=start, elbow_branch=g.elbow_branch, options=opts, span=0.2, max_nfev=80
    )
    got = res.as_dict()
    assert got["hardware.platform.mass_kg"] == pytest.approx(true_mass, rel=1e-3)
    assert got["geometry.base_radius_m"] == pytest.approx(truth[0], rel=1e-3)
    assert np.all(np.abs(res.residual_pct) < 1e-2)


def test_manipulator_level_step_recovers_a_synthetic_platform_mass(default_manip):
    import dataclasses as dc

    from fpm_sim.batch.frequencies import first_frequencies
    from fpm_sim.batch.pose_loop import fast_options
    from fpm_sim.config import LumpedMass
    from fpm_sim.kinematics import Pose
    from fpm_sim.study.identification import identify_manipulator

    opts = fast_options(segments=2)
    g = default_manip.geometry
    values = [
        g.base_radius_m,
        g.platform_radius_m,
        g.proximal_length_m,
        g.distal_length_m,
        math.degrees(g.base_angles_rad[0]) - 90.0,
        math.degrees(g.platform_angles_rad[0] - g.base_angles_rad[0]),
    ]
    ratio = 2.0 / default_manip.hardware.platform.mass_kg
    plat = LumpedMass(2.0, tuple(v * ratio for v in default_manip.hardware.platform.inertia_kg_m2))
    truth_cfg = default_manip.replace(hardware=dc.replace(default_manip.hardware, platform=plat))
    poses = [Pose.from_mm(x, 0.0, 0.0) for x in (-60, 0, 60)]
    synth = first_frequencies(truth_cfg, poses, options=opts)[:, 0]
    res, cfg = identify_manipulator(
        default_manip,
        poses,
        synth,
        initial=[*values, 0.5],
        elbow_branch=g.elbow_branch,
        options=opts,
        geometry_free=False,
    )
    assert res.values[0] == pytest.approx(2.0, rel=1e-4)
    assert cfg.hardware.platform.mass_kg == pytest.approx(2.0, rel=1e-4)
