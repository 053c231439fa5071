"""The motion fit (issue 36): the bank's likelihood vs the numpy filter, the profile interval, the motion section,
per-class tracks, seeded campaigns (interval coverage, coverage after the fit) and `calibrate motion`."""

from __future__ import annotations

import json
import math

import numpy as np
import pyarrow as pa
import pyarrow.csv as pcsv
import pytest
import yaml
from click.testing import CliRunner

from footprint_uq.cameras import general
from footprint_uq.errors import ConfigError, InputError
from footprint_uq.io import save_camera
from footprint_uq.tracking import ConstantVelocity, SchmidtPredictor, SchmidtUpdater, SplitMeasurement, TrackerConfig
from footprint_uq.tracking.classes import ClassTracks, tracker_configs
from footprint_uq.tracking.filter import Initiator, TrackState, mode_switch_probabilities
from footprint_uq.tracking.joint_likelihood_kernels import joint_bank_frame
from footprint_uq.tracking.likelihood_kernels import LOG_2PI, bank_frame
from footprint_uq.tracking.motion_campaigns import campaign_frames, run_campaigns
from footprint_uq.tracking.motion_fit import (
    CHI2_95_1DOF,
    MotionBank,
    MotionGrid,
    fit_class,
    fit_profile,
    scale_gradient,
    scale_sigma,
    widen_interval,
)
from footprint_uq.tracking.synthetic import default_camera
from footprint_uq.tracking.table import SharedJacobianAt, TrackOutput, TrackTable
from footprint_uq.uncertainty.budget import ErrorBudget, load_budget

R_RANK = 3
DEFAULT_Q = np.geomspace(1e-4, 100.0, 37)


def _tracks(rng, n_tracks=4, n_frames=12, r=R_RANK):
    """Random split measurements of n tracks over n frames: ``(t (F,), z (F, n, 2), R, B)``."""
    t = np.cumsum(rng.uniform(0.02, 0.2, n_frames))
    v = rng.normal(0, 8, (n_tracks, 2))
    z = (rng.normal(0, 20, (n_tracks, 2)) + t[:, None, None] * v + rng.normal(0, 0.5, (n_frames, n_tracks, 2)))
    A = rng.normal(0, 0.3, (n_frames, n_tracks, 2, 2))
    R = A @ np.swapaxes(A, -1, -2) + 0.05 * np.eye(2)
    B = rng.normal(0, 0.2, (n_frames, n_tracks, 2, r))
    return t, z, R, B


def _mixture_step(logs):
    """One update of the reference IMMs: the mixture's log-likelihood (the modes' log terms ``logs``, each (n,),
    combined) and the new mode probabilities (n, M), floored as the kernels floor them."""
    L = np.stack(logs, -1)
    top = L.max(-1, keepdims=True)
    lik = np.maximum(np.exp(L - top), 1e-9)
    return (top[:, 0] + np.log(np.exp(L - top).sum(-1))) - LOG_2PI, lik / lik.sum(-1, keepdims=True)


def _reference_ll(t, z, R, B, qs, rates, mu0, var_v0):
    """Per-track log-likelihood of the tracker's filter (IMM over ``qs``) from the numpy classes of filter.py."""
    F, n = z.shape[:2]
    M = len(qs)
    preds = [SchmidtPredictor(ConstantVelocity(q)) for q in qs]
    upd = SchmidtUpdater()
    st = Initiator(math.sqrt(var_v0)).initiate(SplitMeasurement(z[0], R[0], B[0]))
    modes, mu = [st] * M, np.tile(mu0[:M], (n, 1))
    ll = np.zeros(n)
    for k in range(1, F):
        dt = np.full(n, t[k] - t[k - 1])
        meas = SplitMeasurement(z[k], R[k], B[k])
        Pi = mode_switch_probabilities(dt, rates[:M])
        cbar = np.einsum("nij,ni->nj", Pi, mu)
        post, logs = [], []
        for j in range(M):
            w = Pi[:, :, j] * mu / cbar[:, j, None]
            x0 = sum(w[:, i, None] * modes[i].x for i in range(M))
            P0 = sum(w[:, i, None, None] * (modes[i].P + np.einsum("ni,nj->nij", modes[i].x - x0, modes[i].x - x0))
                     for i in range(M))
            C0 = sum(w[:, i, None, None] * modes[i].C for i in range(M))
            pred = preds[j].predict(TrackState(x0, P0, C0), dt)
            y, S, _ = upd.innovation(pred, meas)
            m2 = np.einsum("ni,nij,nj->n", y, np.linalg.inv(S), y)
            logs.append(-0.5 * m2 - 0.5 * np.log(np.linalg.det(S)) + np.log(cbar[:, j]))
            post.append(upd.update(pred, meas)[0])
        step_ll, mu = _mixture_step(logs)
        ll += step_ll
        modes = post
    return ll


