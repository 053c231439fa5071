"""The messages' building blocks, pinned against the standards' rules (the official-module sweep is
test_cpm_official.py): message object ids, CartesianCoordinateLarge, motion conversions, VRU classes."""

from __future__ import annotations

import uuid

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from footprint_uq import PanTiltCamera
from footprint_uq.errors import InputError
from footprint_uq.service import Service
from footprint_uq.service.messages.cpm import CPM_CLASSES_BY_CDD, coordinate_cm
from footprint_uq.service.messages.ids import MESSAGE_ID_HOLD_S, MessageIdMap, preferred_number
from footprint_uq.service.messages.motion import (
    MOTION_ROWS,
    CodedMotion,
    ObjectMotion,
    coded,
    codes_pass,
    motion_codes,
    motion_codes_reference,
    motion_rows,
    unknown_motion,
)

T0 = 1714564800.0


# -- object ids --------------------------------------------------------------------------------------------------
def test_ids_are_unique_per_message_and_stable_across_frames():
    """255 UUID ids per frame for 20 frames (the issue's case: duplicates in 9 of 20 frames before): every
    message has 255 distinct ids, and an id seen again keeps its number."""
    rng = np.random.default_rng(1)
    pool = [str(uuid.UUID(int=int(rng.integers(0, 2 ** 63)))) for _ in range(600)]
    m = MessageIdMap()
    first = {}
    for f in range(20):
        ids = [pool[i] for i in rng.choice(600, 255, replace=False)]
        nums = m.assign(ids, np.arange(255), T0 + f / 30).tolist()
        assert len(set(nums)) == 255, f
        for oid, num in zip(ids, nums, strict=True):
            assert first.setdefault(oid, num) == num  # stable
    # the numbers of different ids never coincide while they are held
    assert len(set(first.values())) == len(first)


def test_integer_and_text_ids_are_distinct_and_collisions_resolved():
    m = MessageIdMap()
    a = m.assign([7, "7", 7, None, None], range(5), T0).tolist()
    assert a[0] == 7 and len(set(a)) == 5  # int 7 keeps 7; "7", the second 7 and the null ids get others
    b = m.assign(["7", "q", 7, None], range(4), T0 + 1).tolist()
    assert [b[0], b[2], b[3]] == [a[1], a[0], a[3]]  # same ids -> same numbers (a null id: the same index)
    # a text id whose hash asks for a number another id holds gets the next free one
    text = next(f"x{k}" for k in range(10 ** 6) if preferred_number(f"x{k}") == 7)
    c = m.assign([text, 7], range(2), T0 + 2).tolist()
    held = set(a) | set(b)
    assert c == [next(k for k in range(8, 65536) if k not in held), 7]


def test_numbers_are_released_only_after_the_hold_time():
    m = MessageIdMap()
    assert m.assign([100], [0], T0).tolist() == [100]
    text = next(f"y{k}" for k in range(10 ** 6) if preferred_number(f"y{k}") == 100)
    assert m.assign([text], [0], T0 + MESSAGE_ID_HOLD_S / 2).tolist() == [101]  # 100 still held
    assert m.assign([text, 100], [0, 1], T0 + MESSAGE_ID_HOLD_S / 2 + 1).tolist() == [101, 100]
    late = m.assign(["z"], [0], T0 + 3 * MESSAGE_ID_HOLD_S)  # everything expired meanwhile
    assert len(m) == 1 and late.tolist() == [preferred_number("z")]


@settings(max_examples=60, deadline=None)
@given(frames=st.lists(st.lists(st.one_of(st.integers(-3, 70000), st.text(max_size=3), st.none()), max_size=40),
                       min_size=1, max_size=6))
def test_ids_unique_in_every_message(frames):
    m = MessageIdMap()
    for f, ids in enumerate(frames):
        nums = m.assign(ids, np.arange(len(ids)), T0 + f).tolist()
        assert len(set(nums)) == len(ids) and all(0 <= n <= 65535 for n in nums)


