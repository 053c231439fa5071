"""The service tried as a hostile user would (issue 22): each fault of the issue as a test.

Without a broker: a detection's corner count, pixel covariances beyond the batch's limit, the queue's depth,
byte bound and per-camera order, over-long stdin lines, SIGTERM with stdin open and idle.  Through the real
Mosquitto (the fixtures of test_service_mqtt.py): camera ids that cannot name a topic, bursts of frames on an
idle service, frames over the size limit -- every frame accounted for.
"""

from __future__ import annotations

import io
import json
import os
import signal
import subprocess
import threading
import time

import numpy as np
import pytest

from footprint_uq import PanTiltCamera
from footprint_uq.service import Service
from footprint_uq.service.runner import FrameQueue, _stdin_lines
from test_service_mqtt import CLI, Client, _wait, broker, camera_file, frame, start_serve, stop_serve  # noqa: F401

T0 = 1714564800.0


@pytest.fixture(scope="module")
def service():
    cam = PanTiltCamera(focal_px=1400, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)
    return Service(cam, "basler1")


# -- input checks ------------------------------------------------------------------------------------------------
def test_a_detection_with_more_corners_than_the_first_is_refused(service):
    one = {"u0_px": 900.0, "v0_px": 700.0}
    four = {f"{a}{k}_px": v for k in range(4) for a, v in (("u", 900.0 + 40 * (k % 2)), ("v", 650.0 + 40 * (k // 2)))}
    rec = service.process_frame({"frame": 1, "timestamp_s": T0, "detections": [one, four]})
    (err,) = rec["detection_errors"]  # that detection's error; the frame's other detection goes on
    assert rec["type"] == "footprints" and rec["n_objects"] == 1
    assert err["index"] == 1 and err["field"] == "detections[1].u1_px" and "4 corners" in err["reason"]
    rec = service.process_frame({"frame": 2, "timestamp_s": T0, "detections": [four, one]})
    (err,) = rec["detection_errors"]
    assert err["field"].startswith("detections[1].") and "1 corners" in err["reason"] and rec["n_objects"] == 1
    ok = service.process_frame({"frame": 3, "timestamp_s": T0, "detections": [four, four]})
    assert ok["type"] == "footprints" and ok["n_objects"] == 2


@pytest.mark.parametrize("cov, field", [((1e13, 0.0, 4.0), "cov_uu_px2"), ((4.0, -2e12, 1e13), "cov_uv_px2"),
                                        ((4.0, 0.0, 1.1e12), "cov_vv_px2")])
def test_pixel_covariance_beyond_the_batch_limit_is_refused(service, cov, field):
    box = {"u_min_px": 900.0, "v_min_px": 600.0, "u_max_px": 1000.0, "v_max_px": 700.0}
    dets = [dict(box, cov_uu_px2=4.0, cov_uv_px2=0.0, cov_vv_px2=9.0),
            dict(box, **dict(zip(("cov_uu_px2", "cov_uv_px2", "cov_vv_px2"), cov, strict=True)))]
    rec = service.process_frame({"frame": 1, "timestamp_s": T0, "detections": dets})
    (err,) = rec["detection_errors"]
    assert err["field"] == f"detections[1].{field}" and "1e+12" in err["reason"] and rec["n_objects"] == 1
    dets[1].update(cov_uu_px2=1e12, cov_uv_px2=0.0, cov_vv_px2=1e12)  # the limit itself is accepted
    rec = service.process_frame({"frame": 1, "timestamp_s": T0, "detections": dets})
    assert rec["detection_errors"] == [] and rec["n_objects"] == 2


# -- the queue ---------------------------------------------------------------------------------------------------
def test_queue_depth_keeps_a_burst_and_drops_only_beyond_it():
    q = FrameQueue("newest", depth=2)
    q.put("a", 1)
    q.put("a", 2)  # a burst of two: both kept
    q.put("b", 1)
    assert len(q) == 3 and q.dropped == 0
    q.put("a", 3)  # a third while two wait: the oldest (1) is replaced
    assert q.dropped == 1
    assert [q.get(0) for _ in range(3)] == [2, 1, 3]  # a's oldest, then b (waiting longer than a's next), then a
    assert q.get(0.01) is None


def test_queue_bytes_are_bounded():
    q = FrameQueue("newest", depth=4, max_bytes=100)
    assert q.put("a", 1, 60) and not q.put("b", 2, 60) and q.dropped == 1 and q.bytes == 60
    assert q.get(0) == 1 and q.bytes == 0
    assert q.put("b", 3, 1000)  # one frame alone may exceed the bound (the frame size limit is separate)


def test_stdin_lines_skip_an_over_long_line_without_holding_it():
    data = b'{"a": 1}\n' + b"x" * 5000 + b"\n" + b'{"b": 2}\n' + b"y" * 3000
    got = list(_stdin_lines(io.BytesIO(data), 1000, threading.Event()))
    assert got == [(b'{"a": 1}\n', 9), (None, 5001), (b'{"b": 2}\n', 9), (None, 3000)]
    r, w = os.pipe()  # the same through a real file descriptor (select + os.read)
    with os.fdopen(w, "wb") as fw:
        fw.write(data)
    with os.fdopen(r, "rb") as fr:
        assert list(_stdin_lines(fr, 1000, threading.Event())) == got


# -- stdin transport ---------------------------------------------------------------------------------------------
def test_sigterm_with_stdin_open_and_idle_exits_0(camera_file):  # noqa: F811
    p = start_serve(["--camera", str(camera_file), "--budget", "basler1", "--input", "-", "--health-interval-s", "0"],
                    stdin=subprocess.PIPE)
    p.stdin.write((json.dumps(frame("cam1", 0)) + "\n").encode())
    p.stdin.flush()
    line = p.stdout.readline()  # its record: the service is up, stdin stays open and idle
    assert json.loads(line)["type"] == "footprints"
    p.send_signal(signal.SIGTERM)
    try:
        rc = p.wait(20)
    finally:
        if p.poll() is None:
            p.kill()
    err = p.stderr.read().decode()
    assert rc == 0 and "Fatal" not in err, err[-2000:]
    rest = [json.loads(x) for x in p.stdout.read().decode().splitlines()]
    assert rest[-1]["type"] == "health" and rest[-1]["frames_in"] == 1 == rest[-1]["frames_out"]
    p.stdin.close()


def test_stdin_records_leave_in_input_order_and_big_lines_are_refused(camera_file):  # noqa: F811
    lines = [json.dumps(frame("cam1", 0)), json.dumps(frame("cam2", 0)), json.dumps(frame("cam1", 1)), "{broken",
             json.dumps(frame("cam1", 2, n=400)), json.dumps(frame("cam1", 3))]
    p = subprocess.run(CLI + ["--camera", str(camera_file), "--budget", "basler1", "--input", "-",
                              "--health-interval-s", "0", "--max-frame-bytes", "20000"],
                       input="\n".join(lines).encode(), capture_output=True, timeout=120,
                       env={**os.environ, "NUMBA_NUM_THREADS": "1"})
    assert p.returncode == 0, p.stderr.decode()[-2000:]
    recs = [json.loads(x) for x in p.stdout.decode().splitlines()]
    cam1 = [(r["type"], r.get("frame"), r.get("source")) for r in recs if r["type"] != "health" and
            r.get("camera_id") in ("cam1", None)]
    assert cam1 == [("footprints", 0, None), ("footprints", 1, None), ("error", None, "stdin line 4"),
                    ("error", None, "stdin line 5"), ("footprints", 3, None)]
    assert "larger than the limit of 20000 bytes" in recs[[r.get("source") for r in recs].index("stdin line 5")][
        "reason"]
    h = recs[-1]
    assert h["frames_in"] == 6 == h["frames_out"] + h["errors"] + h["frames_dropped"] and h["errors"] == 2


def test_stdin_one_bad_detection_among_ten_is_counted_and_the_frame_published(camera_file):  # noqa: F811
    """Issue 33 through the command: ``--class-names coco``, integer classes, one id COCO does not name: the
    frame's record has nine objects and one error entry, and the health record counts the bad detection; with
    ``--unknown-class unknown`` ten objects, that one of the class 'unknown'."""
    f = frame("cam1", 0, n=10)
    for k, d in enumerate(f["detections"]):
        d["class"] = [2, 0, 7][k % 3]
    f["detections"][3]["class"] = 80
    p = subprocess.run(CLI + ["--camera", str(camera_file), "--budget", "basler1", "--input", "-",
                              "--health-interval-s", "0", "--class-names", "coco", "--no-linearity"],
                       input=(json.dumps(f) + "\n").encode(), capture_output=True, timeout=120,
                       env={**os.environ, "NUMBA_NUM_THREADS": "1"})
    assert p.returncode == 0, p.stderr.decode()[-2000:]
    rec, health = (json.loads(x) for x in p.stdout.decode().splitlines())
    assert rec["type"] == "footprints" and rec["n_objects"] == 9
    assert [e["index"] for e in rec["detection_errors"]] == [3] and "not in the names map" in \
        rec["detection_errors"][0]["reason"]
    assert {o["class"] for o in rec["objects"]} == {"car", "person", "truck"}
    assert health["frames_out"] == 1 and health["errors"] == 0 and health["detection_errors"] == 1
    # --unknown-class unknown (as objects): the id without a name is the class 'unknown', no error entry
    p = subprocess.run(CLI + ["--camera", str(camera_file), "--budget", "basler1", "--input", "-",
                              "--health-interval-s", "0", "--class-names", "coco", "--unknown-class", "unknown",
                              "--no-linearity"], input=(json.dumps(f) + "\n").encode(), capture_output=True,
                       timeout=120, env={**os.environ, "NUMBA_NUM_THREADS": "1"})
    assert p.returncode == 0, p.stderr.decode()[-2000:]
    rec = json.loads(p.stdout.decode().splitlines()[0])
    assert rec["n_objects"] == 10 and rec["detection_errors"] == [] and rec["objects"][3]["class"] == "unknown"


# -- through Mosquitto ---------------------------------------------------------------------------------------------
def _settled(rx, sent):
    h = rx.of("health")
    return bool(h) and h[-1]["frames_in"] == sent and h[-1]["pending"] == 0 and \
        h[-1]["frames_out"] + h[-1]["errors"] + h[-1]["frames_dropped"] == sent


def test_camera_ids_that_cannot_name_a_topic_get_error_records(broker, camera_file):  # noqa: F811
    """stdin in, MQTT out: a camera_id with '#' or '+' used to kill the output worker (frames then vanished)."""
    rx = Client(broker, "rx-topics", "footprints/#")
    p = start_serve(["--camera", str(camera_file), "--budget", "basler1", "--input", "-", "--mqtt", broker.url,
                     "--output", "mqtt", "--client-id", "serve-topics", "--health-interval-s", "0.2"],
                    stdin=subprocess.PIPE)
    try:
        for i, cid in enumerate(["cam#1", "a/+", "cam1", "", "cam1"]):
            p.stdin.write((json.dumps(frame(cid, i)) + "\n").encode())
        p.stdin.flush()
        _wait(lambda: _settled(rx, 5), 60, "every frame to be accounted for")
        errs = rx.of("error")
        assert [e["camera_id"] for e in errs] == ["cam#1", "a/+", ""] and all(e["field"] == "camera_id" for e in errs)
        assert [r["frame"] for r in rx.of("footprints")] == [2, 4]
    finally:
        rc, _, err = stop_serve(p)
        rx.close()
    assert rc == 0, err[-2000:]


def test_bursts_on_an_idle_service_are_processed_not_dropped(broker, camera_file):  # noqa: F811
    """Two frames of one camera arriving together (one TCP segment): the queue holds both (--queue-depth 2)."""
    rx = Client(broker, "rx-burst", "footprints/#")
    p = start_serve(["--camera", str(camera_file), "--budget", "basler1", "--mqtt", broker.url, "--output", "mqtt",
                     "--client-id", "serve-burst", "--health-interval-s", "0.2"])
    try:
        _wait(lambda: len(rx.of("health")) >= 1, 60, "the service's first health message")
        tx = Client(broker, "tx-burst")
        for i in range(10):
            tx.publish("detections/cam1", frame("cam1", 2 * i))
            tx.publish("detections/cam1", frame("cam1", 2 * i + 1))
            time.sleep(0.15)
        _wait(lambda: _settled(rx, 20), 30, "every frame to be accounted for")
        assert rx.of("health")[-1]["frames_dropped"] == 0
        assert [r["frame"] for r in rx.of("footprints")] == list(range(20))  # in order, none replaced
        tx.close()
    finally:
        rc, _, err = stop_serve(p)
        rx.close()
    assert rc == 0, err[-2000:]


def test_frames_over_the_size_limit_are_refused_and_accounted_for(broker, camera_file):  # noqa: F811
    rx = Client(broker, "rx-size", "footprints/#")
    p = start_serve(["--camera", str(camera_file), "--budget", "basler1", "--mqtt", broker.url, "--output", "mqtt",
                     "--client-id", "serve-size", "--health-interval-s", "0.2", "--max-frame-bytes", "50000",
                     "--overload", "block"])
    try:
        _wait(lambda: len(rx.of("health")) >= 1, 60, "the service's first health message")
        tx = Client(broker, "tx-size")
        big = json.dumps(frame("cam2", 0)) + " " * 2_000_000  # 2 MB: refused before it is queued
        for i in range(6):
            tx.publish("detections/cam1", frame("cam1", i))
            tx.publish("detections/cam2", big)
        _wait(lambda: _settled(rx, 12), 60, "every frame to be accounted for")
        h = rx.of("health")[-1]
        assert h["frames_out"] == 6 and h["errors"] == 6 and h["frames_dropped"] == 0
        assert all("larger than the limit of 50000 bytes" in e["reason"] and e["camera_id"] == "cam2"
                   for e in rx.of("error"))
        tx.close()
    finally:
        rc, _, err = stop_serve(p)
        rx.close()
    assert rc == 0, err[-2000:]


def _hwm_mb(pid: int) -> float:
    with open(f"/proc/{pid}/status") as f:
        return int(next(x for x in f if x.startswith("VmHWM")).split()[1]) / 1024


def test_big_frames_on_many_topics_keep_memory_bounded(broker, camera_file):  # noqa: F811
    """The issue's 300 topics x 9 MB frames (RSS 2.2 GB, paho's thread dead of MemoryError), scaled down to
    30 topics x 5 MB: each frame is over the default 4 MB limit and refused on receipt, the service's peak
    RSS grows by a few MB (not 150), every frame is accounted for and the service keeps working."""
    rx = Client(broker, "rx-mem", "footprints/#")
    p = start_serve(["--camera", str(camera_file), "--budget", "basler1", "--mqtt", broker.url, "--output", "mqtt",
                     "--client-id", "serve-mem", "--health-interval-s", "0.2"])
    try:
        _wait(lambda: len(rx.of("health")) >= 1, 60, "the service's first health message")
        hwm0 = _hwm_mb(p.pid)
        tx = Client(broker, "tx-mem")
        pad = " " * 5_000_000
        for k in range(30):
            tx.publish(f"detections/c{k}", json.dumps(frame(f"c{k}", 0, n=2)) + pad).wait_for_publish(30)
        tx.publish("detections/cam1", frame("cam1", 1))
        _wait(lambda: _settled(rx, 31), 120, "every frame to be accounted for")
        h = rx.of("health")[-1]
        assert h["errors"] == 30 and h["frames_out"] == 1 and h["frames_dropped"] == 0
        assert _hwm_mb(p.pid) - hwm0 < 60
        tx.close()
    finally:
        rc, _, err = stop_serve(p)
        rx.close()
    assert rc == 0, err[-2000:]


def test_queue_and_limits_in_a_seeded_sequence():
    """Accounting invariant of the queue under a seeded random put/get sequence: taken + pending + dropped ==
    put, bytes never beyond the bound (except one lone frame), and each key's items in put order."""
    rng = np.random.default_rng(3)
    q = FrameQueue("newest", depth=3, max_bytes=1000)
    put = taken = 0
    last = {}
    for step in range(3000):
        if rng.random() < 0.6:
            k = int(rng.integers(0, 5))
            put += 1
            q.put(k, (k, step), int(rng.integers(1, 400)))
            assert q.bytes <= 1000 or len(q) == 1
        else:
            item = q.get(0)
            if item is not None:
                taken += 1
                k, s = item
                assert last.get(k, -1) < s
                last[k] = s
        assert taken + len(q) + q.dropped == put


def test_quick_ack_is_set_on_a_tcp_socket():
    """The 50 Hz fix: after a frame or a PUBACK the service's socket is switched to quick-ack (Linux), so a
    broker with Nagle's algorithm on does not hold the next frame for a delayed ACK."""
    import socket

    from footprint_uq.service.runner import quick_ack

    if not hasattr(socket, "TCP_QUICKACK"):
        pytest.skip("TCP_QUICKACK is Linux-only")
    with socket.create_server(("127.0.0.1", 0)) as srv:
        c = socket.create_connection(srv.getsockname())
        s, _ = srv.accept()
        with c, s:
            c.sendall(b"x")
            s.recv(1)
            s.sendall(b"y")  # sending after receiving: the kernel's delayed-ACK ("ping-pong") mode
            quick_ack(s)
            assert s.getsockopt(socket.IPPROTO_TCP, socket.TCP_QUICKACK) == 1
    quick_ack(None)  # no socket yet (before the connection): nothing to do
