"""``footprint-uq serve`` end to end, through a real Mosquitto broker and through stdin.

The broker (Debian package ``mosquitto``, installed by ``.ci/run``) is started by a fixture on a
free loopback port with its own config file (listener on 127.0.0.1 only, anonymous clients, no
persistence) and killed at the end; every wait is bounded.  The service runs as the real CLI in
a subprocess.  Checked: frames in = frames out + error records (+ the dropped frames the health
message counts), the UPER payloads decode (asn1tools) back to the CPM JSON, the confidence fields
are footprint_uq.products.v2x's, a broker restart in the middle of the stream, SIGTERM drains and exits 0,
and stdin mode with a malformed line in the middle.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from footprint_uq import PanTiltCamera, save_camera
from footprint_uq.products.v2x import cpm_fields, j2735_fields
from footprint_uq.service.messages.cpm import decode_cpm_uper

mqtt = pytest.importorskip("paho.mqtt.client")
pytest.importorskip("asn1tools")

MOSQUITTO = shutil.which("mosquitto") or ("/usr/sbin/mosquitto" if Path("/usr/sbin/mosquitto").exists() else None)
pytestmark = pytest.mark.skipif(MOSQUITTO is None, reason="mosquitto not installed (.ci/run installs it)")

T0 = 1714564800.0
CLI = [sys.executable, "-m", "footprint_uq.cli", "serve"]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait(cond, timeout_s: float, what: str):
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if cond():
            return
        time.sleep(0.02)
    raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")


class Broker:
    def __init__(self, tmp_path: Path):
        self.port = _free_port()
        self.conf = tmp_path / "mosquitto.conf"
        self.conf.write_text(f"listener {self.port} 127.0.0.1\nallow_anonymous true\npersistence false\n")
        self.log = tmp_path / "mosquitto.log"
        self.proc = None

    @property
    def url(self) -> str:
        return f"mqtt://127.0.0.1:{self.port}"

    def start(self):
        self.proc = subprocess.Popen([MOSQUITTO, "-c", str(self.conf)], stdout=open(self.log, "ab"),
                                     stderr=subprocess.STDOUT)

        def up():
            try:
                socket.create_connection(("127.0.0.1", self.port), timeout=0.2).close()
                return True
            except OSError:
                return False

        _wait(up, 10, "mosquitto to listen")

    def stop(self):
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        self.proc = None


@pytest.fixture
def broker(tmp_path):
    b = Broker(tmp_path)
    b.start()
    yield b
    b.stop()


@pytest.fixture(scope="module")
def camera_file(tmp_path_factory):
    p = tmp_path_factory.mktemp("cam") / "cam.yaml"
    save_camera(PanTiltCamera(focal_px=1400, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0),
                p)
    return p


class Client:
    """A paho client that collects what arrives on the subscribed topics (resubscribes on reconnect)."""

    def __init__(self, broker: Broker, name: str, subscribe: str | None = None):
        self.records: list[tuple[str, dict]] = []
        self.lock = threading.Lock()
        self.connects = 0
        self.c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=name, clean_session=False)
        self.c.reconnect_delay_set(1, 2)

        def on_connect(c, u, flags, rc, props):
            self.connects += 1
            if subscribe:
                c.subscribe(subscribe, qos=1)

        def on_message(c, u, msg):
            with self.lock:  # a compact record's CPM: UPER bytes on <prefix>/<camera_id>/cpm
                self.records.append((msg.topic, {"type": "cpm", "bytes": msg.payload} if msg.topic.endswith("/cpm")
                                     else json.loads(msg.payload)))

        self.c.on_connect = on_connect
        self.c.on_message = on_message
        self.c.connect("127.0.0.1", broker.port, keepalive=5)
        self.c.loop_start()
        _wait(lambda: self.connects >= 1, 10, f"{name} to connect")

    def of(self, kind: str) -> list[dict]:
        with self.lock:
            return [r for _, r in self.records if r.get("type") == kind]

    def publish(self, topic, payload):
        return self.c.publish(topic, payload if isinstance(payload, str) else json.dumps(payload), qos=1)

    def close(self):
        self.c.disconnect()
        self.c.loop_stop()


def frame(camera_id, i, n=5, seed=0):
    rng = np.random.default_rng(seed + i)
    dets = [{"object_id": k, "class": "car", "u_min_px": float(u), "v_min_px": float(v - 80), "u_max_px": float(u + 90),
             "v_max_px": float(v)} for k, (u, v) in enumerate(zip(rng.uniform(100, 1700, n), rng.uniform(500, 1070, n),
                                                                 strict=True))]
    return {"camera_id": camera_id, "frame": i, "timestamp_s": T0 + i / 30, "detections": dets}


def check_footprints(rec: dict, heading_offset_deg: float = 0.0):
    """UPER payload decodes to the CPM JSON; confidence fields are footprint_uq.products.v2x's of cov_m2."""
    assert decode_cpm_uper(rec["cpm_uper_hex"]) == rec["cpm"]
    for o in rec["objects"]:
        if o["status"] != "ok":
            continue
        cov = np.array(o["cov_m2"])
        f = {**cpm_fields(cov, heading_offset_deg), **j2735_fields(cov, heading_offset_deg)}
        assert {k: int(v) for k, v in f.items()} == {k: o[k] for k in f}


