"""Issue 32: the CPM size limit works for a unit of 8 cameras.

The 8-camera site of ``bench/bench_cp_serve.py`` (four cameras on the corners of an intersection, four on its arms,
each with its perception region, <= 16 vertices): every camera's Sensor Information and Perception Region entries
do not fit one segment of the default 1,100 bytes with an object.  At the default limit the event's segments then
each stay <= 1,100 bytes, decode with the official modules (asn1tools and pycrate, every CDD release), carry every
camera's two entries once (in the same segment) when they are due and none when not, every object in exactly one
segment, and the decoded polygons lie inside the cameras' true regions (checked on a grid with
:func:`~footprint_uq.products.perception_region.semi_major_at`).  ``serve``'s start-up check accepts the default
and refuses, in one line, only a limit that cannot hold one camera's entries and the largest object.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from matplotlib.path import Path as MplPath

from footprint_uq import PanTiltCamera
from footprint_uq.errors import InputError
from footprint_uq.products.perception_region import perception_region, polygon_east_north_cm, semi_major_at
from footprint_uq.service.cp_rules import CpRules, GenerationClock
from footprint_uq.service.cp_segments import CpmObjectColumns, event_segments, sensor_region
from footprint_uq.service.cp_serve import CpServeOptions, _check_room, cp_cameras
from footprint_uq.service.messages.asn1_cpm import CDD_RELEASES
from footprint_uq.service.messages.cpm import decode_cpm_uper
from test_cpm_containers import REF_MS, _check_official, _motion_ages, _objects
from test_cpm_official import OFFICIAL, decode_official, official  # noqa: F401 - the fixture

pytest.importorskip("asn1tools")

BUDGET = "basler1@deg"
LIMIT_M = 1.0
N_CAMERAS = 8


def _site() -> list:
    """The bench's eight 1920x1080 cameras: corners (+-9, +-9) m at 8 m, arms 25 m out at 10 m, 80 deg wide,
    tilted 20 deg down, all looking at the centre."""
    f = 1920 / (2.0 * math.tan(math.radians(80.0) / 2.0))
    spots = [((9.0, 9.0), 8.0), ((-9.0, 9.0), 8.0), ((-9.0, -9.0), 8.0), ((9.0, -9.0), 8.0),
             ((9.0, 25.0), 10.0), ((-25.0, 9.0), 10.0), ((-9.0, -25.0), 10.0), ((25.0, -9.0), 10.0)]
    return [PanTiltCamera(f, (1920, 1080), h, math.degrees(math.atan2(-x, -y)) % 360.0, 20.0, position_m=(x, y),
                          principal_point_px=(960, 540)) for (x, y), h in spots]


@pytest.fixture(scope="module")
def eight():
    """(cameras, their perception regions, their SensorRegions: sensor ids 1..8, reference position (0, 0))."""
    cams = _site()
    regs = [perception_region(c, BUDGET, max_semi_major_m=LIMIT_M) for c in cams]
    assert all(r is not None for r in regs)
    return cams, regs, [sensor_region(k + 1, r, (0.0, 0.0)) for k, r in enumerate(regs)]


def _columns(seed: int, n: int, cdd: str) -> CpmObjectColumns:
    rng = np.random.default_rng(seed)
    _, c = _objects(rng, n, cdd, N_CAMERAS)
    ids = rng.permutation(65536)[:n]
    sids = [None if s is None else [1 + i for i in s] for s in c["sids"]]
    return CpmObjectColumns(ids, c["x"], c["y"], c["cx"], c["cy"], c["r"], c["cv"], c["cw"], c["lvl"],
                            motion=_motion_ages(c["age"]), measurement_delta_ms=c["mdt"], quality=c["q"],
                            sensor_ids=sids)


def _containers(cpm: dict) -> dict:
    return {c["containerId"]: c["containerData"] for c in cpm["payload"]["cpmContainers"]}


def _inside_the_true_region(cam, vertices_cm: list) -> None:
    """Grid points inside the decoded polygon have a 95 % semi-major axis within the limit (the vertices are rounded
    to the centimetre: a relative tolerance of 1e-3 covers that)."""
    poly = np.asarray(vertices_cm, dtype=np.float64) / 100.0  # reference (0, 0), W = east/north
    lo, hi = poly.min(axis=0), poly.max(axis=0)
    gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], 60), np.linspace(lo[1], hi[1], 60))
    g = np.column_stack([gx.ravel(), gy.ravel()])
    inside = MplPath(poly).contains_points(g)
    assert inside.sum() > 200
    semi = semi_major_at(cam, BUDGET, g[inside])
    assert np.all(semi <= LIMIT_M * (1 + 1e-3)), float(np.max(semi))


@pytest.mark.parametrize("cdd", CDD_RELEASES)
def test_eight_cameras_at_the_default_limit(official, eight, cdd):  # noqa: F811
    cams, regs, srs = eight
    full = _columns(3, 100, cdd)
    clock = GenerationClock(CpRules())  # the default limit: 1,100 bytes
    assert clock.rules.max_size_bytes == 1100
    # an event with 100 objects, two without the containers, one with them again, and one without objects (owed
    # at T_GenCpmMax: the containers alone, spread too)
    for t_s, due, objs in ((0.0, True, full), (0.1, False, full), (0.5, False, full), (1.0, True, full),
                           (2.0, True, full.take(np.arange(0)))):
        ev = event_segments(9, REF_MS + int(round(1000 * t_s)), objs, srs, clock, t_s, cdd=cdd,
                            number_of_perceived_objects=len(objs))
        assert ev.sensor_information == due and len(ev.not_sent) == 0
        cpms = [decode_cpm_uper(p, cdd) for p in ev.payloads]
        for p, cpm in zip(ev.payloads, cpms, strict=True):
            assert len(p) <= 1100
            _check_official(p, cpm, cdd, official)
        # every object in exactly one segment (the decoded ids), in the segments the event says
        sent = [[o["objectId"] for o in _containers(c)[5]["perceivedObjects"]] for c in cpms]
        assert sorted(i for s in sent for i in s) == sorted(objs.object_id.tolist())
        assert sent == [objs.object_id[idx].tolist() for idx in ev.segments]
        if len(cpms) > 1:
            assert [c["payload"]["managementContainer"]["segmentationInfo"] for c in cpms] == [
                {"totalMsgNo": len(cpms), "thisMsgNo": k + 1} for k in range(len(cpms))]
        info = {e["sensorId"]: k for k, c in enumerate(cpms) for e in _containers(c).get(3, [])}
        region = {e["sensorIdList"][0]: (k, e) for k, c in enumerate(cpms) for e in _containers(c).get(4, [])}
        n_info = sum(len(_containers(c).get(3, [])) for c in cpms)
        n_region = sum(len(_containers(c).get(4, [])) for c in cpms)
        if not due:
            assert n_info == n_region == 0
            continue
        # every camera's two entries, once each, in the same segment; spread over more than one segment here
        assert n_info == n_region == N_CAMERAS and sorted(info) == list(range(1, N_CAMERAS + 1))
        assert {s: k for s, (k, _) in region.items()} == info
        assert len(set(info.values())) > 1
        assert [g.tolist() for g in ev.sensor_segments if len(g)] == [
            [s - 1 for s in sorted(info) if info[s] == k] for k in sorted(set(info.values()))]
        for sid, (_, e) in region.items():
            verts = [[v["xCoordinate"], v["yCoordinate"]] for v in e["perceptionRegionShape"]["polygonal"]["polygon"]]
            assert verts == polygon_east_north_cm(regs[sid - 1].polygon_xy_world_m, (0.0, 0.0)).tolist()
            if t_s == 0.0 and cdd == CDD_RELEASES[0]:
                _inside_the_true_region(cams[sid - 1], verts)


def test_three_small_cameras_stay_whole_in_the_first_segment(eight):
    """When every camera's entries fit one segment with the largest object, the first segment carries both
    containers whole (no spreading for its own sake)."""
    _, _, srs = eight
    ev = event_segments(9, REF_MS, _columns(4, 40, "2.2.1"), srs[:3], GenerationClock(CpRules()), 0.0)
    assert [g.tolist() for g in ev.sensor_segments] == [[0, 1, 2]] + [[]] * (len(ev.payloads) - 1)
    assert [c["containerId"] for c in decode_cpm_uper(ev.payloads[0])["payload"]["cpmContainers"]] == [2, 3, 4, 5]


def test_serve_start_check_accepts_the_default_and_refuses_only_what_cannot_work(eight):
    cams, _, _ = eight
    entries = {f"cam{k}": (c, BUDGET) for k, c in enumerate(cams)}
    cp_cams = cp_cameras(entries, max_semi_major_m=LIMIT_M)
    _check_room(cp_cams, CpServeOptions(), 7, "2.2.1", 0.0)  # 1,100 bytes: starts
    # the smallest limit that starts: then an event of 8 cameras with the largest objects really fits
    lo, hi = 64, 1100
    while lo < hi:
        mid = (lo + hi) // 2
        try:
            _check_room(cp_cams, CpServeOptions(cpm_max_bytes=mid), 7, "2.2.1", 0.0)
            hi = mid
        except InputError as e:
            assert str(e).startswith("--cpm-max-bytes: got") and "\n" not in str(e)
            lo = mid + 1
    assert lo < 400
    with pytest.raises(InputError, match="--cpm-max-bytes.*sensor"):
        _check_room(cp_cams, CpServeOptions(cpm_max_bytes=lo - 1), 7, "2.2.1", 0.0)
    srs = [sensor_region(c.sensor_id, c.region, (0.0, 0.0)) for c in cp_cams]
    rules = CpRules(max_size_bytes=lo)
    ev = event_segments(7, REF_MS, _columns(5, 30, "2.2.1"), srs, GenerationClock(rules), 0.0, rules=rules)
    assert all(len(p) <= lo for p in ev.payloads)
    assert sum(len(g) for g in ev.sensor_segments) == N_CAMERAS
