"""The constant-velocity Kalman filter against hand-computed steps and a straight-line walk."""

from __future__ import annotations

import numpy as np
import pytest

from bevflow.tracking.kalman import ConstantVelocityKalman, smooth


def _axis_cov(pos_pos: float, pos_vel: float, vel_vel: float) -> np.ndarray:
    """A (1, 4, 4) covariance with the same 2x2 block on both axes and no X-Y coupling."""
    p = np.zeros((1, 4, 4))
    for axis in (0, 1):
        p[0, axis, axis], p[0, axis + 2, axis + 2] = pos_pos, vel_vel
        p[0, axis, axis + 2] = p[0, axis + 2, axis] = pos_vel
    return p


def test_initiate_starts_at_rest_with_prior_variances() -> None:
    kf = ConstantVelocityKalman(measurement_std_m=0.2, initial_speed_std_mps=1.5)
    x, p = kf.initiate(np.array([[1.0, 2.0], [3.0, 4.0]]))
    np.testing.assert_array_equal(x, [[1, 2, 0, 0], [3, 4, 0, 0]])
    np.testing.assert_allclose(p[1], np.diag([0.04, 0.04, 2.25, 2.25]))


@pytest.mark.parametrize(
    ("dt", "q", "state", "cov", "expected_state", "expected_cov"),
    [
        # F P F^T with P = I and dt = 2 is [[5, 2], [2, 1]]; Q = 0.3 [[8/3, 2], [2, 2]].
        pytest.param(
            2.0, 0.3, [1, 2, 0.5, -1], _axis_cov(1, 0, 1), [2, 0, 0.5, -1], _axis_cov(5.8, 2.6, 1.6), id="dt-2"
        ),
        pytest.param(
            0.0, 0.3, [1, 2, 0.5, -1], _axis_cov(1, 0.5, 2), [1, 2, 0.5, -1], _axis_cov(1, 0.5, 2), id="dt-0-unchanged"
        ),
        # dt = 0.5, q = 0: P' = [[1 + 2·0.5·0.5 + 0.25·2, 0.5 + 0.5·2], [.., 2]] = [[2, 1.5], [1.5, 2]].
        pytest.param(
            0.5, 0.0, [0, 0, 2, 4], _axis_cov(1, 0.5, 2), [1, 2, 2, 4], _axis_cov(2, 1.5, 2), id="no-process-noise"
        ),
    ],
)
def test_predict_hand_computed(dt, q, state, cov, expected_state, expected_cov) -> None:
    kf = ConstantVelocityKalman(process_noise=q)
    x, p = kf.predict(np.array([state], float), cov, dt)
    np.testing.assert_allclose(x, [expected_state], atol=1e-12)
    np.testing.assert_allclose(p, expected_cov, atol=1e-12)


@pytest.mark.parametrize(
    ("cov", "z", "std", "expected_state", "expected_cov"),
    [
        # P = I, R = I: gain 1/2 on position, none on velocity.
        pytest.param(_axis_cov(1, 0, 1), [1, 2], 1.0, [0.5, 1, 0, 0], _axis_cov(0.5, 0, 1), id="uncorrelated"),
        # Per axis P = [[2, 1], [1, 3]], R = 1: S = 3, K = [2/3, 1/3]; innovation 3 on X, 0 on Y.
        # P' = P - K S K^T = [[2/3, 1/3], [1/3, 8/3]].
        pytest.param(_axis_cov(2, 1, 3), [3, 0], 1.0, [2, 0, 1, 0], _axis_cov(2 / 3, 1 / 3, 8 / 3), id="correlated"),
        # A near-exact measurement replaces the position.
        pytest.param(_axis_cov(1, 0, 1), [1, 2], 1e-6, [1, 2, 0, 0], _axis_cov(1e-12, 0, 1), id="exact-measurement"),
    ],
)
def test_update_hand_computed(cov, z, std, expected_state, expected_cov) -> None:
    kf = ConstantVelocityKalman(measurement_std_m=std)
    x, p = kf.update(np.zeros((1, 4)), cov, np.array([z], float))
    np.testing.assert_allclose(x, [expected_state], atol=1e-9)
    np.testing.assert_allclose(p, expected_cov, atol=1e-9)


def test_update_takes_a_measurement_std_per_track() -> None:
    kf = ConstantVelocityKalman(measurement_std_m=100.0)
    x, _ = kf.update(np.zeros((2, 4)), np.concatenate([_axis_cov(1, 0, 1)] * 2), np.ones((2, 2)), np.array([1.0, 3.0]))
    np.testing.assert_allclose(x[:, 0], [0.5, 0.1])  # gains 1/(1+1) and 1/(1+9)