def check_compact(rx, camera_id: str):
    """The compact records of one camera (serve's default with --output mqtt) and the CPMs on their own topic: one
    CPM per record, in order, of the length the record says, decoding (asn1tools) to the record's objects in the
    messages (their message ids)."""
    with rx.lock:
        recs = [r for t, r in rx.records if t == f"footprints/{camera_id}" and r["type"] == "footprints"]
        cpms = [r["bytes"] for t, r in rx.records if t == f"footprints/{camera_id}/cpm"]
    assert recs and len(recs) == len(cpms)
    for rec, cpm in zip(recs, cpms, strict=True):
        assert rec["record"] == "compact" and "cpm" not in rec and rec["cpm_uper_bytes"] == len(cpm)
        objs = decode_cpm_uper(cpm.hex())["payload"]["cpmContainers"][1]["containerData"]["perceivedObjects"]
        assert [o["objectId"] for o in objs] == [o["message_object_id"] for o in rec["objects"]
                                                 if o["message_object_id"] is not None]


def start_serve(args, **kw):
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    return subprocess.Popen(CLI + args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, **kw)


def stop_serve(p, timeout_s=20):
    if p.poll() is None:
        p.send_signal(signal.SIGTERM)
    try:
        out, err = p.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        p.kill()
        out, err = p.communicate()
        raise AssertionError(f"serve did not stop within {timeout_s} s after SIGTERM: {err.decode()[-2000:]}") from None
    return p.returncode, out.decode(), err.decode()


def test_mqtt_end_to_end_registry(broker, camera_file, tmp_path):
    reg = tmp_path / "reg.csv"
    reg.write_text(f"camera_id,camera,budget,heading_offset_deg\ncam1,{camera_file},basler1,\n"
                   f"cam2,{camera_file},bw-cube1,20\n")
    rx = Client(broker, "rx-e2e", "footprints/#")
    p = start_serve(["--registry", str(reg), "--mqtt", broker.url, "--output", "mqtt", "--client-id", "serve-e2e"])
    try:
        _wait(lambda: len(rx.of("health")) >= 1, 60, "the service's first health message")
        tx = Client(broker, "tx-e2e")
        sent = 0
        for i in range(12):
            for cam in ("cam1", "cam2"):
                tx.publish(f"detections/{cam}", frame(None if i % 3 else cam, i, seed=7))  # camera_id from the topic
                sent += 1
            time.sleep(0.03)
        tx.publish("detections/cam1", "{not json")
        tx.publish("detections/cam3", frame("cam3", 0))  # not in the registry
        tx.publish("detections/cam2", frame("cam1", 99))  # camera_id does not match the topic
        sent += 3

        def settled():
            h = rx.of("health")
            return h and h[-1]["frames_in"] == sent and h[-1]["pending"] == 0 and \
                h[-1]["frames_out"] + h[-1]["errors"] + h[-1]["frames_dropped"] == sent

        _wait(settled, 30, "every frame to be accounted for")
        h = rx.of("health")[-1]
        fps, errs = rx.of("footprints"), rx.of("error")
        assert len(fps) == h["frames_out"] and len(errs) == h["errors"] == 3
        assert h["frames_out"] + h["errors"] + h["frames_dropped"] == sent
        assert h["frames_out"] >= 12  # paced publishing: at most a few frames replaced by newer ones
        assert {e["camera_id"] for e in errs} == {"cam1", "cam2", "cam3"}
        for cam in ("cam1", "cam2"):
            check_compact(rx, cam)
        with rx.lock:
            topics = {t for t, r in rx.records if r["type"] == "footprints"}
            cpm_topics = {t for t, r in rx.records if r["type"] == "cpm"}
        assert topics == {"footprints/cam1", "footprints/cam2"}
        assert cpm_topics == {"footprints/cam1/cpm", "footprints/cam2/cpm"}
        tx.close()
    finally:
        rc, _, err = stop_serve(p)
        rx.close()
    assert rc == 0, err[-2000:]