def _bank_ll(t, z, R, B, qs, nm, rates, mu0, var_v0):
    F, n = z.shape[:2]
    G, r = qs.shape[0], B.shape[-1]
    X, P, C, MU = np.zeros((n, G, 2, 4)), np.zeros((n, G, 2, 4, 4)), np.zeros((n, G, 2, 4, r)), np.zeros((n, G, 2))
    t_last = np.zeros(n)
    ll = np.zeros((n, G))
    for i in range(n):  # one track per class: the per-class sums are the per-track likelihoods
        LL, NIS = np.zeros((1, G)), np.zeros((1, G))
        cnt = np.zeros(1, np.int64)
        for k in range(F):
            bank_frame(np.array([i]), np.array([k == 0]), np.zeros(1, np.int64), t[k], z[k, i:i + 1], R[k, i:i + 1],
                       np.zeros((0, 2, r)), B[k, i:i + 1], X, P, C, MU, t_last, qs, nm, rates, mu0, var_v0, LL, NIS,
                       cnt, np.zeros(1, np.int64))
        ll[i] = LL[0]
        assert cnt[0] == F - 1
    return ll


@pytest.mark.parametrize("seed", [0, 1])
def test_bank_likelihood_equals_the_numpy_filter(seed):
    """One-mode and IMM members of the compiled bank give the numpy reference filter's log-likelihood (1e-9)."""
    rng = np.random.default_rng(seed)
    t, z, R, B = _tracks(rng)
    rates = np.array([1 / 3.0, 1 / 1.0])
    qs = np.array([[0.3, 0.3], [4.0, 4.0], [1.5, 30.0]])
    nm = np.array([1, 1, 2])
    stat = (1 / rates) / (1 / rates).sum()
    mu0 = np.array([[1.0, 0.0], [1.0, 0.0], stat])
    got = _bank_ll(t, z, R, B, qs, nm, np.tile(rates, (3, 1)), mu0, 50.0 ** 2)
    for g in range(3):
        want = _reference_ll(t, z, R, B, qs[g, :nm[g]], rates, mu0[g], 50.0 ** 2)
        np.testing.assert_allclose(got[:, g], want, rtol=1e-9, atol=1e-9)


def _joint_reference_ll(t, z, R, B, qs, rates, mu0, var_v0):
    """Per-track log-likelihood of the augmented-state filter (state ``[x (4), w (r)]``, ``w ~ N(0, I)`` estimated
    with it; IMM over ``qs``), in plain matrix form: the reference of ``joint_bank_frame``."""
    F, n = z.shape[:2]
    r = B.shape[-1]
    N, M = 4 + r, len(qs)
    s0, P0 = np.zeros((n, N)), np.zeros((n, N, N))
    s0[:, :2] = z[0]
    P0[:, :2, :2] = R[0] + B[0] @ np.swapaxes(B[0], -1, -2)
    P0[:, 2, 2] = P0[:, 3, 3] = var_v0
    P0[:, :2, 4:], P0[:, 4:, :2], P0[:, 4:, 4:] = -B[0], -np.swapaxes(B[0], -1, -2), np.eye(r)
    modes, mu, ll = [(s0, P0)] * M, np.tile(mu0[:M], (n, 1)), np.zeros(n)
    for k in range(1, F):
        dt = t[k] - t[k - 1]
        Pi = mode_switch_probabilities(np.full(n, dt), rates[:M])
        cbar = np.einsum("nij,ni->nj", Pi, mu)
        Fm = np.eye(N)
        Fm[0, 2] = Fm[1, 3] = dt
        H = np.concatenate([np.broadcast_to(np.eye(2), (n, 2, 2)), np.zeros((n, 2, 2)), B[k]], -1)
        post, logs = [], []
        for j in range(M):
            w = Pi[:, :, j] * mu / cbar[:, j, None]
            x0 = sum(w[:, i, None] * modes[i][0] for i in range(M))
            P = sum(w[:, i, None, None] * (modes[i][1] + np.einsum("ni,nj->nij", modes[i][0] - x0, modes[i][0] - x0))
                    for i in range(M))
            Q = np.zeros((N, N))
            Q[:4, :4] = ConstantVelocity(qs[j]).matrices(np.array([dt]))[1][0]
            xp, Pp = x0 @ Fm.T, Fm @ P @ Fm.T + Q
            y = z[k] - np.einsum("nij,nj->ni", H, xp)
            S = H @ Pp @ np.swapaxes(H, -1, -2) + R[k]
            Kg = Pp @ np.swapaxes(H, -1, -2) @ np.linalg.inv(S)
            m2 = np.einsum("ni,nij,nj->n", y, np.linalg.inv(S), y)
            logs.append(-0.5 * m2 - 0.5 * np.log(np.linalg.det(S)) + np.log(cbar[:, j]))
            post.append((xp + np.einsum("nij,nj->ni", Kg, y), Pp - Kg @ S @ np.swapaxes(Kg, -1, -2)))
        step_ll, mu = _mixture_step(logs)
        ll += step_ll
        modes = post
    return ll


