"""The compiled look-up of integer ids (tracking/kernels.id_lookup / id_insert / id_delete, the open-addressing
table :class:`TrackTable` keeps beside its dictionary) against a dict: random insert / delete / look-up sequences
on small, crowded tables (collisions, runs wrapping round the end, int64's extremes), and whole frame sequences
through two tables -- one on the compiled look-up, one on the dictionary -- with births, deaths by timeout,
repeated ids, None ids, NaN centres, ids as lists and as int64 arrays: output for output equal to the bit."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from footprint_uq.tracking import TrackerConfig, TrackTable
from footprint_uq.tracking.kernels import ID_EMPTY, expire_rows, id_delete, id_insert, id_lookup

_EXTREMES = [-2 ** 63, 2 ** 63 - 1, -1, 0, 1]
_MULT = 0x9E3779B97F4A7C15  # (the kernels' multiplier)


def _keys_by_home(log_cap: int, per_home: int = 6) -> list:
    """For each entry of a table of ``2^log_cap`` entries, ``per_home`` int64 keys whose home it is (computed here
    in Python's integers: the top bits of ``key * _MULT mod 2^64``), so that a test can crowd chosen entries."""
    homes: list = [[] for _ in range(2 ** log_cap)]
    for k in _EXTREMES + list(range(-3000, 3000)):
        h = ((k % 2 ** 64) * _MULT % 2 ** 64) >> (64 - log_cap)
        if len(homes[h]) < per_home and k not in homes[h]:
            homes[h].append(k)
    assert all(len(h) == per_home for h in homes)
    return homes


_HOMES = {c: _keys_by_home(c) for c in (2, 3, 4)}


@settings(max_examples=80, deadline=None)
@given(log_cap=st.sampled_from([2, 3, 4]), ops=st.lists(st.tuples(
    st.sampled_from(["insert", "insert", "delete"]), st.integers(0, 15), st.integers(0, 5)), min_size=1,
    max_size=150))
def test_id_table_equals_a_dict_over_random_inserts_and_deletes(log_cap, ops):
    cap = 2 ** log_cap
    keys, vals, shift = np.zeros(cap, np.int64), np.full(cap, ID_EMPTY, np.int64), 64 - log_cap
    homes = _HOMES[log_cap]
    ref: dict = {}
    probe = np.array(sorted({k for h in homes for k in h}), np.int64)
    for n_op, (op, home, rank) in enumerate(ops):
        key = homes[home % cap][rank]  # (keys crowding a few entries: long probe runs, wrapping round the end)
        a = np.array([key], np.int64)
        if op == "insert":
            if key not in ref and 2 * (len(ref) + 1) > cap:  # (the table is kept at most half full)
                continue
            ref[key] = n_op
            id_insert(keys, vals, shift, a, np.array([n_op], np.int64))
        else:
            ref.pop(key, None)
            id_delete(keys, vals, shift, a)
        got = np.empty(probe.shape[0], np.int64)
        id_lookup(keys, vals, shift, probe, got)
        want = np.array([ref.get(int(k), -1) for k in probe.tolist()], np.int64)
        assert np.array_equal(got, want), (op, key)
        assert int((vals != ID_EMPTY).sum()) == len(ref)


def test_a_deletion_keeps_an_entry_wrapped_round_the_end_reachable():
    """Pinned: a table of 8 with A at its home 6, B and C homed at 7 (C wrapped to entry 0); deleting A must leave C
    where it is (its home 7 lies between the gap 6 and C's entry 0, cyclically)."""
    h = _HOMES[3]
    keys, vals = np.zeros(8, np.int64), np.full(8, ID_EMPTY, np.int64)
    A, B, C = h[6][0], h[7][0], h[7][1]
    id_insert(keys, vals, 61, np.array([A, B, C], np.int64), np.array([10, 11, 12], np.int64))
    assert vals.tolist() == [12, ID_EMPTY, ID_EMPTY, ID_EMPTY, ID_EMPTY, ID_EMPTY, 10, 11]
    id_delete(keys, vals, 61, np.array([A], np.int64))
    got = np.empty(3, np.int64)
    id_lookup(keys, vals, 61, np.array([A, B, C], np.int64), got)
    assert got.tolist() == [-1, 11, 12]


_T_LAST = st.one_of(st.floats(-5.0, 5.0), st.just(float("nan")), st.sampled_from([float("inf"), -float("inf")]))


@settings(max_examples=120, deadline=None)
@given(t_last=st.lists(_T_LAST, min_size=1, max_size=40), t=st.floats(-6.0, 12.0),
       timeout_s=st.sampled_from([0.0, 0.5, 1.0, 3.0, float("inf")]), table=st.booleans(), data=st.data())
def test_the_deleters_compiled_sweep_is_the_numpy_sweep(t_last, t, timeout_s, table, data):
    """expire_rows against the deleter's numpy form (before 2026-11-29, wave 13): the same rows gone, in row order,
    pushed on the free stack in that order, their t_last NaN, their ids out of the id table (every other id still
    found at its row), and the earliest finite t_last left (inf if none); NaN (free) rows never expire."""
    t_last = np.array(t_last)
    cap = t_last.shape[0]
    live = np.flatnonzero(~np.isnan(t_last))
    ids = np.array(data.draw(st.lists(st.integers(-2 ** 63, 2 ** 63 - 1), min_size=live.size, max_size=live.size,
                                      unique=True)), np.int64)
    size = 1 << max(2, (2 * cap).bit_length())
    id_table = (np.zeros(size, np.int64), np.full(size, ID_EMPTY, np.int64), 64 - (size.bit_length() - 1))
    if table:
        id_insert(*id_table, ids, live.astype(np.int64))
    n_free = data.draw(st.integers(0, cap - live.size))
    free = np.full(cap, -7, np.int64)
    free[:n_free] = np.flatnonzero(np.isnan(t_last))[:n_free]
    want_gone = np.flatnonzero(t - t_last > timeout_s)
    left = np.delete(t_last, want_gone)
    want_oldest = float(left[np.isfinite(left)].min()) if np.isfinite(left).any() else np.inf
    gone, gone_keys = np.full(cap, -9, np.int64), np.empty(cap, np.int64)
    before = t_last.copy()
    m, n_free_after, oldest = expire_rows(t, timeout_s, t_last, free, n_free, gone, gone_keys,
                                          *(id_table if table else (np.zeros(1, np.int64),
                                                                    np.full(1, ID_EMPTY, np.int64), 63)))
    assert gone[:m].tolist() == want_gone.tolist()
    assert n_free_after == n_free + m and free[n_free:n_free_after].tolist() == want_gone.tolist()
    assert np.isnan(t_last[want_gone]).all()
    kept = np.setdiff1d(np.arange(cap), want_gone)
    assert np.array_equal(t_last[kept], before[kept], equal_nan=True)
    assert oldest == want_oldest
    if table:
        got = np.empty(ids.shape[0], np.int64)
        id_lookup(*id_table, ids, got)
        expired = np.isin(live, want_gone)
        assert got.tolist() == np.where(expired, -1, live).tolist()
        assert int((id_table[1] != ID_EMPTY).sum()) == live.size - int(expired.sum())


def test_the_deleters_sweep_pinned():
    """Pinned by hand: rows 0..4 last updated at 0.0, 2.5, NaN (free), 1.2, -inf; at t = 3.0 with a 1.5 s timeout
    rows 0 (3.0 s ago), 3 (1.8 s) and 4 (-inf) expire; row 1 (0.5 s) stays and is the earliest left."""
    t_last = np.array([0.0, 2.5, np.nan, 1.2, -np.inf])
    free = np.array([2, -1, -1, -1, -1], np.int64)
    gone, gk = np.empty(5, np.int64), np.empty(5, np.int64)
    keys, vals = np.zeros(16, np.int64), np.full(16, ID_EMPTY, np.int64)
    id_insert(keys, vals, 60, np.array([70, 71, 73, 74], np.int64), np.array([0, 1, 3, 4], np.int64))
    assert expire_rows(3.0, 1.5, t_last, free, 1, gone, gk, keys, vals, 60) == (3, 4, 2.5)
    assert gone[:3].tolist() == [0, 3, 4] and free.tolist() == [2, 0, 3, 4, -1]
    got = np.empty(4, np.int64)
    id_lookup(keys, vals, 60, np.array([70, 71, 73, 74], np.int64), got)
    assert got.tolist() == [-1, 1, -1, -1]


def _frames(seed: int, count: int):
    """Random frames: ids drawn from a small pool (repeats in a frame, ids coming back after a timeout), some None,
    NaN centres, uneven time steps (gaps beyond the timeout), given as a list or as an int64 array."""
    rng = np.random.default_rng(seed)
    t = 0.0
    pool = 12
    for _ in range(count):
        t += float(rng.choice([0.02, 0.04, 0.1, 0.7]))
        n = int(rng.integers(0, 9))
        ids = rng.integers(-3, pool, n).tolist()
        xy = rng.normal(0.0, 3.0, (n, 2)) + np.array(ids, float).reshape(n, 1) * 10.0
        xy[rng.random(n) < 0.1] = np.nan
        if rng.random() < 0.15 and n:
            ids[int(rng.integers(0, n))] = None
        elif rng.random() < 0.5:
            ids = np.array(ids, np.int64)
        if rng.random() < 0.05:
            pool += 1000  # (a burst of new ids: the compiled table grows)
            ids = list(range(pool - 40, pool)) + list(ids)
            xy = np.vstack([np.zeros((40, 2)), xy])
        yield t, ids, xy


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2 ** 31 - 1))
def test_int_id_lookup_is_the_dictionary_over_frames_with_births_and_deaths(seed):
    cfg = TrackerConfig(timeout_s=0.5)
    fast, slow = TrackTable(cfg, rank=1), TrackTable(cfg, rank=1)
    slow._int_ids, slow._ids = False, None  # (the dictionary's look-up for every frame)
    for t, ids, xy in _frames(seed, 40):
        n = xy.shape[0]
        args = (np.repeat(np.eye(2)[None] * 0.04, n, 0), np.full((n, 2, 1), 0.01))
        ids_slow = ids.tolist() if isinstance(ids, np.ndarray) else list(ids)
        got, want = fast.step(t, ids, xy, *args), slow.step(t, ids_slow, xy, *args)
        for name, g, w in zip(got._fields, got, want, strict=True):
            assert np.array_equal(g, w, equal_nan=g.dtype.kind == "f"), (t, name)
        assert len(fast) == len(slow)
        assert np.array_equal(np.nan_to_num(fast.frame_nis(), nan=-1.0), np.nan_to_num(slow.frame_nis(), nan=-1.0))
    assert fast._int_ids and fast._ids is not None  # (the array frames went through the compiled look-up)
    keys = [k for k in fast._index if k is not None]
    got = np.empty(len(keys), np.int64)
    id_lookup(*fast._ids, np.array(keys, np.int64), got)
    assert got.tolist() == [fast._index[k] for k in keys]


