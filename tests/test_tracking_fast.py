"""The tracker's production pass (tracking/imm_kernels.frame_pass) against its compiled reference
(tracking/kernels.frame_update, itself held to the numpy classes in tests/test_tracking.py): the same numbers to
1e-9 of each field's scale, over random single steps (Hypothesis: one or two modes, ranks 0..13, steps from 1 ms to
3 s, any mode probabilities, gate failures, non-finite inputs) and over whole frame sequences through
:class:`TrackTable` (starts, id reuse beyond the gate, repeated and missing ids, NaN centres, timeouts, B at the
predicted positions with holes, the three calibration modes)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from footprint_uq.errors import InputError
from footprint_uq.fast.footprint_kernels import SCRATCH_SHAPE
from footprint_uq.tracking import TrackerConfig, TrackTable, object_motion
from footprint_uq.tracking.imm_kernels import frame_pass, scratch
from footprint_uq.tracking.kernels import ROW_START, ROW_UPDATE, frame_update


def _close(got, want, what: str, rel: float = 1e-9) -> None:
    """Equal NaN pattern, and equal to ``rel`` of the field's largest finite magnitude."""
    got, want = np.asarray(got), np.asarray(want)
    assert np.array_equal(np.isnan(got), np.isnan(want)), what
    fin = np.isfinite(want)
    scale = float(np.abs(want[fin]).max()) if fin.any() else 0.0
    np.testing.assert_allclose(got[fin], want[fin], rtol=rel, atol=rel * scale, err_msg=what)


def _storage(rng, cap: int, M: int, r: int):
    """Random valid track storage: per mode a joint covariance of (x, w) with w's block the identity (the consider
    columns ``Cm (cap, M, r, 4)``, column by column as :class:`TrackTable` stores them)."""
    Xm = rng.normal(0.0, 20.0, (cap, M, 4))
    Pm, Cm = np.empty((cap, M, 4, 4)), np.empty((cap, M, 4, r))
    for s in range(cap):
        for j in range(M):
            A = rng.normal(size=(4 + r, 4 + r))
            full = A @ A.T + 0.5 * np.eye(4 + r)
            L = np.linalg.cholesky(full[4:, 4:]) if r else np.eye(0)
            T = np.eye(4 + r)
            T[4:, 4:] = np.linalg.inv(L) if r else T[4:, 4:]
            full = T @ full @ T.T
            Pm[s, j], Cm[s, j] = full[:4, :4], full[:4, 4:]
    mu = rng.dirichlet(np.full(M, 2.0), cap) if M > 1 else np.ones((cap, 1))
    return Xm, Pm, np.ascontiguousarray(np.swapaxes(Cm, -1, -2)), mu  # (C stored column by column, as the table)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2 ** 31 - 1), M=st.sampled_from([1, 2]), r=st.sampled_from([0, 1, 4, 13]),
       h=st.floats(1e-3, 3.0), with_pred=st.booleans())
