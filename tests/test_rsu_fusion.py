"""RsuFusion: one object list per roadside unit (tracking/rsu_fusion.py, docs/rsu-fusion.md)."""

import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from footprint_uq.errors import InputError
from footprint_uq.tracking.rsu_fusion import (
    MAX_OBJECT_ID,
    RsuFusion,
    RsuFusionConfig,
    _IdPool,
    fuse_estimates,
    gate_chi2,
)

EYE = np.eye(2)


def _frame(xy, var=0.04, v=(10.0, 0.0), var_v=0.25, tids=None, age=None):
    xy = np.atleast_2d(np.asarray(xy, dtype=float))
    n = xy.shape[0]
    return dict(track_id=np.arange(n) if tids is None else np.asarray(tids),
                xy_m=xy, cov_xy_m2=np.broadcast_to(var * EYE, (n, 2, 2)).copy(),
                v_mps=np.broadcast_to(np.asarray(v, float), (n, 2)).copy(),
                cov_v_m2ps2=np.broadcast_to(var_v * EYE, (n, 2, 2)).copy(),
                age_s=np.zeros(n) if age is None else np.asarray(age, float))


def _unit(n_cams=2, **cfg):
    f = RsuFusion(RsuFusionConfig(**cfg))
    for c in range(n_cams):
        f.add_camera(f"cam{c}", c + 1)
    return f


def test_gate_is_chi2_two_dof_99():
    assert gate_chi2(0.99) == pytest.approx(9.2103, abs=1e-4)
    assert RsuFusion().gate == pytest.approx(9.2103, abs=1e-4)


def test_fuse_pinned_values():
    """Hand-checked: variances 1 and 3 on x, 2 and 2 on y -> 0.75 and 1; x_f = (3*0 + 1*4)/4 = 1 on x."""
    x, P = fuse_estimates([[0.0, 0.0], [4.0, 2.0]], [np.diag([1.0, 2.0]), np.diag([3.0, 2.0])])
    assert np.allclose(P, np.diag([0.75, 1.0]))
    assert np.allclose(x, [1.0, 1.0])
    # covariance intersection, weights 1/tr: (1/3, 1/5) normalised -> 5/8, 3/8
    x, P = fuse_estimates([[0.0, 0.0], [4.0, 2.0]], [np.diag([1.0, 2.0]), np.diag([3.0, 2.0])], "ci")
    info = 5 / 8 * np.diag([1.0, 0.5]) + 3 / 8 * np.diag([1 / 3, 0.5])
    assert np.allclose(P, np.linalg.inv(info))


@st.composite
def _spd(draw):
    a = np.array(draw(st.lists(st.floats(-3, 3), min_size=4, max_size=4))).reshape(2, 2)
    return a @ a.T + draw(st.floats(0.01, 2.0)) * EYE


@settings(max_examples=60, deadline=None)
@given(st.lists(_spd(), min_size=2, max_size=4))
def test_information_fusion_no_larger_than_any_camera(Ps):
    _, Pf = fuse_estimates(np.zeros((len(Ps), 2)), np.array(Ps))
    for P in Ps:
        assert np.linalg.eigvalsh(P - Pf).min() >= -1e-9 * np.abs(P).max()


def test_fusion_covariance_monte_carlo():
    """Two independent estimates with the stated covariances: the fused error's sample covariance matches."""
    rng = np.random.default_rng(3)
    P1, P2 = np.array([[1.0, 0.4], [0.4, 0.5]]), np.array([[0.3, -0.1], [-0.1, 2.0]])
    n = 20000
    e1 = rng.multivariate_normal([0, 0], P1, n)
    e2 = rng.multivariate_normal([0, 0], P2, n)
    _, Pf = fuse_estimates(np.zeros((2, 2)), np.array([P1, P2]))
    W1 = Pf @ np.linalg.inv(P1)
    W2 = Pf @ np.linalg.inv(P2)
    ef = e1 @ W1.T + e2 @ W2.T
    assert np.allclose(np.cov(ef.T), Pf, rtol=0.05, atol=0.01)
    assert np.allclose(fuse_estimates(np.array([[1.0, 0.0], [1.0, 0.0]]), np.array([P1, P2]))[0], [1.0, 0.0])


