"""Edge-service load through a real Mosquitto on loopback: 8 cameras x 30 frames/s x 100 objects.

    .venv/bin/python bench/bench_service.py [--seconds 60] [--cameras 8] [--fps 30] [--objects 100] [--quick]
        [--tracks] [--stagger] [--serve-args='--queue-depth 1']

Starts ``mosquitto`` on a free loopback port and ``footprint-uq serve --registry ... --mqtt ...
--output mqtt`` as a subprocess (the real CLI, default overload policy ``newest``), then publishes,
from this process, one frame per camera every 1/fps s (QoS 1, 100 2D boxes each, a fresh
``timestamp_s`` = the publish time) for ``--seconds``, and receives every output on
``footprints/#``.  Reported:

* sustained rate: output frames per second over the run; frames published / out / dropped /
  errors (the service's final health message; target: every frame processed, none dropped);
* end-to-end latency p50 / p99: publish -> output received by the subscriber (same clock; the
  path detector -> broker -> service -> broker -> receiver), target p99 <= 20 ms;
* peak RSS of the service process (``VmHWM``);
* processing time per 100-object frame inside the service (``processing_us`` of the records:
  the footprints (detections into arrays + fused kernel), the per-object records, the messages
  (CPM + UPER + SDSM), the total, all as JSON text), and, in this process on the same frame
  (:func:`in_process_times`), the same stages, the payload's JSON parsing, CPU times, the dict API
  ``Service.process_frame`` and ``FrameProcessor.boxes2d`` alone (the reference); target <= 300 us
  per 100-object frame;
* CPU seconds of the service (and of each of its threads: the worker, paho's network thread, ...),
  the broker, the publisher (this process) and the receiver (a process of its own, so that reading
  ~33 MB/s of records does not compete with the publisher for the GIL), and the load average;
* ``chain_cpu_ms_per_frame`` (all of them per frame) and, synchronised, ``burst_cpu_floor_ms`` = cameras x
  that / cores: the end-to-end latency no arrangement of workers can beat on this machine for the last frame
  of a burst (the p99 target is out of reach where the floor is near it); ``vm_steal_s``: CPU seconds the
  hypervisor took from this virtual machine during the run (``/proc/stat``), where a stall came from.

``--quick`` runs 5 s; ``--tracks`` runs the service with ``--tracks`` (issue 22's configuration: motion per
``object_id``, in the records, the CPM and the SDSM; the boxes stand still, which costs the tracker what moving
ones do).  ``latency_split_ms`` says where the latency goes (processing, queueing, MQTT).  :func:`run` returns
rows for ``bench/run.py`` (section ``service``).
Nothing is asserted: the figures depend on the machine and its load (a shared 2-core VM).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
from mqtt_broker import mosquitto
from mqtt_broker import wait as _wait

TARGET_P99_MS = 20.0
TARGET_US = 300.0
CAMERA = dict(focal_px=1400.0, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)
_TS = re.compile(rb'"timestamp_s":([0-9.eE+-]+)')



def start_receiver(script: str, port: int, env: dict) -> tuple[subprocess.Popen, list, dict, threading.Lock]:
    """The bench's receiver (``script --receiver PORT``) in a process of its own, and a thread that collects its JSON
    lines: health records into a list, its final figures into a dict (both under the returned lock). Returns once
    the receiver says it is ready: ``(process, health, result, lock)``."""
    rx = subprocess.Popen([sys.executable, script, "--receiver", str(port)], stdin=subprocess.PIPE,
                          stdout=subprocess.PIPE, env=env)
    health: list[dict] = []
    result: dict = {}
    lock = threading.Lock()
    ready = threading.Event()

    def read_rx():
        for line in rx.stdout:
            d = json.loads(line)
            with lock:
                if "health" in d:
                    health.append(d["health"])
                elif "result" in d:
                    result.update(d["result"])
            if "ready" in d:
                ready.set()

    threading.Thread(target=read_rx, daemon=True).start()
    _wait(ready.is_set, 30, "the receiver")
    return rx, health, result, lock

def make_detections(n: int, seed: int) -> list[dict]:
    """n 2D boxes below the horizon of the bench camera (pixels, bottom edge = ground contact)."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(50, 1800, n)
    v = rng.uniform(420, 1070, n)
    w = rng.uniform(20, 120, n)
    return [{"object_id": int(k), "class": "car", "u_min_px": round(float(a), 2),
             "v_min_px": round(float(b - 0.8 * c), 2), "u_max_px": round(float(a + c), 2),
             "v_max_px": round(float(b), 2)}
            for k, (a, b, c) in enumerate(zip(u, v, w, strict=True))]