def test_frame_pass_equals_the_reference_on_random_steps(seed, M, r, h, with_pred):
    rng = np.random.default_rng(seed)
    cap, n = 9, 7
    Xm, Pm, Cm, mu = _storage(rng, cap, M, r)
    X, P = np.zeros((cap, 4)), np.zeros((cap, 4, 4))
    t_last = np.full(cap, -h)
    t_first, n_upd, tid = np.full(cap, -5.0), np.full(cap, 3, np.int64), np.arange(cap, dtype=np.int64)
    slots = rng.permutation(cap)[:n].astype(np.int64)
    act = np.full(n, ROW_UPDATE, np.int8)
    act[-1] = ROW_START  # a new track in the same frame
    old = np.arange(n - 1, dtype=np.int64)
    z = Xm[slots, 0, :2] + h * Xm[slots, 0, 2:] + rng.normal(0.0, 1.0, (n, 2))  # near mode 0's prediction
    z[n - 3] += 1e4  # a jump beyond the gate
    A = rng.normal(0.0, 0.3, (n, 2, 2))
    R = A @ np.swapaxes(A, 1, 2) + 0.01 * np.eye(2)
    R[1, 0, 0] = np.nan  # a non-finite measurement: NaN distance, a start
    B_frame = rng.normal(0.0, 0.5, (n, 2, r))
    B_pred = B_frame[old] + rng.normal(0.0, 0.05, (n - 1, 2, r)) if with_pred else np.zeros((0, 2, 0))
    if with_pred and r:
        B_pred[2, 1, 0] = np.nan  # no B at this predicted position: the frame's B
        B_pred[3, 0, r - 1] = np.inf  # (nor at this one: its last entry infinite)
    qs, rates, mu0 = np.array([1.5, 30.0])[:M], np.array([1 / 3, 1.0])[:M], np.full(M, 1.0 / M)
    runs = []
    for fast in (True, False):
        st_ = [a.copy() for a in (act, X, P, Xm, Pm, Cm, mu, t_last, t_first, n_upd, tid)]
        outs = (np.empty(n, np.int64), np.empty(n, bool), np.empty(n, np.int64), np.empty(n), np.empty((n, 2)),
                np.empty((n, 2, 2)), np.empty((n, 2)), np.empty((n, 2, 2)))
        args = (st_[0], slots, old, n - 1, *st_[1:7], st_[7], st_[8], st_[9], st_[10], 40, 0.0, qs, rates, mu0,
                400.0, z, R, B_pred, B_frame, 27.6, *outs)
        nid = frame_pass(*args, *scratch(M, r), np.full(n, np.nan)) if fast else frame_update(*args)
        runs.append((nid, st_, outs))
    (nid_f, st_f, out_f), (nid_r, st_r, out_r) = runs
    assert nid_f == nid_r and np.array_equal(st_f[0], st_r[0])  # the same tracks updated, cut and started
    assert st_f[0][1] == ROW_START and st_f[0][n - 3] == ROW_START  # the NaN measurement, the jump
    for name, a, b in zip(("X", "P", "Xm", "Pm", "Cm", "mu", "t_last", "t_first", "n_upd", "tid"), st_f[1:], st_r[1:],
                          strict=True):
        _close(a, b, name)
    for k, (a, b) in enumerate(zip(out_f, out_r, strict=True)):
        _close(a, b, f"output {k}")
    Pf = st_f[2][slots]
    assert np.array_equal(Pf, np.swapaxes(Pf, 1, 2), equal_nan=True)  # exactly symmetric


def _sequence(seed: int = 3, n: int = 24, frames: int = 50):
    """A frame sequence that visits every branch of a table: objects drive at 5-15 m/s at 20 Hz; ids reused far
    away (beyond the gate), a repeated id and a None id in every frame, NaN centres, a 1.5 s gap (timeouts)."""
    rng = np.random.default_rng(seed)
    xy0 = rng.uniform(-40.0, 40.0, (n, 2)) + np.array([0.0, 50.0])
    v = rng.uniform(5.0, 15.0, n)[:, None] * np.stack([np.cos(a := rng.uniform(0, 2 * np.pi, n)), np.sin(a)], -1)
    turn = rng.uniform(-0.3, 0.3, n)
    t = 0.0
    for k in range(frames):
        t += 1.5 if k == 30 else 0.05
        heading = turn * t
        rot = np.stack([np.cos(heading), -np.sin(heading), np.sin(heading), np.cos(heading)], -1).reshape(n, 2, 2)
        xy = xy0 + np.einsum("nij,nj->ni", rot, v) * t + rng.normal(0.0, 0.08, (n, 2))
        ids: list = list(range(n))
        if k % 7 == 3:
            xy[k % n] += 40.0  # the same id far away: a new track in the same row
        ids[5] = ids[4]  # a repeated id: only its first object is tracked
        ids[6] = None
        if k % 5 == 2:
            xy[8] = np.nan
        B = rng.normal(0.0, 0.05, (n, 2, 13)) * (1.0 + 0.002 * xy[:, :1, None])
        A = rng.normal(0.0, 0.05, (n, 2, 2))
        cov = A @ np.swapaxes(A, 1, 2) + 0.004 * np.eye(2) + B @ np.swapaxes(B, 1, 2)
        yield t, ids, xy, cov, B


def _shared_at(xy):
    """A deterministic ``B`` at predicted positions, NaN for points west of x = -30 (B_frame is used there)."""
    xy = np.asarray(xy)
    B = np.empty((xy.shape[0], 2, 13))
    B[:] = 0.05 * np.sin(np.arange(26).reshape(2, 13) + xy[:, :1, None] * 0.01 + xy[:, 1:, None] * 0.02)
    B[xy[:, 0] < -30.0] = np.nan
    return B