def test_two_cameras_one_object():
    f = _unit()
    r0 = f.step("cam0", 0.0, **_frame([[10.0, 5.0]], var=0.09, age=[0.5]))
    r1 = f.step("cam1", 0.0, **_frame([[10.3, 4.8]], var=0.04))
    assert r0.status == r1.status == "ok" and r0.object_id[0] == r1.object_id[0] == 0
    objs = f.objects(0.0)
    assert objs.object_id.tolist() == [0] and objs.sensor_ids == [(1, 2)] and objs.n_sources.tolist() == [2]
    assert objs.age_s[0] == pytest.approx(0.5)  # the first detection of any camera
    assert np.allclose(objs.cov_xy_m2[0], 1 / (1 / 0.09 + 1 / 0.04) * EYE)
    cams, xs, Ps = f.contributions(0, 0.0)
    assert cams == ["cam0", "cam1"]
    for P in Ps:
        assert np.linalg.eigvalsh(P - objs.cov_xy_m2[0]).min() > 0


def test_global_assignment_and_one_track_per_camera():
    """Camera 1's two tracks sit between camera 0's two objects: greedy (nearest first) would pair track 0 with
    object B; the optimal assignment pairs both.  A third track of camera 1 never lands on a taken object."""
    f = _unit()
    f.step("cam0", 0.0, **_frame([[0.0, 0.0], [2.0, 0.0]], var=0.5))
    r = f.step("cam1", 0.0, **_frame([[1.2, 0.0], [2.9, 0.0], [2.2, 0.1]], var=0.5))
    ids = r.object_id.tolist()
    assert len(set(ids)) == 3  # every track of camera 1 on its own object
    assert ids[0] == 0 and 1 in ids[1:]  # total d2 minimal: track 0 -> object 0
    assert len(f) == 3


def test_sticky_until_gate_broken_for_unstick_frames():
    f = _unit(unstick_frames=3)
    f.step("cam0", 0.0, **_frame([[0.0, 0.0]], v=(0, 0)))
    f.step("cam1", 0.0, **_frame([[0.1, 0.0]], v=(0, 0)))
    for k in range(1, 3):  # camera 1 jumps 3 m away (d2 ~ 112 > 9.21) for two frames: still sticky
        f.step("cam0", 0.1 * k, **_frame([[0.0, 0.0]], v=(0, 0)))
        r = f.step("cam1", 0.1 * k, **_frame([[3.0, 0.0]], v=(0, 0)))
        assert r.object_id[0] == 0 and len(f) == 1
    f.step("cam0", 0.3, **_frame([[0.0, 0.0]], v=(0, 0)))
    r = f.step("cam1", 0.3, **_frame([[3.0, 0.0]], v=(0, 0)))
    assert r.object_id[0] == 1 and len(f) == 2 and f.n_unstuck == 1
    assert f.objects().sensor_ids == [(1,), (2,)]


@pytest.mark.parametrize("leave, stays", [(0.999, True), (0.99, False)])
def test_a_sticky_pair_leaves_only_beyond_the_wider_leave_gate(leave, stays):
    """Hysteresis: joining needs d^2 <= 9.21 (99 %), leaving needs d^2 > 13.8 (99.9 %) in unstick_frames frames
    running; a pair at d^2 ~ 11 (a camera whose calibration error is ~3 sigma in a region) stays in its object."""
    f = _unit(unstick_frames=3, leave_confidence=leave)
    f.step("cam0", 0.0, **_frame([[0.0, 0.0]], v=(0, 0)))
    f.step("cam1", 0.0, **_frame([[0.1, 0.0]], v=(0, 0)))
    dx = math.sqrt(11.0 * 0.08)  # P_c + P_o = 0.08 I: d^2 = 11
    for k in range(1, 6):
        f.step("cam0", 0.1 * k, **_frame([[0.0, 0.0]], v=(0, 0)))
        f.step("cam1", 0.1 * k, **_frame([[dx, 0.0]], v=(0, 0)))
    assert (len(f) == 1 and f.n_unstuck == 0) == stays