def test_service_record_ids_follow_the_map():
    cam = PanTiltCamera(focal_px=1400, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)
    svc = Service(cam, "basler1")
    det = {"u_min_px": 900.0, "v_min_px": 600.0, "u_max_px": 960.0, "v_max_px": 700.0}
    dets = [{**det, "object_id": i} for i in (7, "7", "abc", 7)]
    recs = [svc.process_frame({"frame": f, "timestamp_s": T0 + f, "detections": dets[::-1] if f else dets})
            for f in range(2)]
    ids = [[o["message_object_id"] for o in r["objects"]] for r in recs]
    assert len(set(ids[0])) == 4 and ids[0][0] == 7
    # reversed order: the same object ids keep their numbers ("7" and "abc" exactly; the two 7s are the first and
    # second occurrence, so they swap with the order)
    assert ids[1][2] == ids[0][1] and ids[1][1] == ids[0][2] and sorted(ids[1]) == sorted(ids[0])


# -- CartesianCoordinateLarge ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("v_m, n", [(0.0, 0), (0.07, 7), (0.0701, 8), (0.004, 1), (-0.004, 0), (-0.01, -1),
                                    (-0.0101, -1), (12.34, 1234), (1310.70, 131070), (1310.7001, 131071),
                                    (5000.0, 131071), (-1310.71, -131071), (-1310.7101, -131071), (-1310.7201, -131072),
                                    (-1310.72, -131072), (-9999.0, -131072)])
def test_cartesian_coordinate_large_is_the_cdds_ceiling(v_m, n):
    """TS 102 894-2 (V2.1.1 and V2.2.1), DE CartesianCoordinateLarge: n if n x 0.01 m >= v > (n-1) x 0.01 m;
    -131072 at or below -1310.72 m, 131071 above 1310.70 m."""
    assert int(coordinate_cm(v_m)) == n


# -- motion ---------------------------------------------------------------------------------------------------------
def _one(**kw):
    m = unknown_motion(1)._asdict()
    for k, v in kw.items():
        m[k] = np.array([v], dtype=float) if k != "cov_v_m2ps2" else np.array([v], dtype=float)
    return motion_codes(ObjectMotion(**m), 1)


def test_motion_codes_pinned_values():
    c = _one(v_east_mps=1.234, v_north_mps=-0.004, cov_v_m2ps2=[[0.25, 0.0], [0.0, 1.0]])
    assert c.has_velocity[0] and (c.vx[0], c.vy[0]) == (124, 0)  # ceil: 1.234 -> 124, -0.004 -> 0
    assert (c.vx_conf[0], c.vy_conf[0]) == (98, 126)  # 1.96 x 0.5 = 0.98 m/s; 1.96 m/s > 1.25: out of range
    assert _one(v_east_mps=200.0).vx[0] == 16382 and _one(v_east_mps=-200.0).vx[0] == -16383
    assert _one(v_east_mps=1.0).vy[0] == 16383 and _one(v_east_mps=1.0).vx_conf[0] == 127  # unknown parts
    assert not _one().has_velocity[0] and not _one().has_yaw[0] and not _one().has_age[0]
    # yaw: compass (clockwise from north) -> CartesianAngleValue (counter-clockwise from east), 0.1 deg, ceil
    for yaw, z in ((0.0, 900), (90.0, 0), (180.0, 2700), (270.0, 1800), (359.99, 901), (89.99, 1), (-90.0, 1800)):
        assert _one(yaw_deg=yaw).yaw[0] == z, yaw
    assert _one(yaw_deg=10.0, sigma_yaw_deg=1.0).yaw_conf[0] == 20  # 1.96 deg -> 20 x 0.1
    assert _one(yaw_deg=10.0, sigma_yaw_deg=7.0).yaw_conf[0] == 126 and _one(yaw_deg=1.0).yaw_conf[0] == 127
    assert _one(age_s=0.7499).age_ms[0] == 749 and _one(age_s=9.0).age_ms[0] == 2047
    # SDSM: J2735 Speed 0.02 m/s, Heading 0.0125 deg, the confidences' tightest level >= 1.96 sigma
    s = _one(speed_mps=10.01, sigma_speed_mps=0.3, heading_deg=45.0, sigma_heading_deg=0.006)
    assert (s.sdsm_speed[0], s.sdsm_heading[0]) == (500, 3600)
    assert s.sdsm_speed_conf[0] == 4  # 0.588 m/s -> prec1ms
    assert s.sdsm_heading_conf[0] == 7  # 0.01176 deg -> prec0-0125deg (0.01 deg would understate it)
    assert _one(heading_deg=-0.005).sdsm_heading[0] == 0 and _one(speed_mps=1.0).sdsm_speed_conf[0] == 0
    assert _one(speed_mps=1.0, sigma_speed_mps=60.0).sdsm_speed_conf[0] == 0  # 117.6 m/s: no level holds it