def _joint_bank_ll(t, z, R, B, qs, nm, rates, mu0, var_v0):
    F, n = z.shape[:2]
    G, r = qs.shape[0], B.shape[-1]
    X, P, MU = np.zeros((n, G, 2, 4 + r)), np.zeros((n, G, 2, 4 + r, 4 + r)), np.zeros((n, G, 2))
    t_last, ll = np.zeros(n), np.zeros((n, G))
    for i in range(n):  # one track per class: the per-class sums are the per-track likelihoods
        LL, NIS, cnt = np.zeros((1, G)), np.zeros((1, G)), np.zeros(1, np.int64)
        for k in range(F):
            joint_bank_frame(np.array([i]), np.array([k == 0]), np.zeros(1, np.int64), t[k], z[k, i:i + 1],
                             R[k, i:i + 1], np.zeros((0, 2, r)), B[k, i:i + 1], X, P, MU, t_last, qs, nm, rates, mu0,
                             var_v0, LL, NIS, cnt, np.zeros(1, np.int64))
        ll[i] = LL[0]
        assert cnt[0] == F - 1
    return ll


@pytest.mark.parametrize("seed", [0, 1])
def test_joint_bank_likelihood_equals_the_augmented_filter(seed):
    """One-mode and IMM members of the compiled joint bank give the matrix-form augmented filter's log-likelihood
    (1e-9), and it differs from the tracker's (Schmidt) product of innovation densities."""
    rng = np.random.default_rng(seed)
    t, z, R, B = _tracks(rng)
    rates = np.array([1 / 3.0, 1 / 1.0])
    qs = np.array([[0.3, 0.3], [4.0, 4.0], [1.5, 30.0]])
    nm = np.array([1, 1, 2])
    stat = (1 / rates) / (1 / rates).sum()
    mu0 = np.array([[1.0, 0.0], [1.0, 0.0], stat])
    got = _joint_bank_ll(t, z, R, B, qs, nm, np.tile(rates, (3, 1)), mu0, 50.0 ** 2)
    for g in range(3):
        want = _joint_reference_ll(t, z, R, B, qs[g, :nm[g]], rates, mu0[g], 50.0 ** 2)
        np.testing.assert_allclose(got[:, g], want, rtol=1e-9, atol=1e-9)
        schmidt = _reference_ll(t, z, R, B, qs[g, :nm[g]], rates, mu0[g], 50.0 ** 2)
        assert np.all(np.abs(schmidt - want) > 1e-3)


def _linear_tracks(rng, q, n_tracks, n_frames=90, dt=1 / 30, r=4, b_m=0.6, r_m=0.1):
    """Tracks of the split model exactly: truth of density ``q`` (the filter's discrete model), ``z = x + B_k w +
    e`` with one ``w ~ N(0, I_r)`` per track and ``B_k`` changing along the path as a camera's does, not linearly in
    time (``B0 + s dB + s^2 d2B``, ``s`` from -1 to 1 over the track: the calibration's share accelerates along the
    path), ``e ~ N(0, r_m^2 I)``."""
    t = np.arange(n_frames) * dt
    F_, Q = ConstantVelocity(max(q, 1e-300)).matrices(np.array([dt]))
    A = np.linalg.cholesky(Q[0]) if q > 0 else np.zeros((4, 4))
    x = np.column_stack([rng.normal(0, 20, (n_tracks, 2)), rng.normal(0, 8, (n_tracks, 2))])
    B0, dB, d2B = rng.normal(0, b_m, (3, n_tracks, 2, r))
    w = rng.standard_normal((n_tracks, r))
    z, Bs = np.empty((n_frames, n_tracks, 2)), np.empty((n_frames, n_tracks, 2, r))
    for k in range(n_frames):
        s = (k / n_frames - 0.5) * 2.0
        Bs[k] = B0 + s * dB + s * s * d2B
        z[k] = x[:, :2] + np.einsum("nij,nj->ni", Bs[k], w) + rng.normal(0, r_m, (n_tracks, 2))
        x = x @ F_[0].T + rng.standard_normal((n_tracks, 4)) @ A.T
    R = np.broadcast_to(r_m ** 2 * np.eye(2), (n_frames, n_tracks, 2, 2)).copy()
    return t, z, R, Bs


