"""Batches of 2 × 2 matrices (floor covariances and their sums), worked by hand: numpy's batched
``linalg.inv`` and ``linalg.det`` cost more than everything else in a tracker update of 1,000
people, for matrices this small.

>>> m = np.array([[[4.0, 1.0], [1.0, 2.0]]])
>>> determinant(m).tolist(), (inverse(m) @ m).round(12).tolist(), mahalanobis2(np.array([[2.0, 0.0]]), m).round(12).tolist()
([7.0], [[[1.0, 0.0], [0.0, 1.0]]], [1.142857142857])
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def determinant(m: FloatArray) -> FloatArray:
    """Determinants of (..., 2, 2) matrices."""
    result: FloatArray = m[..., 0, 0] * m[..., 1, 1] - m[..., 0, 1] * m[..., 1, 0]
    return result


def inverse(m: FloatArray, det: FloatArray | None = None) -> FloatArray:
    """Inverses of (..., 2, 2) matrices; non-finite where a matrix is singular or not finite.
    ``det``: their determinants, where the caller has them already."""
    a, b, c, d = m[..., 0, 0], m[..., 0, 1], m[..., 1, 0], m[..., 1, 1]
    det = determinant(m) if det is None else det
    with np.errstate(invalid="ignore", divide="ignore"):
        inv = np.empty_like(m)
        inv[..., 0, 0], inv[..., 0, 1], inv[..., 1, 0], inv[..., 1, 1] = d / det, -b / det, -c / det, a / det
    return inv


def mahalanobis2(offset: FloatArray, m: FloatArray, det: FloatArray | None = None) -> FloatArray:
    """Squared Mahalanobis lengths of (..., 2) offsets under (..., 2, 2) covariances: offsetᵀ m⁻¹
    offset. ``det`` as for ``inverse``."""
    d2: FloatArray = np.einsum("...i,...ij,...j->...", offset, inverse(m, det), offset)
    return d2