def test_a_non_integer_id_ends_the_compiled_lookup_and_the_tracks_go_on():
    table = TrackTable(TrackerConfig(), rank=0)
    B = np.zeros((2, 2, 0))
    cov = np.repeat(np.eye(2)[None], 2, 0)
    first = table.step(0.0, [5, 7], np.array([[0.0, 0.0], [9.0, 9.0]]), cov, B)
    assert table._int_ids
    out = table.step(0.1, ["a", 7], np.array([[0.0, 0.0], [9.0, 9.1]]), cov, B)
    assert not table._int_ids
    assert out.track_id[1] == first.track_id[1] and out.new_track.tolist() == [True, False]
    out = table.step(0.2, np.array([5, 7]), np.array([[0.0, 0.1], [9.0, 9.2]]), cov, B)
    assert out.track_id.tolist() == first.track_id.tolist() and out.n_updates.tolist() == [2, 3]


def test_class_tracks_hand_each_table_its_part_of_an_int64_array():
    """With a motion model per class (two tables), ids as an int64 array reach each table as its part of the array
    (its compiled look-up), ids as a list as lists (the dictionary's look-up, forced): the same outputs to the bit
    over frames with both classes, absent objects, timeouts and births again."""
    from footprint_uq.tracking.classes import ClassTracks
    per_class = {"truck": TrackerConfig(timeout_s=0.5, accel_psd_m2ps3=0.5, manoeuvre_accel_psd_m2ps3=None)}
    cfg = TrackerConfig(timeout_s=0.5)
    arr, lst = (ClassTracks(cfg, per_class, rank=2) for _ in range(2))
    for table in lst.tables:  # (the dictionary's look-up: a list of integers would be made an int64 array)
        table._int_ids = False
    rng = np.random.default_rng(3)
    start, vel = rng.uniform(-20.0, 20.0, (40, 2)), rng.uniform(-5.0, 5.0, (40, 2))
    for f in range(30):
        t = 0.1 * f
        keep = np.flatnonzero((np.arange(40) + f) % 7 != 0)  # (one in seven absent from each frame)
        if 10 <= f < 18:
            keep = keep[keep < 20]  # (half absent for 0.8 s: timeouts, then births again)
        ids = (keep * 1000 - 7).astype(np.int64)
        classes = ["truck" if i % 3 == 0 else "car" for i in keep]
        xy = start[keep] + t * vel[keep] + rng.normal(0.0, 0.05, (len(keep), 2))
        cov = np.tile(np.eye(2) * 0.04, (len(keep), 1, 1))
        B = np.zeros((len(keep), 2, 2))
        a = arr.step(t, ids, classes, xy, shared_m=B, cov_m2=cov)
        b = lst.step(t, ids.tolist(), classes, xy, shared_m=B, cov_m2=cov)
        for name in a._fields:
            assert np.array_equal(getattr(a, name), getattr(b, name), equal_nan=True), (f, name)
    assert all(len(t._index) > 1 and t._ids is not None for t in arr.tables)  # (both tables: the compiled look-up)
    assert all(t._ids is None for t in lst.tables)
    assert arr.tables[0]._next_id > 30 and arr.tables[1]._next_id > 10  # (births again after the timeouts)