def test_motion_checks_name_the_field():
    m = unknown_motion(2)
    with pytest.raises(InputError, match="motion.sigma_yaw_deg"):
        motion_codes(m._replace(sigma_yaw_deg=np.array([1.0, -1.0])), 2)
    with pytest.raises(InputError, match="motion.v_east_mps"):
        motion_codes(m._replace(v_east_mps=np.zeros(3)), 2)
    with pytest.raises(InputError, match="motion.heading_deg"):
        motion_codes(m._replace(heading_deg=np.array([np.inf, 0.0])), 2)


def _random_motion(rng, n):
    """n objects' motion over and beyond every field's range, NaN in 20 % of each field, a tenth of the values on
    the fields' steps (0.01 m/s, ...)."""
    def col(lo, hi):
        a = rng.uniform(lo, hi, n)
        k = rng.random(n) < 0.1
        a[k] = np.round(a[k], 2)
        a[rng.random(n) < 0.2] = np.nan
        return a
    cov = np.zeros((n, 2, 2))
    cov[:, 0, 0], cov[:, 1, 1] = col(0, 2), col(0, 2)
    cov[:, 0, 1] = cov[:, 1, 0] = col(-0.5, 0.5)
    return ObjectMotion(col(-200, 200), col(-200, 200), cov, col(0, 300), col(0, 60), col(-720, 720), col(0, 12),
                        col(-720, 720), col(0, 20), col(0, 5))


def test_motion_codes_compiled_equals_the_numpy_reference():
    """The compiled pass gives the numpy reference's codes value for value (ceil / rint / mod at the steps, NaN,
    beyond range) and the same error for the same first bad field."""
    rng = np.random.default_rng(8)
    for _ in range(40):
        m = _random_motion(rng, 120)
        got, want = motion_codes(m, 120), motion_codes_reference(m, 120)
        for name, a, b in zip(got._fields, got, want, strict=True):
            assert a.dtype == b.dtype and np.array_equal(a, b), name
    m = _random_motion(rng, 5)
    for field, value in (("age_s", -1.0), ("speed_mps", -0.5), ("yaw_deg", -np.inf), ("v_north_mps", np.inf)):
        bad = m._replace(**{field: np.where(np.arange(5) == 3, value, getattr(m, field))})
        with pytest.raises(InputError) as e1:
            motion_codes(bad, 5)
        with pytest.raises(InputError) as e2:
            motion_codes_reference(bad, 5)
        assert str(e1.value) == str(e2.value) and f"motion.{field}" in str(e1.value)


def _reference_rows(m: ObjectMotion, n: int) -> np.ndarray:
    """motion_codes_reference's fields as motion_rows' (14, n) int64 rows (MOTION_ROWS' order)."""
    ref = motion_codes_reference(m, n)
    return np.array([getattr(ref, name) for name in MOTION_ROWS], dtype=np.int64)


