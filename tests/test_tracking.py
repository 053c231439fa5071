"""The tracker (footprint_uq.tracking): components against closed forms and an augmented Kalman filter, the
compiled IMM step against its numpy reference, covariances against seeded Monte Carlo, the track table's timeout /
gate / id reuse, the motion fields' conventions and NaN policy, the coverage sweep (small seeded version;
bench/tracking_coverage.py runs the larger one, bench/bench_tracking.py the cost), and the service / batch / CLI
plumbing."""

from __future__ import annotations

import math

import numpy as np
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from footprint_uq import PanTiltCamera
from footprint_uq.batch.process import TRACK_COLUMNS, process_table
from footprint_uq.errors import InputError
from footprint_uq.io import save_camera
from footprint_uq.tracking import (
    MOTION_FIELDS,
    ConstantVelocity,
    Initiator,
    InteractingModels,
    SchmidtPredictor,
    SchmidtUpdater,
    SharedJacobianAt,
    SplitMeasurement,
    TrackerConfig,
    TrackOutput,
    TrackState,
    TrackTable,
    mode_switch_probabilities,
    object_motion,
)
from footprint_uq.tracking.synthetic import coverage, default_camera

Z95 = 1.959963984540054


def _random_state(rng, n, r):
    A = rng.normal(size=(n, 4 + r, 4 + r))
    full = A @ np.swapaxes(A, -1, -2) + np.eye(4 + r) * 0.5
    # a joint covariance whose consider block is the identity: scale rows/cols of w by its inverse Cholesky
    Lw = np.linalg.cholesky(full[:, 4:, 4:])
    T = np.tile(np.eye(4 + r), (n, 1, 1))
    T[:, 4:, 4:] = np.linalg.inv(Lw)
    full = T @ full @ np.swapaxes(T, -1, -2)
    return TrackState(rng.normal(size=(n, 4)), full[:, :4, :4], full[:, :4, 4:]), full


def test_constant_velocity_matrices_pinned():
    F, Q = ConstantVelocity(2.0).matrices(np.array([0.1, 0.5]))
    np.testing.assert_allclose(F[1], [[1, 0, 0.5, 0], [0, 1, 0, 0.5], [0, 0, 1, 0], [0, 0, 0, 1]])
    q = 2.0
    np.testing.assert_allclose(Q[0][np.ix_([0, 2], [0, 2])], [[q * 1e-3 / 3, q * 1e-2 / 2], [q * 1e-2 / 2, q * 0.1]])
    assert Q[0][0, 1] == Q[0][0, 3] == 0.0
    with pytest.raises(InputError, match="accel_psd_m2ps3"):
        ConstantVelocity(0.0)
    with pytest.raises(InputError, match="calibration"):
        TrackerConfig(calibration="bias")
    with pytest.raises(InputError, match="timeout_s"):
        TrackerConfig(timeout_s=-1.0)