def in_process_times(objects: int, repeats: int, tracks: bool = False, record: str = "compact") -> dict:
    """Median microseconds per 100-object frame, measured in this process on the bench frame (``tracks``: the
    service with ``--tracks``; every call gets a later ``timestamp_s``, so that each is a new frame of the tracks).

    * ``mqtt_payload_parse_us``: ``orjson.loads`` of the frame's MQTT payload (what a payload outside the common
      layout costs the worker before ``process_frame_json``; the common layout is read by ``service/frame_scan.py``
      inside it);
    * ``process_frame_<stage>_us``: ``processing_us`` of the records of ``Service.process_frame_json`` of the
      payload's bytes, as the transports hand it (wall clock): ``footprints`` = the frame read into columns +
      the fused kernel, ``records`` = the
      per-object records' JSON, ``messages`` = CPM JSON + UPER + SDSM JSON, ``total`` = all of it, the
      record's JSON text included;
    * ``process_frame_json_cpu_us``: the same call's thread CPU time (immune to waiting for a core);
    * ``process_frame_dict_us``: ``Service.process_frame`` (the embedding API: the same text, parsed into dicts);
    * ``frame_processor_us`` (and ``_cpu_us``): ``FrameProcessor.boxes2d`` alone on the same boxes (the
      kernel's share; the reference measured in the same run);
    * ``record_bytes`` / ``cpm_bytes``: the record's length and (``record="compact"``, serve's default with MQTT
      output) the CPM's UPER bytes beside it.
    """
    import gc

    import orjson

    from footprint_uq import FrameProcessor, PanTiltCamera
    from footprint_uq.service import Service

    cam = PanTiltCamera(**CAMERA)
    svc = Service(cam, "basler1", linearity=True, tracks=tracks, record=record)  # as `serve` runs it (--linearity)
    dets = make_detections(objects, 0)
    body, t_frame = json.dumps(dets).encode(), [time.time()]

    def payload() -> bytes:  # the next frame (1/30 s later), as the publisher writes it
        t_frame[0] += 1.0 / 30.0
        return b'{"camera_id":"cam0","frame":0,"timestamp_s":%.6f,"detections":%s}' % (t_frame[0], body)

    proc = FrameProcessor(cam, "basler1", joint_cov=False)
    boxes = np.array([[d["u_min_px"], d["v_min_px"], d["u_max_px"], d["v_max_px"]] for d in dets])
    for _ in range(20):
        svc.process_frame(orjson.loads(payload()))
        proc.boxes2d(boxes)
    gc.collect()
    gc.freeze()  # as the service does
    t: dict[str, list] = {}
    stages: list[dict] = []
    wall, cpu = time.perf_counter, time.thread_time
    for _ in range(repeats):  # interleaved, so that a change of the machine's load reaches every figure alike
        text = payload()
        t0 = wall()
        orjson.loads(text)
        t.setdefault("mqtt_payload_parse_us", []).append(wall() - t0)
        c0 = cpu()
        out = svc.process_frame_json(text)
        t.setdefault("process_frame_json_cpu_us", []).append(cpu() - c0)
        k = out.data.rindex(b'"processing_us":')
        stages.append(orjson.loads(out.data[k + 16:-1]))
        t.setdefault("record_bytes", []).append(len(out.data) / 1e6)  # (scaled back below)
        t.setdefault("cpm_bytes", []).append(len(out.cpm_uper or b"") / 1e6)
        frame = orjson.loads(payload())
        t0 = wall()
        svc.process_frame(frame)
        t.setdefault("process_frame_dict_us", []).append(wall() - t0)
        t0, c0 = wall(), cpu()
        proc.boxes2d(boxes)
        t.setdefault("frame_processor_cpu_us", []).append(cpu() - c0)
        t.setdefault("frame_processor_us", []).append(wall() - t0)
    gc.unfreeze()
    out = {f"process_frame_{k}_us": float(np.median([s[k] for s in stages])) for k in stages[0]}
    out.update({k: 1e6 * float(np.median(v)) for k, v in t.items()})
    out["total_over_kernel"] = out["process_frame_total_us"] / out["frame_processor_us"]
    out["record"] = record
    return out


