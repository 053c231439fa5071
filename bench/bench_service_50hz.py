"""One camera at 50 Hz through Mosquitto's default configuration into ``footprint-uq serve`` (issue 22).

Publishes ``--frames`` small frames (5 objects) at ``--rate-hz`` to ``detections/cam1`` with a plain paho client
(Nagle on, as most detectors' clients), runs the real CLI with its defaults (``--overload newest``) and prints:
the frames the service dropped (its last health record), and the inter-arrival gaps of the same messages at a
second subscriber (a listener beside the service: bursts show up as gaps far below 1000/rate ms).

    python bench/bench_service_50hz.py [--frames 250] [--rate-hz 50] [--extra-args "--queue-depth 1"]
"""

from __future__ import annotations

import argparse
import json
import os
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


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=250)
    ap.add_argument("--rate-hz", type=float, default=50.0)
    ap.add_argument("--extra-args", default="", help="more serve options")
    a = ap.parse_args(argv)
    tmp = Path(tempfile.mkdtemp())
    try:
        with mosquitto(tmp, tuned=False) as broker:  # Mosquitto's defaults
            _run(a, tmp, broker.port)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


def _run(a, tmp: Path, port: int) -> None:
    import paho.mqtt.client as mqtt

    from footprint_uq import PanTiltCamera, save_camera

    save_camera(PanTiltCamera(focal_px=1400, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0),
                tmp / "cam.yaml")
    health, gaps, lock = [], [], threading.Lock()

    def on_msg(c, u, m):
        with lock:
            if m.topic.startswith("footprints/health"):
                health.append(json.loads(m.payload))
            elif m.topic.startswith("detections/"):
                gaps.append(time.monotonic())

    rx = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="bench50-rx")
    rx.on_message = on_msg
    rx.connect("127.0.0.1", port)
    rx.subscribe([("footprints/health", 1), ("detections/#", 1)])
    rx.loop_start()
    serve = subprocess.Popen([sys.executable, "-m", "footprint_uq.cli", "serve", "--camera", str(tmp / "cam.yaml"),
                              "--budget", "basler1", "--mqtt", f"mqtt://127.0.0.1:{port}", "--output", "mqtt",
                              "--client-id", "bench50", *shlex.split(a.extra_args)],
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                             env={**os.environ, "NUMBA_NUM_THREADS": "1"})
    try:
        _wait(lambda: health, 120, "the service's first health record")
        tx = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="bench50-tx")
        tx.connect("127.0.0.1", port)
        tx.loop_start()
        dets = [{"object_id": k, "class": "car", "u_min_px": 300.0 + 200 * k, "v_min_px": 600.0,
                 "u_max_px": 380.0 + 200 * k, "v_max_px": 700.0} for k in range(5)]
        t0 = time.monotonic()
        for i in range(a.frames):
            time.sleep(max(0.0, t0 + i / a.rate_hz - time.monotonic()))
            tx.publish("detections/cam1", json.dumps({"camera_id": "cam1", "frame": i, "timestamp_s":
                                                      1714564800.0 + i / a.rate_hz, "detections": dets}), qos=1)
        _wait(lambda: health and health[-1]["frames_in"] == a.frames and health[-1]["pending"] == 0, 30, "the frames")
        h = health[-1]
        with lock:
            g = np.diff(gaps) * 1e3
        print(f"frames {a.frames} at {a.rate_hz} Hz: in {h['frames_in']}, out {h['frames_out']}, dropped "
              f"{h['frames_dropped']}, errors {h['errors']}; inter-arrival at a listener: median {np.median(g):.1f} "
              f"ms, {int((g < 2.0).sum())} gaps < 2 ms, {int((g > 1.5e3 / a.rate_hz).sum())} gaps > 1.5 periods")
        tx.disconnect()
        tx.loop_stop()
    finally:
        serve.send_signal(signal.SIGTERM)
        serve.wait(30)
        rx.disconnect()
        rx.loop_stop()


if __name__ == "__main__":
    sys.exit(main())