def _at():
    from footprint_uq import PanTiltCamera
    from footprint_uq.tracking import SharedJacobianAt

    cam = PanTiltCamera(focal_px=1400.0, image_size_px=(1920, 1080), height_m=8.0, pan_deg=0.0, tilt_deg=20.0)
    return SharedJacobianAt(cam, "basler1@deg")


_AT: list = []  # (one SharedJacobianAt for the module: its processor's set-up is the costly part)


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2 ** 31 - 1))
def test_the_frame_in_one_compiled_call_is_the_four_calls_to_the_bit(seed):
    """A table whose ``shared_at`` forms ``B`` in the rows' call runs a frame of int64 ids in one compiled call
    (``imm_kernels.frame_step``: the deleter's sweep, the id look-up, the rows, the new ids' rows, the update); the
    same table made to take the separate calls (``expire_rows``, ``id_lookup``, ``frame_rows_shared``,
    ``claim_rows``, ``frame_pass``) gives the same
    outputs, NIS, rows and ids to the bit over frames with births, deaths by timeout, repeated ids, NaN centres,
    ids as int64 arrays and as lists (with None; a list with new ids takes the dictionary and two calls, one
    without takes the one call with the dictionary's rows), and a burst of new ids beyond the free rows and the id
    table's room (the one call stops after the rows, the rest is claimed in Python)."""
    from footprint_uq.tracking import table as table_module

    if not _AT:
        _AT.append(_at())
    at = _AT[0]
    cfg = TrackerConfig(timeout_s=0.5)
    one, four = (TrackTable(cfg, rank=at.rank, shared_at=at) for _ in range(2))
    four._rows_call = lambda int_ids: table_module._ROWS_SHARED  # (the generic order of calls)
    sweeps = {"alone": 0, "all": 0}  # (the deleter's: alone, or in the one call -- for int64 ids)
    alone, swept = one._delete_expired, one._swept
    one._delete_expired = lambda t: sweeps.__setitem__("alone", sweeps["alone"] + 1) or alone(t)
    one._swept = lambda *a: sweeps.__setitem__("all", sweeps["all"] + 1) or swept(*a)
    rng = np.random.default_rng(seed)
    for f, (t, ids, xy) in enumerate(_frames(seed, 40)):
        if f == 20:  # (a burst of new int64 ids beyond the free rows: the one call stops, the table grows)
            ids, xy = np.arange(5000, 5070), np.zeros((70, 2))
        n = xy.shape[0]
        xy = np.column_stack([xy[:, 0] * 0.2, 25.0 + xy[:, 1]])  # (in front of the camera, some out of its view)
        B = rng.normal(0.0, 0.05, (n, 2, at.rank))
        cov = np.repeat(np.eye(2)[None] * 0.04, n, 0) + B @ np.swapaxes(B, 1, 2)
        got = one.step(t, ids, xy, shared_m=B, cov_m2=cov)
        want = four.step(t, ids.copy() if isinstance(ids, np.ndarray) else list(ids), xy, shared_m=B, cov_m2=cov)
        for name, g, w in zip(got._fields, got, want, strict=True):
            assert np.array_equal(g, w, equal_nan=g.dtype.kind == "f"), (t, name)
        assert np.array_equal(one.frame_nis(), four.frame_nis(), equal_nan=True)
        assert one._index == four._index and one._next_id == four._next_id and one._n_free == four._n_free
    assert one._ids is not None and one._cap == four._cap > 64  # (int64 frames, and the table grew)
    assert sweeps["all"] > sweeps["alone"]  # (sweeps in the one call; alone before the dictionary's look-up)
    keys = [k for k in one._index if k is not None]
    got = np.empty(len(keys), np.int64)
    id_lookup(*one._ids, np.array(keys, np.int64), got)
    assert got.tolist() == [one._index[k] for k in keys]