def measure(seconds: float = 60.0, cameras: int = 8, fps: float = 30.0, objects: int = 100, workers: int = 1,
            stagger: bool = False, serve_args: tuple = (), tracks: bool = False) -> dict:
    """One run (see the module doc); ``tracks`` adds ``--tracks`` to the service's options."""
    serve_args = tuple(serve_args) + (("--tracks",) if tracks and "--tracks" not in serve_args else ())
    import paho.mqtt.client as mqtt

    from footprint_uq import PanTiltCamera, save_camera
    from footprint_uq.service import tcp_no_delay

    tmp = Path(tempfile.mkdtemp(prefix="bench_service_"))
    save_camera(PanTiltCamera(**CAMERA), tmp / "cam.yaml")
    ids = [f"cam{i}" for i in range(cameras)]
    (tmp / "reg.csv").write_text("camera_id,camera,budget\n" + "".join(f"{c},cam.yaml,basler1\n" for c in ids))
    stack = contextlib.ExitStack()
    stack.callback(shutil.rmtree, tmp, ignore_errors=True)
    broker, port = stack.enter_context(mosquitto(tmp))
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    serve = rx = None
    load_start = os.getloadavg()[0]
    try:
        serve = subprocess.Popen([sys.executable, "-m", "footprint_uq.cli", "serve", "--registry", str(tmp / "reg.csv"),
                                  "--mqtt", f"mqtt://127.0.0.1:{port}", "--output", "mqtt", "--client-id", "bench",
                                  "--workers", str(workers), *serve_args],
                                 stdout=subprocess.DEVNULL, stderr=open(tmp / "serve.err", "wb"), env=env)
        # the receiver runs in a process of its own (it reads ~33 MB/s of records through paho): in this
        # process it would compete with the publisher for the GIL and delay both the frames and the time stamps
        rx, health, result, lock = start_receiver(__file__, port, env)
        _wait(lambda: len({h.get("worker") for h in health}) >= workers, 120, "every worker's first health message")
        tx = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="bench-tx")
        tx.on_socket_open = tcp_no_delay  # a detector's client, as docs/service.md advises
        tx.max_inflight_messages_set(1000)
        tx.connect("127.0.0.1", port)
        tx.loop_start()
        # pre-serialised frames: the publish loop only formats frame number and time stamp
        bodies = {c: json.dumps(make_detections(objects, i)).encode() for i, c in enumerate(ids)}
        sent = 0
        cpu0_s = sum(_cpu_s(p) for p in [serve.pid, *_descendants(serve.pid)])
        cpu0_broker, cpu0_bench = _cpu_s(broker.pid), _cpu_s(os.getpid())
        steal0_s = _steal_s()
        period = 1.0 / fps
        t_start = time.monotonic()
        next_t = t_start
        frame_no = 0
        # synchronised: every camera's frame at the start of each period (the worst case: a burst of `cameras`
        # frames); staggered: camera k at k / cameras of the period (free-running cameras)
        slot = period / cameras if stagger else 0.0
        while time.monotonic() - t_start < seconds:
            for k, c in enumerate(ids):
                if slot:
                    time.sleep(max(0.0, next_t + k * slot - time.monotonic()))
                payload = b'{"camera_id":"%s","frame":%d,"timestamp_s":%.6f,"detections":%s}' % (
                    c.encode(), frame_no, time.time(), bodies[c])
                tx.publish(f"detections/{c}", payload, qos=1)
                sent += 1
            frame_no += 1
            next_t += period
            time.sleep(max(0.0, next_t - time.monotonic()))
        t_pub = time.monotonic() - t_start

        def totals() -> dict:  # the latest health record of every worker, summed
            with lock:
                last = {r.get("worker"): r for r in health}
            keys = ("frames_in", "frames_out", "frames_dropped", "errors", "pending")
            return {k: sum(r[k] for r in last.values()) for k in keys}

        _wait(lambda: totals()["frames_in"] >= sent and totals()["pending"] == 0, 60,
              "the service to take in every frame")
        time.sleep(1.5)  # one more health record from every worker
        rx.stdin.write(json.dumps({"expect": totals()["frames_out"]}).encode() + b"\n")
        rx.stdin.flush()
        _wait(lambda: "latency_ms" in result, 60, "the receiver's figures")
        pids = [serve.pid, *_descendants(serve.pid)]
        peak_rss_mb = sum(_vm_hwm_mb(p) for p in pids)
        cpu_s = sum(_cpu_s(p) for p in pids) - cpu0_s
        threads_cpu_s = sorted((_cpu_s(serve.pid, tid) for tid in _tids(serve.pid)), reverse=True)
        cpu_broker, cpu_bench = _cpu_s(broker.pid) - cpu0_broker, _cpu_s(os.getpid()) - cpu0_bench
        steal_s = None if steal0_s is None else _steal_s() - steal0_s
        serve.send_signal(signal.SIGTERM)
        rc = serve.wait(60)
        h = totals()
        tx.loop_stop()
        rx.wait(30)
    finally:
        if serve is not None and serve.poll() is None:
            serve.kill()
        if rx is not None and rx.poll() is None:
            rx.kill()
        stack.close()
    lat = np.array(result["latency_ms"])
    # the service's own view (receipt -> record handed to paho), per health interval of the run
    svc_p50 = [r["latency_ms_p50"] for r in health if r.get("latency_ms_p50") is not None]
    svc_p99 = [r["latency_ms_p99"] for r in health if r.get("latency_ms_p99") is not None]
    proc_us = result["processing_us"]
    stages = {k: float(np.median([p[k] for p in proc_us])) for k in proc_us[0]} if proc_us else {}
    return {
        "serve_args": " ".join(serve_args), "tracks": "--tracks" in serve_args,
        "seconds": round(t_pub, 2), "workers": workers, "staggered": stagger,
        "cameras": cameras, "fps_per_camera": fps, "objects": objects,
        "frames_published": sent, "frames_in": h["frames_in"], "frames_out": h["frames_out"],
        "frames_dropped": h["frames_dropped"], "errors": h["errors"], "frames_received": result["received"],
        "sustained_frames_per_s": h["frames_out"] / t_pub, "offered_frames_per_s": sent / t_pub,
        "latency_ms_p50": float(np.percentile(lat, 50)), "latency_ms_p99": float(np.percentile(lat, 99)),
        "latency_ms_max": float(lat.max()),
        "service_latency_ms_p50_median_of_intervals": float(np.median(svc_p50)) if svc_p50 else None,
        "service_latency_ms_p99_median_of_intervals": float(np.median(svc_p99)) if svc_p99 else None,
        "service_latency_ms_p99_worst_interval": float(np.max(svc_p99)) if svc_p99 else None,
        "peak_rss_mb": peak_rss_mb, "serve_exit_status": rc,
        "serve_cpu_s": cpu_s, "serve_cpu_ms_per_frame": 1e3 * cpu_s / max(h["frames_in"], 1),
        "serve_threads_cpu_s": threads_cpu_s, "broker_cpu_s": cpu_broker, "bench_publisher_cpu_s": cpu_bench,
        "bench_receiver_cpu_s": result["cpu_s"],
        "load_average_1min_start": load_start, "load_average_1min": os.getloadavg()[0],
        **_cpu_floor(cpu_s + cpu_broker + cpu_bench + result["cpu_s"], h["frames_in"], cameras, stagger),
        "vm_steal_s": steal_s,
        "service_processing_us_median": stages,
        # bytes on the wire per output frame, as received: the record and (compact records) the CPM's UPER bytes
        "record": "full" if "full" in serve_args else "compact",
        "bytes_per_frame_record": result.get("record_bytes", 0) / max(result["received"], 1),
        "bytes_per_frame_cpm": result.get("cpm_bytes", 0) / max(result["received"], 1),
        "latency_split_ms": _latency_split(lat, svc_p50, svc_p99, proc_us),
        # every frame accounted for: published = out + dropped + errors, and every output received
        "frames_unaccounted": sent - h["frames_out"] - h["frames_dropped"] - h["errors"],
        "all_processed": (h["frames_out"] == sent and h["frames_dropped"] == 0 and h["errors"] == 0
                          and result["received"] == sent),
    }


