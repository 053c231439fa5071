"""The service's frame size limit (issue 35, part 8a): a frame of 100,000 detections is ONE error record naming the
limit, through the service's public frame entry (dict and JSON text), never an exception; a frame at the limit
is processed."""

from __future__ import annotations

import json

import numpy as np
import pytest

from footprint_uq import PanTiltCamera
from footprint_uq.errors import InputError
from footprint_uq.service.core import MAX_FRAME_DETECTIONS, RECORD_ERROR, RECORD_FOOTPRINTS, Service

T0 = 1714564800.0


@pytest.fixture(scope="module")
def camera():
    return PanTiltCamera(focal_px=1400, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)


def _dets(n, seed=0):
    rng = np.random.default_rng(seed)
    u, v = rng.uniform(50, 1850, n), rng.uniform(600, 1070, n)
    return [{"object_id": i, "class": "car", "u_min_px": float(a - 20), "v_min_px": float(b - 40),
             "u_max_px": float(a + 20), "v_max_px": float(b)} for i, (a, b) in enumerate(zip(u, v, strict=True))]


def test_a_frame_of_100000_detections_is_one_error_record(camera):
    svc = Service(camera, "basler1", warm_up=False)
    frame = {"camera_id": "c", "frame": 7, "timestamp_s": T0, "detections": _dets(100_000)}
    for given in (frame, json.dumps(frame), json.dumps(frame).encode()):
        out = svc.process_frame_json(given, source="test")
        assert out.type == RECORD_ERROR and out.processing_us is None
        rec = json.loads(out.data)
        assert rec == out.record and rec["type"] == "error" and rec["field"] == "detections"
        assert rec["frame"] == 7 and rec["source"] == "test"
        assert f"100000 detections in one frame, more than the frame limit of {MAX_FRAME_DETECTIONS}" in rec["reason"]
        assert "\n" not in rec["reason"]
    # the service goes on: the next frame is processed
    rec = svc.process_frame({"frame": 8, "timestamp_s": T0 + 0.1, "detections": _dets(2)})
    assert rec["type"] == RECORD_FOOTPRINTS and rec["n_objects"] == 2


def test_the_limit_is_the_service_s_and_a_frame_at_it_is_processed(camera):
    svc = Service(camera, "basler1", warm_up=False, max_frame_detections=300)
    rec = svc.process_frame({"frame": 1, "timestamp_s": T0, "detections": _dets(300)})
    assert rec["type"] == RECORD_FOOTPRINTS and rec["n_objects"] == 300
    rec = svc.process_frame({"frame": 2, "timestamp_s": T0, "detections": _dets(301)})
    assert rec["type"] == RECORD_ERROR and "frame limit of 300" in rec["reason"]
    for bad in (0, -1, 2.5, True, "10"):
        with pytest.raises(InputError, match="max_frame_detections"):
            Service(camera, "basler1", warm_up=False, max_frame_detections=bad)