def test_schmidt_update_is_the_augmented_kalman_filter_on_the_state(rng):
    """The consider update's state, covariance and cross-covariance equal the optimal Kalman update of the state
    augmented with w (measurement matrix [H B]) restricted to the state and its cross block."""
    n, r = 5, 3
    state, full = _random_state(rng, n, r)
    B = rng.normal(size=(n, 2, r))
    R = np.array([[0.3, 0.1], [0.1, 0.2]]) * np.ones((n, 1, 1))
    z = rng.normal(size=(n, 2))
    post, d2 = SchmidtUpdater().update(state, SplitMeasurement(z, R, B))
    Ha = np.zeros((n, 2, 4 + r))
    Ha[:, 0, 0] = Ha[:, 1, 1] = 1.0
    Ha[:, :, 4:] = B
    S = Ha @ full @ np.swapaxes(Ha, -1, -2) + R
    K = full @ np.swapaxes(Ha, -1, -2) @ np.linalg.inv(S)
    y = z - state.x[:, :2]
    x_aug = np.einsum("nij,nj->ni", K, y)
    P_aug = full - K @ S @ np.swapaxes(K, -1, -2)
    np.testing.assert_allclose(post.x, state.x + x_aug[:, :4], rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(post.P, P_aug[:, :4, :4], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(post.C, P_aug[:, :4, 4:], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(d2, np.einsum("ni,nij,nj->n", y, np.linalg.inv(S), y), rtol=1e-10)
    # the predictor: F P F^T + Q, F C; the initiator: the measurement's whole error, C = -B
    pred = SchmidtPredictor(ConstantVelocity(1.5)).predict(state, np.full(n, 0.2))
    F, Q = ConstantVelocity(1.5).matrices(np.full(n, 0.2))
    np.testing.assert_allclose(pred.P, F @ state.P @ np.swapaxes(F, -1, -2) + Q, rtol=1e-12)
    np.testing.assert_allclose(pred.C, F @ state.C, rtol=1e-12)
    init = Initiator(7.0).initiate(SplitMeasurement(z, R, B))
    np.testing.assert_allclose(init.P[:, :2, :2], R + B @ np.swapaxes(B, -1, -2), rtol=1e-12)
    np.testing.assert_array_equal(init.C[:, :2], -B)
    assert (init.P[:, 2:, 2:] == 49.0 * np.eye(2)).all() and (init.x[:, 2:] == 0).all()


def test_compiled_initiation_equals_the_initiator(rng):
    """kernels.initiate_row (the tracker's new tracks, inside frame_update) = Initiator.initiate in every mode of the
    IMM: position the measurement, P its whole error R + B B^T, C = -B, velocity 0 with variance sigma_v0^2."""
    from footprint_uq.tracking.kernels import initiate_row

    n, m, r = 5, 2, 3
    z, B = rng.normal(0, 30, (n, 2)), rng.normal(0, 0.4, (n, 2, r))
    A = rng.normal(0, 0.3, (n, 2, 2))
    R = A @ np.swapaxes(A, -1, -2) + 0.01 * np.eye(2)
    ref = Initiator(7.0).initiate(SplitMeasurement(z, R, B))
    X, P = np.full((n, 4), np.nan), np.full((n, 4, 4), np.nan)
    Xm, Pm, Cm = np.full((n, m, 4), np.nan), np.full((n, m, 4, 4), np.nan), np.full((n, m, r, 4), np.nan)
    mu, mu0 = np.full((n, m), np.nan), np.array([0.7, 0.3])
    for s in range(n):
        initiate_row(s, X, P, Xm, Pm, Cm, mu, mu0, 49.0, z[s], R[s], B[s])
    np.testing.assert_allclose(X, ref.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(P, ref.P, rtol=1e-12, atol=1e-12)
    for j in range(m):
        np.testing.assert_allclose(Xm[:, j], ref.x, rtol=0, atol=1e-12)
        np.testing.assert_allclose(Pm[:, j], ref.P, rtol=1e-12, atol=1e-12)
        np.testing.assert_array_equal(np.swapaxes(Cm[:, j], 1, 2), ref.C)  # (the table's column-by-column C)
    np.testing.assert_array_equal(mu, np.broadcast_to(mu0, (n, m)))


def test_compiled_step_equals_the_numpy_components(rng, random_opencv_camera):
    """kernels.predict_update = SchmidtPredictor + SchmidtUpdater (gate-rejected tracks untouched);
    kernels.project_ground = camera.project on the ground (distortion, points behind the camera)."""
    from footprint_uq.fast.footprint_kernels import camera_constants
    from footprint_uq.tracking.kernels import predict_update, project_ground

    n, r = 7, 4
    state, _ = _random_state(rng, n, r)
    B = rng.normal(size=(n, 2, r))
    R = np.array([[0.3, 0.1], [0.1, 0.2]]) * np.ones((n, 1, 1))
    z = state.x[:, :2] + rng.normal(size=(n, 2)) * np.array([1, 1, 1, 1, 1, 1, 30.0])[:, None]
    dt = rng.uniform(0.01, 0.2, n)
    model = ConstantVelocity(2.5)
    post, d2_ref = SchmidtUpdater().update(SchmidtPredictor(model).predict(state, dt), SplitMeasurement(z, R, B))
    x, P, C, d2 = state.x.copy(), state.P.copy(), state.C.copy(), np.empty(n)
    gate = np.sort(d2_ref)[-2] + 1e-9  # the largest innovation fails the gate
    predict_update(x, P, C, dt, 2.5, z, R, B, gate, d2)
    np.testing.assert_allclose(d2, d2_ref, rtol=1e-12)
    ok = d2_ref <= gate
    assert ok.sum() == n - 1
    for got, want, before in ((x, post.x, state.x), (P, post.P, state.P), (C, post.C, state.C)):
        np.testing.assert_allclose(got[ok], want[ok], rtol=1e-11, atol=1e-12)
        np.testing.assert_array_equal(got[~ok], before[~ok])
    for cam in (random_opencv_camera(rng, distortion="mild"), default_camera()):
        xy = np.column_stack([rng.uniform(-30, 30, 50), rng.uniform(-20, 80, 50)])
        xy[3] = np.nan
        uv = np.empty((50, 2))
        project_ground(xy, camera_constants(cam)[0], uv)
        ref = cam.project(np.column_stack([xy, np.full(50, cam.ground_z_m)])).uv_px
        assert np.array_equal(np.isnan(uv), np.isnan(ref)) and np.isnan(ref).any()
        np.testing.assert_allclose(uv, ref, rtol=1e-12, equal_nan=True)


def test_mode_switch_probabilities():
    """Rows are distributions; a short step switches with probability ~ rate * dt, a long one reaches the stationary
    distribution (the mean sojourns' shares); one mode never switches."""
    Pi = mode_switch_probabilities(np.array([1e-4, 0.05, 1e4]), [0.25, 1.0])
    np.testing.assert_allclose(Pi.sum(-1), 1.0, rtol=1e-14)
    np.testing.assert_allclose([Pi[0, 0, 1], Pi[0, 1, 0]], [0.25e-4, 1e-4], rtol=1e-3)
    np.testing.assert_allclose(Pi[2], [[0.8, 0.2], [0.8, 0.2]], rtol=1e-12)
    np.testing.assert_allclose(Pi[1] @ Pi[1], mode_switch_probabilities([0.1], [0.25, 1.0])[0], rtol=1e-12)
    assert (mode_switch_probabilities([0.3], [0.5]) == 1.0).all()
    with pytest.raises(InputError, match="manoeuvre_sojourn_s"):
        TrackerConfig(manoeuvre_sojourn_s=0.0)


def test_imm_kernel_equals_the_numpy_reference(rng):
    """kernels.update_slots (two modes) = InteractingModels.step (mixing, modes' Schmidt steps, probabilities,
    combination); a track failing the gate (smallest mode distance) is left untouched; with one mode the kernel is
    the plain predict_update."""
    from footprint_uq.tracking.kernels import predict_update, update_slots

    n, r, M = 6, 3, 2
    modes = [_random_state(rng, n, r)[0] for _ in range(M)]
    mu = rng.dirichlet([2.0, 2.0], n)
    B = rng.normal(size=(n, 2, r))
    R = np.array([[0.3, 0.1], [0.1, 0.2]]) * np.ones((n, 1, 1))
    z = modes[0].x[:, :2] + rng.normal(size=(n, 2)) * np.array([1, 1, 1, 1, 1, 40.0])[:, None]
    t_last = -rng.uniform(0.01, 0.3, n)
    qs, sojourn = np.array([2.0, 30.0]), np.array([4.0, 1.0])
    ref = InteractingModels([ConstantVelocity(q) for q in qs], sojourn)
    post, mu_ref, x_ref, P_ref, d2_ref = ref.step(modes, mu, -t_last, SplitMeasurement(z, R, B))
    Xm = np.stack([m.x for m in modes], 1)
    Pm, Cm = np.stack([m.P for m in modes], 1), _by_column(np.stack([m.C for m in modes], 1))
    X, P = np.zeros((n, 4)), np.zeros((n, 4, 4))
    st = [a.copy() for a in (Xm, Pm, Cm, mu, t_last)]
    n_upd, d2 = np.zeros(n, np.int64), np.empty(n)
    gate = np.sort(d2_ref)[-2] + 1e-9
    update_slots(X, P, *st, n_upd, np.arange(n), 0.0, qs, 1.0 / sojourn, z, R, np.zeros((0, 2, 0)), B, gate, d2)
    np.testing.assert_allclose(d2, d2_ref, rtol=1e-11)
    ok = d2_ref <= gate
    assert ok.sum() == n - 1 and (n_upd == ok).all() and (st[4][ok] == 0.0).all()
    for got, want, before in ((st[0], np.stack([p.x for p in post], 1), Xm), (st[1], np.stack([p.P for p in post], 1),
                                                                              Pm),
                              (st[2], _by_column(np.stack([p.C for p in post], 1)), Cm), (st[3], mu_ref, mu)):
        np.testing.assert_allclose(got[ok], want[ok], rtol=1e-9, atol=1e-12)
        np.testing.assert_array_equal(got[~ok], before[~ok])
    np.testing.assert_allclose(X[ok], x_ref[ok], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(P[ok], P_ref[ok], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(st[3].sum(1), 1.0, rtol=1e-12)
    assert (np.linalg.eigvalsh(P[ok]) > 0).all() and np.array_equal(P, np.swapaxes(P, 1, 2))
    # a non-finite measurement covariance: NaN distance, the track untouched (the NaN policy)
    R_bad = R.copy()
    R_bad[0, 0, 0] = np.nan
    before = [a.copy() for a in st]
    update_slots(X, P, *st, n_upd, np.arange(1), 1.0, qs, 1.0 / sojourn, z, R_bad, np.zeros((0, 2, 0)), B, np.inf,
                 d2)
    assert np.isnan(d2[0]) and n_upd[0] == ok[0]
    for got, want in zip(st, before, strict=True):
        np.testing.assert_array_equal(got[0], want[0])
    # one mode: the plain filter
    st1 = [modes[0].x.copy(), modes[0].P.copy(), modes[0].C.copy()]
    predict_update(*st1, -t_last, 2.0, z, R, B, np.inf, np.empty(n))
    X1, P1 = np.zeros((n, 4)), np.zeros((n, 4, 4))
    sm = [modes[0].x[:, None].copy(), modes[0].P[:, None].copy(), _by_column(modes[0].C[:, None]), np.ones((n, 1))]
    update_slots(X1, P1, *sm, t_last.copy(), np.zeros(n, np.int64), np.arange(n), 0.0, qs[:1], 1.0 / sojourn[:1], z,
                 R, np.zeros((0, 2, 0)), B, np.inf, np.empty(n))
    np.testing.assert_allclose(X1, st1[0], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(P1, st1[1], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(sm[2][:, 0], _by_column(st1[2]), rtol=1e-12, atol=1e-12)


def _by_column(C):
    """Consider columns ``(..., 4, r)`` in the table's storage order ``(..., r, 4)`` (contiguous)."""
    return np.ascontiguousarray(np.swapaxes(C, -1, -2))


def test_imm_finds_the_manoeuvre(rng):
    """20 objects at 10 m/s driving straight and 20 turning at 8 m/s^2 (a hard manoeuvre), 5 cm of noise at 20 Hz,
    over the second second: the turning tracks are far more often in the manoeuvre mode, and their velocity's
    normalised squared error (2 on average for a consistent 2-D estimate) is near 2 with the IMM but well above it
    with a single constant-velocity mode (q = 3, the tracker before the IMM), which lags the turn."""
    hz, steps, a, n = 20.0, 41, 8.0, 20
    t = np.arange(steps) / hz
    om = a / 10.0
    ph = rng.uniform(-np.pi, np.pi, n)
    circ = np.stack([10 / om * (np.sin(om * t[:, None] + ph) - np.sin(ph)),
                     -10 / om * (np.cos(om * t[:, None] + ph) - np.cos(ph))], -1)  # (steps, n, 2)
    v_circ = 10 * np.stack([np.cos(om * t[:, None] + ph), np.sin(om * t[:, None] + ph)], -1)
    line = 10 * t[:, None, None] * np.stack([np.cos(ph), np.sin(ph)], -1)
    xy = np.concatenate([line, circ], 1) + np.array([0.0, 30.0]) + np.arange(2 * n)[:, None] * 20.0
    v = np.concatenate([np.broadcast_to(10 * np.stack([np.cos(ph), np.sin(ph)], -1), (steps, n, 2)), v_circ], 1)
    noise = rng.normal(0, 0.05, xy.shape)
    nees, mu = {}, []
    for label, cfg in (("imm", TrackerConfig()), ("cv", TrackerConfig(accel_psd_m2ps3=3.0,
                                                                       manoeuvre_accel_psd_m2ps3=None))):
        tab = TrackTable(cfg, rank=1)
        nees[label] = []
        for k in range(steps):
            o = tab.step(t[k], list(range(2 * n)), xy[k] + noise[k], np.broadcast_to(0.0025 * np.eye(2), (2 * n, 2, 2)),
                         np.zeros((2 * n, 2, 1)))
            if k > steps // 2:
                d = o.v_mps - v[k]
                nees[label].append(np.einsum("ni,nij,nj->n", d, np.linalg.inv(o.cov_v_m2ps2), d))
                if label == "imm":
                    mu.append(tab._mu[[tab._index[i] for i in range(2 * n)], 1])
    assert (o.track_id == np.arange(2 * n)).all()  # no track cut by the gate
    mu = np.mean(mu, 0)
    assert mu[n:].mean() > 5 * mu[:n].mean(), mu
    imm, cv = np.mean(nees["imm"], 0)[n:].mean(), np.mean(nees["cv"], 0)[n:].mean()
    assert imm < 2.0 and cv > 2.3, (imm, cv)


def test_filter_covariance_against_monte_carlo(rng):
    """The exact linear model (one w per run, B changing along the path, white frame noise, random accelerations):
    the error covariance of position, velocity and their cross-covariance with w match the filter's P and C."""
    runs, r, steps, dt = 6000, 3, 12, 0.05
    model = ConstantVelocity(2.0)
    F, Q = model.matrices(np.full(1, dt))
    B_seq = [np.array([[0.3 + 0.04 * k, 0.1, -0.05 * k], [0.0, 0.2 - 0.01 * k, 0.15]]) for k in range(steps)]
    R = np.array([[0.01, 0.002], [0.002, 0.02]])
    w = rng.standard_normal((runs, r))
    x = np.column_stack([rng.normal(0, 1, (runs, 2)), rng.normal(0, 3, (runs, 2))])
    LQ = np.linalg.cholesky(Q[0])
    LR = np.linalg.cholesky(R)
    pred, upd, init = SchmidtPredictor(model), SchmidtUpdater(), Initiator(3.0)  # the truth's velocity prior
    st = None
    for k in range(steps):
        if k:
            x = x @ F[0].T + rng.standard_normal((runs, 4)) @ LQ.T
        B = np.broadcast_to(B_seq[k], (runs, 2, r))
        z = x[:, :2] + w @ B_seq[k].T + rng.standard_normal((runs, 2)) @ LR.T
        meas = SplitMeasurement(z, np.broadcast_to(R, (runs, 2, 2)), B)
        st = init.initiate(meas) if st is None else upd.update(pred.predict(st, np.full(runs, dt)), meas)[0]
    e = x - st.x
    emp = e.T @ e / runs
    scale = np.sqrt(np.outer(np.diag(st.P[0]), np.diag(st.P[0])))
    assert (np.abs(emp - st.P[0]) <= 0.06 * scale).all(), (emp, st.P[0])
    assert (np.abs(e.T @ w / runs - st.C[0]) <= 0.05 * np.sqrt(np.diag(st.P[0]))[:, None]).all()
    # a filter that ignores w (white frame noise only) is over-confident in position by far
    assert emp[0, 0] > 5 * (st.P[0, 0, 0] - (st.C[0] @ st.C[0].T)[0, 0])


def _meas(n, xy, r=2, scale=0.3):
    return (np.asarray(xy, float).reshape(n, 2), np.broadcast_to(0.01 * np.eye(2), (n, 2, 2)),
            np.broadcast_to(np.full((2, r), scale / r), (n, 2, r)))


def test_track_table_timeout_gate_reuse_and_nan_policy():
    tab = TrackTable(TrackerConfig(timeout_s=0.5), rank=2)
    o = tab.step(0.0, ["a", "b", None], *_meas(3, [[0, 0], [10, 0], [5, 5]]))
    assert o.track_id.tolist() == [0, 1, -1] and o.new_track.tolist() == [True, True, False]
    assert np.isnan(o.v_mps).all() and o.age_s[:2].tolist() == [0.0, 0.0] and np.isnan(o.age_s[2])
    o = tab.step(0.1, ["a", "b", "a"], *_meas(3, [[1, 0], [10, 0.5], [50, 50]]))
    assert o.track_id.tolist() == [0, 1, -1]  # a repeated id in a frame: only its first object is tracked
    assert o.n_updates.tolist() == [2, 2, 0] and np.allclose(o.age_s[:2], 0.1)
    assert np.allclose(o.v_mps[0], [10.0, 0.0], atol=0.5) and np.isfinite(o.cov_v_m2ps2[:2]).all()
    # a jump far beyond the gate: the id was reused, a new track starts; a centre-less object waits
    o = tab.step(0.2, ["a", "b"], *_meas(2, [[40, -30], [np.nan, np.nan]]))
    assert o.track_id[0] == 2 and o.new_track[0] and o.n_updates[0] == 1 and np.isnan(o.v_mps[0]).all()
    assert o.track_id[1] == -1
    # b was last updated at 0.1: at 0.7 it has timed out (0.6 s > 0.5 s) and its id starts track 3; "a" (last
    # updated at 0.2: 0.5 s ago, not more) is kept until the next frame
    o = tab.step(0.7, ["b"], *_meas(1, [[10, 1]]))
    assert o.track_id.tolist() == [3] and o.new_track[0] and len(tab) == 2
    # frames out of time order are not tracked; the same time continues the frame
    o = tab.step(0.6, ["b"], *_meas(1, [[10, 1]]))
    assert o.track_id.tolist() == [-1] and tab.n_stale_frames == 1
    o = tab.step(0.75, ["c", "b"], *_meas(2, [[0, 0], [10, 1]]))
    assert o.track_id.tolist() == [4, 3] and len(tab) == 2  # "a" deleted (0.55 s)
    o = tab.step(0.75, ["d", "b"], *_meas(2, [[0, 0], [10, 1]]))
    assert o.track_id.tolist() == [5, -1]  # b was updated at 0.75 already
    with pytest.raises(InputError, match="shared_m"):
        tab.step(0.8, ["x"], np.zeros((1, 2)), np.zeros((1, 2, 2)), np.zeros((1, 2, 5)))
    with pytest.raises(InputError, match="object_ids"):
        tab.step(0.8, ["x", "y"], *_meas(1, [[0, 0]]))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.floats(0.0, 0.8), st.lists(st.sampled_from("abcdef"), max_size=5)), min_size=1,
                max_size=25), st.floats(0.05, 1.0))
def test_deleter_sweeps_only_when_needed_and_deletes_the_same(frames, timeout_s):
    """The deleter skips its sweep while no track can have expired (a lower bound of the last updates): the same
    tracks, ids and outputs as a table that sweeps every frame, over random gaps, ids and timeouts."""
    cfg = TrackerConfig(timeout_s=timeout_s)
    lazy, eager = TrackTable(cfg, rank=2), TrackTable(cfg, rank=2)
    t = 0.0
    for dt, ids in frames:
        t += dt
        xy = [[10.0 * "abcdef".index(i), 0.0] for i in ids]
        eager._oldest_s = -math.inf  # (forces the sweep)
        a, b = lazy.step(t, ids, *_meas(len(ids), xy)), eager.step(t, ids, *_meas(len(ids), xy))
        assert a.track_id.tolist() == b.track_id.tolist() and a.new_track.tolist() == b.new_track.tolist()
        assert len(lazy) == len(eager) and set(lazy._index) == set(eager._index)


def test_track_table_takes_the_whole_covariance():
    """``cov_m2=`` (the whole covariance, the per-frame part taken in the compiled pass) tracks as
    ``cov_frame_m2`` = cov - B B^T does; exactly one of the two."""
    rng = np.random.default_rng(3)
    n, r = 5, 3
    B = rng.normal(0.0, 0.2, (n, 2, r))
    R = np.broadcast_to(0.01 * np.eye(2), (n, 2, 2))
    total = R + B @ np.swapaxes(B, 1, 2)
    a, b = TrackTable(rank=r), TrackTable(rank=r)
    for k in range(4):
        xy = np.column_stack([np.arange(n) * 10.0 + k, np.full(n, 1.0 * k)]) + rng.normal(0, 0.05, (n, 2))
        oa = a.step(0.1 * k, list("abcde"), xy, R, B)
        ob = b.step(0.1 * k, list("abcde"), xy, shared_m=B, cov_m2=total)
        for x, y in zip(oa, ob, strict=True):
            np.testing.assert_allclose(x, y, rtol=1e-9, atol=1e-12)
    assert np.isfinite(ob.v_mps).all()
    with pytest.raises(InputError, match="cov_frame_m2/cov_m2"):
        a.step(1.0, ["a"], np.zeros((1, 2)), R[:1], B[:1], cov_m2=total[:1])


def test_track_table_grows_and_keeps_tracks_apart(rng):
    """200 objects (beyond the initial capacity), ids in a shuffled order each frame: every track follows its own
    object (velocities of all 200 recovered)."""
    n = 200
    v = rng.uniform(-10, 10, (n, 2))
    x0 = rng.uniform(-100, 100, (n, 2))
    tab = TrackTable(TrackerConfig(), rank=1)
    for k in range(6):
        order = rng.permutation(n)
        xy = x0[order] + v[order] * 0.1 * k + rng.normal(0, 0.05, (n, 2))
        o = tab.step(0.1 * k, [f"id{i}" for i in order], xy, np.broadcast_to(0.0025 * np.eye(2), (n, 2, 2)),
                     np.zeros((n, 2, 1)))
    assert sorted(o.track_id.tolist()) == list(range(n)) and (o.n_updates == 6).all()
    d = o.v_mps - v[order]
    d2 = np.einsum("ni,nij,nj->n", d, np.linalg.inv(o.cov_v_m2ps2), d)
    assert np.mean(d2 <= -2 * math.log(0.05)) > 0.9


def _output(v, cov, age=1.0):
    v = np.atleast_2d(np.asarray(v, float))
    n = v.shape[0]
    out = TrackOutput.untracked(n)
    return out._replace(track_id=np.arange(n), v_mps=v, cov_v_m2ps2=np.broadcast_to(cov, (n, 2, 2)).copy(),
                        age_s=np.full(n, age), n_updates=np.full(n, 3))


def test_motion_conventions_pinned():
    cov = np.diag([0.04, 0.09])
    m = object_motion(_output([[0, 10], [10, 0], [0, -10], [-3, -4]], cov))
    assert m._fields == MOTION_FIELDS and MOTION_FIELDS[0] == "v_east_mps" and MOTION_FIELDS[-1] == "age_s"
    np.testing.assert_allclose(m.heading_deg, [0, 90, 180, np.rad2deg(np.arctan2(-3, -4)) + 360])
    np.testing.assert_allclose(m.speed_mps, [10, 10, 10, 5])
    # moving north: the speed's sigma is the north sigma, the heading's the east sigma / speed (radians)
    np.testing.assert_allclose(m.sigma_speed_mps[0], 0.3)
    np.testing.assert_allclose(m.sigma_heading_deg[0], np.rad2deg(0.2 / 10))
    np.testing.assert_allclose(m.sigma_speed_mps[1], 0.2)
    np.testing.assert_allclose(m.sigma_heading_deg[1], np.rad2deg(0.3 / 10))
    # world +y 30 deg east of north: world east motion is a compass heading of 120 deg, rotated velocity / covariance
    m = object_motion(_output([[10, 0]], cov), heading_offset_deg=30.0, yaw_rad=np.array([np.pi / 2]))
    np.testing.assert_allclose(m.heading_deg, [120.0])
    np.testing.assert_allclose([m.v_east_mps[0], m.v_north_mps[0]], [10 * np.cos(np.deg2rad(30)),
                                                                     -10 * np.sin(np.deg2rad(30))])
    np.testing.assert_allclose(np.linalg.eigvalsh(m.cov_v_m2ps2[0]), [0.04, 0.09])
    np.testing.assert_allclose(m.yaw_deg, [30.0])  # a box along world +y
    assert np.isnan(m.sigma_yaw_deg).all() and m.age_s.tolist() == [1.0]


def test_motion_nan_policy_near_zero_speed():
    cov = np.diag([0.25, 0.25])  # 0.5 m/s per axis: heading sigma only from 1.5 m/s (ratio 3)
    out = _output([[0, 1.4], [0, 1.6], [0, 0], [np.nan, np.nan]], cov)
    out.cov_v_m2ps2[3] = np.nan  # (as the table writes an object without a velocity)
    m = object_motion(out)
    assert np.isfinite(m.heading_deg[:2]).all() and np.isnan(m.sigma_heading_deg[0])
    assert np.isfinite(m.sigma_heading_deg[1])
    assert np.isnan(m.heading_deg[2]) and np.isnan(m.sigma_heading_deg[2]) and np.isnan(m.sigma_speed_mps[2])
    assert m.speed_mps[2] == 0.0
    assert all(np.isnan(getattr(m, f)[3]).all() for f in ("v_east_mps", "speed_mps", "heading_deg", "cov_v_m2ps2"))
    m = object_motion(_output([[0, 1.4]], cov), heading_min_ratio=2.0)
    assert np.isfinite(m.sigma_heading_deg[0])


def test_motion_sigmas_against_monte_carlo(rng):
    """Delta-method sigmas of speed and heading against seeded samples of the velocity (well above the ratio)."""
    v = np.array([[6.0, 8.0]])
    cov = np.array([[0.09, 0.03], [0.03, 0.16]])
    m = object_motion(_output(v, cov))
    s = rng.multivariate_normal(v[0], cov, 200_000)
    speed = np.hypot(s[:, 0], s[:, 1])
    head = np.rad2deg(np.arctan2(s[:, 0], s[:, 1]))
    np.testing.assert_allclose(m.sigma_speed_mps[0], speed.std(), rtol=0.02)
    np.testing.assert_allclose(m.sigma_heading_deg[0], head.std(), rtol=0.02)


def test_coverage_small_seeded_sweep():
    """Monte Carlo over seeded trajectories (calibration error drawn once per run, pixel noise per frame): the split
    model's 95 % velocity ellipses and heading intervals cover 95 +- 2.5 % driving straight, turning and braking
    (the sweep in docs/uncertainty-model.md is larger), where the single constant-velocity mode's heading lags the
    turn and its velocity the braking; the whole covariance fed as white noise: positions far over-confident,
    velocity sigmas twice the error; the calibration ignored: positions useless."""
    for scenario, hz in (("straight", 10), ("turning", 30), ("stopping", 20)):
        r = coverage(scenario, hz, n_runs=250, duration_s=2.0, seed=11)
        assert 0.93 <= r.velocity <= 0.975, (scenario, r)
        assert 0.93 <= r.heading <= 0.975, (scenario, r)
        assert 0.92 <= r.position <= 0.975, (scenario, r)
    cv = TrackerConfig(accel_psd_m2ps3=3.0, manoeuvre_accel_psd_m2ps3=None)  # the single-mode filter
    assert coverage("turning", 30, n_runs=250, duration_s=2.0, seed=11, config=cv).heading < 0.935
    assert coverage("stopping", 20, n_runs=250, duration_s=2.0, seed=11, config=cv).velocity < 0.94
    white = coverage("straight", 30, n_runs=250, duration_s=2.0, seed=11, calibration="white")
    assert white.position < 0.75 and white.velocity > 0.97 and white.mean_sigma_v_mps > 1.5 * white.rms_error_v_mps
    ignore = coverage("straight", 30, n_runs=250, duration_s=2.0, seed=11, calibration="ignore")
    assert ignore.position < 0.3


def test_shared_jacobian_at_world_points():
    cam = default_camera()
    at = SharedJacobianAt(cam, "basler1@deg")
    xy = np.array([[0.0, 30.0], [5.0, 50.0], [0.0, -20.0]])  # the last one behind the camera
    B = at(xy)
    assert B.shape == (3, 2, at.rank) and np.isnan(B[2]).all()
    from footprint_uq.products.footprints import footprints_from_corners

    uv = cam.project(np.column_stack([xy[:2], np.zeros(2)])).uv_px[:, None, :]
    np.testing.assert_allclose(B[:2], footprints_from_corners(cam, "basler1@deg", uv).centre_shared_m, rtol=1e-9)
    # the compiled call taken from the processor's hook (no products/ frame per call) gives the method's numbers;
    # a second thread meanwhile (its scratch busy) takes the method's path, with the same numbers
    assert at._kernel is not None
    uv3 = np.empty((3, 1, 2))
    from footprint_uq.tracking.kernels import project_ground

    project_ground(xy, at._cam, uv3[:, 0])
    via_method = at.processor.point_shared_jacobian(uv3)
    np.testing.assert_array_equal(B, via_method)
    with at._busy:
        np.testing.assert_array_equal(at(xy), via_method)


def _frames(n_frames=4, dt=0.1):
    """Frames of two cars (3D boxes) driving east at 10 m/s and north at 5 m/s, 40 m in front of the camera."""
    out = []
    for k in range(n_frames):
        t = 1.7e9 + k * dt
        out.append({"camera_id": "cam1", "frame": k, "timestamp_s": t, "detections": [
            {"object_id": 7, "class": "car", "x_m": -5.0 + 10.0 * k * dt, "y_m": 40.0, "z_m": 0.8, "length_m": 4.5,
             "width_m": 1.8, "height_m": 1.5, "yaw_rad": 0.0},
            {"object_id": "p", "class": "car", "x_m": 4.0, "y_m": 30.0 + 5.0 * k * dt, "z_m": 0.8, "length_m": 4.5,
             "width_m": 1.8, "height_m": 1.5, "yaw_rad": math.pi / 2}]})
    return out


@pytest.fixture(scope="module")
def camera():
    return PanTiltCamera(1400.0, (1920, 1080), 8.0, 0.0, 12.0)


def test_service_motion_fields_and_id_reuse(camera):
    from footprint_uq.service.core import Service

    svc = Service(camera, "basler1@deg", camera_id="cam1", tracks=True, heading_offset_deg=10.0)
    recs = [svc.process_frame(f) for f in _frames()]
    first, last = recs[0]["objects"], recs[-1]["objects"]
    assert [o["track_id"] for o in first] == [0, 1] and first[0]["v_east_mps"] is None
    assert first[0]["heading_deg"] is None and first[0]["age_s"] == 0.0 and first[0]["yaw_deg"] == pytest.approx(100)
    car, other = last
    assert car["track_id"] == 0 and car["age_s"] == pytest.approx(0.3, abs=1e-6)
    # world east at 10 m/s; world +y is 10 deg east of north: compass heading 100 deg
    assert car["speed_mps"] == pytest.approx(10.0, abs=0.05) and car["heading_deg"] == pytest.approx(100.0, abs=0.5)
    assert car["v_east_mps"] == pytest.approx(10 * math.cos(math.radians(10)), abs=0.05)
    assert 0 < car["sigma_speed_mps"] < 1 and 0 < car["sigma_heading_deg"] < 10
    cov = np.array(car["cov_v_m2ps2"])
    assert cov.shape == (2, 2) and cov[0, 1] == cov[1, 0] and np.all(np.linalg.eigvalsh(cov) > 0)
    assert other["heading_deg"] == pytest.approx(10.0, abs=1.0) and other["yaw_deg"] == pytest.approx(10.0)
    assert set(MOTION_FIELDS) - {"cov_v_m2ps2"} <= set(car)
    # the same id two seconds later (beyond the 1 s timeout): a new track, no velocity
    late = _frames()[0]
    late["timestamp_s"] += 3.0
    rec = svc.process_frame(late)
    assert rec["objects"][0]["track_id"] == 2 and rec["objects"][0]["speed_mps"] is None
    # a frame out of time order: positions as always, no motion
    rec = svc.process_frame(_frames()[1])
    assert rec["type"] == "footprints" and rec["objects"][0]["track_id"] is None and rec["objects"][0]["x_m"]
    # without tracks: no motion fields
    plain = Service(camera, "basler1@deg", camera_id="cam1").process_frame(_frames()[0])
    assert "track_id" not in plain["objects"][0] and "speed_mps" not in plain["objects"][0]


def test_serve_cli_tracks(tmp_path, camera):
    import json

    from footprint_uq.cli.main import main

    save_camera(camera, tmp_path / "cam.yaml")
    text = "".join(json.dumps(f) + "\n" for f in _frames(3))
    r = CliRunner().invoke(main, ["serve", "--camera", str(tmp_path / "cam.yaml"), "--budget", "basler1@deg",
                                  "--camera-id", "cam1", "--tracks", "--input", "-"], input=text)
    assert r.exit_code == 0, r.output
    recs = [json.loads(ln) for ln in r.stdout.splitlines() if ln.startswith("{") and '"footprints"' in ln]
    assert len(recs) == 3 and recs[-1]["objects"][0]["speed_mps"] == pytest.approx(10.0, abs=0.1)


def _batch_table(frames):
    rows = [dict(d, camera_id=f["camera_id"], frame=f["frame"], timestamp_s=f["timestamp_s"],
                 object_id=str(d["object_id"])) for f in frames for d in f["detections"]]
    return {k: [r[k] for r in rows] for k in rows[0]}


def test_batch_tracks_columns_and_equal_to_the_service(camera, tmp_path):
    from footprint_uq.service.core import Service

    frames = _frames(5)
    cols = _batch_table(frames)
    out = process_table(camera, "basler1@deg", cols, tracks=True, heading_offset_deg=10.0)
    assert out.column_names[-len(TRACK_COLUMNS):] == list(TRACK_COLUMNS)
    svc = Service(camera, "basler1@deg", camera_id="cam1", tracks=True, heading_offset_deg=10.0, messages=False)
    objs = [o for f in frames for o in svc.process_frame(f)["objects"]]
    assert out.column("track_id").to_pylist() == [o["track_id"] for o in objs]
    for name in ("v_east_mps", "speed_mps", "heading_deg", "sigma_heading_deg", "yaw_deg", "age_s"):
        got = np.array(out.column(name).to_pylist(), dtype=float)
        np.testing.assert_allclose(got, np.array([o[name] for o in objs], dtype=float), rtol=1e-9, atol=1e-9)
    # needs timestamps and ids; a row without a time is not tracked
    with pytest.raises(InputError, match="timestamp_s and object_id"):
        process_table(camera, "basler1@deg", {k: v for k, v in cols.items() if k != "timestamp_s"}, tracks=True)
    cols["timestamp_s"][2] = float("nan")
    out = process_table(camera, "basler1@deg", cols, tracks=True)
    assert out.column("track_id")[2].as_py() is None and out.column("status")[2].as_py() == "ok"


def test_batch_tracks_integer_ids_as_the_same_ids_in_text(camera):
    """The batch hands an integer id column without nulls to the tracker as int64 arrays (the compiled look-up),
    text or a column with nulls as Python values: the same tracks either way (int32, uint64 and int64 columns,
    the ids as text); a null id is not tracked, the others go on."""
    import pyarrow as pa

    from footprint_uq.batch.process import _track_ids

    cols = _batch_table(_frames(5))
    cols["object_id"] = [{"7": "7", "p": "9"}[i] for i in cols["object_id"]]  # (two integer ids, as text)
    text = process_table(camera, "basler1@deg", cols, tracks=True)
    assert text.column("track_id").null_count == 0
    for typ in (pa.int32(), pa.uint64(), pa.int64()):
        ints = dict(cols, object_id=pa.array([int(i) for i in cols["object_id"]], typ))
        got = process_table(camera, "basler1@deg", ints, tracks=True)
        assert got.column("track_id").to_pylist() == text.column("track_id").to_pylist(), typ
        assert isinstance(_track_ids(pa.chunked_array([ints["object_id"]])), np.ndarray)
    nulls = dict(cols, object_id=pa.array([None if k == 3 else int(i) for k, i in enumerate(cols["object_id"])]))
    got = process_table(camera, "basler1@deg", nulls, tracks=True)
    assert got.column("track_id")[3].as_py() is None and got.column("track_id")[0].as_py() is not None
    assert isinstance(_track_ids(pa.chunked_array([nulls["object_id"]])), list)
    big = pa.chunked_array([pa.array([1, 2 ** 63], pa.uint64())])
    assert _track_ids(big) == [1, 2 ** 63]


def test_objects_cli_tracks(camera, tmp_path):
    import pyarrow as pa
    import pyarrow.csv as pcsv

    from footprint_uq.cli.main import main

    save_camera(camera, tmp_path / "cam.yaml")
    pcsv.write_csv(pa.table(_batch_table(_frames(4))), tmp_path / "d.csv")
    args = ["objects", "--camera", str(tmp_path / "cam.yaml"), "--budget", "basler1@deg", "--detections",
            str(tmp_path / "d.csv"), "--out", str(tmp_path / "o.parquet"), "--quiet", "--chunk-rows", "3"]
    r = CliRunner().invoke(main, [*args, "--tracks"])
    assert r.exit_code == 0, r.output
    t = pq.read_table(tmp_path / "o.parquet")
    assert t.column("track_id").to_pylist() == [0, 1] * 4  # frames split across chunks continue
    assert t.column("speed_mps")[6].as_py() == pytest.approx(10.0, abs=0.1)
    r = CliRunner().invoke(main, [*args])
    assert r.exit_code == 0 and "track_id" not in pq.read_table(tmp_path / "o.parquet").column_names


def test_warm_up_leaves_the_table_untouched():
    at = SharedJacobianAt(default_camera(), "basler1@deg")
    tab = TrackTable(rank=at.rank, shared_at=at)
    tab.warm_up()
    assert len(tab) == 0 and tab.step(0.0, ["a"], *_meas(1, [[0, 30]], r=at.rank)).track_id.tolist() == [0]
