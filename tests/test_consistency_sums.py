"""The NIS monitor's per-class sums of a frame (tracking/consistency.py): one compiled pass, the same sums and counts
as the plain-Python reference object by object, and the window's numbers pinned by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from footprint_uq.errors import InputError
from footprint_uq.tracking.consistency import NisMonitor, _class_sums, _class_sums_reference

_NIS = st.one_of(st.floats(0.0, 1e6), st.just(math.nan), st.just(math.inf), st.just(-math.inf))
_CLASS = st.sampled_from(["car", "truck", "pedestrian", None, "", 1, "1"])


def _same(got: dict, want: dict) -> None:
    assert set(got) == set(want)
    for key, (s, k) in want.items():
        assert got[key][1] == k and isinstance(got[key][1], int), key
        assert isinstance(got[key][0], float) and got[key][0] == pytest.approx(s, rel=1e-12, abs=1e-300), key


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(_NIS, _CLASS), max_size=60), st.booleans())
def test_class_sums_are_the_references_over_any_frame(rows, no_classes):
    """Any NIS (finite, NaN, +-inf: only the finite count) and any classes (one, several, None, "" and None, 1 and
    "1" -- keys that meet as strings), or no classes at all: the same classes, sums (1e-12) and counts."""
    nis = np.array([v for v, _ in rows], dtype=float)
    classes = None if no_classes else [c for _, c in rows]
    _same(_class_sums(nis, classes, len(rows)), _class_sums_reference(nis, classes, len(rows)))


def test_class_sums_one_class_and_several_pinned():
    nis = np.array([1.5, 2.0, np.nan, 4.0, np.inf, 0.25, -np.inf, 8.0])
    one = _class_sums(nis, ["car"] * 8, 8)
    assert one == {"car": (15.75, 5)}
    several = _class_sums(nis, ["car", "truck", "car", None, "truck", "", "car", "truck"], 8)
    assert several == {"car": (1.5, 1), "truck": (10.0, 2), "": (4.25, 2)}
    assert _class_sums(nis, None, 8) == {"": (15.75, 5)}
    assert _class_sums(np.full(3, np.nan), ["car", "bus", "car"], 3) == {}  # (no update: no entry)
    assert _class_sums(np.zeros(0), [], 0) == {} and _class_sums(np.zeros(0), None, 0) == {}
    assert _class_sums(np.array([1.0, 2.0]), ("a", "b"), 2) == {"a": (1.0, 1), "b": (2.0, 1)}  # (any sequence)
    with pytest.raises(InputError, match="classes"):
        _class_sums(nis, ["car"] * 7, 8)


class _Tracks:
    """What NisMonitor reads of the tracks: the NIS of the last step's objects."""

    def __init__(self):
        self.nis = np.zeros(0)

    def frame_nis(self) -> np.ndarray:
        return self.nis


class _Out:
    def __init__(self, n: int):
        self.track_id = np.zeros(n, np.int64)


def test_the_monitor_window_holds_the_frames_sums_pinned():
    """Three frames through NisMonitor.observe: the window's sum and count per class by hand, the oldest frame
    leaving after window_s, the status' ratio mean NIS / 2."""
    tracks = _Tracks()
    mon = NisMonitor(tracks, window_s=1.0, min_updates=1)
    for t, nis, classes in ((0.0, [2.0, 4.0, np.nan], ["car", "car", "car"]),
                            (0.5, [1.0, np.inf, 3.0, 6.0], ["car", "bus", None, "bus"]),
                            (1.2, [8.0], ["car"])):
        tracks.nis = np.array(nis)
        mon.observe(t, _Out(len(nis)), classes)
    st_ = mon.status()
    assert st_["car"]["n_updates"] == 2 and st_["car"]["nis_ratio"] == pytest.approx(9.0 / 4.0)  # (1 + 8) / 2 / 2
    assert st_["bus"]["n_updates"] == 1 and st_["bus"]["nis_ratio"] == pytest.approx(3.0)
    assert st_[""]["n_updates"] == 1 and st_[""]["nis_ratio"] == pytest.approx(1.5)
    tracks.nis = np.zeros(2)
    with pytest.raises(InputError, match="out"):
        mon.observe(1.3, _Out(3), ["car"] * 3)


def _window(mon: NisMonitor) -> dict:
    """The monitor's window as plain values: class -> (the frames' (time, sum, count), the totals)."""
    return {c: (list(dq), tuple(mon._sums[c])) for c, dq in mon._frames.items()}


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(st.lists(_NIS, max_size=12), _CLASS, st.booleans(), st.sampled_from(["list", "tuple",
                                                                                                "none"])),
                min_size=1, max_size=25))
def test_observe_of_one_class_frames_is_the_general_paths(frames):
    """`NisMonitor.observe`'s one-class path (a list of one class or no classes: one compiled sum, no dictionary)
    keeps the same window -- frames, sums to the bit, counts, expiry -- as the general path (the same frames with
    their classes as a tuple, `_class_sums`), over frames of one class, of two, empty, and without classes."""
    fast, general = _Tracks(), _Tracks()
    mon_f = NisMonitor(fast, window_s=0.25, min_updates=1, max_updates=40)
    mon_g = NisMonitor(general, window_s=0.25, min_updates=1, max_updates=40)
    for k, (nis, cls, mixed, kind) in enumerate(frames):
        classes = [cls] * len(nis)
        if mixed and nis:
            classes[-1] = "other"
        fast.nis = general.nis = np.array(nis, dtype=float)
        mon_f.observe(0.1 * k, _Out(len(nis)), None if kind == "none" else classes if kind == "list" else
                      tuple(classes))
        mon_g.observe(0.1 * k, _Out(len(nis)), None if kind == "none" else tuple(classes))
        assert _window(mon_f) == _window(mon_g)
    assert mon_f.status() == mon_g.status()


def test_observe_of_one_class_frames_pinned():
    """One-class frames by hand: the key of None is "", of 1 is "1"; a frame without a finite NIS adds no entry;
    the sums leave the window after window_s; a strided or integer NIS array is read as float64."""
    tracks = _Tracks()
    mon = NisMonitor(tracks, window_s=1.0, min_updates=1)
    for t, nis, classes in ((0.0, np.array([2.0, np.nan, 4.0]), ["car"] * 3), (0.2, np.array([1.0]), [None]),
                            (0.4, np.arange(6)[::2], [1, 1, 1]), (0.6, np.array([np.nan, np.inf]), ["bus"] * 2),
                            (0.8, np.array([0.5, 0.25]), None)):
        tracks.nis = nis
        mon.observe(t, _Out(len(nis)), classes)
    assert _window(mon) == {"car": ([(0.0, 6.0, 2)], (6.0, 2)), "": ([(0.2, 1.0, 1), (0.8, 0.75, 2)], (1.75, 3)),
                            "1": ([(0.4, 6.0, 3)], (6.0, 3))}
    tracks.nis = np.array([3.0])
    mon.observe(1.1, _Out(1), ["car"])
    assert _window(mon)["car"] == ([(1.1, 3.0, 1)], (3.0, 1)) and _window(mon)[""][1] == (1.75, 3)
