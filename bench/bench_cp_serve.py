"""The deployed CP service under issue 32's load: 8 cameras x 30 Hz x 100 road users around one intersection, fused,
CPMs at 10 Hz, through a real Mosquitto on loopback.

    PYTHONPATH=src .venv/bin/python bench/bench_cp_serve.py [--seconds 40] [--quick] [--json PATH]

The site (:func:`site`): the 8 straight-through lanes of :mod:`footprint_uq.tracking.rsu_synthetic` and eight
1920x1080 cameras around the box (four on the corners, 8 m high, four on the arms 25 m out, 10 m high), each looking
at the centre, 80 deg wide, tilted 20 deg down, views overlapping.  100 road users (:func:`road_users`): 60 vehicles
driving the lanes at 8-12 m/s (evenly spaced, one speed per lane; one that leaves
at 50 m comes back at -50 m as a new road user), 25 parked cars along the kerbs, 15 persons walking the pavements.
Each camera's frame holds the users it images inside the picture, ahead of it, within 60 m, as 2D boxes (bottom
centre = the ground contact point + 1 px of noise, class and confidence), every frame prepared before the run; at
publish time the frame gets ``timestamp_s`` = the publish time (the same clock as the receiver's).

Two runs in one invocation, the same frames: ``serve --registry R --tracks --cp-service --mqtt ... --output mqtt
--no-per-camera-output`` (serve's default ``--cpm-max-bytes``, 1,100 bytes, unless ``--cpm-max-bytes`` is given)
and, the reference, the same without the CP service (``serve --registry R --tracks``: every camera frame's record,
as before issue 32).  The 8 cameras' frames are published synchronised (one burst every
1/30 s); a receiver in a process of its own takes every message on ``footprints/#``.  Measured:

* ``serve_cpu_s_per_traffic_s``: CPU seconds of the service process (all threads, ``/proc``) per second of traffic;
* CPM segment sizes (bytes, p50 / p99 / max), segments per event, objects per event (perceived and sent);
* the latency from a frame's publish to the CPM segments of the first generation event after it that sent any
  (``latency_to_first_segment_ms`` and ``latency_to_event_complete_ms``: the first and the last segment of that event
  received on ``footprints/rsu/cpm``; a segment is matched to its event by order: each event's segments arrive
  before its record on ``footprints/rsu/events``, from one client), p50 / p99 -- it includes the wait for the next
  generation event (up to T_GenCpm = 100 ms); the reference's is publish -> the frame's own record;
* frames dropped / errors (the service's last health record), the load average at start and end, VM steal.

Nothing is asserted: the figures depend on the machine and its load (a shared 2-core VM).
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import orjson
from bench_service import _TS, _cpu_s, _descendants, _steal_s, _vm_hwm_mb, start_receiver
from mqtt_broker import mosquitto
from mqtt_broker import wait as _wait

HERE = Path(__file__).resolve().parent
RATE_HZ = 30.0
N_CAMERAS = 8
N_OBJECTS = 100
#: the CPM size limit of the runs: None = serve's default (1,100 bytes).  The 8 cameras' Sensor Information and
#: Perception Region entries (1,119 bytes together) no longer fit one segment: an event spreads them over its first
#: segments (docs/service.md, "Segmentation"); before that, the bench needed --cpm-max-bytes 1300
CPM_MAX_BYTES = None


def site() -> list:
    """The eight cameras (module doc): corners (+-9, +-9) m at 8 m, arms 25 m out at 10 m, all looking at the
    centre."""
    from footprint_uq import PanTiltCamera

    f = 1920 / (2.0 * math.tan(math.radians(80.0) / 2.0))
    spots = [((9.0, 9.0), 8.0), ((-9.0, 9.0), 8.0), ((-9.0, -9.0), 8.0), ((9.0, -9.0), 8.0),
             ((9.0, 25.0), 10.0), ((-25.0, 9.0), 10.0), ((-9.0, -25.0), 10.0), ((25.0, -9.0), 10.0)]
    cams = []
    for (x, y), h in spots:
        pan = math.degrees(math.atan2(-x, -y)) % 360.0  # pan: clockwise from +y, towards the centre
        cams.append(PanTiltCamera(f, (1920, 1080), h, pan, 20.0, position_m=(x, y), principal_point_px=(960, 540)))
    return cams


def road_users(n: int = N_OBJECTS, seed: int = 0):
    """``(xy_at(t) -> ((n, 2) m, object ids (n,)), classes (n,))``: 60 % vehicles on the lanes, 25 % parked,
    15 % persons (module doc)."""
    from footprint_uq.tracking.rsu_synthetic import LANES

    rng = np.random.default_rng(seed)
    n_move, n_park = int(round(0.6 * n)), int(round(0.25 * n))
    n_walk = n - n_move - n_park
    # each lane: its vehicles evenly spaced over its 100 m at the lane's one speed (nobody drives through anybody);
    # a vehicle that leaves at +50 m enters again at -50 m as a new road user (a new object_id)
    lane = np.arange(n_move) % len(LANES)
    base = np.array([LANES[k][0] for k in lane])
    step = np.array([LANES[k][1] for k in lane])
    per_lane = np.bincount(lane, minlength=len(LANES))
    rank = np.array([np.count_nonzero(lane[:i] == lane[i]) for i in range(n_move)])
    s0 = rng.uniform(0.0, 100.0, len(LANES))[lane] + 100.0 * rank / per_lane[lane]
    speed = rng.uniform(8.0, 12.0, len(LANES))[lane]
    # parked: along the kerbs (8.5 m from an axis), outside the box
    axis = rng.integers(0, 2, n_park)
    along = rng.choice([-1.0, 1.0], n_park) * rng.uniform(14.0, 45.0, n_park)
    side = rng.choice([-8.5, 8.5], n_park)
    parked = np.where(axis[:, None] == 0, np.column_stack([side, along]), np.column_stack([along, side]))
    # persons: on the pavements (10 m from an axis), walking along it at 1.4 m/s
    w_axis = rng.integers(0, 2, n_walk)
    w_side = rng.choice([-10.0, 10.0], n_walk)
    w_s0 = rng.uniform(-40.0, 40.0, n_walk)
    w_dir = rng.choice([-1.0, 1.0], n_walk)

    def xy_at(t: float) -> tuple[np.ndarray, np.ndarray]:
        lap, s = np.divmod(s0 + speed * t, 100.0)
        move = base + (s - 50.0)[:, None] * step
        ids = np.arange(n)
        ids[:n_move] += n * lap.astype(np.int64)  # (a road user that wraps round comes back as a new one)
        w_lap, ws = np.divmod(w_s0 + 1.4 * w_dir * t + 40.0, 80.0)
        ws = ws - 40.0
        ids[n - n_walk:] += n * np.abs(w_lap).astype(np.int64)
        walk = np.where(w_axis[:, None] == 0, np.column_stack([w_side, ws]), np.column_stack([ws, w_side]))
        return np.concatenate([move, parked, walk]), ids

    classes = ["car"] * (n_move + n_park) + ["person"] * n_walk
    return xy_at, classes


def frame_bodies(cams: list, n_frames: int, seed: int = 0) -> list[list[bytes]]:
    """Each frame's detections (JSON bytes) per camera: ``bodies[k][j]`` (module doc)."""
    xy_at, classes = road_users(seed=seed)
    rng = np.random.default_rng(seed + 1)
    out = []
    for k in range(n_frames):
        xy, oid = xy_at(k / RATE_HZ)
        row = []
        for cam in cams:
            pr = cam.project_ground(xy)
            uv = pr.uv_px + rng.normal(0.0, 1.0, xy.shape)
            rel = xy - np.asarray(cam.position_m)
            pan = math.radians(cam.pan_deg)
            fwd = rel @ np.array([math.sin(pan), math.cos(pan)])
            lat = rel @ np.array([math.cos(pan), -math.sin(pan)])
            rng_m = np.hypot(rel[:, 0], rel[:, 1])
            seen = (pr.valid & np.isfinite(uv).all(1) & (uv[:, 0] >= 0) & (uv[:, 0] < 1920) & (uv[:, 1] >= 0)
                    & (uv[:, 1] < 1080) & (rng_m < 60.0) & (fwd > 0)
                    & (np.abs(lat) < fwd * 0.5 * 1920 / cam.focal_px))
            dets = []
            for i in np.flatnonzero(seen):
                wpx = float(min(cam.focal_px * (0.6 if classes[i] == "person" else 1.8) / max(rng_m[i], 1.0), 600.0))
                u, v = float(uv[i, 0]), float(uv[i, 1])
                dets.append({"object_id": int(oid[i]), "class": classes[i], "class_confidence": 0.9,
                             "u_min_px": round(u - wpx / 2, 2), "v_min_px": round(v - 0.8 * wpx, 2),
                             "u_max_px": round(u + wpx / 2, 2), "v_max_px": round(v, 2)})
            row.append(orjson.dumps(dets))
        out.append(row)
    return out


