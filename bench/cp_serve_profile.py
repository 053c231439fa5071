"""The CP path of ``serve --cp-service`` in one process, without MQTT: where its CPU goes at 8 cameras x 100 road
users (bench/bench_cp_serve.py's site and frames).

    PYTHONPATH=src .venv/bin/python bench/cp_serve_profile.py [--seconds 4] [--repeats 3] [--profile]

Each camera frame goes through ``Service.process_frame_json`` (the tracker, as ``serve --tracks`` runs it), its
``on_tracked`` hook (:class:`~footprint_uq.service.cp_serve.CpServe`: ``CpBasicService.ingest`` / ``poll``) and the
sink wrapper (the event record's JSON, the segments, the SDSM's JSON) into a null sink that only counts bytes.
Measured per run (``time.process_time``, CPU seconds per second of traffic): the same frames with the CP service and
without it (the reference, in the same run, interleaved run by run); the median over ``--repeats`` runs and the
ratio.  ``--profile``: cProfile of one CP run, the top functions by own time; ``--dump PATH``: every CP output of
one run, to show that a change of the code leaves every byte as it was.
"""

from __future__ import annotations

import argparse
import cProfile
import io
import json
import pstats
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from bench_cp_serve import CPM_MAX_BYTES, RATE_HZ, frame_bodies, site, write_site


class NullSink:
    """A transport sink that counts what it is given (bytes per kind)."""

    def __init__(self, keep: bool = False):
        self.bytes: dict = {}
        self.kept: list | None = [] if keep else None  # every CP output (topic, bytes), with --dump

    def _add(self, key, n):
        self.bytes[key] = self.bytes.get(key, 0) + n

    def write(self, record):
        self._add("record", 1)

    def write_json(self, kind, camera_id, data):
        self._add(kind, len(data))

    def write_cpm(self, camera_id, data):
        self._add("cpm", len(data))

    def publish(self, sub, data):
        self._add(sub, len(data))
        if self.kept is not None:
            self.kept.append((sub, bytes(data)))

    def close(self, timeout_s):
        pass