def _latency_split(lat_ms: np.ndarray, svc_p50: list, svc_p99: list, proc_us: list) -> dict:
    """Where the end-to-end latency goes (ms, p50 and p99; the parts' percentiles do not add up exactly):
    ``processing`` -- one frame's ``processing_us`` (a sample of the records); ``service`` -- receipt -> record
    handed to paho (the health records' per-interval percentiles, median over the intervals); ``queue`` ~
    service - processing (waiting behind other frames: with synchronised cameras the k-th frame of a burst waits
    for k - 1 others); ``mqtt`` ~ end-to-end - service (publish -> broker -> service and service -> broker ->
    receiver)."""
    if not (proc_us and svc_p50 and svc_p99 and lat_ms.size):
        return {}
    tot = np.array([p["total"] for p in proc_us]) / 1e3
    out = {"processing_p50": float(np.percentile(tot, 50)), "processing_p99": float(np.percentile(tot, 99)),
           "service_p50": float(np.median(svc_p50)), "service_p99": float(np.median(svc_p99)),
           "end_to_end_p50": float(np.percentile(lat_ms, 50)), "end_to_end_p99": float(np.percentile(lat_ms, 99))}
    for q in ("p50", "p99"):
        out[f"queue_{q}"] = out[f"service_{q}"] - out[f"processing_{q}"]
        out[f"mqtt_{q}"] = out[f"end_to_end_{q}"] - out[f"service_{q}"]
    return {k: round(v, 2) for k, v in out.items()}