def test_an_int64_frame_with_room_is_one_compiled_call(monkeypatch):
    """With free rows and room in the id table, a frame of int64 ids (new ones among them) calls nothing but
    ``frame_step``, nor does a list of ids that all have rows (None among them) or a list of integers (an int64
    array then); a list with a new id among ids that are not all integers takes the two calls; a frame with more
    new ids than free rows grows the table and claims them after the call."""
    from footprint_uq.tracking import table as table_module

    if not _AT:
        _AT.append(_at())
    at = _AT[0]
    table = TrackTable(TrackerConfig(), rank=at.rank, shared_at=at)
    B = np.zeros((3, 2, at.rank))
    cov = np.repeat(np.eye(2)[None] * 0.04, 3, 0)
    xy = np.array([[0.0, 20.0], [2.0, 25.0], [-3.0, 30.0]])
    table.step(0.0, np.array([4, 5, 6]), xy, shared_m=B, cov_m2=cov)
    calls = []
    for name in ("frame_pass", "frame_rows_shared", "claim_rows", "id_lookup"):
        monkeypatch.setattr(table_module, name, lambda *a, _n=name: calls.append(_n))
    out = table.step(0.1, np.array([4, 7, 6]), xy + 0.1, shared_m=B, cov_m2=cov)
    assert calls == [] and out.new_track.tolist() == [False, True, False] and out.n_updates.tolist() == [2, 1, 2]
    out = table.step(0.2, [4, None, 6], xy + 0.2, shared_m=B, cov_m2=cov)
    assert calls == [] and out.n_updates.tolist() == [3, 0, 3] and out.track_id[1] == -1
    out = table.step(0.25, [4, 9, 6], xy + 0.25, shared_m=B, cov_m2=cov)  # (a list of ints: an int64 array)
    assert calls == [] and out.new_track.tolist() == [False, True, False]
    monkeypatch.undo()
    calls_pass = []
    monkeypatch.setattr(table_module, "frame_pass", lambda *a: calls_pass.append(1) or 9)
    table.step(0.3, [4, 8, None], xy + 0.3, shared_m=B, cov_m2=cov)  # (a new id in a list of other ids: Python's)
    assert calls_pass == [1]
    monkeypatch.undo()
    n = table._n_free + 1
    out = table.step(0.4, np.arange(100, 100 + n), np.zeros((n, 2)) + [0.0, 20.0], shared_m=np.zeros((n, 2, at.rank)),
                     cov_m2=np.repeat(np.eye(2)[None], n, 0))
    assert out.new_track.all() and len(table) == 6 + n and table._cap == 128


