"""A V2X receiver: decode the edge service's UPER CPM and draw the objects' 95 % ellipses.

    python examples/cpm_receiver.py [--out DIR] [--mqtt mqtt://HOST:PORT [--frames N]]

What a vehicle does with a Collective Perception Message of a roadside unit: decode the UPER
bytes (asn1tools, the project's CPM subset module), read every perceived object's position
(0.01 m east/north of the reference position), its ``CoordinateConfidence`` x/y (0.01 m at
95 %, per axis) and the x/y ``CorrelationCellValue``, rebuild the covariance

    sigma_x = confidence_x * 0.01 m / 1.96,   sigma_y = ...,   cov_xy = (correlation / 100) sigma_x sigma_y

and draw its 95 % ellipse (2-D chi-square, 2.4477 sigma).  The thin line is the ellipse of the
service's own ``cov_m2`` (not in the message): the CPM's confidences are rounded up to the next
centimetre and the correlation to the nearest 0.01, so the two differ by about a centimetre.

Without ``--mqtt`` the script runs the service in-process on a simulated detector frame (three
cars and a pedestrian, 2D boxes) -- the same record ``footprint-uq serve`` publishes -- and
decodes that.  With ``--mqtt`` it subscribes to ``footprints/#`` on a running service's broker and
draws the first ``--frames`` records it receives.  Writes ``cpm_ellipses.png``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from footprint_uq import PanTiltCamera
from footprint_uq.products.v2x import Z95_1D
from footprint_uq.service import Service
from footprint_uq.service.messages.cpm import decode_cpm_uper
from footprint_uq.uncertainty.ellipse import chi2_scale, ellipse_points

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("--out", default=os.environ.get("FOOTPRINT_UQ_EXAMPLES_OUT", "out/examples"))
ap.add_argument("--mqtt", default=None, help="mqtt://HOST:PORT of a running `footprint-uq serve --output mqtt`")
ap.add_argument("--frames", type=int, default=1, help="with --mqtt: how many records to draw")
args = ap.parse_args()
out = Path(args.out) / "cpm_receiver"
out.mkdir(parents=True, exist_ok=True)
os.environ.setdefault("MPLBACKEND", "Agg")


def simulated_records() -> list[dict]:
    cam = PanTiltCamera(focal_px=1400.0, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)
    svc = Service(cam, "bw-bullet1", heading_offset_deg=12.0, origin_lat_deg=42.2808, origin_lon_deg=-83.7430)
    boxes = [("car-1", "car", (880, 560, 1060, 700)), ("car-2", "car", (300, 420, 420, 500)),
             ("car-3", "car", (1400, 380, 1500, 450)), ("ped-1", "pedestrian", (1180, 620, 1215, 720))]
    frame = {"camera_id": "cam1", "frame": 1, "timestamp_s": 1714564800.0,
             "detections": [{"object_id": oid, "class": cls, "u_min_px": u0, "v_min_px": v0, "u_max_px": u1,
                             "v_max_px": v1} for oid, cls, (u0, v0, u1, v1) in boxes]}
    return [svc.process_frame(frame)]


def mqtt_records(url: str, n: int) -> list[dict]:
    import paho.mqtt.client as mqtt

    from footprint_uq.service.runner import parse_mqtt_url

    host, port = parse_mqtt_url(url)
    got: list[dict] = []
    c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2)
    c.on_connect = lambda c_, u, f, rc, p: c_.subscribe("footprints/+", qos=1)

    def on_message(c_, u, msg):
        rec = json.loads(msg.payload)
        if rec.get("type") == "footprints":
            got.append(rec)

    c.on_message = on_message
    c.connect(host, port)
    c.loop_start()
    end = time.monotonic() + 60
    while len(got) < n and time.monotonic() < end:
        time.sleep(0.05)
    c.loop_stop()
    if not got:
        sys.exit("no footprints record received within 60 s")
    return got[:n]


records = mqtt_records(args.mqtt, args.frames) if args.mqtt else simulated_records()

import matplotlib.pyplot as plt  # noqa: E402  (after MPLBACKEND)

k95 = chi2_scale(0.95)
fig, ax = plt.subplots(figsize=(7, 7))
for rec in records:
    cpm = decode_cpm_uper(rec["cpm_uper_hex"], rec.get("cpm_cdd", "2.1.1"))  # the bytes, in the release compiled
    assert cpm == rec["cpm"]
    ref = cpm["payload"]["managementContainer"]["referencePosition"]
    objs = cpm["payload"]["cpmContainers"][1]["containerData"]["perceivedObjects"]
    by_id = {o["message_object_id"]: o for o in rec["objects"] if o["message_object_id"] is not None}
    h = np.deg2rad(rec["heading_offset_deg"])
    R = np.array([[np.cos(h), np.sin(h)], [-np.sin(h), np.cos(h)]])  # world x/y -> east/north
    print(f"station {cpm['header']['stationId']}, reference position "
          f"{ref['latitude'] / 1e7:.7f} deg, {ref['longitude'] / 1e7:.7f} deg, {len(objs)} perceived objects "
          f"({len(rec['cpm_uper_hex']) // 2} octets UPER)")
    for po in objs:
        p = po["position"]
        e_m, n_m = p["xCoordinate"]["value"] / 100, p["yCoordinate"]["value"] / 100
        sx = p["xCoordinate"]["confidence"] * 0.01 / Z95_1D
        sy = p["yCoordinate"]["confidence"] * 0.01 / Z95_1D
        corr = po.get("lowerTriangularCorrelationMatrices")
        rho = corr[0]["matrix"][0][0] / 100 if corr else 0.0
        cov = np.array([[sx * sx, rho * sx * sy], [rho * sx * sy, sy * sy]])
        pts = ellipse_points(np.array([e_m, n_m]), cov, confidence=0.95)
        ax.plot(pts[..., 0], pts[..., 1], lw=2)
        src = by_id[po["objectId"]]
        exact = ellipse_points(np.array([e_m, n_m]), R @ np.array(src["cov_m2"]) @ R.T, confidence=0.95)
        ax.plot(exact[..., 0], exact[..., 1], "k-", lw=0.6)
        cls = po.get("classification", [{}])[0].get("objectClass", "no class")
        ax.annotate(f"{src['object_id']} ({po['objectId']})", (e_m, n_m), fontsize=8)
        print(f"  object {po['objectId']:5d} {str(cls):45s} east {e_m:8.2f} m north {n_m:8.2f} m  "
              f"conf x/y {p['xCoordinate']['confidence']:4d}/{p['yCoordinate']['confidence']:4d} (0.01 m, 95 %)  "
              f"corr {rho:+.2f}  95 % semi-major {k95 * np.sqrt(np.linalg.eigvalsh(cov)[-1]):.2f} m")
ax.set_aspect("equal")
ax.set_xlabel("east of the reference position [m]")
ax.set_ylabel("north of the reference position [m]")
ax.set_title("CPM perceived objects: 95 % ellipses decoded from the UPER bytes\n(thin: the service's own covariance)")
ax.grid(alpha=0.3)
fig.savefig(out / "cpm_ellipses.png", dpi=120, bbox_inches="tight")
print(f"wrote {out / 'cpm_ellipses.png'}")