def test_merge_keeps_older_id():
    """Two objects seen by one camera each (first seen apart), later consistent: merged under the older id."""
    f = _unit()
    f.step("cam0", 0.0, **_frame([[0.0, 0.0]], v=(0, 0)))
    f.step("cam1", 0.0, **_frame([[5.0, 0.0]], v=(0, 0)))
    assert len(f) == 2
    f.step("cam0", 0.1, **_frame([[0.0, 0.0]], v=(0, 0)))
    r = f.step("cam1", 0.1, **_frame([[0.2, 0.0]], v=(0, 0)))
    assert len(f) == 1 and r.object_id[0] == 0 and f.n_merged == 1
    assert f.pairs() == {("cam0", 0): 0, ("cam1", 0): 0}


def test_clock_backwards_is_the_frames_error_and_keeps_tracks():
    f = _unit()
    f.step("cam0", 1.0, **_frame([[0.0, 0.0]]))
    before = f.objects(1.0)
    r = f.step("cam0", 0.9, **_frame([[50.0, 0.0]]))
    assert r.status == "clock_backwards" and "cam0" in r.error and "0.9" in r.error
    assert (r.object_id == -1).all() and f.counts["clock_backwards"] == 1
    after = f.objects(1.0)
    assert after.object_id.tolist() == before.object_id.tolist() and np.allclose(after.xy_m, before.xy_m)


def test_late_frames_fused_or_dropped_never_reordered():
    f = _unit(max_lateness_s=0.2)
    f.step("cam0", 1.0, **_frame([[10.0, 0.0]]))
    r = f.step("cam1", 0.9, **_frame([[9.0, 0.0]]))  # 0.1 s late: predicted to 1.0 -> 10.0, same object
    assert r.status == "late" and r.object_id[0] == 0 and f.objects().n_sources.tolist() == [2]
    r = f.step("cam1", 0.95, **_frame([[9.5, 0.0]]))
    assert r.status == "late"
    f.step("cam0", 2.0, **_frame([[20.0, 0.0]]))
    r = f.step("cam1", 1.5, **_frame([[15.0, 0.0]]))  # 0.5 s late > 0.2
    assert r.status == "dropped_late" and r.error and f.counts == {"ok": 2, "late": 2, "dropped_late": 1,
                                                                    "clock_backwards": 0}
    assert f.last_time_s == 2.0


def test_clock_term_in_the_contribution():
    """Prediction by tau with the clock's sigma: P + tau^2 Pv + sigma_t^2 (v v^T + Pv) + q |tau|^3 / 3 I."""
    f = RsuFusion(RsuFusionConfig(accel_psd_m2ps3=3.0))
    f.add_camera("a", 7, clock_offset_sigma_s=0.03, clock_jitter_sigma_s=0.04)
    f.step("a", 0.0, **_frame([[1.0, 2.0]], var=0.04, v=(10.0, -2.0), var_v=0.25))
    _, xs, Ps = f.contributions(0, 0.2)
    v = np.array([10.0, -2.0])
    expected = 0.04 * EYE + 0.04 * 0.25 * EYE + 0.05 ** 2 * (np.outer(v, v) + 0.25 * EYE) + 3.0 * 0.008 / 3 * EYE
    assert np.allclose(xs[0], [3.0, 1.6]) and np.allclose(Ps[0], expected)


def test_object_ends_after_timeout_and_id_not_reused_at_once():
    f = _unit(member_timeout_s=0.5)
    f.step("cam0", 0.0, **_frame([[0.0, 0.0]]))
    f.step("cam0", 1.0, **_frame([[50.0, 0.0]], tids=[1]))
    assert f.objects().object_id.tolist() == [1]  # object 0 ended; the new one got a fresh id


