"""``serve --cp-service`` end to end with a real Mosquitto broker, received as a V2X stack would receive it.

Three cameras of the intersection (tests/cp_traffic.py: the cameras of footprint_uq.tracking.rsu_synthetic, their
files and a registry written into tmp_path), vehicles on the lanes, a parked car and a pedestrian; every camera's
frames published to ``detections/<camera_id>`` at 20 Hz of data time, paced at about 20 Hz; the service runs as the
real CLI in a subprocess.  A receiver subscribed to ``footprints/#`` checks:

* every CPM on ``footprints/rsu/cpm`` decodes with BOTH official decoders (asn1tools and pycrate, the ETSI modules of
  CDD 2.2.1 and 2.4.1: tests/test_cpm_official.py) to the same JSON as the project's decoder;
* the events on ``footprints/rsu/events``: one every T_GenCpm (100 ms) of data time, each event's segments those of
  its referenceTime (numbered, every object the record sends in exactly the segment it names, no other object;
  ``--cpm-max-bytes 520`` splits the events that carry the sensor containers);
* the Sensor Information container in the first event's first segment and again at the first event once a second
  has passed;
* the SDSM on ``footprints/rsu/sdsm`` of each event: the same fused objects (ids) and positions as the record, the
  CPM's positions equal to the record's (cm), the per-camera records still on ``footprints/<camera_id>``;
* the health record's ``cp_service`` counts equal what arrived.
"""

from __future__ import annotations

import json
import threading
import time

import numpy as np
import pytest

from cp_traffic import T0, frames, write_site
from footprint_uq.service.messages.cpm import coordinate_cm, decode_cpm_uper
from footprint_uq.service.messages.sdsm import offset_dm
from test_cpm_official import decode_official, official  # noqa: F401 - the fixture
from test_service_mqtt import MOSQUITTO, Broker, _wait, start_serve, stop_serve

mqtt = pytest.importorskip("paho.mqtt.client")
pytestmark = pytest.mark.skipif(MOSQUITTO is None, reason="mosquitto not installed (.ci/run installs it)")

RATE_HZ = 20.0
N_STEPS = 60  # 3 s of data time


@pytest.fixture
def broker(tmp_path):
    b = Broker(tmp_path)
    b.start()
    yield b
    b.stop()


class Receiver:
    """Every message on ``footprints/#`` as ``(topic, payload bytes)``, in arrival order."""

    def __init__(self, broker: Broker, name: str):
        self.msgs: list[tuple[str, bytes]] = []
        self.lock = threading.Lock()
        self.c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=name, clean_session=True)
        self.c.on_connect = lambda c, u, f, rc, p: c.subscribe("footprints/#", qos=1)
        self.c.on_message = self._on_message
        self.c.connect("127.0.0.1", broker.port, keepalive=5)
        self.c.loop_start()

    def _on_message(self, c, u, msg):
        with self.lock:
            self.msgs.append((msg.topic, bytes(msg.payload)))

    def on(self, topic: str) -> list[bytes]:
        with self.lock:
            return [p for t, p in self.msgs if t == topic]

    def health(self) -> list[dict]:
        return [json.loads(p) for p in self.on("footprints/health")]


def _publish_frames(broker: Broker) -> int:
    tx = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="tx-cp", clean_session=True)
    tx.connect("127.0.0.1", broker.port, keepalive=5)
    tx.loop_start()
    fr = frames(N_STEPS, rate_hz=RATE_HZ, seed=3)
    infos = []
    for k in range(N_STEPS):
        for f in fr[3 * k:3 * k + 3]:
            infos.append(tx.publish(f"detections/{f['camera_id']}", json.dumps(f), qos=1))
        time.sleep(1.0 / RATE_HZ)
    for i in infos:
        i.wait_for_publish(10)
    tx.disconnect()
    tx.loop_stop()
    return len(fr)


def _check_segments(ev: dict, cpms: list[dict]) -> None:
    """The CPMs of one event against its record (numbering, objects in exactly their segment, positions)."""
    assert len(cpms) == ev["counts"]["segments"] == len(ev["counts"]["bytes"])
    where, pos = {}, {}
    for k, cpm in enumerate(cpms):
        seg = cpm["payload"]["managementContainer"].get("segmentationInfo")
        assert (seg is None) == (len(cpms) == 1) and (seg is None or (seg["thisMsgNo"], seg["totalMsgNo"]) == (
            k + 1, len(cpms)))
        for c in cpm["payload"]["cpmContainers"]:
            if c["containerId"] == 5:
                assert c["containerData"]["numberOfPerceivedObjects"] == ev["counts"]["perceived"]
                for o in c["containerData"]["perceivedObjects"]:
                    assert o["objectId"] not in where  # every object in exactly one segment
                    where[o["objectId"]] = k + 1
                    pos[o["objectId"]] = (o["position"]["xCoordinate"]["value"], o["position"]["yCoordinate"]["value"])
    sent = {o["objectId"]: o for o in ev["objects"] if o["segment"] is not None}
    assert where == {i: o["segment"] for i, o in sent.items()}
    for i, xy_cm in pos.items():  # no origin, heading 0: east = x, north = y of W (the CDD's 0.01 m steps)
        assert xy_cm == tuple(coordinate_cm(np.array(sent[i]["xy_m"])).tolist())