def _cpu_floor(chain_cpu_s: float, frames: int, cameras: int, stagger: bool) -> dict:
    """The CPU the whole chain spends per frame (service, broker, publisher, receiver: everything on this machine
    that a frame passes through) and, for synchronised cameras, the latency floor that implies: a burst of
    ``cameras`` frames needs ``cameras x chain`` ms of CPU, which this machine's cores (``os.cpu_count()``) cannot
    finish sooner than ``cameras x chain / cores`` ms even with perfect parallelism -- the last frame of a burst
    cannot be answered faster, whatever the number of workers."""
    per_frame_ms = 1e3 * chain_cpu_s / max(frames, 1)
    cores = os.cpu_count() or 1
    return {"chain_cpu_ms_per_frame": round(per_frame_ms, 3), "cores": cores,
            "burst_cpu_floor_ms": None if stagger else round(cameras * per_frame_ms / cores, 2)}


def _steal_s() -> float | None:
    """CPU seconds the hypervisor took from this (virtual) machine so far, all cores (``/proc/stat``'s steal; None
    where there is none to read): a run's difference says whether the host, not the service, stalled it."""
    try:
        fields = Path("/proc/stat").read_text().split("\n", 1)[0].split()
        return int(fields[8]) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return None


def _descendants(pid: int) -> list[int]:
    out = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        for c in (task / "children").read_text().split():
            out += [int(c), *_descendants(int(c))]
    return out


def _tids(pid: int) -> list[int]:
    return [int(t.name) for t in Path(f"/proc/{pid}/task").iterdir()]


def _cpu_s(pid: int, tid: int | None = None) -> float:
    """User + system CPU seconds of a process (all its threads), or of one of its threads."""
    path = f"/proc/{pid}/stat" if tid is None else f"/proc/{pid}/task/{tid}/stat"
    fields = Path(path).read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _vm_hwm_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def run(quick: bool = False) -> list[dict]:
    """Rows for ``bench/run.py`` (section ``service``)."""
    res = measure(seconds=5.0 if quick else 60.0)
    times = in_process_times(100, 100 if quick else 500)
    st = res["service_processing_us_median"]
    load = (f"{res['cameras']} cameras x {res['fps_per_camera']:.0f} frames/s x {res['objects']} objects, "
            f"{res['seconds']:.0f} s, through Mosquitto on loopback")
    return [
        {"case": f"serve, {load}: end-to-end latency p50 (publish -> output received)",
         "median_ms": res["latency_ms_p50"], "items": res["frames_out"], "peak_rss_mb": res["peak_rss_mb"],
         "target": "every frame processed, none dropped", "met": res["all_processed"], **res,
         "notes": f"published {res['frames_published']}, out {res['frames_out']}, dropped {res['frames_dropped']}, "
                  f"errors {res['errors']}; sustained {res['sustained_frames_per_s']:.1f} frames/s of "
                  f"{res['offered_frames_per_s']:.1f} offered; p99 {res['latency_ms_p99']:.1f} ms, max "
                  f"{res['latency_ms_max']:.1f} ms; peak RSS {res['peak_rss_mb']:.0f} MB"},
        {"case": f"serve, {load}: end-to-end latency p99", "median_ms": res["latency_ms_p99"],
         "items": res["frames_out"], "target": f"<= {TARGET_P99_MS:.0f} ms",
         "met": res["latency_ms_p99"] <= TARGET_P99_MS},
        {"case": "one 100-object frame in the service: parse + FrameProcessor (footprints stage)",
         "median_us": st.get("footprints", times["process_frame_footprints_us"]), "items": 100,
         "target": f"<= {TARGET_US:.0f} us", "met": st.get("footprints", times["process_frame_footprints_us"])
         <= TARGET_US, "in_process": times},
        {"case": "one 100-object frame in the service: everything (footprints + records + CPM/UPER/SDSM, as JSON text)",
         "median_us": st.get("total", times["process_frame_total_us"]), "items": 100,
         "target": f"<= {TARGET_US:.0f} us", "met": st.get("total", times["process_frame_total_us"]) <= TARGET_US,
         "notes": "stages (median us, in the service under load): " + ", ".join(f"{k} {v:.0f}" for k, v in st.items())
                  + "; in the bench process after the load run: "
                  + ", ".join(f"{k} {v:.0f}" if isinstance(v, int | float) else f"{k} {v}"
                              for k, v in times.items())},
    ]