def test_joint_likelihood_score_is_unbiased_where_the_tracker_s_is_not():
    """Monte Carlo of the estimating equation: over seeded tracks of the exact linear split model, the joint
    likelihood's slope in log q at the true q averages zero (within 3 standard errors); the tracker's (Schmidt)
    product of innovation densities has a clearly positive slope there -- it prefers a larger q (the bias of the
    fit before, docs/motion-fit.md section 2a)."""
    q_true = 0.5
    qs_grid = q_true * np.exp(np.array([-0.05, 0.0, 0.05]))
    qs = np.tile(qs_grid[:, None], (1, 2))
    nm, rates, mu0 = np.ones(3, np.int64), np.ones((3, 2)), np.tile([1.0, 0.0], (3, 1))
    t, z, R, B = _linear_tracks(np.random.default_rng(21), q_true, 160)
    joint = _joint_bank_ll(t, z, R, B, qs, nm, rates, mu0, 50.0 ** 2)
    schmidt = _bank_ll(t, z, R, B, qs, nm, rates, mu0, 50.0 ** 2)
    for ll, biased in ((joint, False), (schmidt, True)):
        slope = (ll[:, 2] - ll[:, 0]) / 0.1  # d log L / d log q per track
        mean, se = slope.mean(), slope.std(ddof=1) / math.sqrt(slope.size)
        if biased:
            assert mean > 4 * se
        else:
            assert abs(mean) < 3 * se


def test_fit_profile_pinned_on_a_quadratic_log_likelihood():
    """A log-likelihood quadratic in log q with curvature 1/0.1^2: estimate 2.0, interval 2 exp(+-1.96 * 0.1)."""
    q = np.geomspace(1e-4, 100.0, 37)
    ll = -0.5 * ((np.log(q) - math.log(2.0)) / 0.1) ** 2 + 7.0
    p = fit_profile(q, ll)
    half = math.sqrt(CHI2_95_1DOF) * 0.1
    assert p["q_hat"] == pytest.approx(2.0, rel=2e-3)
    assert p["ci95"][0] == pytest.approx(2.0 * math.exp(-half), rel=3e-3)
    assert p["ci95"][1] == pytest.approx(2.0 * math.exp(half), rel=3e-3)
    # flat towards 0 (calm): the interval starts at 0; rising at the top: unbounded above
    assert fit_profile(q, -q)["ci95"][0] == 0.0 and fit_profile(q, -q)["at_lower_edge"]
    assert fit_profile(q, np.log(q))["ci95"][1] is None
    with pytest.raises(InputError, match="log-likelihood"):
        fit_profile(q, np.r_[ll[:-1], np.nan])


def test_scale_sigma_pinned_for_a_height_error():
    """A camera whose only calibration error is its height (sigma 0.1936 m at 8 m) sees the ground scaled about its
    foot point by 1 + dh/h: ``tr(dB/dx) = 2 sigma_h / h = 0.0484`` at every point (hand value); with the whole
    basler1@deg budget the tilt adds a range-dependent stretch (0.062 over the campaigns' area, docs)."""
    cam = default_camera()
    d = load_budget("basler1@deg").to_dict()
    only_h = {k: ([0.0] * len(v) if isinstance(v, list) else 0.0) for k, v in d.items()
              if k not in ("name", "description")}
    only_h.update(height_m=0.1936, imaging_px=[0.1, 0.1])
    at = SharedJacobianAt(cam, ErrorBudget.from_dict({**d, **only_h}))
    rng = np.random.default_rng(0)
    xy = np.column_stack([rng.uniform(-12, 12, 200), rng.uniform(25, 55, 200)])
    assert at.rank == 1
    assert scale_gradient(at, xy) == pytest.approx([0.0484], rel=1e-6)
    assert scale_sigma(at, xy[:3]) == pytest.approx(2 * 0.1936 / 8.0, rel=1e-6)
    full = scale_sigma(SharedJacobianAt(cam, load_budget("basler1@deg")), xy)
    assert 0.055 < full < 0.07
    assert scale_sigma(at, np.zeros((0, 2))) == 0.0