def _check_sdsm(ev: dict, sdsm: dict) -> None:
    """The event's SDSM: the record's fused objects (at most 255), their positions in dm."""
    objs = {o["objectId"]: o for o in ev["objects"]}
    got = {o["detObjCommon"]["objectID"]: o["detObjCommon"]["pos"] for o in sdsm["objects"]}
    assert set(got) == set(objs) and len(got) == ev["counts"]["sdsm_objects"]
    for i, p in got.items():  # (J2735's 0.1 m offsets)
        assert (p["offsetX"], p["offsetY"]) == tuple(int(v) for v in offset_dm(np.array(objs[i]["xy_m"])))
    assert sdsm["sDSMTimeStamp"]["second"] == round((ev["time_s"] % 60) * 1000)


def test_cp_service_over_mosquitto_decodes_with_both_official_decoders(broker, tmp_path, official):  # noqa: F811
    reg = write_site(tmp_path)
    rx = Receiver(broker, "rx-cp")
    p = start_serve(["--registry", str(reg), "--mqtt", broker.url, "--output", "mqtt", "--tracks", "--cp-service",
                     "--overload", "block", "--client-id", "serve-cp", "--cpm-max-bytes", "520"])
    try:
        _wait(lambda: len(rx.health()) >= 1, 90, "the service's first health message")
        sent = _publish_frames(broker)

        def settled():
            h = rx.health()
            return h and h[-1]["frames_in"] == sent and h[-1]["pending"] == 0 and \
                h[-1]["cp_service"]["frames_ingested"] == sent and \
                h[-1]["cp_service"]["events"] == len(rx.on("footprints/rsu/events"))

        _wait(settled, 60, "every frame and event to be accounted for")
    finally:
        rc, _, err = stop_serve(p)
        rx.c.disconnect()
        rx.c.loop_stop()
    assert rc == 0, err[-2000:]
    events = [json.loads(m) for m in rx.on("footprints/rsu/events")]
    payloads = rx.on("footprints/rsu/cpm")
    sdsms = [json.loads(m) for m in rx.on("footprints/rsu/sdsm")]
    cp = rx.health()[-1]["cp_service"]
    assert cp["events"] == len(events) and cp["cpm_messages_published"] == len(payloads) == cp["cpms"]
    assert cp["frame_errors"] == cp["internal_errors"] == cp["frames_clock_backwards"] == 0
    assert {t for t, _ in rx.msgs if t.startswith("footprints/cam")} >= {f"footprints/cam{k}" for k in range(3)}

    # every CPM with both official decoders, the CDD 2.2.1 and 2.4.1 modules, equal to the project's decoder
    decoded = []
    for folder in ("cdd-v2.2.1", "cdd-v2.4.1"):
        spec, pycrate_cpm = official(folder)
        assert pycrate_cpm is not None, "pycrate is needed: the service's CPMs are checked by both decoders"
        for raw in payloads:
            outs = decode_official(raw, spec, pycrate_cpm)
            mine = decode_cpm_uper(raw)
            assert len(outs) == 2 and outs[0] == outs[1] == mine
            if folder == "cdd-v2.2.1":
                decoded.append(mine)
    by_ref: dict = {}
    for cpm in decoded:
        by_ref.setdefault(cpm["payload"]["managementContainer"]["referenceTime"], []).append(cpm)

    # events at 1 / T_GenCpm of data time (each at the first frame at or after its point of the 100-ms grid)
    t = np.array([e["time_s"] for e in events])
    assert abs(len(events) - N_STEPS / RATE_HZ / 0.1) <= 1
    assert np.all(np.diff(t) > 0.1 - 1e-6) and np.all(np.diff(t) < 0.1 + 1.0 / RATE_HZ + 1e-6)
    assert t[0] == pytest.approx(T0, abs=1e-6)
    assert sum(len(v) for v in by_ref.values()) == len(payloads)
    assert any(len(v) >= 2 for v in by_ref.values())  # 520 bytes: the events with the sensor containers are split
    info_t = []
    for ev in events:
        cpms = by_ref.get(ev["reference_time_ms"], [])
        _check_segments(ev, cpms)
        has_info = bool(cpms) and any(c["containerId"] == 3 for c in cpms[0]["payload"]["cpmContainers"])
        assert has_info == ev["sensor_information"]
        if has_info:
            info_t.append(ev["time_s"])
            regions = [c for c in cpms[0]["payload"]["cpmContainers"] if c["containerId"] == 4]
            assert {tuple(r["sensorIdList"]) for r in regions[0]["containerData"]} == {(1,), (2,), (3,)}
    # Sensor Information: at the first event, then at the first event once 1 s has passed
    assert info_t[0] == t[0] and len(info_t) >= 3
    for a, b in zip(info_t, info_t[1:], strict=False):
        assert b == min(x for x in t if x - a > 1.0 - 1e-6)
    # one SDSM per event with objects, the same fused objects
    with_objects = [e for e in events if e["objects"]]
    assert len(sdsms) == len(with_objects) and len(with_objects) >= len(events) - 1
    for ev, sdsm in zip(with_objects, sdsms, strict=True):
        _check_sdsm(ev, sdsm)
    # the fused list: each true object once (6), and an object two cameras see has both in sensorIdList
    last = events[-1]["objects"]
    assert len(last) == 6 and len({o["objectId"] for o in last}) == 6
    assert any(len(o["sensorIdList"]) >= 2 for e in events for o in e["objects"])
