"""Time as a source of error (uncertainty/timing.py): the clock's term sigma_t^2 (v v^T + P_v) and the prediction
to a message's time, checked by hand, by seeded Monte Carlo and by central differences."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from footprint_uq.errors import InputError
from footprint_uq.uncertainty.timing import clock_sigma_s, dcov_dv, predict_position, timing_covariance


def test_by_hand():
    # 10 m/s east, 10 ms of clock error: 0.1 m along the motion, nothing across it
    c = timing_covariance([10.0, 0.0], np.zeros((2, 2)), 0.01)
    assert c == pytest.approx(np.array([[0.01, 0.0], [0.0, 0.0]]), abs=1e-15)
    assert clock_sigma_s(0.003, 0.004) == pytest.approx(0.005)
    xy, cov = predict_position([1.0, 2.0], np.eye(2) * 0.04, [3.0, -4.0], np.eye(2) * 0.25, 0.2)
    assert xy == pytest.approx([1.6, 1.2])
    assert cov == pytest.approx(np.eye(2) * (0.04 + 0.04 * 0.25))


def test_monte_carlo_prediction_with_clock_error():
    rng = np.random.default_rng(20261128)
    p, v = np.array([5.0, -3.0]), np.array([8.0, 6.0])
    A = rng.normal(size=(4, 4))
    S = A @ A.T * 0.05 + np.diag([0.02, 0.03, 0.4, 0.3])   # joint covariance of (p, v)
    tau, sigma_t = 0.35, 0.02
    n = 400_000
    pv = rng.multivariate_normal(np.concatenate([p, v]), S, size=n)
    dt = rng.normal(0.0, sigma_t, size=n)
    moved = pv[:, :2] + pv[:, 2:] * (tau + dt)[:, None]
    xy, cov = predict_position(p, S[:2, :2], v, S[2:, 2:], tau, cov_xv_m2ps=S[:2, 2:], sigma_t_s=sigma_t)
    mc = np.cov(moved.T)
    assert moved.mean(0) == pytest.approx(xy, abs=4 * np.sqrt(np.diag(cov) / n).max())
    # sampling error of a covariance entry ~ sqrt((c_ii c_jj + c_ij^2) / n)
    se = np.sqrt((np.outer(np.diag(mc), np.diag(mc)) + mc ** 2) / n)
    assert np.all(np.abs(mc - cov) < 4.5 * se), (mc, cov)
    # without the clock term the same Monte Carlo disagrees (the test can fail)
    _, cov0 = predict_position(p, S[:2, :2], v, S[2:, 2:], tau, cov_xv_m2ps=S[:2, 2:])
    assert np.any(np.abs(mc - cov0) > 10 * se)


def test_jacobian_against_central_differences():
    rng = np.random.default_rng(5)
    for _ in range(20):
        v, s = rng.normal(0, 10, 2), abs(rng.normal(0, 0.05))
        J = dcov_dv(v, s)
        h = 1e-5
        for k in range(2):
            e = np.zeros(2)
            e[k] = h
            z = np.zeros((2, 2))
            fd = (timing_covariance(v + e, z, s) - timing_covariance(v - e, z, s)) / (2 * h)
            assert J[..., k] == pytest.approx(fd, rel=1e-7, abs=1e-12)


@settings(max_examples=100, deadline=None)
@given(shape=st.sampled_from([(), (3,), (2, 4)]), seed=st.integers(0, 2**32 - 1))
def test_broadcasts_over_leading_dimensions_and_stays_psd(shape, seed):
    rng = np.random.default_rng(seed)
    v = rng.normal(0, 20, shape + (2,))
    B = rng.normal(size=shape + (2, 2))
    P = B @ np.swapaxes(B, -1, -2)
    s = rng.uniform(0, 0.1, shape)
    c = timing_covariance(v, P, s)
    assert c.shape == shape + (2, 2)
    assert np.all(np.linalg.eigvalsh(c) >= -1e-12 * (1 + np.abs(c).max()))
    flat = c.reshape(-1, 2, 2)
    for i, (vi, Pi, si) in enumerate(zip(v.reshape(-1, 2), P.reshape(-1, 2, 2), s.reshape(-1), strict=True)):
        assert flat[i] == pytest.approx(si ** 2 * (np.outer(vi, vi) + Pi), rel=1e-12, abs=1e-15)


def test_bad_input_is_named_and_unknown_motion_stays_unknown():
    for args, name in [(([1.0, 0.0], np.zeros((2, 2)), float("nan")), "sigma_t_s"),
                       (([1.0, 0.0], np.zeros((2, 2)), -0.1), "sigma_t_s"),
                       (([1.0, 0.0, 2.0], np.zeros((2, 2)), 0.1), "v_mps"),
                       (([1.0, 0.0], np.zeros((3, 3)), 0.1), "cov_v_m2ps2")]:
        with pytest.raises(InputError, match=name):
            timing_covariance(*args)
    for kw in ({"clock_offset_sigma_s": float("nan")}, {"clock_jitter_sigma_s": -1.0},
               {"clock_offset_sigma_s": "abc"}):
        with pytest.raises(InputError, match=next(iter(kw))):
            clock_sigma_s(**kw)
    with pytest.raises(InputError, match="tau_s"):
        predict_position([0, 0], np.eye(2), [1, 1], np.eye(2), float("inf"))
    assert np.all(np.isnan(timing_covariance([np.nan, 1.0], np.eye(2), 0.01)[0]))