def test_bank_samples_positions_over_the_whole_recording(monkeypatch):
    """The joint bank keeps at most SCALE_SAMPLE_CAP positions per class, spread over the whole recording (the
    stride doubles when full): with ``B(x) = 0.001 x^2`` per axis (``tr dB/dx = 0.002 (x + y)``) and objects
    moving steadily, the sigma from the kept positions is the mean over every update's position (hand value)."""
    import footprint_uq.tracking.motion_fit as mf

    monkeypatch.setattr(mf, "SCALE_SAMPLE_CAP", 64)
    shared_at = lambda xy: 0.001 * (np.asarray(xy) ** 2)[:, :, None]  # noqa: E731
    grid = MotionGrid(q_m2ps3=np.array([0.1, 1.0, 3.0, 10.0]), imm_q_m2ps3=np.zeros(0),
                      prior=TrackerConfig(accel_psd_m2ps3=1.0, manoeuvre_accel_psd_m2ps3=None))
    bank = MotionBank.from_grid(grid, rank=1, shared_at=shared_at)
    n, frames = 3, 600
    every = []
    for k in range(frames):
        xy = np.column_stack([np.full(n, 0.05 * k), 10.0 + np.arange(n)])
        out = TrackOutput(np.arange(n), np.full(n, k == 0), np.zeros(n, np.int64), np.zeros(n),
                          np.zeros((n, 2)), np.zeros((n, 2, 2)), np.zeros((n, 2)), np.zeros((n, 2, 2)))
        bank.observe(k / 30.0, out, ["a"] * n, xy, np.broadcast_to(0.01 * np.eye(2), (n, 2, 2)),
                     shared_at(xy))
        if k:
            every.append(xy)
    rec = bank._scale_xy[bank.classes["a"]]
    assert rec[3] <= 64 and rec[1] > 1 and rec[3] == sum(a.shape[0] for a in rec[0])
    want = 0.002 * np.concatenate(every).sum(1).mean()  # (x from 0.05 to 30 m: a sample of the start only is far off)
    sigma, n_upd = bank.scale_sigmas()["a"]
    assert n_upd == n * (frames - 1) and sigma == pytest.approx(want, rel=0.03)
    assert MotionBank.from_grid(grid, rank=1, shared_at=shared_at, likelihood="tracker").scale_sigmas() == {}


def test_widen_interval_pinned():
    """Half-widths in log q combined with 1.96 sigma in quadrature; 0 and unbounded ends kept."""
    lo, hi = widen_interval(2.0, [1.5, 2.6], 0.05)
    z = 1.959963984540054 * 0.05
    assert lo == pytest.approx(2.0 * math.exp(-math.hypot(math.log(2.0 / 1.5), z)), rel=1e-12)
    assert hi == pytest.approx(2.0 * math.exp(math.hypot(math.log(2.6 / 2.0), z)), rel=1e-12)
    assert lo < 1.5 and hi > 2.6
    assert widen_interval(2.0, [0.0, None], 0.05) == [0.0, None]
    assert widen_interval(2.0, [1.5, 2.6], 0.0) == [1.5, 2.6]
    e = fit_class(MotionGrid(imm_q_m2ps3=np.zeros(0)),
                  _sums(-0.5 * ((np.log(DEFAULT_Q) - math.log(0.5)) / 0.1) ** 2), scale_sigma_log=0.05)
    assert "widened by the camera's scale (5.0 % in q)" in e["note"]
    assert e["accel_psd_ci95_m2ps3"][0] < 0.5 * math.exp(-math.sqrt(CHI2_95_1DOF) * 0.1) * 0.99


def _sums(ll, n_upd=5000, n_tracks=50):
    return (np.asarray(ll, float), np.zeros(len(ll)), n_upd, 0, n_tracks)


def test_fit_class_keeps_the_prior_where_the_data_cannot_tell():
    grid = MotionGrid(imm_q_m2ps3=np.zeros(0))
    q = grid.q_m2ps3
    peaked = -0.5 * ((np.log(q) - math.log(0.5)) / 0.1) ** 2
    e = fit_class(grid, _sums(peaked))
    assert e["status"] == "identified" and e["accel_psd_m2ps3"] == pytest.approx(0.5, rel=3e-3)
    assert e["manoeuvre_accel_psd_m2ps3"] is None
    few = fit_class(grid, _sums(peaked, n_tracks=3))
    assert few["status"] == "prior" and "too little data: 3 tracks" in few["note"]
    assert few["accel_psd_m2ps3"] == TrackerConfig().accel_psd_m2ps3
    assert few["manoeuvre_accel_psd_m2ps3"] == TrackerConfig().manoeuvre_accel_psd_m2ps3
    flat = fit_class(grid, _sums(0.01 * np.log(q)))
    assert flat["status"] == "prior" and "unbounded above" in flat["note"]


def test_fit_class_keeps_the_imm_only_where_it_wins():
    grid = MotionGrid()
    n1 = grid.n_single
    one = -0.5 * ((np.log(grid.q_m2ps3) - math.log(1.0)) / 0.1) ** 2
    imm = -0.5 * ((np.log(grid.imm_q_m2ps3) - math.log(0.3)) / 0.1) ** 2
    win = fit_class(grid, _sums(np.r_[one, imm + 10.0]))
    assert win["manoeuvre_accel_psd_m2ps3"] == 30.0 and win["accel_psd_m2ps3"] == pytest.approx(0.3, rel=0.02)
    assert win["log_likelihood_gain"] == pytest.approx(10.0, abs=0.05) and "two modes" in win["note"]
    lose = fit_class(grid, _sums(np.r_[one, imm + 1.0]))
    assert lose["manoeuvre_accel_psd_m2ps3"] is None and lose["accel_psd_m2ps3"] == pytest.approx(1.0, rel=0.01)
    assert n1 == 37