def test_id_pool_reuses_only_freed_ids_oldest_first():
    pool = _IdPool()
    assert [pool.take() for _ in range(3)] == [0, 1, 2]
    pool.free(1)
    pool.free(0)
    pool._next = MAX_OBJECT_ID
    assert pool.take() == MAX_OBJECT_ID
    assert [pool.take(), pool.take(), pool.take()] == [1, 0, None]


def test_bad_rows_reported_with_index_rest_fused():
    f = _unit()
    fr = _frame([[0.0, 0.0], [np.nan, 1.0], [5.0, 5.0], [9.0, 9.0]], tids=[0, 1, -1, 0])
    r = f.step("cam0", 0.0, **fr)
    assert r.object_id[0] == 0 and (r.object_id[1:] == -1).all()
    assert [i for i, _ in r.rejected] == [1, 2, 3]
    assert "not finite" in r.rejected[0][1] and "-1" in r.rejected[1][1] and "repeated" in r.rejected[2][1]


@pytest.mark.parametrize("kw, field", [
    (dict(gate_confidence=math.nan), "gate_confidence"), (dict(gate_confidence=1.0), "gate_confidence"),
    (dict(unstick_frames=0), "unstick_frames"), (dict(max_lateness_s=math.nan), "max_lateness_s"),
    (dict(leave_confidence=0.95), "leave_confidence"), (dict(leave_confidence=1.0), "leave_confidence"),
    (dict(member_timeout_s=-1.0), "member_timeout_s"), (dict(method="mean"), "method")])
def test_config_refuses_bad_values(kw, field):
    with pytest.raises(InputError) as e:
        RsuFusionConfig(**kw)
    assert e.value.field == field


def test_bad_frames_and_cameras():
    f = _unit()
    with pytest.raises(InputError, match="camera_id"):
        f.step("nope", 0.0, **_frame([[0.0, 0.0]]))
    fr = _frame([[0.0, 0.0]])
    fr["cov_xy_m2"] = np.eye(2)
    with pytest.raises(InputError, match="cov_xy_m2"):
        f.step("cam0", 0.0, **fr)
    with pytest.raises(InputError, match="time_s"):
        f.step("cam0", math.nan, **_frame([[0.0, 0.0]]))
    with pytest.raises(InputError, match="sensor_id"):
        f.add_camera("cam9", 1)
    with pytest.raises(InputError, match="sensor_id"):
        f.add_camera("cam9", 256)
    with pytest.raises(InputError, match="clock_offset_sigma_s"):
        f.add_camera("cam9", 9, clock_offset_sigma_s=math.nan)


def test_intersection_every_vehicle_once_seeded():
    """Three cameras over the signalised intersection (tracking/rsu_synthetic.py), 200 unit frames at 10 Hz: every
    vehicle a camera detects is in exactly one fused object, no fused object holds two vehicles, no fused covariance
    exceeds a camera's (the full 1,000-frame run and the coverage sweep: bench/rsu_fusion.py)."""
    from footprint_uq.tracking.rsu_synthetic import simulate

    r = simulate(200, seed=0)
    assert r.n_truth_frames > 500 and r.max_objects >= 5 and r.n_multi > 200
    assert r.n_duplicates == 0 and r.n_missing == 0 and r.n_mixed == 0
    assert r.n_larger == 0
    assert r.fusion_counts["clock_backwards"] == 0 and r.fusion_counts["dropped_late"] == 0


def test_a_second_track_of_a_camera_never_joins_its_first_tracks_object():
    f = _unit()
    f.step("cam0", 0.0, **_frame([[0.0, 0.0]], v=(0, 0)))
    f.step("cam1", 0.0, **_frame([[0.1, 0.0]], v=(0, 0)))
    f.step("cam0", 0.1, **_frame([[0.0, 0.0]], v=(0, 0)))
    r = f.step("cam1", 0.1, **_frame([[0.1, 0.0], [0.05, 0.0]], v=(0, 0), tids=[0, 1]))
    assert r.object_id.tolist() == [0, 1]  # track 1 is as close, but camera 1 is already in object 0
    assert f.objects().sensor_ids == [(1, 2), (2,)]