def write_site(folder: Path, cams: list) -> Path:
    from footprint_uq.io import save_camera

    rows = ["camera_id,camera,budget,sensor_id,clock_offset_sigma_s"]
    for j, cam in enumerate(cams):
        save_camera(cam, folder / f"cam{j}.yaml")
        rows.append(f"cam{j},cam{j}.yaml,basler1@deg,{j + 1},0.002")
    (folder / "registry.csv").write_text("\n".join(rows) + "\n")
    return folder / "registry.csv"


def measure(seconds: float, *, cp: bool, bodies: list, reg_dir: Path,
            cpm_max_bytes: int | None = CPM_MAX_BYTES) -> dict:
    """One run (module doc): the CP service (``cp``) or the reference; ``bodies`` from :func:`frame_bodies`."""
    import paho.mqtt.client as mqtt

    from footprint_uq.service import tcp_no_delay

    tmp = Path(tempfile.mkdtemp(prefix="bench_cp_serve_"))
    stack = contextlib.ExitStack()
    stack.callback(shutil.rmtree, tmp, ignore_errors=True)
    broker, port = stack.enter_context(mosquitto(tmp))
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    args = ["--registry", str(reg_dir / "registry.csv"), "--tracks", "--mqtt", f"mqtt://127.0.0.1:{port}",
            "--output", "mqtt", "--client-id", "bench-cp"]
    if cp:
        args += ["--cp-service", "--no-per-camera-output"]
        if cpm_max_bytes is not None:
            args += ["--cpm-max-bytes", str(cpm_max_bytes)]
    serve = rx = None
    load_start = os.getloadavg()
    n_frames = min(len(bodies), int(round(seconds * RATE_HZ)))
    try:
        serve = subprocess.Popen([sys.executable, "-m", "footprint_uq.cli", "serve", *args],
                                 stdout=subprocess.DEVNULL, stderr=open(tmp / "serve.err", "wb"), env=env)
        rx, health, result, lock = start_receiver(__file__, port, env)
        def started() -> bool:
            if serve.poll() is not None:
                raise RuntimeError(f"serve exited: {(tmp / 'serve.err').read_text()[-400:]}")
            return bool(health)

        _wait(started, 300, "the service's first health message (numba may compile)")
        tx = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="bench-cp-tx")
        tx.on_socket_open = tcp_no_delay
        tx.max_inflight_messages_set(1000)
        tx.connect("127.0.0.1", port)
        tx.loop_start()
        ids = [f"cam{j}".encode() for j in range(len(bodies[0]))]
        stamps = np.empty((n_frames, len(ids)))
        cpu0_s = sum(_cpu_s(p) for p in [serve.pid, *_descendants(serve.pid)])
        steal0 = _steal_s()
        period = 1.0 / RATE_HZ
        t_start = time.monotonic()
        next_t = t_start
        for k in range(n_frames):  # synchronised: every camera's frame at the start of each period
            for j, c in enumerate(ids):
                ts = round(time.time(), 6)
                stamps[k, j] = ts
                payload = b'{"camera_id":"%s","frame":%d,"timestamp_s":%.6f,"detections":%s}' % (
                    c, k, ts, bodies[k][j])
                tx.publish(f"detections/{c.decode()}", payload, qos=1)
            next_t += period
            time.sleep(max(0.0, next_t - time.monotonic()))
        t_pub = time.monotonic() - t_start
        sent = stamps.size

        def last() -> dict:
            with lock:
                return dict(health[-1]) if health else {}

        _wait(lambda: last().get("frames_in", 0) >= sent and last().get("pending", 1) == 0, 120,
              "the service to take in every frame")
        time.sleep(1.5)  # one more health record
        h = last()
        expect = {"events": h["cp_service"]["events"]} if cp else {"records": h["frames_out"]}
        rx.stdin.write(json.dumps(expect).encode() + b"\n")
        rx.stdin.flush()
        _wait(lambda: "received" in result, 90, "the receiver's figures")
        pids = [serve.pid, *_descendants(serve.pid)]
        cpu_s = sum(_cpu_s(p) for p in pids) - cpu0_s
        peak_rss_mb = sum(_vm_hwm_mb(p) for p in pids)
        steal_s = None if steal0 is None else _steal_s() - steal0
        serve.send_signal(signal.SIGTERM)
        rc = serve.wait(60)
        tx.loop_stop()
        rx.wait(30)
    finally:
        if serve is not None and serve.poll() is None:
            serve.kill()
        if rx is not None and rx.poll() is None:
            rx.kill()
        stack.close()
    out = {"cp_service": cp, "serve_args": " ".join(args[2:]), "seconds": round(t_pub, 2),
           "cameras": len(ids), "fps_per_camera": RATE_HZ, "road_users": N_OBJECTS,
           "detections_per_frame_mean": result.get("detections_per_frame_mean"),
           "frames_published": sent, "frames_in": h["frames_in"], "frames_out": h["frames_out"],
           "frames_dropped": h["frames_dropped"], "errors": h["errors"],
           "serve_cpu_s": round(cpu_s, 2), "serve_cpu_s_per_traffic_s": round(cpu_s / t_pub, 3),
           "serve_cpu_ms_per_frame": round(1e3 * cpu_s / max(h["frames_in"], 1), 3),
           "peak_rss_mb": round(peak_rss_mb, 1), "serve_exit_status": rc,
           "load_average_start": [round(x, 2) for x in load_start],
           "load_average_end": [round(x, 2) for x in os.getloadavg()], "vm_steal_s": steal_s}
    if cp:
        out.update(_cp_figures(result, stamps, h))
    else:
        lat = np.asarray(result["latency_ms"])
        out.update({"records_received": result["received"], "latency_to_record_ms": _pct(lat)})
    return out


