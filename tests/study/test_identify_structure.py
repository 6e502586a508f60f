"""Issue 23 item 5: the parameter <-> description mapping is data (picklable, so a spawned worker gets the
problem whole), and importing the parameter groups stays light."""

import pickle
import subprocess
import sys

import numpy as np

from fpm_sim.config import default_config
from fpm_sim.kinematics import Pose
from fpm_sim.study.identify import IdentifyOptions, Observation, Problem, parameter_set
from fpm_sim.study.identify.objective import Objective
from fpm_sim.study.identify.parameters import apply_parameters


def test_a_problem_and_its_objective_pickle_and_apply_the_same_description():
    cfg = default_config()
    ps = parameter_set(cfg, ["geometry", "hardware", "compliance", "offsets"])
    x = ps.lower + 0.37 * (ps.upper - ps.lower)
    problem = Problem(ps, [Observation(Pose(0.0, 0.0, 0.0), 1, 40.0, 0.4, None, "synthetic")])
    obj = Objective(problem, IdentifyOptions(segments=2), branch=(1, -1, 1))
    back = pickle.loads(pickle.dumps(obj))
    assert back.problem.parameters.parameters == ps.parameters  # frozen specs compare as data
    assert back.ps.apply(x) == obj.ps.apply(x)
    assert back.ps.apply(x).geometry.elbow_branch == (1, -1, 1)
    np.testing.assert_array_equal(back.x(back.z(x)), x)
    # the one function that applies the specs, by their dotted paths
    edited = apply_parameters(cfg, ps.parameters, x)
    assert edited == ps.apply(x)
    assert edited.hardware.platform.mass_kg == x[ps.names.index("hardware.platform.mass_kg")]


def test_importing_the_parameter_groups_imports_neither_mujoco_scipy_jax_nor_numpy():
    code = (
        "import sys, fpm_sim.study.identify.parameters as p; "
        "print(len(p.GROUPS), sorted(m for m in ('mujoco', 'scipy', 'jax', 'numpy') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["10", "[]"]  # the as-built group is the tenth
