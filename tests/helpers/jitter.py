"""Another machine's round-off, imitated (issue 32, item 0): a decision a test asserts (a stable pole, a rank, which
mode is which near a repeated pair) must not flip when its input moves by far more than any BLAS kernel rounds.

A test runs the decision on its input and on the input jittered at :data:`JITTER_RTOL` relative with each of
:data:`JITTER_SEEDS` (``np.random.default_rng(seed)``), and asserts the same outcome. :func:`jitter` moves each entry
relative to itself, so exact zeros stay zero and the structure a method relies on (decoupled planes, block-diagonal
matrices) is kept; :func:`jitter_dense` moves every entry relative to the scale of its row and column, as rounding
inside a dense factorisation does: it couples what was exactly decoupled, so the basis of a degenerate pair comes
out arbitrary, as another kernel may return it.
"""

from __future__ import annotations

import numpy as np

JITTER_RTOL = 1e-12
"""Relative size of the jitter: 10^4 times double precision's unit round-off, and above what a different BLAS
kernel's summation order changes in the tests' matrices (a few ulps times the dimension)."""

JITTER_SEEDS = (1, 2, 3)
"""The fixed seeds a jittered test runs with (``None`` in a parametrisation: the input as it is)."""


def jitter(a: np.ndarray, seed: int, rtol: float = JITTER_RTOL) -> np.ndarray:
    """``a`` with every entry multiplied by ``1 + rtol * N(0, 1)``, seeded (complex entries keep their phase)."""
    a = np.asarray(a)
    return a * (1.0 + rtol * np.random.default_rng(seed).standard_normal(a.shape))


def jitter_symmetric(a: np.ndarray, seed: int, rtol: float = JITTER_RTOL) -> np.ndarray:
    """:func:`jitter` of a symmetric matrix that stays symmetric (the same factor on ``a_ij`` and ``a_ji``)."""
    a = np.asarray(a, float)
    e = np.random.default_rng(seed).standard_normal(a.shape)
    return a * (1.0 + rtol * 0.5 * (e + e.T))


def jitter_dense(a: np.ndarray, seed: int, rtol: float = JITTER_RTOL) -> np.ndarray:
    """``a`` plus ``rtol * sqrt(r_i c_j) * N(0, 1)`` on every entry, seeded, with ``r_i`` and ``c_j`` the largest
    magnitudes of row ``i`` and column ``j``: rounding of the size a balanced dense eigen-solve commits (LAPACK
    scales rows and columns first), which fills exact zeros and so couples exactly decoupled blocks."""
    a = np.asarray(a, float)
    scale = np.sqrt(np.outer(np.max(np.abs(a), axis=1), np.max(np.abs(a), axis=0)))
    return a + rtol * scale * np.random.default_rng(seed).standard_normal(a.shape)