def test_strided_and_read_only_int64_ids_take_the_same_compiled_call():
    """int64 ids in a strided view or a read-only array (a scanner's buffer) are copied, not compiled for: the one
    call keeps its one signature, and the tracks are those of the same ids in a plain array."""
    from footprint_uq.tracking.imm_kernels import frame_step

    if not _AT:
        _AT.append(_at())
    at = _AT[0]
    plain, other = (TrackTable(TrackerConfig(), rank=at.rank, shared_at=at) for _ in range(2))
    B = np.zeros((3, 2, at.rank))
    cov = np.repeat(np.eye(2)[None] * 0.04, 3, 0)
    xy = np.array([[0.0, 20.0], [2.0, 25.0], [-3.0, 30.0]])
    read_only = np.array([4, 5, 6])
    read_only.flags.writeable = False
    for k, ids in enumerate((np.array([4, 0, 5, 0, 6])[::2], read_only)):
        got = other.step(0.1 * k, ids, xy + 0.1 * k, shared_m=B, cov_m2=cov)
        want = plain.step(0.1 * k, np.array([4, 5, 6]), xy + 0.1 * k, shared_m=B, cov_m2=cov)
        for name, g, w in zip(got._fields, got, want, strict=True):
            assert np.array_equal(g, w, equal_nan=g.dtype.kind == "f"), (k, name)
    assert got.n_updates.tolist() == [2, 2, 2] and len(frame_step.signatures) == 1