def test_cost_matrix_equals_the_per_pair_distance():
    """The assignment's vectorised d^2 matrix equals the readable per-pair distance (predicted contributions fused
    with fuse_estimates, the row's clock term, unknown velocities included)."""
    rng = np.random.default_rng(5)
    f = RsuFusion()
    f.add_camera("a", 1, clock_offset_sigma_s=0.02)
    f.add_camera("b", 2, clock_offset_sigma_s=0.01)
    fa = _frame(rng.uniform(-20, 20, (6, 2)), var=0.3, v=(4.0, -3.0))
    fa["v_mps"][2] = np.nan
    f.step("a", 0.0, **fa)
    fb = _frame(rng.uniform(-20, 20, (5, 2)), var=0.2, v=(-1.0, 6.0))
    fb["v_mps"][1] = np.nan
    fb["cov_xy_m2"][3] = [[0.5, 0.2], [0.2, 0.3]]
    cands = sorted(f._objects)
    cost = f._cost("b", 0.05, list(range(5)), cands, fb["xy_m"], fb["cov_xy_m2"], fb["v_mps"], fb["cov_v_m2ps2"])
    for i in range(5):
        v = fb["v_mps"][i]
        Pc = fb["cov_xy_m2"][i] + (0.01 ** 2 * (np.outer(v, v) + fb["cov_v_m2ps2"][i]) if np.isfinite(v).all()
                                   else 0.0)
        for b, o in enumerate(cands):
            _, xs, Ps = f.contributions(o, 0.05)
            xo, Po = fuse_estimates(xs, Ps)
            d = fb["xy_m"][i] - xo
            assert cost[i, b] == pytest.approx(d @ np.linalg.solve(Pc + Po, d), rel=1e-9)


@pytest.mark.slow
def test_fused_coverage_small_seeded_sweep():
    """8 independent runs (each its own calibration draws and clock offsets): the 95 % ellipse of objects fused from
    2+ cameras holds the truth 95 +- 4 % (the 200-run sweep, +-2 %: bench/rsu_fusion.py, docs/rsu-fusion.md), fusion
    covers at least as well as the cameras' own estimates of the same objects, and is never larger than any."""
    from footprint_uq.tracking.rsu_synthetic import coverage_sweep

    r = coverage_sweep(8, 100, seed=1000)
    assert r.n_multi > 1000
    assert 0.91 <= r.coverage_multi <= 0.99
    assert r.coverage >= r.coverage_camera - 0.01
    assert r.n_larger == 0


def _usable_rows_reference(tid, xy, P):
    """The readable per-row rule (the order of the checks; a repeat only of an accepted row)."""
    rejected, rows, seen = [], [], set()
    for i in range(tid.shape[0]):
        if tid[i] < 0:
            rejected.append((i, "not tracked (track_id -1)"))
        elif int(tid[i]) in seen:
            rejected.append((i, f"track_id {int(tid[i])} repeated in the frame"))
        elif not (np.isfinite(xy[i]).all() and np.isfinite(P[i]).all()):
            rejected.append((i, "position or covariance not finite"))
        elif not (P[i, 0, 0] > 0 and np.linalg.det(P[i]) > 0):
            rejected.append((i, "covariance not positive definite"))
        else:
            rows.append(i)
            seen.add(int(tid[i]))
    return rejected, rows