def test_motion_section_in_the_budget_file(tmp_path):
    d = load_budget("basler1@deg").to_dict()
    d["motion"] = {"source": "test", "default": {"accel_psd_m2ps3": 2.0},
                   "classes": {"car": {"accel_psd_m2ps3": 0.5, "manoeuvre_accel_psd_m2ps3": None,
                                       "accel_psd_ci95_m2ps3": [0.4, 0.6], "status": "identified", "n_tracks": 20,
                                       "n_updates": 900}}}
    path = tmp_path / "b.yaml"
    path.write_text(yaml.safe_dump(d))
    b = load_budget(str(path))
    assert b.motion["classes"]["car"]["manoeuvre_accel_psd_m2ps3"] is None
    assert ErrorBudget.from_dict(b.to_dict()) == b and hash(b)
    default, per = tracker_configs(b.motion)
    assert default.accel_psd_m2ps3 == 2.0 and default.manoeuvre_accel_psd_m2ps3 == 30.0
    assert per["car"].accel_psd_m2ps3 == 0.5 and per["car"].manoeuvre_accel_psd_m2ps3 is None
    assert per["car"].timeout_s == TrackerConfig().timeout_s
    for bad, field in [({"classes": {"car": {"accel_psd_m2ps3": float("nan")}}}, "car.accel_psd_m2ps3"),
                       ({"classes": {"car": {"accel_psd_m2ps3": 1.0, "q": 1}}}, "car.q"),
                       ({"classes": {"car": {}}}, "car.accel_psd_m2ps3"),
                       ({"classes": {"car": {"accel_psd_m2ps3": 1.0, "status": "guess"}}}, "car.status"),
                       ({"classes": {"car": {"accel_psd_m2ps3": 1.0, "accel_psd_ci95_m2ps3": [1]}}}, "ci95"),
                       ({"other": 1}, "motion.other")]:
        with pytest.raises(ConfigError, match=field):
            ErrorBudget.from_dict({**d, "motion": bad})


def test_class_tracks_equal_one_table_per_model():
    """Two classes with two models: each class's objects get exactly what its own TrackTable gives."""
    at_rank = R_RANK
    rng = np.random.default_rng(3)
    t, z, R, B = _tracks(rng, n_tracks=4, n_frames=6)
    cfg_a, cfg_b = TrackerConfig(), TrackerConfig(accel_psd_m2ps3=0.2, manoeuvre_accel_psd_m2ps3=None)
    ct = ClassTracks(cfg_a, {"car": cfg_a, "person": cfg_b}, rank=at_rank)
    ta, tb = TrackTable(cfg_a, rank=at_rank), TrackTable(cfg_b, rank=at_rank)
    classes = ["car", "person", None, "person"]
    for k in range(6):
        out = ct.step(t[k], [0, 1, 2, 3], classes, z[k], R[k], B[k])
        oa = ta.step(t[k], [0, 2], z[k, [0, 2]], R[k, [0, 2]], B[k, [0, 2]])
        ob = tb.step(t[k], [1, 3], z[k, [1, 3]], R[k, [1, 3]], B[k, [1, 3]])
        np.testing.assert_array_equal(out.v_mps[[0, 2]], oa.v_mps)
        np.testing.assert_array_equal(out.cov_v_m2ps2[[1, 3]], ob.cov_v_m2ps2)
        assert out.track_id[[0, 2]].tolist() == (2 * oa.track_id).tolist()
        assert out.track_id[[1, 3]].tolist() == (2 * ob.track_id + 1).tolist()
    # one model for every class: one table, its own ids
    one = ClassTracks(cfg_a, {"car": cfg_a}, rank=at_rank)
    assert len(one.tables) == 1 and one.step(t[0], [5], ["car"], z[0, :1], R[0, :1], B[0, :1]).track_id.tolist() == [0]


@pytest.mark.parametrize("likelihood", ["joint", "tracker"])
def test_bank_follows_the_tracker_association(likelihood):
    """The bank's one-mode member at the tracker's own density (B from the frame) gives the per-update innovation
    likelihood of its reference filter (joint: the augmented one; tracker: the tracker's Schmidt filter), over
    restarts by the gate (a reused id)."""
    rng = np.random.default_rng(5)
    t, z, R, B = _tracks(rng, n_tracks=3, n_frames=10)
    z[6:, 1] += 500.0  # id 1 jumps: the tracker restarts its track
    cfg = TrackerConfig(accel_psd_m2ps3=1.0, manoeuvre_accel_psd_m2ps3=None)
    grid = MotionGrid(q_m2ps3=np.array([0.1, 1.0, 3.0, 10.0]), imm_q_m2ps3=np.zeros(0), prior=cfg)
    bank = MotionBank.from_grid(grid, rank=R_RANK, likelihood=likelihood)
    tab = TrackTable(cfg, rank=R_RANK)
    for k in range(10):
        out = tab.step(t[k], [0, 1, 2], z[k], R[k], B[k])
        bank.observe(t[k], out, ["a"] * 3, z[k], R[k], B[k])
    ll, _, n_upd, n_bad, n_tracks = bank.sums()["a"]
    assert n_tracks == 4 and n_upd == 3 * 9 - 1 and n_bad == 0
    seg = [(0, slice(0, 10)), (1, slice(0, 6)), (1, slice(6, 10)), (2, slice(0, 10))]
    ref = _joint_reference_ll if likelihood == "joint" else _reference_ll
    want = sum(ref(t[s], z[s, i:i + 1], R[s, i:i + 1], B[s, i:i + 1], [1.0], np.array([1.0]), np.array([1.0]),
                   50.0 ** 2)[0] for i, s in seg)
    assert ll[1] == pytest.approx(want, rel=1e-9)
    with pytest.raises(InputError, match="likelihood"):
        MotionBank.from_grid(grid, rank=R_RANK, likelihood="schmidt")


