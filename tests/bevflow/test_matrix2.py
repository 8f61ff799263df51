"""2 × 2 inverses, determinants and Mahalanobis lengths by hand, against numpy's, for any batch shape."""

from __future__ import annotations

import numpy as np
import pytest

from bevflow.matrix2 import determinant, inverse, mahalanobis2

RNG = np.random.default_rng(0)


@pytest.mark.parametrize("shape", [(0,), (1,), (5,), (3, 4), (2, 3, 2)])
def test_inverse_and_determinant_match_numpy(shape: tuple[int, ...]) -> None:
    a = RNG.normal(size=(*shape, 2, 2))
    m = a @ np.swapaxes(a, -1, -2) + 0.1 * np.eye(2)  # covariances, as the callers pass
    assert determinant(m).shape == shape and inverse(m).shape == m.shape
    np.testing.assert_allclose(determinant(m), np.linalg.det(m), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(inverse(m), np.linalg.inv(m) if m.size else m, rtol=1e-9, atol=1e-12)
    v = RNG.normal(size=(*shape, 2))
    expected = np.einsum("...i,...i->...", v, np.linalg.solve(m, v[..., None])[..., 0]) if m.size else np.zeros(shape)
    assert mahalanobis2(v, m).shape == shape
    np.testing.assert_allclose(mahalanobis2(v, m), expected, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(mahalanobis2(v, m, determinant(m)), expected, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize(
    ("m", "finite"),
    [
        ([[1.0, 2.0], [2.0, 4.0]], False),  # singular
        ([[np.nan, 0.0], [0.0, 1.0]], False),
        ([[2.0, 0.0], [0.0, 0.5]], True),
    ],
)
def test_a_singular_or_unknown_matrix_has_no_finite_inverse(m: list[list[float]], finite: bool) -> None:
    assert bool(np.isfinite(inverse(np.array([m]))).all()) is finite
