"""The CP basic service's rules (service/cp_rules.py): generation events, object inclusion, segmentation."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from footprint_uq.errors import InputError
from footprint_uq.service.cp_rules import MAX_SEGMENTS, CpRules, GenerationClock, InclusionMemory, plan_segments


def test_rules_refuse_what_the_standard_does_not_allow():
    for kw, name in [({"t_gen_cpm_s": 0.05}, "t_gen_cpm_s"), ({"t_gen_cpm_s": float("nan")}, "t_gen_cpm_s"),
                     ({"t_gen_cpm_s": 1.5}, "t_gen_cpm_s"), ({"t_gen_cpm_max_s": 0.05}, "t_gen_cpm_max_s"),
                     ({"position_change_m": float("inf")}, "position_change_m"),
                     ({"speed_change_mps": 0.0}, "speed_change_mps"), ({"max_size_bytes": 10}, "max_size_bytes")]:
        with pytest.raises(InputError, match=name):
            CpRules(**kw)


@pytest.mark.parametrize("t_gen_s", [0.1, 0.25, 1.0])
def test_events_fall_every_t_gen_cpm_on_a_fixed_grid_whatever_the_frame_rate(t_gen_s):
    clock = GenerationClock(CpRules(t_gen_cpm_s=t_gen_s))
    rng = np.random.default_rng(3)
    t = np.cumsum(np.full(600, 1 / 30) + rng.uniform(-0.004, 0.004, 600))  # 20 s of 30 Hz frames with jitter
    events = t[[clock.tick(x) for x in t]]
    assert len(events) == pytest.approx((t[-1] - t[0]) / t_gen_s, abs=1.01)
    # no drift: event k is the first frame at or after t0 + k T
    grid = t[0] + t_gen_s * np.arange(len(events))
    assert np.all(events >= grid - 1e-9) and np.all(events - grid < 1 / 30 + 0.01)


@pytest.mark.parametrize("t_gen_s", [0.1, 0.2, 0.3])
def test_frames_on_the_grid_in_unix_seconds_are_events_where_the_grid_says(t_gen_s):
    """Unix times near 1.7e9 s resolve to ~2.4e-7 s: a frame on the grid (10 Hz frames, T0 + i / 10) is the event
    it is on, never one frame late; and the sent-interval rules hold at their boundary in unix time."""
    t0 = 1714564800.0
    t = t0 + np.arange(300) / 10.0
    clock = GenerationClock(CpRules(t_gen_cpm_s=t_gen_s))
    events = np.flatnonzero([clock.tick(x) for x in t])
    step = round(t_gen_s * 10)
    assert events.tolist() == list(range(0, 300, step))
    clock = GenerationClock(CpRules(t_gen_cpm_s=0.1, t_gen_cpm_max_s=0.3))
    clock.sent(t[0], sensor_info=True)
    assert clock.must_send(t[3]) and clock.sensor_info_due(t[10]) and not clock.sensor_info_due(t[9])


def test_a_cpm_is_owed_at_least_every_t_gen_cpm_max_and_sensor_information_once_a_second():
    clock = GenerationClock(CpRules(t_gen_cpm_s=0.1, t_gen_cpm_max_s=0.5))
    assert clock.must_send(0.0) and clock.sensor_info_due(0.0)
    clock.sent(0.0, sensor_info=True)
    assert not clock.must_send(0.4) and clock.must_send(0.5)
    clock.sent(0.5, sensor_info=False)
    assert not clock.sensor_info_due(0.9) and clock.sensor_info_due(1.0)


def _run(memory, speeds, headings, xy, t, vru=False):
    sent = []
    for k, tk in enumerate(t):
        inc = memory.select(tk, [7], xy[k][None], [speeds[k]], [headings[k]], [vru])
        if inc[0]:
            memory.included(tk, [7], xy[k][None], [speeds[k]], [headings[k]])
            sent.append(round(tk, 6))
    return sent


def test_inclusion_follows_each_rule():
    t = np.round(np.arange(0, 3.0001, 0.1), 6)
    zero = np.zeros(len(t))
    parked = _run(InclusionMemory(), zero, zero, np.zeros((len(t), 2)), t)
    assert parked == [0.0, 1.0, 2.0, 3.0]                       # the 1 s rule only
    walker = _run(InclusionMemory(), zero, zero, np.zeros((len(t), 2)), t, vru=True)
    assert walker == [0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0]        # persons and animals: 0.5 s
    v = 10.0
    moving = _run(InclusionMemory(), zero + v, zero, np.column_stack([v * t, zero]), t)
    assert moving == [0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0]        # > 4 m after 0.5 s (4 m at 0.4 s is not > 4)
    fast = _run(InclusionMemory(), zero + 50.0, zero, np.column_stack([50.0 * t, zero]), t)
    assert fast == list(t)                                      # 5 m per event: every event
    turning = _run(InclusionMemory(), zero + 1.0, 4.5 * np.arange(len(t)), np.zeros((len(t), 2)), t)
    assert turning == list(t)                                   # 4.5 deg per event
    braking = _run(InclusionMemory(), 10.0 - 0.3 * np.arange(len(t)), zero, np.zeros((len(t), 2)), t)
    assert braking[:4] == [0.0, 0.2, 0.4, 0.6]                  # 0.6 m/s > 0.5 every second event


def test_unknown_speed_or_heading_never_triggers_and_heading_wraps():
    m = InclusionMemory()
    m.included(0.0, [1, 2], [[0, 0], [0, 0]], [np.nan, 3.0], [359.0, np.nan])
    inc = m.select(0.1, [1, 2, 3], [[0, 0], [0, 0], [0, 0]], [5.0, np.nan, 0.0], [2.0, 90.0, 0.0],
                   [False, False, True])
    # 1: speed was unknown (no rule), heading 359 -> 2 = 3 deg (no); 2: speed unknown now, heading was unknown;
    # 3: new
    assert inc.tolist() == [False, False, True]
    assert m.select(0.1, [1], [[0, 0]], [np.nan], [4.5], [False]).tolist() == [True]  # 359 -> 4.5 = 5.5 deg
    m.forget([1])
    assert len(m) == 1 and m.select(0.2, [1], [[0, 0]], [0.0], [0.0], [False]).tolist() == [True]


@settings(max_examples=200, deadline=None)
@given(sizes=st.lists(st.integers(1, 300), max_size=120), limit=st.integers(400, 1400), header=st.integers(20, 90))
def test_segments_hold_every_object_once_each_within_the_size(sizes, limit, header):
    segs, not_sent = plan_segments(sizes, header_bytes=header, max_size_bytes=limit)
    flat = np.concatenate(segs + [not_sent]) if segs else not_sent
    assert flat.tolist() == list(range(len(sizes)))             # every object once, in order
    assert 1 <= len(segs) <= MAX_SEGMENTS
    s = np.asarray(sizes, dtype=int)
    for seg in segs:
        assert header + s[seg].sum() <= limit
    if len(not_sent):
        assert len(segs) == MAX_SEGMENTS
    else:  # greedy packing: a segment ends only where the next object would not fit
        for a, b in zip(segs, segs[1:], strict=False):
            assert header + s[a].sum() + s[b[0]] > limit


@settings(max_examples=80, deadline=None, derandomize=True)
@given(sizes=st.lists(st.integers(1, 300), max_size=120), limit=st.integers(400, 1400),
       heads=st.lists(st.integers(20, 1000), min_size=1, max_size=4), plain=st.integers(20, 90))
def test_segments_with_their_own_headers(sizes, limit, heads, plain):
    """A header per segment (the first ones carry the cameras' containers): each segment within the limit with its
    own header, every object once in order, a segment ends only where the next object would not fit its room."""
    header = [min(h, limit) for h in heads] + [plain]
    segs, not_sent = plan_segments(sizes, header_bytes=header, max_size_bytes=limit)
    flat = np.concatenate(segs + [not_sent])
    assert flat.tolist() == list(range(len(sizes)))
    assert 1 <= len(segs) <= MAX_SEGMENTS and (len(not_sent) == 0 or len(segs) == MAX_SEGMENTS)
    s = np.asarray(sizes, dtype=int)
    head = [header[min(k, len(header) - 1)] for k in range(len(segs))]
    for k, seg in enumerate(segs):
        assert head[k] + s[seg].sum() <= limit
        if k + 1 < len(segs) and len(segs[k + 1]):
            assert head[k] + s[seg].sum() + s[segs[k + 1][0]] > limit


def test_a_full_first_header_sends_the_objects_on_pinned():
    # room 100, 10, 100, then 900 - 100 = 800: the 60-byte object skips the second segment (left empty)
    segs, not_sent = plan_segments([50, 40, 60, 500], header_bytes=[800, 890, 800, 100], max_size_bytes=900)
    assert [g.tolist() for g in segs] == [[0, 1], [], [2], [3]] and len(not_sent) == 0
    # an object that fits no room left to it (in order) is named, never dropped
    with pytest.raises(InputError, match=r"object_bytes\[1\]"):
        plan_segments([50, 850], header_bytes=[10, 100], max_size_bytes=900)
    assert [g.tolist() for g in plan_segments([850, 10], header_bytes=[10, 100], max_size_bytes=900)[0]] == [[0, 1]]


def test_an_object_larger_than_a_segment_is_named():
    with pytest.raises(InputError, match=r"object_bytes\[2\]"):
        plan_segments([10, 10, 2000], header_bytes=50, max_size_bytes=1100)


def test_reasons_name_the_first_rule_that_holds_and_retain_forgets_the_rest():
    from footprint_uq.service.cp_rules import INCLUSION_REASONS

    m = InclusionMemory()
    m.included(0.0, [1, 2, 3, 4, 5], np.zeros((5, 2)), [5.0] * 5, [90.0] * 5)
    r = m.reasons(0.3, [1, 2, 3, 4, 5, 6], [[0, 0], [5, 0], [0, 0], [0, 0], [5, 0], [0, 0]],
                  [5.0, 5.0, 5.6, 5.0, 9.0, 0.0], [90.0, 90.0, 90.0, 95.0, 180.0, 0.0], [False, False, False, False,
                                                                                     False, False])
    assert [INCLUSION_REASONS[k] for k in r] == ["not_due", "position", "speed", "heading", "position", "new"]
    assert [INCLUSION_REASONS[k] for k in m.reasons(1.0, [1], [[5, 0]], [9.0], [0.0], [False])] == ["interval"]
    assert m.last_included_s([1, 6]).tolist() == [0.0, -np.inf]
    m.retain([2, 4, 99])
    assert len(m) == 2 and m.last_included_s([1, 2, 4]).tolist() == [-np.inf, 0.0, 0.0]