@settings(max_examples=60, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2 ** 32 - 1), n=st.integers(0, 25))
def test_usable_rows_column_wise_equals_the_per_row_rule(seed, n):
    from footprint_uq.tracking.rsu_fusion import _usable_rows

    rng = np.random.default_rng(seed)
    tid = rng.integers(-1, 6, n)
    xy = rng.normal(0, 5, (n, 2))
    P = np.broadcast_to(0.1 * EYE, (n, 2, 2)).copy()
    bad = rng.random(n)
    xy[bad < 0.15, 0] = np.nan
    P[(bad >= 0.15) & (bad < 0.3)] = [[0.1, 0.2], [0.2, 0.1]]   # not positive definite
    P[(bad >= 0.3) & (bad < 0.35), 1, 1] = np.inf
    assert _usable_rows(tid, xy, P) == _usable_rows_reference(tid, xy, P)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 2), st.sampled_from([-0.45, -0.2, 0.0, 0.05, 0.3, 0.6, 1.2]),
                          st.lists(st.integers(0, 4), max_size=4)), min_size=1, max_size=40))
@example([(0, 0.0, [1]), (0, 0.7, []), (0, 0.7, [])])
def test_expiry_shortcut_equals_a_full_scan_every_frame(steps):
    """``_expire`` skips its scan while no member can be past ``member_timeout_s`` (a lower bound of the members'
    times): the same frames through a unit that scans every frame give the same pairs, objects and ids, also with
    late frames (a camera's frame up to 0.45 s behind the unit) and gaps longer than the timeout
    (mutation-checked: without the bound lowered by each frame stored, objects never end)."""
    fast, full = _unit(3), _unit(3)
    t_cam, t_unit = [0.0, 0.0, 0.0], 0.0
    for cam, dt, tids in steps:
        t = max(t_cam[cam], t_unit + dt)  # a camera's clock never goes backwards; late by up to 0.45 s
        t_cam[cam], t_unit = t, max(t_unit, t)
        tids = sorted(set(tids))
        xy = [[10.0 * k + 0.1 * cam, 0.0] for k in tids]
        for f in (fast, full):
            if f is full:
                f._oldest_member_s = -math.inf  # the scan every frame
            ff = f.step(f"cam{cam}", 100.0 + t, **_frame(xy if tids else np.zeros((0, 2)), tids=tids, v=(0.0, 0.0)))
        assert fast.pairs() == full.pairs()
        assert ff.status == "ok" or ff.status == "late"
        a, b = fast.objects(), full.objects()
        assert a.object_id.tolist() == b.object_id.tolist() and a.sensor_ids == b.sensor_ids
        assert np.array_equal(a.xy_m, b.xy_m, equal_nan=True)
        for obj in fast._objects.values():
            assert all(fast.last_time_s - m.time_s <= fast.config.member_timeout_s for m in obj.members.values())


def test_an_object_is_reported_only_while_a_contribution_is_fresh():
    """Issue 32 (ghosts): camera 0's track ends at 0.2 s; its object is reported up to report_timeout_s (0.3 s)
    after its last update and not after, but kept (for re-association) until member_timeout_s; an object with one
    fresh and one stale camera is fused from the fresh one only and lists only its sensor."""
    f = _unit(report_timeout_s=0.3)
    for k in range(3):
        f.step("cam0", 0.1 * k, **_frame([[1.0 * k, 0.0]]))
    assert f.objects(0.5).object_id.tolist() == [0]
    assert f.objects(0.51).object_id.tolist() == [] and len(f) == 1
    g = _unit(report_timeout_s=0.3)
    g.step("cam0", 0.0, **_frame([[0.0, 0.0]]))
    g.step("cam1", 0.0, **_frame([[0.2, 0.0]]))
    g.step("cam1", 0.4, **_frame([[4.2, 0.0]]))
    o = g.objects(0.4)
    assert o.sensor_ids == [(2,)] and o.n_sources.tolist() == [1] and np.allclose(o.xy_m[0], [4.2, 0.0])
    assert g.contributions(0, 0.4)[0] == ["cam1"]


