"""The closed forms of :mod:`fpm_sim.linalg3` against LAPACK (numpy's ``svd``, ``eigvalsh``, ``eigvals``).

Tolerances follow from the method: the largest eigenvalue of the cubic's trigonometric roots is right to a few
``eps`` of the matrix's norm; a small one taken from the determinant keeps a relative accuracy of a few ``eps``
times the ratio of the determinant's magnitude to its terms' (a well-conditioned ``J``: ~1e-12 relative, allowed
1e-9). Where two eigenvalues of ``J^T J`` coincide, a root of the cubic (or of the quadratic for the smaller pair)
moves by ``sqrt(eps |A| / lambda)`` for an ``eps`` change of the coefficients: ~1e-8 relative of the singular-value
ratio at the ratios tested, allowed 1e-6."""

from __future__ import annotations

import numpy as np
import pytest

from fpm_sim.linalg3 import det3, inverse_condition3, smallest_generalized_eigenvalue3, symmetric_eigenvalues3


def _with_singular_values(n: int, s: np.ndarray, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    u, _, vt = np.linalg.svd(rng.standard_normal((n, 3, 3)))
    return np.einsum("nij,nj,njk->nik", u, s, vt)


def _ratio_svd(j: np.ndarray) -> np.ndarray:
    sv = np.linalg.svd(j, compute_uv=False)
    return sv[:, -1] / sv[:, 0]


def test_determinant_is_lapacks() -> None:
    j = np.random.default_rng(0).standard_normal((2000, 3, 3))
    np.testing.assert_allclose(det3(j), np.linalg.det(j), rtol=1e-12, atol=1e-13)


def test_symmetric_eigenvalues_are_lapacks_in_order() -> None:
    j = np.random.default_rng(1).standard_normal((2000, 3, 3))
    a = j @ np.swapaxes(j, 1, 2)
    big, mid, small = symmetric_eigenvalues3(a)
    ref = np.linalg.eigvalsh(a)
    scale = ref[:, 2:]
    np.testing.assert_allclose(np.column_stack([small, mid, big]) / scale, ref / scale, rtol=0, atol=1e-12)


@pytest.mark.parametrize("ratio", [1.0, 0.3, 1e-2, 1e-3, 1e-5, 1e-8])
def test_inverse_condition_keeps_relative_accuracy_near_a_singularity(ratio: float) -> None:
    s = np.column_stack([np.full(500, 2.0), np.linspace(0.5, 2.0, 500), np.full(500, 2.0 * ratio)])
    s[:, 2] = np.minimum(s[:, 2], s[:, 1])
    j = _with_singular_values(500, s, seed=2)
    got, det = inverse_condition3(j)
    ref = _ratio_svd(j)
    # the SVD's own error is ~eps |J| absolute: 1e-15 against a ratio of 1e-8 is 1e-7 of it
    coincide = np.isclose(s[:, 1], s[:, 2], rtol=1e-3) | np.isclose(s[:, 0], s[:, 1], rtol=1e-3)
    np.testing.assert_allclose(got[~coincide], ref[~coincide], rtol=1e-9 if ratio >= 1e-5 else 1e-6, atol=1e-15)
    np.testing.assert_allclose(got[coincide], ref[coincide], rtol=1e-6, atol=1e-15)
    np.testing.assert_allclose(det, np.linalg.det(j), rtol=1e-9, atol=1e-15)


def test_inverse_condition_where_the_two_smaller_singular_values_coincide() -> None:
    j = _with_singular_values(500, np.tile([2.0, 0.1, 0.1], (500, 1)), seed=3)
    np.testing.assert_allclose(inverse_condition3(j)[0], _ratio_svd(j), rtol=1e-6)


def test_inverse_condition_of_a_zero_and_of_an_isotropic_matrix() -> None:
    j = np.stack([np.zeros((3, 3)), 2.0 * np.eye(3)])
    np.testing.assert_array_equal(inverse_condition3(j)[0], [1.0, 1.0])


def test_smallest_generalized_eigenvalue_is_lapacks() -> None:
    rng = np.random.default_rng(4)
    jk, jm = rng.standard_normal((2, 2000, 3, 3))
    k = jk @ np.swapaxes(jk, 1, 2)
    m = jm @ np.swapaxes(jm, 1, 2) + 0.1 * np.eye(3)
    ev = np.linalg.eigvals(np.linalg.solve(m, k)).real
    ref, largest = ev.min(axis=1), ev.max(axis=1)
    # absolute error ~ eps times the pencil's largest eigenvalue, times M's condition (up to ~1e4 here)
    np.testing.assert_allclose(smallest_generalized_eigenvalue3(k, m), ref, rtol=1e-9, atol=1e-10 * largest.max())


def test_smallest_generalized_eigenvalue_of_a_double_root_is_exact() -> None:
    k = np.diag([2.0, 2.0, 7.0])[None]
    m = np.diag([1.0, 1.0, 3.0])[None]
    np.testing.assert_allclose(smallest_generalized_eigenvalue3(k, m), [2.0], rtol=1e-15)


def test_smallest_generalized_eigenvalue_of_a_nearly_singular_stiffness() -> None:
    rng = np.random.default_rng(5)
    k = _with_singular_values(500, np.tile([3.0, 1.0, 1e-7], (500, 1)), seed=6)
    k = k @ np.swapaxes(k, 1, 2)  # eigenvalues 9, 1, 1e-14
    m = np.eye(3) + 0.1 * np.einsum("ni,nj->nij", *rng.standard_normal((2, 500, 3))).clip(-0.3, 0.3)
    m = 0.5 * (m + np.swapaxes(m, 1, 2))
    ref = np.linalg.eigvalsh(
        np.linalg.solve(np.linalg.cholesky(m), np.linalg.solve(np.linalg.cholesky(m), k).swapaxes(1, 2))
    )[:, 0]
    got = smallest_generalized_eigenvalue3(k, m)
    # both are LAPACK's symmetric solver, on reductions of M in two ways: ~eps * 9 absolute apart
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-14)
    assert np.all(got > 0)