def _edge_motion() -> ObjectMotion:
    """One object per edge of the codes: velocities at and beside the CPM's bounds (163.81 / -163.83 m/s) and
    steps, SDSM speeds at and beyond 8190 x 0.02 m/s, headings / yaws at the wrap and the steps, sigmas whose 95 %
    value sits on a confidence level or just above it, ages at 2.047 s, NaN (unknown) in every field."""
    ve = [163.81, 163.8099, -163.83, -163.8299, 0.01, -0.01, 0.0, np.nan, 1.0, np.nan, 2.5, 7.0]
    vn = [0.0, 163.81, 163.82, -163.84, 0.02, np.nan, -0.0, np.nan, np.nan, 1.0, 1e-12, -7.0]
    sp = [163.8, 163.81, 163.79, 0.01, 0.0, np.nan, 1e9, 0.02, 0.03, 5.0, 0.0101, 2.0]
    hd = [359.995, 359.99375, 0.00625, -0.00625, 360.0, -360.0, 720.0125, np.nan, 90.0, 180.0, 0.0, 45.0]
    yw = [90.0, 89.99, 90.01, 0.0, 359.99, -90.0, 450.0, np.nan, 180.05, 270.0, 0.05, 12.3]
    lv = np.array([100.0, 10.0, 5.0, 1.0, 0.1, 0.05, 0.01]) / 1.96
    ssp = [lv[0], lv[0] * 1.001, lv[3], lv[3] * 1.0001, lv[6], lv[6] * 0.5, 0.0, np.nan, lv[4], lv[5], 1.25 / 1.96,
           60.0]
    shd = [10.0 / 1.96, 5.0 / 1.96, 0.0125 / 1.96, 0.01 / 1.96, 0.0, np.nan, 0.05 / 1.96, 11.0, 0.1 / 1.96, 1.0,
           0.011 / 1.96, 0.5]
    syw = [12.5 / 1.96, 12.6 / 1.96, 0.0, 0.1 / 1.96, 0.05 / 1.96, np.nan, 1.0, 100.0, 0.2 / 1.96, 2.0, 0.3, 6.0]
    age = [2.047, 2.0475, 2.046999, 0.0, 0.0009999, np.nan, 1e6, 0.5, 1.5, 0.001, 0.0125, 3.0]
    n = len(ve)
    sv = np.array([1.25 / 1.96, 1.26 / 1.96, 0.01 / 1.96, 0.0, np.nan, 0.5, 0.02 / 1.96, 0.64, 0.1, 0.2, 1e-9, 3.0])
    cov = np.zeros((n, 2, 2))
    cov[:, 0, 0], cov[:, 1, 1] = sv ** 2, sv[::-1] ** 2
    return ObjectMotion(*(np.array(a, dtype=float) for a in (ve, vn)), cov,
                        *(np.array(a, dtype=float) for a in (sp, ssp, hd, shd, yw, syw, age)))


def test_motion_rows_are_the_reference_codes_at_the_edges_and_in_any_order():
    """motion_rows (one compiled pass from the motion's columns; the service's compact CPM takes its first 10
    rows) gives the numpy reference's codes value for value: at the codes' bounds and steps, NaN fields, random
    motion over and beyond every range; and with ``rows`` the codes of those objects in that order (repeats, a
    subset, none) -- what motion.take(rows) then the codes gave."""
    m = _edge_motion()
    n = len(m.age_s)
    got = motion_rows(m, n)
    assert got.shape == (14, n) and got.dtype == np.int64 and got.flags.c_contiguous
    np.testing.assert_array_equal(got, _reference_rows(m, n))
    # a few pinned by hand: 163.81 m/s -> 16382 (max), -163.83 -> -16383 (min), 0.01 -> 1, unknown -> 16383;
    # SDSM speed 163.8 m/s -> 8190, beyond -> 8190; heading 359.995 deg -> 28799.6 -> 28800 -> 0 (wraps)
    assert list(got[1, [0, 2, 4, 7]]) == [16382, -16383, 1, 16383]
    assert list(got[10, [0, 1, 5]]) == [8190, 8190, 8191] and got[12, 0] == 0 and got[12, 7] == 28800
    assert list(got[9, [0, 1, 5]]) == [2047, 2047, 0] and list(got[8, [0, 5]]) == [1, 0]
    assert got[6, 0] == 0 and got[6, 7] == 3601 and got[5, 7] == 0  # yaw 90 (east) -> 0; unknown -> 3601
    rng = np.random.default_rng(31)
    for k in range(20):
        r = _random_motion(rng, 300)
        rows = rng.permutation(300)[:rng.integers(0, 300)] if k % 3 else rng.integers(0, 300, 400)
        want = _reference_rows(r.take(rows), len(rows))
        np.testing.assert_array_equal(motion_rows(r, 300, rows), want)
        np.testing.assert_array_equal(motion_rows(r, 300, rows)[:, :0], want[:, :0])
        np.testing.assert_array_equal(motion_rows(r, 300), _reference_rows(r, 300))
    # fields that are not C-contiguous float64 (a column of a wider array, float32, lists) give the same codes
    wide = np.stack([m.v_east_mps, m.v_north_mps], axis=1)
    odd = m._replace(v_east_mps=wide[:, 0], speed_mps=m.speed_mps.astype(np.float32),
                     age_s=list(m.age_s))
    np.testing.assert_array_equal(motion_rows(odd, n), _reference_rows(odd, n))