@pytest.mark.parametrize("cfg, shared_at", [
    (TrackerConfig(timeout_s=1.0), _shared_at),
    (TrackerConfig(timeout_s=1.0), None),
    (TrackerConfig(timeout_s=1.0, manoeuvre_accel_psd_m2ps3=None), _shared_at),
    (TrackerConfig(timeout_s=1.0, calibration="white"), None),
    (TrackerConfig(timeout_s=1.0, calibration="ignore", manoeuvre_accel_psd_m2ps3=None), None),
], ids=["imm-consider-shared_at", "imm-consider", "cv-consider", "imm-white", "cv-ignore"])
def test_track_table_equals_the_reference_pass_over_a_sequence(cfg, shared_at):
    fast, ref = (TrackTable(cfg, rank=13, shared_at=shared_at) for _ in range(2))
    ref._reference_pass = True
    kinds = set()
    for t, ids, xy, cov, B in _sequence():
        a = fast.step(t, ids, xy, shared_m=B, cov_m2=cov)
        b = ref.step(t, ids, xy, shared_m=B, cov_m2=cov)
        for name in a._fields:
            _close(getattr(a, name), getattr(b, name), f"t={t:.2f} {name}")
        kinds.update({"new" if nw else "update" for nw, n_ in zip(a.new_track, a.n_updates, strict=True) if n_})
        kinds.add("restart" if (a.new_track & (a.track_id > len(ids))).any() else "none")
    assert {"new", "update", "restart"} <= kinds
    for name in ("_x", "_P", "_xm", "_Pm", "_Cm", "_mu", "_t_last", "_t_first", "_n", "_tid"):
        live = np.isfinite(ref._t_last)
        _close(getattr(fast, name)[live], getattr(ref, name)[live], name)
    assert fast._index == ref._index and fast._next_id == ref._next_id > 40  # restarts, timeouts


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), np.float64("nan"), "0.1", True, None])
def test_bad_frame_time_and_motion_options_are_named(bad):
    """The fast paths for finite floats (no call into _checks) still send everything else to its one-line check."""
    tab = TrackTable(rank=2)
    meas = (np.zeros((1, 2)), 0.01 * np.eye(2)[None], np.zeros((1, 2, 2)))
    if isinstance(bad, str):  # a numeric string is a number to as_float: accepted, as before
        assert tab.step(bad, [1], *meas).track_id.tolist() == [0]
        return
    with pytest.raises(InputError, match="time_s"):
        tab.step(bad, [1], *meas)
    out = tab.step(0.5, [1], *meas)
    with pytest.raises(InputError, match="heading_offset_deg"):
        object_motion(out, heading_offset_deg=bad)
    for ratio in (bad, 0.0, -1.0):
        with pytest.raises(InputError, match="heading_min_ratio"):
            object_motion(out, heading_min_ratio=ratio)
    assert np.isfinite(object_motion(out, heading_offset_deg=np.float64(12.5)).age_s).all()


def test_repeated_unknown_ids_the_first_object_decides():
    """A new id twice in one frame: only its first object is tracked (the kernel lists the unknown ids' objects for
    the table's new rows; their frame order decides), even when that first object has no centre."""
    tab = TrackTable(rank=2)
    meas = (np.array([[0.0, 10.0], [5.0, 10.0], [40.0, 10.0], [np.nan, np.nan], [9.0, 9.0], [60.0, 9.0]]),
            np.broadcast_to(0.01 * np.eye(2), (6, 2, 2)), np.full((6, 2, 2), 0.05))
    o = tab.step(0.0, ["p", "q", "p", "r", "s", "r"], *meas)
    assert o.track_id.tolist() == [0, 1, -1, -1, 2, -1]
    assert np.allclose(o.xy_m[[0, 1, 4]], meas[0][[0, 1, 4]]) and len(tab) == 3  # "r" got no row
    o = tab.step(0.1, ["r", "p", "r"], *(a[[5, 0, 2]] for a in meas))
    assert o.track_id.tolist() == [3, 0, -1] and o.n_updates.tolist() == [1, 2, 0]


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("whole", [True, False], ids=["cov_m2", "cov_frame_m2"])
def test_an_object_with_one_non_finite_b_entry_is_not_tracked(bad, whole):
    """The rows' pass takes an object only if every entry of its ``B`` is finite (one test of the entries' sum of
    ``b - b``): one bad entry anywhere -- the first column, a middle one, the last, either row -- leaves that object
    untracked (known id: its track waits; new id: no track), the others go on."""
    r = 13
    tab = TrackTable(rank=r)
    xy = np.array([[0.0, 10.0], [5.0, 10.0], [10.0, 10.0], [15.0, 10.0], [20.0, 10.0]])
    cov = np.broadcast_to(0.05 * np.eye(2), (5, 2, 2)).copy()
    B = np.full((5, 2, r), 0.01)
    kw = (lambda B: dict(cov_m2=cov + B @ np.swapaxes(B, 1, 2))) if whole else (lambda B: dict(cov_frame_m2=cov))
    tab.step(0.0, [1, 2, 3, 4, 5], xy, shared_m=B, **kw(B))
    Bb = B.copy()
    Bb[0, 0, 0] = Bb[1, 1, 6] = Bb[2, 0, r - 1] = Bb[3, 1, r - 1] = bad  # (objects 0-3; object 4 untouched)
    with np.errstate(invalid="ignore"):
        o = tab.step(0.1, [1, 2, 3, 4, 9], xy + [0.1, 0.0], shared_m=Bb, **kw(np.nan_to_num(Bb, posinf=0.0,
                                                                                             neginf=0.0)))
    assert o.track_id.tolist() == [-1, -1, -1, -1, 5] and o.n_updates.tolist() == [0, 0, 0, 0, 1]
    Bb[4, 0, 3] = bad  # (a new id with one bad entry: no track)
    with np.errstate(invalid="ignore"):
        o = tab.step(0.2, [1, 2, 3, 4, 10], xy + [0.2, 0.0], shared_m=np.where(np.arange(5)[:, None, None] < 4,
                                                                               B, Bb), **kw(B))
    assert o.track_id.tolist() == [0, 1, 2, 3, -1] and o.n_updates.tolist() == [2, 2, 2, 2, 0]