# -- seeded campaigns (the bench's bench/motion_fit_campaigns.py on a smaller scale) -------------------------------
@pytest.mark.parametrize("q_true", [0.0, 0.5, 2.5, 5.0])
def test_campaigns_interval_and_coverage_after_the_fit(q_true):
    """Seeded traffic of known manoeuvre noise seen by cameras with the full basler1@deg calibration error (the
    case where the tracker's own innovations gave +8..+30 % and the truth in 6-75 % of the intervals): with the
    joint likelihood the truth is in the fitted 95 % interval of nearly every campaign, and the fitted trackers' 95 %
    velocity / heading regions cover 95 +- 2.5 % (pooled over the campaigns); docs/motion-fit.md, section 3."""
    r = run_campaigns(q_true, n_campaigns=12, n_objects=10, duration_s=4.0, seed=11, prior_coverage=False)
    assert r.identified.all()
    assert r.within.sum() >= 10
    assert 0.925 <= r.coverage_velocity <= 0.975 and 0.925 <= r.coverage_heading <= 0.975
    assert r.n_velocity > 4000


# -- the command --------------------------------------------------------------------------------------------------
def _write_recording(path, q_true, n_objects=12, duration_s=3.0, seed=2):
    """2D boxes of one seeded campaign as a CSV recording, two classes: the bottom centre at the measured pixel
    (:func:`campaign_frames`' ground point, with its detector noise of 1.5 px, projected by the nominal camera) and
    the detector's pixel covariance, so that `objects` sees what the campaign's tracker sees."""
    cam = default_camera()
    rows = []
    frames = campaign_frames(q_true, 1, n_objects, duration_s=duration_s, rate_hz=30.0, seed=seed, camera=cam)
    for k, (t, ids, _, xy, _, _, _) in enumerate(frames):
        uv = general.project(cam.params, np.column_stack([xy, np.zeros(len(ids))]), domain=cam.lens_domain).uv_px
        for i in ids:
            if not np.isfinite(uv[i]).all():
                continue
            rows.append({"camera_id": "c1", "frame": k, "timestamp_s": t, "object_id": f"o{i}",
                         "class": "car" if i % 2 else "truck", "u_min_px": uv[i, 0] - 20, "v_min_px": uv[i, 1] - 40,
                         "u_max_px": uv[i, 0] + 20, "v_max_px": uv[i, 1],  # the detector's 1.5 px noise:
                         "cov_uu_px2": 2.25, "cov_uv_px2": 0.0, "cov_vv_px2": 2.25})
    rows.append({**rows[-1], "u_max_px": float("nan")})  # one bad row: reported, the rest goes on
    pcsv.write_csv(pa.table({k: [r[k] for r in rows] for k in rows[0]}), path)
    return len(rows)