def test_broker_restart_mid_stream(broker, camera_file):
    rx = Client(broker, "rx-restart", "footprints/#")
    p = start_serve(["--camera", str(camera_file), "--budget", "basler1", "--mqtt", broker.url, "--output", "mqtt",
                     "--overload", "block", "--client-id", "serve-restart", "--record", "full"])
    try:
        _wait(lambda: len(rx.of("health")) >= 1, 60, "the service's first health message")
        tx = Client(broker, "tx-restart")
        for i in range(10):
            tx.publish("detections/cam1", frame("cam1", i))
        _wait(lambda: len(rx.of("footprints")) == 10, 30, "the first 10 frames")
        broker.stop()
        time.sleep(1.0)
        broker.start()
        n_health = len(rx.of("health"))
        # the service and both clients reconnect with back-off; the service's health messages resume
        _wait(lambda: len(rx.of("health")) > n_health + 1, 40, "health messages after the restart")
        _wait(lambda: tx.connects >= 2, 20, "the publisher to reconnect")
        for i in range(10, 20):
            tx.publish("detections/cam1", frame("cam1", i))
        _wait(lambda: len(rx.of("footprints")) == 20, 30, "the 10 frames sent after the restart")
        assert sorted(r["frame"] for r in rx.of("footprints")) == list(range(20))
        for rec in rx.of("footprints"):
            check_footprints(rec)
        h = rx.of("health")[-1]
        assert h["frames_dropped"] == 0 and h["errors"] == 0
        tx.close()
    finally:
        rc, _, err = stop_serve(p)
        rx.close()
    assert rc == 0, err[-2000:]


def test_sigterm_drains_and_exits_0(broker, camera_file):
    p = start_serve(["--camera", str(camera_file), "--budget", "basler1", "--mqtt", broker.url, "--output", "-",
                     "--client-id", "serve-drain"])
    lines: list[dict] = []
    reader = threading.Thread(target=lambda: lines.extend(json.loads(raw) for raw in p.stdout), daemon=True)
    reader.start()
    _wait(lambda: any(r["type"] == "health" for r in list(lines)), 60, "the service's first health message")
    tx = Client(broker, "tx-drain")
    infos = [tx.publish("detections/cam1", frame("cam1", i, n=50)) for i in range(40)]
    for info in infos:
        info.wait_for_publish(10)
    p.send_signal(signal.SIGTERM)
    assert p.wait(30) == 0, p.stderr.read().decode()[-2000:]
    reader.join(10)
    tx.close()
    last = lines[-1]
    assert last["type"] == "health" and last["pending"] == 0
    n_fp = sum(r["type"] == "footprints" for r in lines)
    assert last["frames_out"] == n_fp and last["errors"] == 0
    assert last["frames_in"] == last["frames_out"] + last["frames_dropped"]
    assert last["frames_in"] > 0 and n_fp >= 1