def _pct(a, qs=(50, 99)) -> dict:
    a = np.asarray(a, dtype=float)
    return {**{f"p{q}": round(float(np.percentile(a, q)), 2) for q in qs}, "max": round(float(a.max()), 2),
            "n": int(a.size)} if a.size else {}


def _cp_figures(result: dict, stamps: np.ndarray, health: dict) -> dict:
    """Events and per-frame latencies from the receiver's event list (module doc)."""
    ev = result["events"]  # [time_s, first segment rx, last segment rx, segments, perceived, sent, [bytes], [xy]]
    with_seg = [e for e in ev if e[3] > 0]
    t_ev = np.array([e[0] for e in with_seg])
    first = np.array([e[1] for e in with_seg])
    last = np.array([e[2] for e in with_seg])
    ts = stamps.ravel()
    k = np.searchsorted(t_ev, ts - 1e-7, side="left")  # the first event at or after the frame's time
    ok = k < len(t_ev)
    seg_bytes = [b for e in ev for b in e[6]]
    return {"events_received": len(ev), "events_with_cpm": len(with_seg),
            "segment_mismatches": result["segment_mismatches"],
            "cpm_rate_hz": round(len(ev) / max(ev[-1][0] - ev[0][0], 1e-9) * (len(ev) - 1) / len(ev), 3)
            if len(ev) > 1 else None,
            "segment_bytes": _pct(seg_bytes, (5, 50, 95, 99)),
            "segments_per_event": _pct([e[3] for e in with_seg], (50, 99)),
            "objects_perceived_per_event": _pct([e[4] for e in ev], (50, 99)),
            "objects_sent_per_event": _pct([e[5] for e in ev], (50, 99)),
            "frames_without_a_later_event": int((~ok).sum()),
            **_ghosts(ev, stamps),
            "latency_to_first_segment_ms": _pct(1e3 * (first[k[ok]] - ts[ok])),
            "latency_to_event_complete_ms": _pct(1e3 * (last[k[ok]] - ts[ok])),
            "cp_service_counts": health.get("cp_service")}