_TRUCKS = {"truck": TrackerConfig(timeout_s=1.0, accel_psd_m2ps3=0.5, manoeuvre_accel_psd_m2ps3=None)}


@pytest.mark.parametrize("cfg, per_class", [(TrackerConfig(timeout_s=1.0), None),
                                            (TrackerConfig(timeout_s=1.0, manoeuvre_accel_psd_m2ps3=None), None),
                                            (TrackerConfig(timeout_s=1.0), _TRUCKS)], ids=["imm", "cv", "two-models"])
def test_nis_monitor_takes_the_tracks_own_nis_with_the_same_numbers(cfg, per_class):
    """The on-line check sums the NIS the tracks' compiled pass computed (ClassTracks.frame_nis) instead of
    re-running the filter in a MotionBank (the path before, with ``shared_at`` evaluated again at its
    predictions): per frame and class the same NIS sum (1e-9) and count, over the sequence's starts, restarts
    beyond the gate, repeated / None ids, NaN centres and timeouts; and no second evaluation of ``shared_at``.
    With two motion models the default model's class agrees to 1e-9; the other class's B is now at its own
    table's predictions (the bank's: at the default model's), so its sums agree to 1e-3 only."""
    from footprint_uq.tracking.classes import ClassTracks
    from footprint_uq.tracking.consistency import NisMonitor
    from footprint_uq.tracking.motion_fit import MotionBank, members_of

    calls = [0, 0]

    def counted(xy, which=0):
        calls[which] += 1
        return _shared_at(xy)

    tracks = ClassTracks(cfg, per_class, rank=13, shared_at=counted)
    mon = NisMonitor(tracks, window_s=100.0)
    bank = MotionBank(members_of(tracks.configs), rank=13, shared_at=lambda xy: counted(xy, 1),
                      sigma_v0_mps=cfg.sigma_v0_mps, timeout_s=cfg.timeout_s)
    member = {"car": 0, "truck": 1}
    frames, n_cmp = 0, {"car": 0, "truck": 0}
    for t, ids, xy, cov, B in _sequence():
        classes = ["car" if i % 3 or per_class is None else "truck" for i in range(len(ids))]
        out = tracks.step(t, ids, classes, xy, shared_m=B, cov_m2=cov)
        before_nis, before_n = bank.NIS.copy(), bank.n_upd.copy()
        bank.observe(t, out, classes, xy, cov - B @ np.swapaxes(B, 1, 2), B)
        mon.observe(t, out, classes)
        frames += 1
        for cls, k in bank.classes.items():
            n_new = int(bank.n_upd[k] - (before_n[k] if k < before_n.shape[0] else 0))
            if not n_new:
                continue
            g = member[cls]
            want = bank.NIS[k, g] - (before_nis[k, g] if k < before_nis.shape[0] else 0.0)
            t_got, s_got, n_got = mon._frames[cls][-1]
            assert t_got == t and n_got == n_new, (t, cls)
            assert s_got == pytest.approx(want, rel=1e-9 if cls == "car" else 1e-3), (t, cls)
            n_cmp[cls] += 1
    assert n_cmp["car"] > 40 and (n_cmp["truck"] > 40) == (per_class is not None)
    assert calls[0] > frames // 2 and calls[1] > frames // 2  # B at the predictions was used (by both)
    assert mon.status()["car"]["n_updates"] == bank.n_upd[bank.classes["car"]] > 300
    with pytest.raises(InputError, match="out"):  # a frame that is not the tracks' last one
        mon.observe(t + 0.05, out._replace(track_id=out.track_id[:3]), classes[:3])