def old_fusion(rev: str):
    """``RsuFusion`` of ``tracking/rsu_fusion.py`` at git revision ``rev``, imported beside today's (a module of the
    same package, so that its relative imports resolve): a before/after in one run."""
    import importlib.util
    import subprocess

    import footprint_uq.tracking as pkg

    text = subprocess.run(["git", "show", f"{rev}:src/footprint_uq/tracking/rsu_fusion.py"], check=True,
                          capture_output=True, text=True, cwd=Path(__file__).resolve().parent).stdout
    path = Path(tempfile.mkdtemp()) / "_rsu_fusion_rev.py"
    path.write_text(text)
    spec = importlib.util.spec_from_file_location(f"{pkg.__name__}._rsu_fusion_rev", path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod.RsuFusion


def build(reg: Path, cp: bool, keep: bool = False):
    from footprint_uq.io.registry import load_registry
    from footprint_uq.service import Service
    from footprint_uq.service.cp_serve import CpServeOptions, start_cp_service

    registry = load_registry(reg)
    svc = Service(None, None, registry=registry, linearity=True, tracks=True, record="compact")
    sink = NullSink(keep)
    out = sink
    if cp:
        cps = start_cp_service(svc, CpServeOptions(cpm_max_bytes=CPM_MAX_BYTES, per_camera_output=False),
                               registry=registry, camera=(None, None),
                               station_id=None, cdd=svc.cpm_cdd)
        out = cps.wrap(sink, mqtt=True)
    return svc, out, sink


def run_once(svc, out, payloads: list) -> float:
    """CPU seconds for every frame of ``payloads``."""
    import orjson

    c0 = time.process_time()
    for p in payloads:
        fo = svc.process_frame_json(orjson.loads(p))
        out.write_json(fo.type, fo.camera_id, fo.data)
        if fo.cpm_uper is not None:
            out.write_cpm(fo.camera_id, fo.cpm_uper)
    return time.process_time() - c0


def payloads_of(bodies: list, t0: float) -> list[bytes]:
    return [b'{"camera_id":"cam%d","frame":%d,"timestamp_s":%.6f,"detections":%s}' % (j, k, t0 + k / RATE_HZ, b)
            for k, row in enumerate(bodies) for j, b in enumerate(row)]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=4.0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--profile", action="store_true")
    ap.add_argument("--fusion-from", default=None, metavar="REV",
                    help="also run the CP service with RsuFusion of git revision REV (interleaved): before / after")
    ap.add_argument("--dump", type=Path, default=None,
                    help="write every CP output of one run (topic and hex of each message, JSON) to compare versions")
    args = ap.parse_args(argv)
    cams = site()
    bodies = frame_bodies(cams, int(round(args.seconds * RATE_HZ)))
    res: dict = {"cp": [], "reference": []}
    import footprint_uq.service.cp_service as cps_mod

    fusions = {"cp": cps_mod.RsuFusion, "reference": cps_mod.RsuFusion}
    if args.fusion_from:
        fusions["cp_fusion_" + args.fusion_from] = old_fusion(args.fusion_from)
        res["cp_fusion_" + args.fusion_from] = []
    with tempfile.TemporaryDirectory() as d:
        reg = write_site(Path(d), cams)
        t0 = 1.75e9
        for r in range(args.repeats):
            for key in fusions:
                cps_mod.RsuFusion = fusions[key]
                svc, out, sink = build(reg, key != "reference")
                run_once(svc, out, payloads_of(bodies[:15], t0 - 10.0))  # warm up (kernels, caches)
                res[key].append(run_once(svc, out, payloads_of(bodies, t0 + 100.0 * r)) / args.seconds)
                res[f"{key}_bytes"] = sink.bytes
            cps_mod.RsuFusion = fusions["cp"]
        if args.dump is not None:
            svc, out, sink = build(reg, True, keep=True)
            run_once(svc, out, payloads_of(bodies, t0))
            args.dump.write_text(json.dumps([(k, v.hex()) for k, v in sink.kept]))
        if args.profile:
            svc, out, _ = build(reg, True)
            run_once(svc, out, payloads_of(bodies[:15], t0 - 10.0))
            pr = cProfile.Profile()
            pl = payloads_of(bodies, t0)
            pr.enable()
            run_once(svc, out, pl)
            pr.disable()
            s = io.StringIO()
            pstats.Stats(pr, stream=s).sort_stats("tottime").print_stats(30)
            pstats.Stats(pr, stream=s).sort_stats("cumulative").print_stats(40)
            print(s.getvalue(), file=sys.stderr)
    out = {"cpu_s_per_traffic_s_cp": float(np.median(res["cp"])),
           "cpu_s_per_traffic_s_reference": float(np.median(res["reference"])),
           "runs_cp": res["cp"], "runs_reference": res["reference"], "bytes_cp": res["cp_bytes"]}
    out["cp_over_reference"] = out["cpu_s_per_traffic_s_cp"] / out["cpu_s_per_traffic_s_reference"]
    out["cp_share_s_per_traffic_s"] = out["cpu_s_per_traffic_s_cp"] - out["cpu_s_per_traffic_s_reference"]
    for key in fusions:
        if key.startswith("cp_fusion_"):
            old = float(np.median(res[key]))
            ref = out["cpu_s_per_traffic_s_reference"]
            out[key] = {"cpu_s_per_traffic_s": old, "runs": res[key], "over_reference": old / ref,
                        "cp_share_s_per_traffic_s": old - ref,
                        "cp_share_now_over_then": out["cp_share_s_per_traffic_s"] / (old - ref),
                        "same_bytes": res[f"{key}_bytes"] == res["cp_bytes"]}
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