def _ghosts(ev: list, stamps: np.ndarray) -> dict:
    """Ghosts (objects > 3 m from every road user) and duplicates (road users with a second object) per event
    (:func:`footprint_uq.tracking.rsu_synthetic.score_positions`), against the road users of the frame whose publish
    time the event's time is (the event is polled at that frame's ``timestamp_s``)."""
    from footprint_uq.tracking.rsu_synthetic import score_positions

    xy_at, _ = road_users()
    first = stamps.min(1)
    g, d = [], []
    for e in ev:
        k = int(np.abs(stamps - e[0]).min(1).argmin()) if abs(first - e[0]).min() < 1.0 else None
        if k is None:
            continue
        gk, dk = score_positions(np.asarray(e[7], np.float64).reshape(-1, 2), xy_at(k / RATE_HZ)[0])
        g.append(gk)
        d.append(dk)
    return {"ghosts_per_event": {**_pct(g, (50, 99)), "mean": round(float(np.mean(g)), 2)} if g else {},
            "duplicates_per_event": {**_pct(d, (50, 99)), "mean": round(float(np.mean(d)), 2)} if d else {}}


def _receiver(port: int) -> None:
    """The subscriber (``--receiver PORT``): health records passed on at once; per event its time, the receive times
    of its first and last segment, its counts; per frame record (the reference) its latency."""
    import gc

    import paho.mqtt.client as mqtt

    from footprint_uq.service import tcp_no_delay

    lock, out_lock = threading.Lock(), threading.Lock()
    pending: list[tuple[float, int]] = []  # segments (rx time, bytes) waiting for their event record
    events: list = []
    lat_ms: list[float] = []
    st = {"segment_mismatches": 0}

    def say(d: dict) -> None:
        with out_lock:
            sys.stdout.write(json.dumps(d) + "\n")
            sys.stdout.flush()

    def on_message(c, u, msg):
        t = time.time()
        topic = msg.topic
        if topic == "footprints/rsu/cpm":
            with lock:
                pending.append((t, len(msg.payload)))
        elif topic == "footprints/rsu/events":
            rec = orjson.loads(msg.payload)
            n = rec["counts"]["segments"]
            with lock:
                segs = pending[len(pending) - n:] if n else []
                if len(pending) != n or [b for _, b in segs] != rec["counts"]["bytes"]:
                    st["segment_mismatches"] += 1
                del pending[:]
                events.append([rec["time_s"], segs[0][0] if segs else None, segs[-1][0] if segs else None, n,
                               rec["counts"]["perceived"], rec["counts"]["sent"], rec["counts"]["bytes"],
                               [o["xy_m"] for o in rec["objects"]]])
        elif topic == "footprints/health":
            say({"health": json.loads(msg.payload)})
        elif topic.count("/") == 1 and not topic.endswith(("/errors", "/rsu")):
            m = _TS.search(msg.payload, 0, 400)
            if m is not None:
                with lock:
                    lat_ms.append(1e3 * (t - float(m.group(1))))

    gc.collect()
    gc.freeze()
    rx = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="bench-cp-rx")
    rx.on_socket_open = tcp_no_delay
    rx.on_message = on_message
    subscribed = threading.Event()
    rx.on_connect = lambda c, u, f, rc, p: c.subscribe("footprints/#", qos=1)
    rx.on_subscribe = lambda *a: subscribed.set()
    rx.connect("127.0.0.1", port)
    rx.loop_start()
    _wait(subscribed.is_set, 30, "the subscription")
    say({"ready": True})
    expect = json.loads(sys.stdin.readline())
    with contextlib.suppress(RuntimeError):  # reported: received < expected
        if "events" in expect:
            _wait(lambda: len(events) >= expect["events"], 30, "the last events")
        else:
            _wait(lambda: len(lat_ms) >= expect["records"], 30, "the last records")
    rx.loop_stop()
    with lock:
        say({"result": {"events": events, "latency_ms": lat_ms, "received": len(events) or len(lat_ms),
                        **st}})