def test_a_cameras_new_track_takes_over_its_lapsed_member():
    """Issue 32 (duplicates): a camera alone sees a car; its tracker restarts the track under a new id (same place):
    the new track takes over the object (same objectId, one object reported), also when two of its objects became
    one car's (they merge, the older id survives)."""
    f = _unit()
    for k in range(3):
        f.step("cam0", 0.1 * k, **_frame([[1.0 * k, 0.0]], tids=[7]))
    r = f.step("cam0", 0.3, **_frame([[3.0, 0.0]], tids=[8]))
    assert r.object_id.tolist() == [0] and f.objects().object_id.tolist() == [0] and f.pairs() == {("cam0", 8): 0}
    # a track whose own object (camera 1's stale member in it) has no fresh other camera may join another object
    g = _unit()
    g.step("cam0", 0.0, **_frame([[0.0, 0.0]], tids=[1]))
    g.step("cam1", 0.0, **_frame([[0.1, 0.0]], tids=[5]))   # object 0: cam0/1, cam1/5
    g.step("cam1", 0.5, **_frame([[5.0, 0.0]], tids=[6]))   # cam1's track restarts: joins object 0 (cam0's stale 1)
    assert g.pairs() == {("cam0", 1): 0, ("cam1", 6): 0}


def test_report_timeout_must_not_exceed_member_timeout():
    with pytest.raises(InputError) as e:
        RsuFusionConfig(report_timeout_s=2.0)
    assert e.value.field == "report_timeout_s"
    with pytest.raises(InputError) as e:
        RsuFusionConfig(report_timeout_s=math.nan)
    assert e.value.field == "report_timeout_s"


def test_score_positions_pinned():
    """Ghosts and duplicates by position (hand-checked): two road users 1 m apart with an object each are two
    matches, not a duplicate; a third object by one of them is its duplicate; an object 10 m from everybody a
    ghost; NaN road users ignored."""
    from footprint_uq.tracking.rsu_synthetic import score_positions

    truth = [[0.0, 0.0], [1.0, 0.0], [20.2, 0.0], [np.nan, np.nan]]
    assert score_positions([[0.0, 0.0], [0.5, 0.0], [10.0, 0.0], [20.0, 0.0]], truth) == (1, 0)
    assert score_positions([[0.0, 0.0], [0.5, 0.0], [0.7, 0.0], [20.0, 0.0]], truth) == (0, 1)
    assert score_positions([[0.0, 0.0], [0.1, 0.0], [0.2, 0.0]], [[0.0, 0.0], [30.0, 0.0]]) == (0, 1)
    assert score_positions([[3.1, 0.0]], [[0.0, 0.0]]) == (1, 0)
    assert score_positions(np.zeros((0, 2)), truth) == (0, 0)
    assert score_positions([[0.0, 0.0]], np.zeros((0, 2))) == (1, 0)


def test_a_merge_keeps_each_cameras_newer_member():
    """Two objects of one car, each with a track of both cameras: when camera 0's newer track (object 1) finds object
    0 through camera 1's track there, the two merge under the older id and camera 1 keeps its newer member (track 1,
    updated at 0.2 s; track 2 of 0.1 s leaves with its pair): never two members, or a dangling pair, of one camera."""
    f = _unit()
    still = dict(v=(0.0, 0.0))
    f.step("cam0", 0.0, **_frame([[0.0, 0.0]], tids=[1], **still))
    f.step("cam1", 0.0, **_frame([[0.0, 0.0]], tids=[1], **still))                  # object 0: cam0/1, cam1/1
    f.step("cam0", 0.1, **_frame([[0.0, 0.0], [50.0, 0.0]], tids=[1, 2], **still))  # cam0/2: object 1
    f.step("cam1", 0.1, **_frame([[0.0, 0.0], [50.0, 0.0]], tids=[1, 2], **still))  # cam1/2 joins object 1
    f.step("cam1", 0.2, **_frame([[0.0, 0.0]], tids=[1], **still))
    assert f.pairs() == {("cam0", 1): 0, ("cam1", 1): 0, ("cam0", 2): 1, ("cam1", 2): 1}
    r = f.step("cam0", 0.5, **_frame([[0.0, 0.0]], tids=[2], **still))  # object 1's camera 1 is stale: it may merge
    assert r.object_id.tolist() == [0] and f.n_merged == 1 and len(f) == 1
    assert f.pairs() == {("cam0", 2): 0, ("cam1", 1): 0}
