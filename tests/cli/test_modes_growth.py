"""``fpm-sim modes`` says which cause a growing step map has, in one line naming what to change (issue 32).

The causes are constructed as in ``tests/linear/test_growth.py`` (no real configuration buckles, and compilation
refuses the steps that grow): the model ``modes`` builds gets a step beyond the compile-time rule, and for the
buckling also a gravity-prestressed stiffness softened below zero.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from fpm_sim.cli.main import main
from fpm_sim.model import manipulator
from fpm_sim.model.spec import highest_frequency_rad_s
from tests.helpers.growth import soften_under_gravity, with_step

NEAR = ["modes", "--x-mm", "-99.4", "--y-mm", "50", "--segments", "3", "--n-modes", "2"]


@pytest.fixture
def coarse_step(monkeypatch):
    """``modes`` builds its model with a step 100 / w_max (the compile-time rule allows < 2 / w_max)."""
    original = manipulator.build_manipulator

    def build(*args, **kwargs):
        built = original(*args, **kwargs)
        return with_step(built, 100.0 / highest_frequency_rad_s(built.model))

    monkeypatch.setattr(manipulator, "build_manipulator", build)


def run(capsys, argv):
    code = main(argv)
    _, err = capsys.readouterr()
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith("warning:")]
    assert code == 2, err
    assert "Traceback" not in err
    assert len(lines) == 1, err
    assert lines[0].startswith("error: "), err
    return lines[0]


def test_a_too_coarse_step_is_named_with_the_step_that_works(capsys, coarse_step):
    line = run(capsys, NEAR)
    assert re.match(r"error: --timestep-s: \S+ s is too coarse for this model at this pose", line), line
    assert re.search(r"the equilibrium is stable \(constrained eigen-solve, no time step: f1 = 0\.\d+ Hz\)", line)
    assert re.search(r"; timestep_s=\S+ s works", line), line
    assert " or " not in line.split(";")[0]


def test_buckling_under_gravity_is_named_with_the_measure_and_f1_without_gravity(capsys, coarse_step, monkeypatch):
    soften_under_gravity(monkeypatch, (2 * np.pi * 1.0) ** 2)  # f1 under gravity is 0.59 Hz here
    line = run(capsys, NEAR)
    assert re.match(r"error: the structure buckles under gravity's prestress at this pose \(singularity measure "
                    r"0\.0016\)", line), line  # fmt: skip
    assert re.search(r"without gravity it is stable with f1 = 0\.2\d* Hz", line), line
    assert "no timestep_s helps" in line
