"""Where a tracked compact frame's time goes: its parts timed inside the frame, medians over the repeats.

    PYTHONPATH=src .venv/bin/python bench/bench_frame_parts.py [--repeats 300] [--objects 100] [--out FILE]

The frame of ``bench/bench_frame.py``'s case ``tracked-compact`` (a warmed ``Service(tracks=True,
record="compact")``, the bench camera, 100 2-D boxes, ``process_frame_json(payload bytes)``), with each part wrapped
in a ``perf_counter`` pair (~0.1 us each, counted in its part): the text read (``scan_frame``), the positions
(``Service._footprints``), the tracker's step (``ClassTracks.step``), its NIS check (``NisMonitor.observe``), the
slide term (``ContactSlide.apply``), the motion fields (``object_motion``), the record's objects
(``Service._compact_objects``), the UPER CPM (``Service._plain_cpm_uper``; inside it the message's motion codes,
``motion_rows``), and the rest of the frame (the total minus the parts: the glue between them, the record's head).
A tree whose tracked compact frame takes the lean columns (``Service._lean_records``, wave 9 e) has no
``_footprints`` / ``_compact_objects`` / ``_plain_cpm_uper`` call: its parts are then the processor's
``boxes2d_columns`` (positions), ``Service._compact_text`` (record objects) and ``lean_cpm_uper`` (the UPER CPM;
``plain_cpm_uper`` before 2026-11-29, wave 10 c,
its motion codes ``motion_rows`` called before it, outside it: subtracted from the rest as a part of its own).
``FrameProcessor.boxes2d`` alone on the same boxes is timed in the same loop (issue 31's reference).  Nothing is
asserted: the parts and the rest in us, and the sum of the parts that ``bench_frame.py``'s
``frame_bytes_minus_step_us`` counts.
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
from bench_service import CAMERA, make_detections

from footprint_uq import FrameProcessor, PanTiltCamera
from footprint_uq.service import Service
from footprint_uq.service import core as service_core
from footprint_uq.tracking import camera_tracker

#: the parts timed (an instance's method is wrapped on the instance, a module's function in the calling module)
PARTS = ("scan", "footprints", "tracker_step", "nis_check", "slide_term", "object_motion", "motion_codes",
         "record_objects", "uper_cpm")


def _wrap(owner, name: str, into: list) -> None:
    inner = getattr(owner, name)

    def timed(*a, **k):
        t0 = time.perf_counter()
        out = inner(*a, **k)
        into.append(time.perf_counter() - t0)
        return out

    setattr(owner, name, timed)


def measure(objects: int, repeats: int) -> dict:
    """The medians of one run (module doc), us."""
    cam = PanTiltCamera(**CAMERA)
    svc = Service(cam, "basler1", linearity=True, tracks=True, record="compact")
    dets = make_detections(objects, 0)
    body = json.dumps(dets, separators=(",", ":")).encode()
    t_frame = [1.7e9]

    def payload() -> bytes:
        t_frame[0] += 1.0 / 30.0
        return b'{"camera_id":"cam0","frame":0,"timestamp_s":%.6f,"detections":%s}' % (t_frame[0], body)

    proc = FrameProcessor(cam, "basler1", joint_cov=False)
    boxes = np.array([[d["u_min_px"], d["v_min_px"], d["u_max_px"], d["v_max_px"]] for d in dets])
    for _ in range(30):
        svc.process_frame_json(payload())
        proc.boxes2d(boxes)
    got: dict[str, list] = {p: [] for p in PARTS}
    setup = next(iter(svc.cameras.values()))
    tracker = setup.tracker
    # (core's scan_frame: since 2026-11-29, wave 11 a, a frame's bytes go to it without _scan_text; before, _scan_text
    # called it)
    _wrap(service_core, "scan_frame", got["scan"])
    lean = hasattr(Service, "_lean_records")  # (wave 9 e: the tracked compact frame on the lean columns)
    _wrap(setup.processor if lean else svc, "boxes2d_columns" if lean else "_footprints", got["footprints"])
    _wrap(tracker.tracks, "step", got["tracker_step"])
    _wrap(tracker.nis, "observe", got["nis_check"])
    _wrap(tracker.slide, "apply", got["slide_term"])
    _wrap(camera_tracker, "object_motion", got["object_motion"])
    # (main before 2026-11-28 wave 9: motion_codes, then the rows copied in kernel_motion)
    _wrap(service_core, "motion_rows" if hasattr(service_core, "motion_rows") else "motion_codes",
          got["motion_codes"])
    _wrap(svc, "_compact_text" if lean else "_compact_objects", got["record_objects"])
    # (since 2026-11-29, wave 10 c: the lean frame's CPM by lean_cpm_uper, plain_cpm_uper only where it declines)
    cpm = "lean_cpm_uper" if hasattr(service_core, "lean_cpm_uper") else "plain_cpm_uper"
    _wrap(service_core if lean else svc, cpm if lean else "_plain_cpm_uper", got["uper_cpm"])
    for _ in range(10):
        svc.process_frame_json(payload())
    for v in got.values():
        v.clear()
    frame, ref = [], []
    gc.collect()
    gc.freeze()
    for _ in range(repeats):
        text = payload()
        t0 = time.perf_counter()
        svc.process_frame_json(text)
        frame.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        proc.boxes2d(boxes)
        ref.append(time.perf_counter() - t0)
    gc.unfreeze()
    per = {p: np.array(v) for p, v in got.items()}
    assert all(len(v) == repeats for v in per.values()), {p: len(v) for p, v in per.items()}
    frame_a = np.array(frame)
    # (motion_codes runs inside uper_cpm, except on the lean columns: counted there, not twice in the rest)
    rest = frame_a - sum(v for p, v in per.items() if lean or p != "motion_codes")
    res = {f"{p}_us": 1e6 * float(np.median(v)) for p, v in per.items()}
    res["rest_us"] = 1e6 * float(np.median(rest))
    res["frame_us"] = 1e6 * float(np.median(frame_a))
    res["frame_minus_step_us"] = 1e6 * float(np.median(frame_a - per["tracker_step"]))
    res["boxes2d_us"] = 1e6 * float(np.median(ref))
    res["frame_minus_step_over_boxes2d"] = res["frame_minus_step_us"] / res["boxes2d_us"]
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=300)
    ap.add_argument("--objects", type=int, default=100)
    ap.add_argument("--out", type=Path, default=None, help="write the figures as JSON here")
    args = ap.parse_args(argv)
    res = measure(args.objects, args.repeats)
    out = {"what": f"bench/bench_frame_parts.py: the tracked compact {args.objects}-object frame's parts, "
                   f"{args.repeats} repeats, medians (us)",
           "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "cores": os.cpu_count(),
           "load_average_1min_start": os.getloadavg()[0], "parts": res}
    for k, v in res.items():
        print(f"{k:32s} {v:8.2f}")
    if args.out:
        args.out.write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