def test_motion_rows_name_the_first_bad_field_of_the_objects_it_codes():
    """The check's order is motion_codes_reference's (field by field, then object by object), in one pass: a later
    object bad in an earlier field is named before an earlier object bad in a later field; an object outside
    ``rows`` is not checked; a bad shape or index is named."""
    m = unknown_motion(6)
    bad = m._replace(yaw_deg=np.array([0.0, np.inf, 0.0, 0.0, 0.0, 0.0]),
                     age_s=np.array([0.0, 0.0, 0.0, -2.0, -1.0, 0.0]))
    for fn in (lambda mm, k, rows=None: motion_rows(mm, k, rows), motion_codes):
        with pytest.raises(InputError) as e:
            fn(bad, 6)
        assert "motion.age_s" in str(e.value) and "-2.0" in str(e.value)
    with pytest.raises(InputError) as e2:
        motion_codes_reference(bad, 6)
    with pytest.raises(InputError) as e1:
        motion_rows(bad, 6)
    assert str(e1.value) == str(e2.value)
    with pytest.raises(InputError, match="motion.yaw_deg"):
        motion_rows(bad, 6, np.array([0, 1, 2]))  # (rows 3 and 4, the bad ages, not coded)
    with pytest.raises(InputError, match="-1.0"):
        motion_rows(bad, 6, np.array([4, 3]))  # (the first of the objects coded)
    assert motion_rows(bad, 6, np.array([5, 0, 2])).shape == (14, 3)
    with pytest.raises(InputError, match="motion.cov_v_m2ps2"):
        motion_rows(m._replace(cov_v_m2ps2=np.zeros((6, 2))), 6)
    with pytest.raises(InputError, match="rows"):
        motion_rows(m, 6, np.array([0, 6]))
    with pytest.raises(InputError, match="rows"):
        motion_rows(m, 6, np.array([-1]))


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64).view(np.int64)


def test_a_coded_motion_gives_its_codes_to_one_motion_rows(monkeypatch):
    """A CodedMotion keeping the codes of its arrays (as coded() keeps the codes pass's) hands the next motion_rows
    the codes an ObjectMotion of the same arrays gets -- every object, a subset, repeats, none; C-contiguous int64
    -- without a second pass (the kernel made to fail), once (the call after computes them again); codes of
    another count are not taken; a CodedMotion without codes is checked as any motion (a bad value named)."""
    from footprint_uq.service.messages import motion as mm

    def no_pass(*args):
        raise AssertionError("a second pass over the motion")

    rng = np.random.default_rng(12)
    for k in range(12):
        m = _random_motion(rng, 150)
        rows = None if k % 3 == 0 else rng.permutation(150)[:rng.integers(0, 150)] if k % 3 == 1 else \
            rng.integers(0, 150, 200)
        want = motion_rows(m, 150, rows)
        kept = CodedMotion.of(m)
        kept.codes = motion_rows(m, 150)
        assert kept == m
        with monkeypatch.context() as mp:
            mp.setattr(mm, "_rows_kernel", no_pass)
            got = motion_rows(kept, 150, rows)
        assert got.dtype == np.int64 and got.flags.c_contiguous and np.array_equal(got, want)
        assert kept.codes is None
        np.testing.assert_array_equal(motion_rows(kept, 150, rows), want)
    plain = _random_motion(rng, 4)
    other = CodedMotion.of(plain)
    other.codes = np.zeros((14, 3), np.int64)  # (of 3 objects: not these 4)
    np.testing.assert_array_equal(motion_rows(other, 4), motion_rows(plain, 4))
    bad = CodedMotion.of(plain._replace(age_s=np.array([0.0, 0.0, -2.0, 0.0])))
    with pytest.raises(InputError, match="motion.age_s"):
        motion_rows(bad, 4)
    np.testing.assert_array_equal(motion_rows(bad, 4, np.array([3, 0])), _reference_rows(bad.take([3, 0]), 2))