def _receiver(port: int) -> None:
    """The subscriber (``--receiver PORT``, run by :func:`measure`): end-to-end latency of every record, a
    sample of their ``processing_us``; health records passed on at once, one JSON line each on stdout."""
    import gc

    import paho.mqtt.client as mqtt

    from footprint_uq.service import tcp_no_delay

    lat_ms: list[float] = []
    proc_us: list[dict] = []
    lock = threading.Lock()
    out_lock = threading.Lock()

    def say(d: dict) -> None:
        with out_lock:
            sys.stdout.write(json.dumps(d) + "\n")
            sys.stdout.flush()

    sizes = {"record_bytes": 0, "cpm_bytes": 0, "cpm_messages": 0}

    def on_message(c, u, msg):
        t = time.time()
        if msg.topic.endswith("/cpm"):  # a compact record's CPM: UPER bytes on a topic of their own
            with lock:
                sizes["cpm_bytes"] += len(msg.payload)
                sizes["cpm_messages"] += 1
            return
        if msg.topic.endswith("/health"):
            say({"health": json.loads(msg.payload)})
            return
        if msg.topic.endswith("/errors"):
            return
        m = _TS.search(msg.payload, 0, 400)
        with lock:
            sizes["record_bytes"] += len(msg.payload)
            lat_ms.append(1e3 * (t - float(m.group(1))))
            if len(lat_ms) % 10 == 0:  # a sample of the per-stage times (parsing every record would load the VM)
                k = msg.payload.rfind(b'"processing_us":')
                proc_us.append(json.loads(msg.payload[k + 16:-1]))

    gc.collect()
    gc.freeze()  # as the service does: no cyclic-GC stalls in the time stamps
    rx = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="bench-rx")
    rx.on_socket_open = tcp_no_delay
    rx.on_message = on_message
    subscribed = threading.Event()
    rx.on_connect = lambda c, u, f, rc, p: c.subscribe("footprints/#", qos=1)
    rx.on_subscribe = lambda *a: subscribed.set()
    rx.connect("127.0.0.1", port)
    rx.loop_start()
    _wait(subscribed.is_set, 30, "the subscription")
    say({"ready": True})
    expect = json.loads(sys.stdin.readline())["expect"]
    try:
        _wait(lambda: len(lat_ms) >= expect, 30, "the last outputs")
    except RuntimeError:
        pass  # reported: received < frames out
    rx.loop_stop()
    with lock:
        say({"result": {"latency_ms": lat_ms, "processing_us": proc_us, "received": len(lat_ms),
                        "cpu_s": time.process_time(), **sizes}})


def main(argv=None) -> int:
    if argv is None and len(sys.argv) == 3 and sys.argv[1] == "--receiver":
        _receiver(int(sys.argv[2]))
        return 0
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--cameras", type=int, default=8)
    ap.add_argument("--fps", type=float, default=30.0)
    ap.add_argument("--objects", type=int, default=100)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--stagger", action="store_true", help="cameras spread over the frame period (not in a burst)")
    ap.add_argument("--quick", action="store_true", help="5 s instead of --seconds")
    ap.add_argument("--serve-args", default="",
                    help="more `footprint-uq serve` options, e.g. --serve-args='--queue-depth 1' (with '=')")
    ap.add_argument("--tracks", action="store_true",
                    help="issue 22's load: the service with --tracks (motion per object_id, in the CPM and SDSM)")
    args = ap.parse_args(argv)
    res = measure(seconds=5.0 if args.quick else args.seconds, cameras=args.cameras, fps=args.fps,
                  objects=args.objects, workers=args.workers, stagger=args.stagger,
                  serve_args=tuple(shlex.split(args.serve_args)), tracks=args.tracks)
    res["in_process"] = in_process_times(args.objects, 200, tracks=res["tracks"], record=res["record"])
    print(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