def test_b_formed_in_the_rows_call_is_shared_at_to_the_bit_over_classes():
    """The table's fused path (``shared_at`` a SharedJacobianAt: ``kernels.frame_rows_shared`` forms ``B`` at the
    predicted positions in the rows' call) against the same tables calling ``shared_at`` (the generic path): bit
    for bit, output for output and row for row, over seeded frames with births, restarts beyond the gate,
    timeouts, missed frames (NaN centres, objects absent), repeated / None ids and two classes with their own
    motion models (a real camera: some predicted positions have no ground point, their B is the frame's).  Before
    that, both paths' B at predicted positions is compared directly.  (The pass's agreement with the compiled
    reference is :func:`test_track_table_equals_the_reference_pass_over_a_sequence`'s; over this longer sequence
    with a real camera's B the two differ by rounding that grows past 1e-9 of a field's scale after ~25 frames, and
    a detection near the gate can fall on either side of it.)"""
    from footprint_uq import PanTiltCamera
    from footprint_uq.tracking import SharedJacobianAt
    from footprint_uq.tracking.classes import ClassTracks
    from footprint_uq.tracking.kernels import frame_rows, frame_rows_shared

    cam = PanTiltCamera(focal_px=1400.0, image_size_px=(1920, 1080), height_m=8.0, pan_deg=10.0, tilt_deg=20.0)
    at = SharedJacobianAt(cam, "basler1@deg")
    assert at.rank == 13 and at.kernel_inputs() is not None
    rng = np.random.default_rng(5)
    pred = np.column_stack([rng.uniform(-60.0, 60.0, 40), rng.uniform(-20.0, 120.0, 40)])  # (behind it too)
    uv, Bp, S = np.empty((40, 2)), np.full((40, 2, 13), 7.0), np.empty(SCRATCH_SHAPE)
    X = np.zeros((40, 4))
    X[:, :2] = pred
    args = (np.arange(40, dtype=np.int64), np.zeros((2, 40)), np.zeros((2, 2, 40)), np.zeros((40, 2, 13)), False,
            np.empty((40, 2)), np.empty((40, 2, 2)), 1.0, np.zeros(40), np.zeros(40, np.int64), 1, X,
            np.empty(40, np.int8), np.empty(40, np.int64), np.empty((40, 2)))
    k, _ = frame_rows_shared(*args, *at.kernel_inputs(), uv, Bp, S)
    want = at(args[14][:k])
    assert k == 40 and np.isnan(want).any() and np.isfinite(want).any()
    assert np.array_equal(Bp[:k], want, equal_nan=True)
    args[9][:] = 0
    assert frame_rows(*args)[0] == 40 and np.array_equal(args[14], pred)
    per_class = {"truck": TrackerConfig(timeout_s=1.0, accel_psd_m2ps3=0.5, manoeuvre_accel_psd_m2ps3=None)}
    cfg = TrackerConfig(timeout_s=1.0)
    fused, generic = (ClassTracks(cfg, per_class, rank=13, shared_at=s) for s in (at, lambda xy: at(xy)))
    kinds = set()
    for f, (t, ids, xy, cov, B) in enumerate(_sequence(seed=11, n=30, frames=60)):
        keep = np.flatnonzero(np.arange(len(ids)) % 9 != f % 9)  # one object in nine absent from each frame
        ids, xy, cov, B = [ids[i] for i in keep], xy[keep], cov[keep], B[keep]
        classes = ["truck" if i % 4 == 0 else "car" for i in keep]
        a, b = (tr.step(t, ids, classes, xy, shared_m=B, cov_m2=cov) for tr in (fused, generic))
        for name in a._fields:
            assert np.array_equal(getattr(a, name), getattr(b, name), equal_nan=True), (t, name)
        kinds.update({"new" if nw else "update" for nw, n_ in zip(a.new_track, a.n_updates, strict=True) if n_})
        assert np.array_equal(fused.frame_nis(), generic.frame_nis(), equal_nan=True)
    assert {"new", "update"} <= kinds
    for ta, tb in zip(fused.tables, generic.tables, strict=True):
        assert ta._fused is True and tb._fused is False and ta._index == tb._index
        for name in ("_x", "_P", "_xm", "_Pm", "_Cm", "_mu", "_t_last", "_tid"):
            assert np.array_equal(getattr(ta, name), getattr(tb, name), equal_nan=True), name
    assert len(fused.tables[1]) > 0 and fused.tables[0]._next_id > 40  # both classes tracked, restarts, timeouts