def test_the_codes_pass_gives_object_motion_to_the_bit_and_keeps_its_codes():
    """object_motion with codes_pass' motion_pass (the service's tracked frame, through CameraTracker.step_frame:
    the motion fields and the messages' codes in one compiled call) gives object_motion's ten arrays bit for bit --
    tracks with and without a velocity, velocities at zero, heading offsets, 3-D boxes' yaw as a strided column or
    none -- and coded() keeps the codes motion_rows gives the plain motion; a track output with a bad value keeps
    none, and motion_rows names it as for the plain motion; a pass of another size keeps none."""
    from footprint_uq.tracking import object_motion
    from footprint_uq.tracking.table import TrackOutput

    rng = np.random.default_rng(21)
    n = 90
    a = rng.normal(0.0, 0.7, (n, 2, 2))
    cov = a @ np.swapaxes(a, 1, 2)
    v = rng.normal(0.0, 6.0, (n, 2))
    v[rng.random(n) < 0.2] = np.nan  # (no velocity yet)
    v[:5] = 0.0
    cov[np.isnan(v[:, 0])] = np.nan
    age = rng.uniform(0.0, 4.0, n)
    tracks = TrackOutput(np.arange(n), np.zeros(n, bool), np.full(n, 3), age, rng.normal(0.0, 9.0, (n, 2)),
                         cov.copy(), v, cov)
    boxes = rng.normal(0.0, 1.0, (n, 7))
    for h in (0.0, 12.5, -123.25):
        for yaw in (None, boxes[:, 6]):
            want = object_motion(tracks, heading_offset_deg=h, yaw_rad=yaw)
            p = codes_pass(n)
            got = coded(object_motion(tracks, heading_offset_deg=h, yaw_rad=yaw, motion_pass=p), p)
            assert type(got) is CodedMotion
            for name, g, w in zip(want._fields, got, want, strict=True):
                assert g.shape == w.shape and np.array_equal(_bits(g), _bits(w)), (h, name)
            assert got.age_s is not tracks.age_s and np.array_equal(got.codes, motion_rows(want, n))
            np.testing.assert_array_equal(motion_rows(got, n, np.array([4, 0, 4])), motion_rows(want, n)[:, [4, 0, 4]])
    bad = tracks._replace(age_s=np.where(np.arange(n) == 7, -1.0, age))
    p = codes_pass(n)
    got = coded(object_motion(bad, heading_offset_deg=3.0, motion_pass=p), p)
    assert got.codes is None
    with pytest.raises(InputError) as e1:
        motion_rows(got, n)
    with pytest.raises(InputError) as e2:
        motion_rows(object_motion(bad, heading_offset_deg=3.0), n)
    assert str(e1.value) == str(e2.value) and "motion.age_s" in str(e1.value)
    p = codes_pass(n - 1)
    assert coded(object_motion(tracks, motion_pass=p), p).codes is None


def test_the_container_kernel_takes_motion_rows_as_they_are():
    """uper_cpm.kernel_motion hands motion_rows' first 10 rows to the container kernel without a copy (the same
    container bytes as from the ObjectMotion or its MotionCodes), and names an array of another shape."""
    from footprint_uq.service.messages.uper_cpm import kernel_motion, perceived_object_container_uper_arrays

    m = _edge_motion()
    n = len(m.age_s)
    rows = motion_rows(m, n)
    got, with_motion = kernel_motion(rows, n)
    assert with_motion and np.shares_memory(got, rows) and got.flags.c_contiguous and got.shape == (10, n)
    np.testing.assert_array_equal(got, kernel_motion(motion_codes(m, n), n)[0])
    one = np.ones(n, np.int64)
    cols = (np.arange(n), one, one, one, one, np.full(n, 101), 0 * one, 0 * one, one)
    assert (perceived_object_container_uper_arrays(*cols, motion=rows)
            == perceived_object_container_uper_arrays(*cols, motion=m))
    for wrong in (rows[:10], rows[:, :3], rows.astype(np.int32), np.asfortranarray(rows)):
        with pytest.raises(InputError, match="motion"):
            kernel_motion(wrong, n)


