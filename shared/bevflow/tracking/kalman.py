"""A constant-velocity Kalman filter on the floor, vectorised over many tracks.

State per track: (X, Y, vX, vY) in metres and metres per second; covariance (4, 4). Arrays
hold every track at once: states (T, 4), covariances (T, 4, 4), so one call predicts or
updates the whole site. Time steps may differ between calls and between tracks (a track that
was missed for a while has coasted longer), and ``dt = 0`` leaves a track unchanged.

The paper predicts with constant velocity (constant acceleration was tried and rejected:
crowds move chaotically). Unmodelled changes of velocity are continuous white-noise
acceleration with spectral density ``q`` (m²/s³), which gives, per axis and step ``dt``,

    F = [[1, dt], [0, 1]],  Q = q · [[dt³/3, dt²/2], [dt²/2, dt]]

so the uncertainty added by a step depends only on its length, not on how it is cut into
steps. The measurement is the feet position (X, Y) with isotropic noise σ (m).

Height and radius barely change and are not needed for association, so they are smoothed
with an exponential moving average (:func:`smooth`) rather than carried in the state.

>>> kf = ConstantVelocityKalman(process_noise=0.5, measurement_std_m=0.1, initial_speed_std_mps=1.0)
>>> x, p = kf.initiate(np.array([[0.0, 0.0]]))
>>> x, p = kf.predict(x, p, 0.5)
>>> x, p = kf.update(x, p, np.array([[0.5, 0.0]]))
>>> bool(x[0, 2] > 0.5)  # moving along +X after one observation of motion
True
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from bevflow.matrix2 import inverse

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ConstantVelocityKalman:
    """Noise settings of the filter; the methods are pure functions of arrays.

    ``process_noise``: white-noise acceleration density q (m²/s³).
    ``measurement_std_m``: standard deviation of a measured feet position, per axis.
    ``initial_speed_std_mps``: prior standard deviation of a new track's velocity, per axis
    (a new track starts at rest, so this covers walking speed)."""

    process_noise: float = 1.0
    measurement_std_m: float = 0.15
    initial_speed_std_mps: float = 1.0

    def initiate(self, xy: FloatArray) -> tuple[FloatArray, FloatArray]:
        """New tracks at the measured positions ``xy`` (N, 2), at rest."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        n = len(xy)
        state = np.zeros((n, 4))
        state[:, :2] = xy
        variance = np.array([self.measurement_std_m**2] * 2 + [self.initial_speed_std_mps**2] * 2)
        covariance = np.zeros((n, 4, 4))
        covariance[:, np.arange(4), np.arange(4)] = variance
        return state, covariance

    def predict(
        self, state: FloatArray, covariance: FloatArray, dt: float | FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """States and covariances ``dt`` seconds later (``dt`` scalar or one per track)."""
        n = len(state)
        dt = np.broadcast_to(np.asarray(dt, dtype=np.float64), (n,))
        if np.any(dt < 0):
            raise ValueError("dt must not be negative")
        state = state.copy()
        state[:, :2] += dt[:, None] * state[:, 2:]
        # F P F^T with F = I + dt·E (E moves velocity into position), as two row/column shifts:
        # cheaper than batched 4x4 products for thousands of tracks.
        step = dt[:, None, None]
        fp = covariance.copy()
        fp[:, :2, :] += step * covariance[:, 2:, :]
        fpf = fp.copy()
        fpf[:, :, :2] += step * fp[:, :, 2:]
        q = self.process_noise
        pos, cross, vel = q * dt**3 / 3.0, q * dt**2 / 2.0, q * dt
        for p, v in ((0, 2), (1, 3)):
            fpf[:, p, p] += pos
            fpf[:, p, v] += cross
            fpf[:, v, p] += cross
            fpf[:, v, v] += vel
        return state, fpf

    def update(
        self,
        state: FloatArray,
        covariance: FloatArray,
        xy: FloatArray,
        measurement_std_m: float | FloatArray | None = None,
        measurement_covariance: FloatArray | None = None,
    ) -> tuple[FloatArray, FloatArray]:
        """Correct each track with its measured feet position ``xy`` (N, 2).

        ``measurement_std_m`` overrides the filter's own, as a scalar or one per track;
        ``measurement_covariance`` (N, 2, 2), m², replaces both with each measurement's own."""
        innovation = np.asarray(xy, dtype=np.float64).reshape(-1, 2) - state[:, :2]
        if measurement_covariance is not None:
            s = covariance[:, :2, :2] + np.asarray(measurement_covariance, dtype=np.float64).reshape(-1, 2, 2)
        else:
            std = self.measurement_std_m if measurement_std_m is None else measurement_std_m
            r = np.broadcast_to(np.asarray(std, dtype=np.float64) ** 2, (len(state),))
            s = covariance[:, :2, :2].copy()
            s[:, 0, 0] += r
            s[:, 1, 1] += r
        gain = covariance[:, :, :2] @ inverse(s)  # (N, 4, 2)
        state = state + np.einsum("nij,nj->ni", gain, innovation)
        # P - K H P, symmetrised so rounding never lets it drift from symmetric.
        covariance = covariance - gain @ covariance[:, :2, :]
        covariance = 0.5 * (covariance + covariance.transpose(0, 2, 1))
        return state, covariance


def smooth(previous: FloatArray, measured: FloatArray, weight: float) -> FloatArray:
    """Exponential moving average: ``weight`` is the share given to the new measurement."""
    return (1.0 - weight) * np.asarray(previous, dtype=np.float64) + weight * np.asarray(measured, dtype=np.float64)
