"""The ``jax`` pose-loop backend (MuJoCo's formulas in JAX) and frequency gradients against the ``cpu`` path.

JAX compiles take seconds here; this file holds two compiles at 2-3 segments per link (the batched
solve and the sensitivity) so that it stays well under the suite's budget.
"""

import re
import subprocess
import sys

import numpy as np
import pytest

from fpm_sim.batch.frequencies import pose_frequencies
from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.config import default_config
from fpm_sim.kinematics import Pose
from fpm_sim.model.options import ModelOptions
from fpm_sim.study.poses import study_poses


def test_importing_fpm_sim_and_the_cpu_path_does_not_import_jax():
    code = (
        "import sys, fpm_sim, fpm_sim.cli.main, fpm_sim.batch.frequencies, fpm_sim.batch.jax_backend\n"
        "import fpm_sim.batch.mjx_backend\n"
        "from fpm_sim.config import default_config\n"
        "from fpm_sim.kinematics import Pose\n"
        "from fpm_sim.batch.pose_loop import fast_options\n"
        "from fpm_sim.batch.frequencies import first_frequencies, BACKENDS\n"
        "first_frequencies(default_config(), [Pose(0, 0, 0)], options=fast_options(segments=2))\n"
        "assert {'cpu', 'jax', 'mjx'} <= set(BACKENDS)\n"
        "assert 'jax' not in sys.modules, 'jax imported'\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_the_jax_backend_leaves_the_processs_jax_settings_alone():
    """x64 is switched on inside the backend call only; importing the modules changes nothing."""
    code = (
        "import jax, jax.numpy as jnp\n"
        "import fpm_sim.batch.jax_backend, fpm_sim.batch.jax_linearisation, fpm_sim.batch.mjx_backend\n"
        "assert not jax.config.jax_enable_x64, 'x64 switched on at import'\n"
        "from fpm_sim.config import default_config\n"
        "from fpm_sim.kinematics import Pose\n"
        "from fpm_sim.batch.pose_loop import fast_options\n"
        "from fpm_sim.batch.frequencies import pose_frequencies\n"
        "r = pose_frequencies(default_config(), [Pose(0, 0, 0)], backend='jax', options=fast_options(segments=2))\n"
        "assert not jax.config.jax_enable_x64, 'x64 left on after a backend call'\n"
        "assert jnp.zeros(1).dtype == jnp.float32\n"
        "assert r.timings.compile_s > 0 and r.timings.poses == 1, r.timings\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_old_names_resolve_with_a_deprecation_warning_and_the_global_timings_are_gone():
    from fpm_sim.batch import jax_backend

    with pytest.warns(DeprecationWarning, match="jax_pose_frequencies"):
        old = jax_backend.mjx_pose_frequencies
    assert old is jax_backend.jax_pose_frequencies
    with pytest.warns(DeprecationWarning, match="BackendTimings"):
        assert jax_backend.MjxTimings is jax_backend.BackendTimings
    with pytest.raises(AttributeError, match="timings"):
        jax_backend.LAST_TIMINGS  # noqa: B018


def test_compile_cache_is_bounded_and_least_recently_used():
    from fpm_sim.batch.jax_backend import CompileCache

    cache = CompileCache(maxsize=2)
    made = []
    for key in ("a", "b", "a", "c", "b"):
        cache.get(key, lambda key=key: made.append(key) or key)
    # "a" was used again before "c" came, so "b" was dropped and had to be made again
    assert made == ["a", "b", "c", "b"]
    assert len(cache) == 2


def test_jax_backend_matches_cpu_backend_at_the_25_study_poses(reference_manip):
    config = reference_manip  # the geometry the tolerance was measured on (conftest)
    poses = [p.pose for p in study_poses()]
    opts = fast_options(segments=2)
    cpu = pose_frequencies(config, poses, backend="cpu", n_modes=6, options=opts)
    jax_ = pose_frequencies(config, poses, backend="jax", n_modes=6, options=opts)
    assert jax_.status == cpu.status
    ok = np.isfinite(cpu.frequencies_hz[:, 0])
    assert ok.sum() >= 24
    assert np.array_equal(np.isfinite(jax_.frequencies_hz), np.isfinite(cpu.frequencies_hz))
    # Both solve the same discrete eigenproblem (same M, K, weld Jacobian); they differ only in
    # round-off (SVD/Cholesky/eigh in XLA vs LAPACK through scipy). Measured: 1e-12 relative at 2
    # segments, 6e-10 at 6. The acceptance bound is 0.5 %; 1e-8 keeps the test sharp.
    np.testing.assert_allclose(jax_.frequencies_hz[ok], cpu.frequencies_hz[ok], rtol=1e-8)
    np.testing.assert_allclose(jax_.in_plane[ok], cpu.in_plane[ok], rtol=0, atol=1e-8)
    np.testing.assert_allclose(jax_.singularity, cpu.singularity, rtol=1e-12)


def test_smooth_terms_match_mujoco_away_from_qpos0_with_gravity_and_slides():
    """M, the generalised force and the weld Jacobian at a deformed configuration against C MuJoCo.

    The backend evaluates them at ``qpos0`` (no joint rotation), so this checks the joint formulas
    (hinge rotation about the anchor, slide translation) that the JAX derivatives go through.
    """
    import jax
    import mujoco

    from fpm_sim.batch import jax_linearisation as jl
    from fpm_sim.linear.equilibrium import equality_jacobian
    from fpm_sim.linear.matrices import mass_matrix
    from fpm_sim.model.manipulator import build_manipulator

    built = build_manipulator(default_config(), Pose(0.0, 0.0, 0.0), ModelOptions(segments=2, axial=True))
    model = built.model
    rng = np.random.default_rng(0)
    q = model.qpos0 + 0.05 * rng.standard_normal(model.nv) * np.where(model.jnt_type == 2, 0.01, 1.0)
    data = mujoco.MjData(model)
    data.qpos[:] = q
    mujoco.mj_forward(model, data)
    structure = jl.structure_of(model)
    p = jl.params_of(model)
    with jax.enable_x64(True):
        mass, force, jac, resid = jax.jit(lambda p, q: jl.smooth_terms(structure, p, q))(p, q)
    # Same formulas in float64 as MuJoCo's C code: agreement at round-off (measured ~1e-16 relative).
    m_ref = mass_matrix(model, data)
    np.testing.assert_allclose(mass, m_ref, rtol=0, atol=1e-12 * np.abs(m_ref).max())
    f_ref = data.qfrc_passive - data.qfrc_bias
    np.testing.assert_allclose(force, f_ref, rtol=0, atol=1e-11 * np.abs(f_ref).max())
    j_ref = equality_jacobian(model, data)
    np.testing.assert_allclose(jac, j_ref, rtol=0, atol=1e-12 * np.abs(j_ref).max())
    assert np.abs(resid).max() > 1e-4  # the deformation opens the welds: the residual is not trivial
    np.testing.assert_allclose(resid, data.efc_pos[: len(resid)], rtol=0, atol=1e-13)


def test_gradients_match_central_differences_of_the_cpu_path():
    from fpm_sim.batch.jax_backend import pose_frequency_gradients
    from fpm_sim.config import parameter_value, with_parameter

    config = default_config()
    poses = [Pose.from_mm(50.0, -50.0, 0.0), Pose.from_mm(-50.0, 0.0, 0.2)]
    opts = fast_options(segments=3)
    names = ["section.thickness_m", "material.young_pa", "hardware.platform.mass_kg"]
    grads = pose_frequency_gradients(config, poses, names, n_modes=6, options=opts)
    ref = pose_frequencies(config, poses, n_modes=6, options=opts).frequencies_hz
    for pose, grad, f_ref in zip(poses, grads, ref):
        assert grad.pose == pose
        np.testing.assert_allclose(grad.frequencies_hz, f_ref, rtol=1e-8)  # same eigenproblem (see above)
        assert (np.diff(f_ref) / f_ref[1:]).min() > 1e-3  # distinct modes: individual derivatives are defined
        for k, name in enumerate(names):
            v = parameter_value(config, name)
            h = 1e-4 * v
            up = pose_frequencies(with_parameter(config, name, v + h), [pose], n_modes=6, options=opts)
            down = pose_frequencies(with_parameter(config, name, v - h), [pose], n_modes=6, options=opts)
            fd = (up.frequencies_hz[0] - down.frequencies_hz[0]) / (2 * h)
            # The 1 % bound: central differences at a 1e-4 relative step have truncation error
            # ~1e-8 and round-off ~1e-9 relative; measured agreement 2e-8 .. 6e-5 (platform mass, pose 2).
            np.testing.assert_allclose(grad.gradient[:, k], fd, rtol=1e-2, atol=1e-6 * np.abs(fd).max())
        # E scales every spring: f ~ sqrt(E) exactly, so (E/f) df/dE = 1/2.
        np.testing.assert_allclose(grad.relative[:, 1], 0.5, rtol=1e-6)


def test_bad_input_is_refused_with_the_parameter_named():
    from fpm_sim.batch.jax_backend import frequency_gradients
    from fpm_sim.config import with_parameter

    config = default_config()
    with pytest.raises(ValueError, match="gravity"):
        pose_frequencies(config, [Pose(0, 0, 0)], backend="jax", options=ModelOptions(segments=2))
    with pytest.raises(ValueError, match=re.escape("section.width_m: unknown parameter: 'width_m'")):
        frequency_gradients(config, Pose(0, 0, 0), ["section.width_m"], options=fast_options(segments=2))
    with pytest.raises(ValueError, match="unknown parameter"):
        with_parameter(config, "hardware.nothing.mass_kg", 1.0)
    with pytest.raises(ValueError, match="moves the geometry"):
        frequency_gradients(config, Pose(0, 0, 0), ["geometry.proximal_length_m"], options=fast_options(segments=2))
    with pytest.raises(ValueError, match="unreachable"):
        frequency_gradients(config, Pose(1.0, 0.0, 0.0), options=fast_options(segments=2))


def test_sweep_paper_grid_with_jax_backend_writes_poses_csv_like_the_cpu_backend(tmp_path):
    import csv

    from fpm_sim.cli.main import main

    rows = {}
    for backend in ("cpu", "jax"):
        out = tmp_path / backend
        args = ["sweep", "--grid", "paper", "--segments", "2", "--backend", backend, "--out", str(out)]
        assert main(args) == 0
        with open(out / "poses.csv") as fh:
            rows[backend] = list(csv.DictReader(fh))
    assert len(rows["jax"]) == 25
    assert rows["jax"][0].keys() == rows["cpu"][0].keys()
    for a, b in zip(rows["cpu"], rows["jax"]):
        assert (a["x_mm"], a["y_mm"], a["phi_rad"], a["comsol_hz"]) == (
            b["x_mm"],
            b["y_mm"],
            b["phi_rad"],
            b["comsol_hz"],
        )
        for col in ("f1_hz", "f2_hz", "f3_hz"):
            # written with 6 decimals; the backends agree to ~1e-12 relative (see above)
            assert float(a[col]) == pytest.approx(float(b[col]), abs=2e-6)


def test_unknown_backend_is_a_user_error(capsys):
    from fpm_sim.cli.main import main

    assert main(["sweep", "--grid", "paper", "--segments", "2", "--backend", "gpu", "--out", "unused"]) == 2
    assert "--backend" in capsys.readouterr().err


@pytest.mark.slow
def test_linearise_with_gravity_and_geometric_term_matches_finite_differences_of_mujoco():
    """``K`` by ``jax.jacfwd`` (springs, gravity, constraint force) against central differences in C MuJoCo."""
    import jax
    import mujoco

    from fpm_sim.batch import jax_linearisation as jl
    from fpm_sim.linear.equilibrium import equality_jacobian
    from fpm_sim.model.manipulator import build_manipulator

    built = build_manipulator(default_config(), Pose(0.0, 0.0, 0.0), ModelOptions(segments=2, axial=False))
    model = built.model
    data = mujoco.MjData(model)
    q0 = model.qpos0.copy()

    def terms(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        data.qpos[:] = q
        mujoco.mj_forward(model, data)
        return data.qfrc_passive - data.qfrc_bias, equality_jacobian(model, data)

    f0, j0 = terms(q0)
    lam = np.linalg.lstsq(j0.T, -f0, rcond=None)[0]
    eps = 1e-6
    k_ref = np.zeros((model.nv, model.nv))
    for i in range(model.nv):
        dq = np.zeros(model.nv)
        dq[i] = eps
        fp, jp = terms(q0 + dq)
        fm, jm = terms(q0 - dq)
        k_ref[:, i] = -(fp - fm) / (2 * eps) - ((jp - jm) / (2 * eps)).T @ lam
    structure = jl.structure_of(model)
    with jax.enable_x64(True):
        _, k, _ = jax.jit(lambda p, q: jl.linearise(structure, p, q, geometric=True))(jl.params_of(model), q0)
    k = np.asarray(k)
    springs = np.diag(model.jnt_stiffness)
    # The springs are exact in both; the rest (gravity, constraint force) is small (~1e-4 of the springs)
    # and carries the finite-difference error of the reference (eps^2 truncation, 1e-16/eps round-off):
    # measured ~1e-10 of its size in the research notes. 1e-6 of the non-spring part's size bounds it.
    rest = k_ref - springs
    assert np.abs(rest).max() > 1e-8 * np.abs(springs).max()  # gravity and lam make a non-trivial term
    np.testing.assert_allclose(k - springs, rest, rtol=0, atol=1e-6 * np.abs(rest).max())
