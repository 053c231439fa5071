"""Camera orientation: R_W_C is a rotation, the angle round trip (gimbal included), derivatives."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from footprint_uq.cameras.rotation import R_G_P, R_P_C, R_W_C, R_W_G, dR_W_C, pan_tilt_roll_from_R_W_C


def _random_angles(rng, n):
    pan = rng.uniform(-np.pi, np.pi, n)
    tilt = rng.uniform(-np.pi / 2 + 1e-3, np.pi / 2 - 1e-3, n)
    roll = rng.uniform(-np.pi + 1e-3, np.pi - 1e-3, n)
    return pan, tilt, roll


def test_is_a_rotation(rng):
    R = R_W_C(*_random_angles(rng, 200))
    assert R.shape == (200, 3, 3)
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape), atol=1e-15)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-14)
    for M in (R_W_G, R_P_C):  # the fixed frame changes are proper rotations too
        np.testing.assert_array_equal(M @ M.T, np.eye(3))
        assert np.linalg.det(M) == pytest.approx(1.0)


def test_paper_transformation_matrix():
    # The paper's T_{c->e} (Section II) at zero roll, transcribed.
    a, t = np.deg2rad(37.0), np.deg2rad(21.0)
    ca, sa, ct, st = np.cos(a), np.sin(a), np.cos(t), np.sin(t)
    T = np.array([[ct * ca, -sa, -st * ca], [ct * sa, ca, -st * sa], [st, 0.0, ct]])
    np.testing.assert_allclose(R_G_P(a, t), T, atol=1e-15)


def test_pinned_directions():
    # pan 0, tilt 0: boresight (camera z) points north (+y of W), image right (camera x) east, image down (-z).
    np.testing.assert_allclose(R_W_C(0.0, 0.0), [[1, 0, 0], [0, 0, 1], [0, -1, 0]], atol=1e-15)
    # pan 90 deg (compass east), tilt 30 deg down: boresight (cos30, 0, -sin30) in W, right = -y (south).
    R = R_W_C(np.pi / 2, np.deg2rad(30.0))
    np.testing.assert_allclose(R[:, 2], [np.cos(np.pi / 6), 0.0, -0.5], atol=1e-15)
    np.testing.assert_allclose(R[:, 0], [0.0, -1.0, 0.0], atol=1e-15)
    # tilt 90: straight down; with pan 0 the image top (-camera y) faces north
    R = R_W_C(0.0, np.pi / 2)
    np.testing.assert_allclose(R[:, 2], [0, 0, -1], atol=1e-15)
    np.testing.assert_allclose(-R[:, 1], [0, 1, 0], atol=1e-15)


def test_angle_round_trip(rng):
    pan, tilt, roll = _random_angles(rng, 500)
    p2, t2, r2 = pan_tilt_roll_from_R_W_C(R_W_C(pan, tilt, roll))
    np.testing.assert_allclose(np.angle(np.exp(1j * (p2 - pan))), 0.0, atol=1e-12)
    np.testing.assert_allclose(t2, tilt, atol=1e-12)
    np.testing.assert_allclose(np.angle(np.exp(1j * (r2 - roll))), 0.0, atol=1e-12)
    assert np.all((p2 > -np.pi) & (p2 <= np.pi)) and np.all(np.abs(t2) <= np.pi / 2)


@pytest.mark.parametrize("tilt_deg", [90.0, -90.0, 90.0 - 1e-6, -90.0 + 1e-6, 90.0 - 1e-10, 89.9, 89.9999])
def test_gimbal_round_trip_reproduces_the_rotation(tilt_deg):
    for pan_deg, roll_deg in [(0.0, 0.0), (40.0, 7.0), (-170.0, 25.0), (135.0, -60.0)]:
        a, t, r = np.deg2rad([pan_deg, tilt_deg, roll_deg])
        R = R_W_C(a, t, r)
        a2, t2, r2 = pan_tilt_roll_from_R_W_C(R)
        np.testing.assert_allclose(R_W_C(a2, t2, r2), R, atol=1e-13)
        # tilt is recovered to full precision (arcsin would give only ~1e-8 rad near +-90 deg)
        assert abs(t2 - t) < 1e-12
        if abs(tilt_deg) == 90.0:
            assert r2 == 0.0  # only pan +- roll is defined: all of it goes to pan
            # at +90 the rotation about the vertical is pan + roll, at -90 pan - roll
            expect = a + r if tilt_deg > 0 else a - r
            assert np.angle(np.exp(1j * (a2 - expect))) == pytest.approx(0.0, abs=1e-12)


def test_derivatives_vs_central_differences(rng):
    pan, tilt, roll = _random_angles(rng, 50)
    d = dR_W_C(pan, tilt, roll)
    assert d.shape == (50, 3, 3, 3)
    h = 1e-6
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        fd = (R_W_C(pan + e[0], tilt + e[1], roll + e[2]) - R_W_C(pan - e[0], tilt - e[1], roll - e[2])) / (2 * h)
        np.testing.assert_allclose(d[:, k], fd, rtol=0, atol=1e-9)


def test_broadcasting():
    R = R_W_C(np.zeros((4, 1)), np.zeros((1, 5)), 0.1)
    assert R.shape == (4, 5, 3, 3)
    assert dR_W_C(0.0, 0.2).shape == (3, 3, 3)
    p, t, r = pan_tilt_roll_from_R_W_C(R)
    assert p.shape == t.shape == r.shape == (4, 5)


@given(st.floats(-7.0, 7.0), st.floats(-1.6, 1.6), st.floats(-0.5, 0.5))
def test_scalar_path_equals_the_broadcasting_path(pan, tilt, roll):
    """Scalar angles take a path of their own (``math``, six small arrays: the kernels' per-call camera
    constants); it gives the broadcasting path's rotation and derivatives to rounding."""
    for f in (R_G_P, R_W_C, dR_W_C):
        scalar = f(pan, tilt, roll)
        batch = f(np.array([pan]), np.array([tilt]), np.array([roll]))[0]
        assert scalar.shape == batch.shape
        np.testing.assert_allclose(scalar, batch, rtol=0, atol=1e-15)
    assert R_W_C(np.float64(pan), np.float32(tilt), 0).shape == (3, 3)