def test_calibrate_motion_cli(tmp_path):
    from footprint_uq.cli.main import main

    save_camera(default_camera(), tmp_path / "cam.yaml")
    n = _write_recording(tmp_path / "d.csv", 0.5)
    args = ["calibrate", "motion", "--camera", str(tmp_path / "cam.yaml"), "--budget", "basler1@deg",
            "--detections", str(tmp_path / "d.csv"), "--out", str(tmp_path / "fit"), "--modes", "one",
            "--min-tracks", "5", "--min-updates", "100"]
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 0, r.output
    summary = json.loads((tmp_path / "fit" / "motion_fit.json").read_text())
    assert summary["rows"]["rows_in"] == n and summary["rows"]["rows_error"] == 1
    assert summary["bad_rows"][0][0] == n - 1 and "u_max_px" in summary["bad_rows"][0][2]
    b = load_budget(str(tmp_path / "fit" / "budget.yaml"))
    assert set(b.motion["classes"]) == {"car", "truck"} and b.motion["default"]["n_tracks"] == 12
    for e in b.motion["classes"].values():
        assert e["n_tracks"] == 6 and e["status"] == "identified" and e["manoeuvre_accel_psd_m2ps3"] is None
        lo, hi = e["accel_psd_ci95_m2ps3"]
        assert lo < e["accel_psd_m2ps3"] < hi and 0.2 < e["accel_psd_m2ps3"] < 2.0  # (truth 0.5; 6 tracks)
    assert "car" in r.output and "wrote" in r.output
    # the fitted budget drives `objects --tracks`: each class its own model
    out = tmp_path / "o.parquet"
    r2 = CliRunner().invoke(main, ["objects", "--camera", str(tmp_path / "cam.yaml"), "--budget",
                                   str(tmp_path / "fit" / "budget.yaml"), "--detections", str(tmp_path / "d.csv"),
                                   "--out", str(out), "--tracks", "--quiet"])
    assert r2.exit_code == 0, r2.output
    # bad options: one line, exit 2
    r3 = CliRunner().invoke(main, [*args[:-4], "--q-min", "nan"])
    assert r3.exit_code == 2 and "--q-min" in r3.output and "Traceback" not in r3.output
    r4 = CliRunner().invoke(main, [*args[:-4], "--q-min", "10", "--q-max", "1"])  # the grid's own check
    assert r4.exit_code == 2 and "q grid" in r4.output and len(r4.output.strip().splitlines()) == 1


# -- the on-line check (serve --tracks) ----------------------------------------------------------------------------
@pytest.mark.slow
def test_nis_monitor_flags_agitated_traffic_and_stays_quiet_otherwise():
    """Seeded steady traffic tracked with its own density: no flag in unchanged runs; the density x4 halfway: flagged
    within the window, with the ratio above 1 (more agitated than the model)."""
    from footprint_uq.tracking.motion_campaigns import monitor_runs

    calm = monitor_runs(2.5, 2.5, change_s=20.0, n_runs=4, n_objects=20, duration_s=40.0, window_s=20.0, seed=3)
    assert np.isnan(calm.first_flag_s).all()
    assert np.all(np.abs(calm.last_ratio - 1.0) < 0.05)
    x4 = monitor_runs(2.5, 10.0, change_s=20.0, n_runs=4, n_objects=20, duration_s=40.0, window_s=20.0, seed=3)
    assert np.all((x4.first_flag_s > 20.0) & (x4.first_flag_s <= 40.0)) and np.all(x4.flag_ratio > 1.0)


def test_service_health_carries_the_motion_check():
    """serve --tracks: the health entry per camera and class, and a log line once per new flag."""
    from footprint_uq.service.core import Service

    camera = default_camera()
    svc = Service(camera, "basler1@deg", camera_id="cam1", tracks=True, messages=False)
    assert svc.cameras["cam1"].nis is not None
    for k in range(4):
        svc.process_frame({"camera_id": "cam1", "frame": k, "timestamp_s": 0.1 * k, "detections": [
            {"object_id": 1, "class": "car", "u_min_px": 900, "v_min_px": 700 - 20 * k, "u_max_px": 960,
             "v_max_px": 760 - 20 * k}]})
    sec, lines = svc.motion_health()
    rec = sec["cameras"]["cam1"]["car"]
    assert rec["n_updates"] == 3 and rec["consistent"] is None and sec["inconsistent"] == [] and lines == []
    mon = svc.cameras["cam1"].nis
    mon._sums["car"] = [2.0 * 1.5 * 1000, 1000]  # a window whose mean NIS is 1.5 x its expectation
    sec, lines = svc.motion_health()
    assert sec["inconsistent"] == ["cam1/car"] and "class car" in lines[0] and "more agitated" in lines[0]
    assert svc.motion_health()[1] == []  # said once
    off = Service(camera, "basler1@deg", camera_id="cam1", tracks=True, messages=False, consistency_window_s=0)
    assert off.motion_health() == (None, [])


def test_serve_motion_window_option(tmp_path):
    """--motion-window-s: 0 turns the check off; NaN or a negative window is refused in one line (exit 2)."""
    from footprint_uq.cli.main import main

    save_camera(default_camera(), tmp_path / "cam.yaml")
    base = ["serve", "--camera", str(tmp_path / "cam.yaml"), "--budget", "basler1@deg", "--tracks", "--input", "-",
            "--health-interval-s", "0"]
    for bad in ("nan", "-1"):
        r = CliRunner().invoke(main, [*base, "--motion-window-s", bad], input="")
        assert r.exit_code == 2 and "--motion-window-s" in r.output and "Traceback" not in r.output
    frame = {"camera_id": "c", "frame": 0, "timestamp_s": 0.0, "detections": [
        {"object_id": 1, "class": "car", "u_min_px": 900, "v_min_px": 700, "u_max_px": 960, "v_max_px": 760}]}
    r = CliRunner().invoke(main, [*base, "--motion-window-s", "0"], input=json.dumps(frame) + "\n")
    assert r.exit_code == 0, r.output