@pytest.mark.parametrize("ids, made", [
    ([3, 4, 5], True), ([np.int64(3), 4], True), ([True, 4], True),  # (a bool: the integer's key, as in the dict)
    ([3, None], False), ([3, 4.0], False), ([3, "a"], False), ([2 ** 63, 1], False), ([-1, 2 ** 63], False),
    ([3, [4]], False)])
def test_a_list_of_integers_is_made_the_int64_ids_and_nothing_else(ids, made):
    from footprint_uq.tracking.table import _list_int64

    got = _list_int64(ids)
    assert (got is not None) == made
    if made:
        assert got.dtype == np.int64 and got.tolist() == [int(i) for i in ids]


@pytest.mark.parametrize("ids, made", [
    (np.array([3, -4], np.int32), True), (np.array([3, 4], np.uint8), True), (np.array([3, 4], np.int16), True),
    (np.array([3, 2 ** 63 - 1], np.uint64), True), (np.array([3, 2 ** 63], np.uint64), False),
    (np.array([], np.uint64), True), (np.array([3.0, 4.0]), False), (np.array([True, False]), False),
    (np.array([[3, 4]]), False), (np.array(["3", "4"]), False)])
def test_an_integer_array_of_any_width_takes_the_compiled_look_up(ids, made):
    """A reader's int32 (or uint8 ...) ids become the int64 ids (values equal, hashes equal: the same keys as the
    dictionary's), not a list for the dictionary; uint64 beyond int64's range, floats, bools, 2-d or text do not."""
    from footprint_uq.tracking.table import _int64_ids

    got = _int64_ids(ids)
    assert (got is not None) == made
    if made:
        assert got.dtype == np.int64 and got.flags.c_contiguous and got.tolist() == [int(i) for i in ids]


def test_int32_ids_and_a_list_of_numpy_integers_track_as_the_int64_ids():
    """The same frames with the ids as int64, int32 and a list of numpy int64 scalars: the same outputs, and the
    compiled id table holds them (no dictionary frames)."""
    tables = [TrackTable(TrackerConfig(timeout_s=0.5), rank=1) for _ in range(3)]
    for t, ids, xy in _frames(11, 30):
        ids = [i for i in (ids.tolist() if isinstance(ids, np.ndarray) else ids) if i is not None]
        xy = xy[:len(ids)]
        n = len(ids)
        args = (np.repeat(np.eye(2)[None] * 0.04, n, 0), np.full((n, 2, 1), 0.01))
        a64 = np.array(ids, np.int64)
        outs = [tab.step(t, form, xy, *args) for tab, form in zip(tables, (a64, a64.astype(np.int32),
                                                                         list(a64)), strict=True)]
        for o in outs[1:]:
            for name, g, w in zip(o._fields, o, outs[0], strict=True):
                assert np.array_equal(g, w, equal_nan=g.dtype.kind == "f"), (t, name)
    assert all(tab._int_ids and tab._ids is not None for tab in tables)