def test_update_takes_a_full_measurement_covariance_per_track() -> None:
    # R = diag(1, 9) against P = I: gains 1/2 on X and 1/10 on Y; a diagonal R equals the std path
    kf = ConstantVelocityKalman(measurement_std_m=100.0)
    prior = np.concatenate([_axis_cov(1, 0, 1)] * 2)
    r = np.array([np.diag([1.0, 9.0]), np.eye(2)])
    x, p = kf.update(np.zeros((2, 4)), prior, np.ones((2, 2)), measurement_covariance=r)
    np.testing.assert_allclose(x[:, :2], [[0.5, 0.1], [0.5, 0.5]])
    np.testing.assert_allclose(p[:, [0, 1], [0, 1]], [[0.5, 0.9], [0.5, 0.5]])
    same, _ = kf.update(np.zeros((1, 4)), prior[:1], np.ones((1, 2)), np.array([1.0]))
    np.testing.assert_allclose(x[1], same[0])


def test_one_long_step_equals_two_half_steps() -> None:
    kf = ConstantVelocityKalman(process_noise=0.7)
    x0, p0 = np.array([[1.0, -2.0, 0.3, 0.9]]), _axis_cov(0.4, 0.1, 0.8)
    x1, p1 = kf.predict(x0, p0, 1.0)
    x2, p2 = kf.predict(*kf.predict(x0, p0, 0.5), 0.5)
    np.testing.assert_allclose(x1, x2)
    np.testing.assert_allclose(p1, p2)


def test_predict_takes_one_dt_per_track() -> None:
    kf = ConstantVelocityKalman(process_noise=0.0)
    state = np.array([[0, 0, 1, 0], [0, 0, 1, 0]], float)
    x, _ = kf.predict(state, np.concatenate([_axis_cov(1, 0, 1)] * 2), np.array([0.1, 2.0]))
    np.testing.assert_allclose(x[:, 0], [0.1, 2.0])


def test_predict_rejects_negative_dt() -> None:
    with pytest.raises(ValueError, match="negative"):
        ConstantVelocityKalman().predict(np.zeros((1, 4)), _axis_cov(1, 0, 1), -0.1)


@pytest.mark.parametrize(("fps", "noise_m"), [(10.0, 0.0), (10.0, 0.1), (2.0, 0.1)])
def test_straight_line_walk_recovers_velocity(fps: float, noise_m: float) -> None:
    rng = np.random.default_rng(1)
    velocity = np.array([1.2, -0.5])
    kf = ConstantVelocityKalman(process_noise=0.05, measurement_std_m=max(noise_m, 0.01))
    times = np.arange(200) / fps
    truth = np.array([3.0, 4.0]) + times[:, None] * velocity
    measured = truth + rng.normal(0, noise_m, truth.shape)
    x, p = kf.initiate(measured[:1])
    errors = []
    for k in range(1, len(times)):
        x, p = kf.predict(x, p, times[k] - times[k - 1])
        x, p = kf.update(x, p, measured[k : k + 1])
        errors.append(np.linalg.norm(x[0, :2] - truth[k]))
    if noise_m:
        # The error stays within what the filter itself claims (3 σ of its velocity variance).
        np.testing.assert_array_less(np.abs(x[0, 2:] - velocity), 3 * np.sqrt(np.diag(p[0])[2:]))
        np.testing.assert_allclose(x[0, 2:], velocity, atol=0.2)
        # Filtering beats the raw measurements once the velocity is known.
        raw = np.linalg.norm(measured[100:] - truth[100:], axis=1).mean()
        assert np.mean(errors[99:]) < 0.9 * raw
    else:
        np.testing.assert_allclose(x[0, 2:], velocity, atol=1e-3)
        assert errors[-1] < 1e-3
    assert np.allclose(p, p.transpose(0, 2, 1)) and np.all(np.linalg.eigvalsh(p) > 0)


@pytest.mark.parametrize(
    ("previous", "measured", "weight", "expected"), [(1.7, 1.5, 0.25, 1.65), (0.3, 0.5, 1.0, 0.5), (0.3, 0.5, 0.0, 0.3)]
)
def test_smooth(previous, measured, weight, expected) -> None:
    assert smooth(np.array([previous]), np.array([measured]), weight)[0] == pytest.approx(expected)