def test_stdin_with_a_malformed_line_in_the_middle(camera_file):
    frames = [json.dumps(frame("cam1", i)) for i in range(5)]
    bad_field = frame("cam1", 5)
    bad_field["detections"][1]["u_max_px"] = "wide"
    lines = frames[:2] + ['{"camera_id": "cam1", "frame": 2,'] + frames[2:] + [json.dumps(bad_field), ""]
    p = subprocess.run(CLI + ["--camera", str(camera_file), "--budget", "basler1", "--input", "-",
                              "--health-interval-s", "0"], input="\n".join(lines).encode(), capture_output=True,
                       timeout=120, env={**os.environ, "NUMBA_NUM_THREADS": "1"})
    assert p.returncode == 0, p.stderr.decode()[-2000:]
    recs = [json.loads(x) for x in p.stdout.decode().splitlines()]
    fps = [r for r in recs if r["type"] == "footprints"]
    errs = [r for r in recs if r["type"] == "error"]
    health = [r for r in recs if r["type"] == "health"]
    assert [r["frame"] for r in fps] == [0, 1, 2, 3, 4, 5]  # 'block' policy on stdin: nothing dropped, in order
    assert len(errs) == 1 and len(health) == 1  # the final health message
    assert errs[0]["source"] == "stdin line 3" and "invalid JSON" in errs[0]["reason"]
    # the bad detection of frame 5 is that detection's error entry; the frame's other detections are published
    assert [e["field"] for e in fps[-1]["detection_errors"]] == ["detections[1].u_max_px"]
    assert fps[-1]["n_objects"] == 4 and health[0]["detection_errors"] == 1
    assert health[0]["frames_in"] == 7 == health[0]["frames_out"] + health[0]["errors"]
    for rec in fps:
        check_footprints(rec)


def test_two_worker_processes_split_the_cameras(broker, camera_file, tmp_path):
    reg = tmp_path / "reg.csv"
    reg.write_text("camera_id,camera,budget\n" + "".join(f"cam{i},{camera_file},basler1\n" for i in range(3)))
    rx = Client(broker, "rx-workers", "footprints/#")
    p = start_serve(["--registry", str(reg), "--mqtt", broker.url, "--output", "mqtt", "--overload", "block",
                     "--workers", "2", "--client-id", "serve-workers"])
    try:
        _wait(lambda: {h.get("worker") for h in rx.of("health")} == {"1/2", "2/2"}, 90, "both workers' health")
        tx = Client(broker, "tx-workers")
        for i in range(4):
            for c in range(3):
                tx.publish(f"detections/cam{c}", frame(f"cam{c}", i))
        _wait(lambda: len(rx.of("footprints")) == 12, 30, "12 records")
        assert sorted((r["camera_id"], r["frame"]) for r in rx.of("footprints")) == \
            sorted((f"cam{c}", i) for c in range(3) for i in range(4))
        tx.close()
    finally:
        rc, _, err = stop_serve(p)
        rx.close()
    assert rc == 0, err[-2000:]
    last = {}
    for h in rx.of("health"):
        last[h["worker"]] = h
    assert sum(h["frames_out"] for h in last.values()) == 12  # cam0, cam2 -> worker 1; cam1 -> worker 2
    assert last["1/2"]["frames_out"] == 8 and last["2/2"]["frames_out"] == 4


def test_sigterm_while_starting_up_exits_0(broker, camera_file):
    p = start_serve(["--camera", str(camera_file), "--budget", "basler1", "--mqtt", broker.url, "--output", "-",
                     "--client-id", "serve-early"])
    assert b"starting" in p.stderr.readline()  # signal handlers in place; cameras and kernels still loading
    rc, out, err = stop_serve(p)
    assert rc == 0, err[-2000:]
    recs = [json.loads(x) for x in out.splitlines()]
    assert recs and recs[-1]["type"] == "health" and recs[-1]["frames_in"] == 0


def test_service_client_disables_nagle(broker):
    """The service's broker connection has TCP_NODELAY (Nagle off): its records and PUBACKs leave at once."""
    from footprint_uq.service.runner import _mqtt_client

    c = _mqtt_client("127.0.0.1", broker.port, "nodelay-check")
    connected = threading.Event()
    c.on_connect = lambda *a: connected.set()
    c.connect("127.0.0.1", broker.port)
    c.loop_start()
    try:
        _wait(connected.is_set, 10, "the connection")
        assert c.socket().getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY) != 0
    finally:
        c.disconnect()
        c.loop_stop()