def main(argv=None) -> int:
    if argv is None and len(sys.argv) == 3 and sys.argv[1] == "--receiver":
        _receiver(int(sys.argv[2]))
        return 0
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=40.0)
    ap.add_argument("--quick", action="store_true", help="5 s instead of --seconds")
    ap.add_argument("--no-reference", action="store_true", help="skip the run without --cp-service")
    ap.add_argument("--cpm-max-bytes", type=int, default=CPM_MAX_BYTES,
                    help="serve's --cpm-max-bytes (default: not given, serve's default 1,100 bytes)")
    ap.add_argument("--json", type=Path, default=None,
                    help="where to write the results (default bench/results/cp-serve-<date>.json)")
    args = ap.parse_args(argv)
    seconds = 5.0 if args.quick else args.seconds
    cams = site()
    t0 = time.perf_counter()
    bodies = frame_bodies(cams, int(round(seconds * RATE_HZ)))
    prep_s = time.perf_counter() - t0
    n_det = [len(orjson.loads(b)) for row in bodies[:30] for b in row]
    with tempfile.TemporaryDirectory(prefix="bench_cp_site_") as d:
        write_site(Path(d), cams)
        runs = {"cp_service": measure(seconds, cp=True, bodies=bodies, reg_dir=Path(d),
                                      cpm_max_bytes=args.cpm_max_bytes)}
        if not args.no_reference:
            runs["reference_without_cp_service"] = measure(seconds, cp=False, bodies=bodies, reg_dir=Path(d))
    for r in runs.values():
        r["detections_per_frame_mean"] = round(float(np.mean(n_det)), 1)
    if len(runs) == 2:
        a, b = runs["cp_service"], runs["reference_without_cp_service"]
        runs["cpu_ratio_cp_over_reference"] = round(a["serve_cpu_s_per_traffic_s"] / b["serve_cpu_s_per_traffic_s"],
                                                    3)
    runs["frames_prepared_s"] = round(prep_s, 2)
    runs["date_utc"] = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    path = args.json or HERE / "results" / f"cp-serve-{datetime.date.today().isoformat()}.json"
    from footprint_uq.io.atomic import atomic_write_text

    atomic_write_text(path, json.dumps(runs, indent=1) + "\n")
    print(json.dumps(runs, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
