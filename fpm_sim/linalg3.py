"""Closed forms for stacks of 3x3 matrices: a determinant, the eigenvalues of a symmetric matrix, a matrix's
inverse condition number, and the smallest eigenvalue of a symmetric-definite pencil.

NumPy's batched ``linalg`` calls LAPACK once per matrix, and for 3x3 matrices that call is most of the cost: a
sampler's kinematics and in-plane surrogate spent a third of their time in ``svd`` and ``eigvals`` of ``(n, 3, 3)``
stacks. These are elementwise array expressions over the stack (the SVD's singular-value ratio seven times as fast,
the pencil's smallest eigenvalue twice).

Accuracy. The eigenvalues come from the trigonometric roots of the characteristic cubic (Smith 1961), which place
the largest to round-off of the matrix's norm. A small eigenvalue computed that way keeps only an absolute accuracy
of ``eps |A|``, so where the smallest is under 1 % of the largest it is taken instead from the two smaller ones' sum
(the trace less the largest) and product (the determinant over the largest), with the determinant from the caller
where it has a better one (``det(J)^2`` for ``J^T J``): a small eigenvalue then keeps its relative accuracy. Where two
eigenvalues coincide, a cubic's roots are right only to ``sqrt(eps)`` of the matrix's norm (~1e-8): enough for a
singularity measure, not for a frequency, so the pencil's smallest eigenvalue uses LAPACK's symmetric solver on the
closed-form reduction. Measured against LAPACK in ``tests/test_linalg3.py``.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["det3", "inverse_condition3", "smallest_generalized_eigenvalue3", "symmetric_eigenvalues3"]

_SMALL = 1e-2
"""Below this fraction of the largest eigenvalue, the smallest is taken from the determinant (module docstring)."""


def det3(a: np.ndarray) -> np.ndarray:
    """``(...)`` the determinants of ``(..., 3, 3)`` matrices by cofactors (absolute error ~ ``eps |a|^3``)."""
    out: np.ndarray = (
        a[..., 0, 0] * (a[..., 1, 1] * a[..., 2, 2] - a[..., 1, 2] * a[..., 2, 1])
        - a[..., 0, 1] * (a[..., 1, 0] * a[..., 2, 2] - a[..., 1, 2] * a[..., 2, 0])
        + a[..., 0, 2] * (a[..., 1, 0] * a[..., 2, 1] - a[..., 1, 1] * a[..., 2, 0])
    )
    return out


def symmetric_eigenvalues3(
    a: np.ndarray, *, det: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(largest, middle, smallest)`` eigenvalues of symmetric positive semi-definite ``(..., 3, 3)`` matrices (only
    the upper triangle is read). ``det``: their determinants where the caller has them more accurately than
    cofactors of ``a`` (module docstring)."""
    q = np.trace(a, axis1=-2, axis2=-1) / 3.0
    a01, a02, a12 = a[..., 0, 1], a[..., 0, 2], a[..., 1, 2]
    b00, b11, b22 = a[..., 0, 0] - q, a[..., 1, 1] - q, a[..., 2, 2] - q
    p = np.sqrt((b00**2 + b11**2 + b22**2 + 2.0 * (a01**2 + a02**2 + a12**2)) / 6.0)
    det_b = b00 * (b11 * b22 - a12**2) - a01 * (a01 * b22 - a12 * a02) + a02 * (a01 * a12 - b11 * a02)
    if det is None:
        det = det3(a)
    with np.errstate(invalid="ignore", divide="ignore"):
        phi = np.arccos(np.clip(det_b / (2.0 * p**3), -1.0, 1.0)) / 3.0
        big = np.where(p > 0, q + 2.0 * p * np.cos(phi), q)  # p = 0: a multiple of the identity
        trig = np.where(p > 0, q + 2.0 * p * np.cos(phi + 2.0 * math.pi / 3.0), q)
        half = 0.5 * (3.0 * q - big)  # (middle + smallest) / 2
        prod = np.maximum(det, 0.0) / big  # middle * smallest
        mid = half + np.sqrt(np.maximum(half**2 - prod, 0.0))
        small = np.where(trig > _SMALL * big, trig, np.where(mid > 0, prod / mid, 0.0))
    return big, 3.0 * q - big - small, small


def inverse_condition3(j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(sigma_min / sigma_max, det)`` of ``(..., 3, 3)`` matrices (``1`` for a zero matrix), from the eigenvalues
    of ``J^T J`` with ``det(J)^2`` (module docstring): ~1e-11 relative for a ratio above 1e-5, 1e-15 absolute
    below it, ~1e-7 relative where two singular values coincide (measured)."""
    det_j = det3(j)
    big, _, small = symmetric_eigenvalues3(np.matmul(np.swapaxes(j, -1, -2), j), det=det_j**2)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.where(big > 0, np.sqrt(np.maximum(small, 0.0) / big), 1.0)
    return ratio, det_j


def smallest_generalized_eigenvalue3(k: np.ndarray, m: np.ndarray) -> np.ndarray:
    """``(...)`` the smallest ``lambda`` of ``K x = lambda M x`` for symmetric positive semi-definite ``K`` and
    positive definite ``M`` (``(..., 3, 3)``; NaN where ``M`` is not): the symmetric ``L^-1 K L^-T`` with ``M = L
    L^T`` (Cholesky in closed form) and LAPACK's symmetric eigenvalues (half the cost of ``eigvals(solve(M, K))``;
    the cubic's roots would lose half the digits of the double root that a symmetric pose gives)."""
    m00, m10, m20, m11, m21, m22 = m[..., 0, 0], m[..., 1, 0], m[..., 2, 0], m[..., 1, 1], m[..., 2, 1], m[..., 2, 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        l00 = np.sqrt(m00)
        l10, l20 = m10 / l00, m20 / l00
        l11 = np.sqrt(m11 - l10**2)
        l21 = (m21 - l20 * l10) / l11
        l22 = np.sqrt(m22 - l20**2 - l21**2)
        inv = np.zeros(m.shape)  # L^-1, lower triangular
        inv[..., 0, 0], inv[..., 1, 1], inv[..., 2, 2] = 1.0 / l00, 1.0 / l11, 1.0 / l22
        inv[..., 1, 0] = -l10 / (l00 * l11)
        inv[..., 2, 1] = -l21 / (l11 * l22)
        inv[..., 2, 0] = (l10 * l21 - l11 * l20) / (l00 * l11 * l22)
        c = np.matmul(np.matmul(inv, k), np.swapaxes(inv, -1, -2))
    ok = np.all(np.isfinite(c), axis=(-2, -1))
    out = np.full(ok.shape, np.nan)
    out[ok] = np.linalg.eigvalsh(c[ok])[..., 0]  # LAPACK: exact where the two smallest coincide (a symmetric pose)
    return out