# -- classes ---------------------------------------------------------------------------------------------------------
def test_vru_classes_per_release():
    for cdd, ped, bike, moto, dog in (("2.1.1", "ordinary-pedestrian", "bicyclist", "motorcycle", "unavailable"),
                                      ("2.2.1", 1, 1, 2, 0)):
        c = CPM_CLASSES_BY_CDD[cdd]
        assert c["pedestrian"] == {"vruSubClass": {"pedestrian": ped}}
        assert c["bicycle"] == c["cyclist"] == {"vruSubClass": {"bicyclistAndLightVruVehicle": bike}}
        assert c["motorcycle"] == {"vruSubClass": {"motorcyclist": moto}}
        assert c["dog"] == {"vruSubClass": {"animal": dog}}
        assert c["car"] == {"vehicleSubClass": 5}


def test_the_array_writer_takes_object_motion_or_its_codes():
    from footprint_uq.service.messages.uper_cpm import perceived_object_container_uper_arrays

    rng = np.random.default_rng(4)
    n = 7
    cov = np.zeros((n, 2, 2))
    cov[:, 0, 0] = cov[:, 1, 1] = 0.04
    m = ObjectMotion(rng.uniform(-20, 20, n), rng.uniform(-20, 20, n), cov, rng.uniform(0, 20, n),
                     np.full(n, 0.2), rng.uniform(0, 360, n), np.full(n, 2.0), rng.uniform(0, 360, n),
                     np.full(n, 1.0), rng.uniform(0, 5, n))
    one = np.ones(n, np.int64)
    cols = (np.arange(n), one, one, one, one, np.full(n, 101), 0 * one, 0 * one, one)
    with_motion = perceived_object_container_uper_arrays(*cols, motion=m)
    assert with_motion == perceived_object_container_uper_arrays(*cols, motion=motion_codes(m, n))
    assert len(with_motion) > len(perceived_object_container_uper_arrays(*cols))  # 78 more bits per object


def test_the_codes_wrap_as_np_mod_does():
    """The codes' pass wraps headings and yaws by a branch where the value is in [0, period) already (_wrap_k):
    np.mod's value everywhere (its -0.0 kept as -0.0, which a code's int makes 0 as np.mod's +0.0), so the codes are
    the reference's at the wrap's edges, their neighbours and far outside."""
    from footprint_uq.service.messages.motion import _wrap_k

    edges = [0.0, -0.0, 5e-324, -5e-324, 0.0125, 359.99375, 359.995, 360.0, -360.0, 720.0, 1e17, -1e17]
    xs = np.array(edges + [np.nextafter(e, d) for e in edges for d in (-np.inf, np.inf)] + [np.nan, np.inf, -np.inf])
    for period in (360.0, 3600.0, 28800.0):
        for x in xs:
            with np.errstate(invalid="ignore"):
                got, want = _wrap_k(x, period), np.mod(x, period)
            assert (got == want or np.isnan(got) and np.isnan(want)) and (x == 0.0 or np.signbit(got) == np.signbit(
                want)), (x, period)
    n = len(xs) - 2  # (the infinite ones are bad values: named, not coded)
    m = ObjectMotion(*(np.full(n, 1.0) for _ in range(2)), np.zeros((n, 2, 2)), np.full(n, 1.0), np.full(n, 0.1),
                     xs[:n], np.full(n, 0.5), 90.0 - xs[:n], np.full(n, 0.5), np.full(n, 1.0))
    np.testing.assert_array_equal(motion_rows(m, n), _reference_rows(m, n))
