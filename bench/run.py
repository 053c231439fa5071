"""footprint-uq benchmarks: one command, printed table, JSON + Markdown results.

Usage::

    .venv/bin/python bench/run.py [--quick] [--sections maps,...] [--out DIR]     (or: make bench)

Each section is a function ``f(quick: bool) -> list[dict]`` registered in :data:`SECTIONS`:
``run`` of a module under ``bench/``, or an adapter in this file where the module returns its
figures in another shape.  Every returned row is one line of the section's table (``case`` plus
any of the measurement columns in :data:`COLUMNS`; other keys go to the JSON only; ``notes`` are
printed under the table).  All sections run in one process, one after the other, on the same
machine; each reports medians and ratios to a reference measured in the same run.  Results go to
``DIR/latest.json`` and ``DIR/latest.md`` (default ``bench/results``), with the machine (CPU
model, cores, versions) and the load average at start and end.  A section that fails is recorded
with its error, the others still run, and the exit status is 1.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import platform
import sys
import time
import traceback
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))  # section modules live next to this file

#: section name -> "module:function" (modules under bench/, or adapters in this file: "run:...")
SECTIONS: dict[str, str] = {
    "maps": "bench_maps:run",
    "uncertainties": "bench_uncertainties:run",
    "montecarlo": "bench_montecarlo:run",
    "footprints": "run:footprints_section",
    "batch": "run:batch_section",
    "dask": "run:dask_section",
    "memory": "run:memory_section",
    "service": "bench_service:run",
}

#: one line per section, printed above its table
TITLES = {
    "maps": "Full-HD (1920x1080) per-pixel covariance map: fused kernel vs naive numpy vs a copy of the same bytes",
    "uncertainties": "Full-HD pan-tilt map: ours vs naive numpy vs the `uncertainties` package (extrapolated) "
                     "vs memory roofline; ratios to ours",
    "montecarlo": "Monte Carlo vs linear propagation on the same points: time and agreement of sigma_major",
    "footprints": "One frame of 100 objects (3D boxes, 4 corners): latency through the Python API",
    "batch": "Batch footprints per second, Parquet -> Parquet, single process",
    "dask": "Fleet batch (partitioned Parquet, several cameras): in-process vs a 2-worker local Dask cluster",
    "memory": "Peak resident memory of the streaming batch at 1x and 10x input sizes",
    "service": "Edge service through Mosquitto on loopback: 8 cameras x 30 frames/s x 100 objects (2D boxes)",
}

#: (key, header, format) of the table columns, in order; a section's table shows the columns its rows have
COLUMNS = [
    ("case", "case", "{}"),
    ("pixels", "pixels", "{:,}"),
    ("items", "items", "{:,}"),
    ("median_ms", "median [ms]", "{:,.2f}"),
    ("median_us", "median [us]", "{:,.1f}"),
    ("min_ms", "fastest [ms]", "{:.2f}"),
    ("cpu_ms", "CPU (all threads) [ms]", "{:.2f}"),
    ("runs", "runs", "{}"),
    ("mpx_per_s", "Mpx/s", "{:,.3g}"),
    ("footprints_per_s", "footprints/s", "{:,.0f}"),
    ("copy_ms", "copy same bytes [ms]", "{:.2f}"),
    ("copy_ratio", "copy / ours", "{:.2f}"),
    ("naive_mpx_per_s", "numpy propagate [Mpx/s]", "{:.3f}"),
    ("speedup_vs_naive", "speed-up vs naive", "{:,.0f}x"),
    ("time_vs_ours", "time / ours", "{:,.3g}"),
    ("time_vs_in_process", "time / in-process", "{:.2f}"),
    ("speedup_vs_mc", "speed-up vs MC", "{:,.0f}x"),
    ("sigma_ratio_median", "sigma_major lin/MC, median", "{:.4f}"),
    ("sigma_ratio_worst", "lin/MC, worst", "{:.4f}"),
    ("worst_at_range_m", "worst at [m]", "{:.0f}"),
    ("sigma_ratio_worst_inner", "lin/MC, worst <= 100 m", "{:.4f}"),
    ("within_1se", "within 1 MC s.e.", "{:.0%}"),
    ("within_2se", "within 2 MC s.e.", "{:.0%}"),
    ("peak_rss_mb", "peak RSS [MB]", "{:,.0f}"),
    ("input_decoded_mb", "input data [MB]", "{:,.0f}"),
    ("target", "target", "{}"),
    ("met", "met", "{}"),
]


# -- adapters: sections whose modules return something else than table rows ---------------------------------------

def footprints_section(quick: bool = False) -> list[dict]:
    """Rows from :func:`bench_footprints.run` (a dict of microseconds per frame)."""
    import bench_footprints

    res = bench_footprints.run(n_objects=100, repeats=300 if quick else 2000, naive_repeats=3 if quick else 20)
    n = res["objects"]
    rows = []
    for cam in ("pan-tilt", "opencv-distortion"):
        r = res[cam]
        naive = r["naive_loop_median_us"]
        common = {"items": n, "reference": "naive per-object loop"}
        for key, what, runs, extra in (
                ("fast_median_us", "FrameProcessor.boxes3d (fused), corners -> centroid, largest point, V2X",
                 res["repeats"], {"target": f"<= {res['target_us']:.0f} us",
                                  "met": r["fast_median_us"] <= res["target_us"]}),
                ("fast_with_joint_cov_median_us", "same, with the joint (8x8) corner covariance", res["repeats"], {}),
                ("fast_without_flag_median_us", "same, without the linearity flag (linearity=False)",
                 res["repeats"], {}),
                ("numpy_reference_median_us", "footprints_from_boxes3d (vectorised numpy), whole frame",
                 max(res["repeats"] // 20, 5), {}),
                ("naive_loop_median_us", "naive per-object loop over the numpy reference", None, {})):
            rows.append({**common, "case": f"{cam}: {what}", "median_us": r[key],
                         "runs": runs if runs is not None else ("3" if quick else "20"),
                         "speedup_vs_naive": naive / r[key], **extra})
        first = rows[-5]
        first["objects_with_valid_centre"] = r["objects_with_valid_centre"]
        first["flagged_centres"] = r.get("flagged_centres")
        rows[-4]["time_vs_ours"] = r["fast_with_joint_cov_median_us"] / r["fast_median_us"]
        rows[-3]["time_vs_ours"] = r["fast_without_flag_median_us"] / r["fast_median_us"]
        rows[-3]["parity_of"] = first["case"]
        # the joint covariance, the numpy reference and the naive loop without the flag: like for like with commits
        # older than the flag (bench/compare.py)
        for key, of in (("fast_with_joint_cov_without_flag_median_us", rows[-4]),
                        ("numpy_reference_without_flag_median_us", rows[-2]),
                        ("naive_loop_without_flag_median_us", rows[-1])):
            rows.append({**common, "case": f"{of['case']}, without the linearity flag", "median_us": r[key],
                         "runs": of["runs"], "speedup_vs_naive": naive / r[key], "parity_of": of["case"],
                         "time_vs_ours": r[key] / of["median_us"]})
    return rows


def batch_section(quick: bool = False) -> list[dict]:
    """Rows of :func:`bench_batch.run` with ``items`` and ``footprints_per_s``, plus the kernel-only floor."""
    import bench_batch

    rows = []
    for r in bench_batch.run(quick=quick):
        if "batch_footprints_per_s" in r:
            r = {**r, "items": r["rows_ok"] + r["rows_partial"] + r["rows_error"],
                 "footprints_per_s": r["batch_footprints_per_s"]}
        rows.append(r)
    return rows


def dask_section(quick: bool = False) -> list[dict]:
    """In-process vs local Dask cluster from :func:`bench_dask.measure` (smaller dataset with ``quick``)."""
    import bench_dask

    if quick:
        res = bench_dask.measure(cameras=2, files_per_camera=1, rows_per_file=50_000, repeats=1)
    else:
        res = bench_dask.measure()  # its defaults: 4 cameras x 2 files x 400,000 rows, 2 workers, 2 runs
    info = {k: v for k, v in res.items() if k != "repeats"}
    base = {"items": res["rows"], "runs": res["repeats"], "reference": "in-process"}
    return [
        {**base, "case": f"in-process (embedded), {res['files']} files of {res['cameras']} cameras",
         "median_ms": 1e3 * res["in_process_s"], "footprints_per_s": res["in_process_footprints_per_s"],
         "time_vs_in_process": 1.0, "target": ">= 2 M footprints/s",
         "met": res["in_process_footprints_per_s"] >= 2e6},
        {**base, **info, "case": f"local Dask cluster, {res['workers']} worker processes x 1 thread",
         "median_ms": 1e3 * res["dask_s"], "footprints_per_s": res["dask_footprints_per_s"],
         "time_vs_in_process": res["dask_s"] / res["in_process_s"], "target": ">= 2 M footprints/s",
         "met": res["dask_footprints_per_s"] >= 2e6,
         "notes": "workers started before the timing; wall time includes task scheduling and writing the "
                  "partitioned output"},
    ]


def memory_section(quick: bool = False) -> list[dict]:
    """Peak RSS at 1x and 10x from :func:`bench_memory.measure` (``quick``: 100,000 rows, 16,384-row chunks)."""
    import bench_memory

    res = (bench_memory.measure(rows=100_000, factor=10, chunk_rows=16_384) if quick
           else bench_memory.measure(rows=1_000_000, factor=10))
    ratio = res["peak_rss_ratio"]
    out = []
    for s in res["sizes"]:
        out.append({**s, "case": f"{s['factor']}x input, 3D boxes", "items": s["rows"],
                    "median_ms": 1e3 * s["elapsed_s"], "runs": 1,
                    "footprints_per_s": s["rows"] / s["elapsed_s"],
                    "target": "peak RSS flat in the input size", "met": ratio < 1.2,
                    "chunk_rows": res["chunk_rows"], "limit_mb": res["limit_mb"], "peak_rss_ratio": ratio,
                    "notes": f"each size in a fresh process, address space capped at {res['limit_mb']} MB; "
                             f"chunk_rows {res['chunk_rows']:,}; output {s['output_uncompressed_mb']:.0f} MB "
                             f"(uncompressed); peak RSS 10x / 1x = {ratio:.2f}"})
    return out


def _versions(*names) -> dict:
    from importlib import metadata

    out = {}
    for n in names:
        try:
            out[n] = metadata.version(n.replace("_", "-"))
        except metadata.PackageNotFoundError:
            out[n] = "not installed"
    return out


def machine_info() -> dict:
    import numba
    import numpy as np

    cpu = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        load = os.getloadavg()
    except OSError:
        load = (float("nan"),) * 3
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "numba_threads": numba.get_num_threads(),
        "numba_threading_layer": numba.config.THREADING_LAYER,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "numba": numba.__version__,
        **_versions("pyarrow", "pandas", "dask", "distributed", "uncertainties", "footprint_uq"),
        "platform": platform.platform(),
        "load_average_1_5_15min": [round(x, 2) for x in load],
        "date_utc": time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime()),
    }


def _fmt(key, fmt, value):
    if value is None or value == "":
        return ""
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    try:
        return fmt.format(value)
    except (ValueError, TypeError):
        return str(value)


def section_markdown(section: str, rows: list[dict]) -> list[str]:
    """Markdown lines of one section: title, table (the columns its rows have), notes."""
    out = [f"## {section}", ""]
    if section in TITLES:
        out += [TITLES[section], ""]
    cols = [c for c in COLUMNS if any(c[0] in r for r in rows)]
    out.append("| " + " | ".join(h for _, h, _ in cols) + " |")
    out.append("|" + "|".join("---" for _ in cols) + "|")
    for r in rows:
        out.append("| " + " | ".join(_fmt(k, f, r.get(k)) for k, _, f in cols) + " |")
    notes = [f"- {r['case']}: {r['notes']}" for r in rows if r.get("notes")]
    notes += [f"- ERROR {r['error']}" for r in rows if r.get("error")]
    if notes:
        out += ["", *notes]
    out.append("")
    return out


def machine_markdown(results: dict) -> list[str]:
    m = results["machine"]
    return [f"- date (UTC): {m['date_utc']}, mode: {'quick (smoke run, small sizes)' if results['quick'] else 'full'}, "
            f"total {results.get('elapsed_s', float('nan')):.0f} s",
            f"- CPU: {m['cpu']}, {m['cores']} cores, numba threads: {m['numba_threads']}",
            f"- Python {m['python']}, numpy {m['numpy']}, numba {m['numba']}, pyarrow {m['pyarrow']}, "
            f"dask {m['dask']}, uncertainties {m['uncertainties']}, footprint-uq {m['footprint_uq']}; "
            f"{m['platform']}",
            f"- load average at start / end (1, 5, 15 min): {m['load_average_1_5_15min']} / "
            f"{results.get('load_average_end')}"]


def _find(rows, *words):
    """First row whose case contains every word (None if absent)."""
    for r in rows or []:
        if all(w in r.get("case", "") for w in words):
            return r
    return None


def _yes_no(v) -> str:
    return v if isinstance(v, str) else ("yes" if v else "no")


def summary_rows(results: dict) -> list[tuple[str, str, str, str, str, str]]:
    """Headline figures: (benchmark, ours, reference measured in the same run, ratio, target, met)."""
    S = results["sections"]
    out = []
    mp = S.get("maps", [])
    pt, oc = _find(mp, "pan-tilt"), _find(mp, "OpenCV")
    unc = _find(S.get("uncertainties"), "uncertainties package")
    if pt:
        ref = f"copy of the same {pt['copy_bytes'] / 1e6:.0f} MB: {pt['copy_ms']:.1f} ms; numpy propagate: " \
              f"{pt['pixels'] / pt['naive_mpx_per_s'] / 1e6:.1f} s"
        ratio = f"copy/ours {pt['copy_ratio']:.2f}; {pt['speedup_vs_naive']:,.0f}x numpy"
        if unc:
            ref += f"; `uncertainties` (extrapolated from {unc['measured_pixels']:,} px): " \
                   f"{unc['median_ms'] / 3.6e6:.1f} h"
            ratio += f"; {unc['time_vs_ours']:.1e}x `uncertainties`"
        out.append(("full-HD covariance map, pan-tilt, all sources", f"{pt['median_ms']:.1f} ms", ref, ratio,
                    pt["target"], _yes_no(pt["met"])))
    for cam in ("pan-tilt", "OpenCV"):
        fl = _find(mp, cam, "linearity flag")
        if fl:
            out.append((f"full-HD map with the linearity flag, {cam}", f"{fl['median_ms']:.1f} ms",
                        f"the same map without the flag: {fl['without_flag_ms']:.1f} ms",
                        f"flag / no flag {fl['time_vs_ours']:.2f} (CPU {fl['cpu_ratio']:.2f})", fl["target"],
                        _yes_no(fl["met"])))
    if oc:
        out.append(("full-HD covariance map, OpenCV with distortion",
                    f"{oc['median_ms']:.1f} ms = {oc['mpx_per_s']:.0f} Mpx/s",
                    f"copy: {oc['copy_ms']:.1f} ms; numpy propagate: {oc['naive_mpx_per_s']:.2f} Mpx/s",
                    f"copy/ours {oc['copy_ratio']:.2f}; {oc['speedup_vs_naive']:,.0f}x numpy", oc["target"],
                    _yes_no(oc["met"])))
    mc_rows = S.get("montecarlo", [])
    for cam in ("pan-tilt", "OpenCV"):
        mc = _find(mc_rows, cam, "Monte Carlo")
        lin = _find(mc_rows, cam, "propagate")
        if mc and lin:
            rng_m = mc["ground_range_m"]
            out.append((f"{mc['points']:,} points at {rng_m[0]:.0f}-{rng_m[1]:.0f} m, {cam}: linear vs Monte Carlo "
                        f"({mc['samples_per_point']:,} samples/point)",
                        f"linear (numpy) {lin['median_ms']:.1f} ms",
                        f"Monte Carlo {mc['median_ms'] / 1e3:.1f} s",
                        f"{lin['speedup_vs_mc']:,.0f}x; sigma_major lin/MC median {mc['sigma_ratio_median']:.3f}, "
                        f"worst {mc['sigma_ratio_worst']:.3f} (at {mc['worst_at_range_m']:.0f} m), within 100 m "
                        f"{mc['sigma_ratio_worst_inner']:.3f}; {mc['within_1se']:.0%} within 1 MC s.e.",
                        "agreement (no target)", ""))
    fp = S.get("footprints", [])
    for cam in ("pan-tilt", "opencv-distortion"):
        fast, naive = _find(fp, cam, "FrameProcessor"), _find(fp, cam, "naive")
        noflag = _find(fp, cam, "without the linearity flag")
        if fast and naive:
            ref = f"naive per-object loop: {naive['median_us'] / 1e3:.0f} ms"
            ratio = f"{fast['speedup_vs_naive']:,.0f}x"
            if noflag:
                ref += f"; without the linearity flag: {noflag['median_us']:.0f} us"
                ratio += f"; the flag costs x{1 / noflag['time_vs_ours']:.2f}"
            out.append((f"one frame of 100 objects (3D boxes), {cam}", f"{fast['median_us']:.0f} us", ref, ratio,
                        fast["target"], _yes_no(fast["met"])))
    for r in S.get("batch", []):
        if "footprints_per_s" in r and "parity_of" not in r:  # (rows without the flag: for bench/compare.py)
            out.append((r["case"].replace("batch ", "batch, single process, "),
                        f"{r['footprints_per_s'] / 1e6:.2f} M footprints/s",
                        f"naive per-object loop: {r['naive_loop_footprints_per_s']:,.0f} /s",
                        f"{r['speedup_vs_naive']:,.0f}x", r["target"], _yes_no(r["met"])))
    dk = S.get("dask", [])
    if len(dk) == 2 and "footprints_per_s" in dk[1]:
        a, b = dk
        out.append((f"fleet batch, {b['rows']:,} rows of {b['cameras']} cameras: local Dask cluster, "
                    f"{b['workers']} workers", f"{b['footprints_per_s'] / 1e6:.2f} M footprints/s",
                    f"in-process: {a['footprints_per_s'] / 1e6:.2f} M footprints/s",
                    f"time x{b['time_vs_in_process']:.2f}", b["target"], _yes_no(b["met"])))
    mem = S.get("memory", [])
    if len(mem) == 2 and "peak_rss_mb" in mem[1]:
        a, b = mem
        out.append((f"streaming batch peak RSS, {a['rows']:,} vs {b['rows']:,} rows",
                    f"{b['peak_rss_mb']:.0f} MB at 10x ({b['input_decoded_mb'] + b['output_uncompressed_mb']:,.0f}"
                    " MB of data)", f"{a['peak_rss_mb']:.0f} MB at 1x", f"10x/1x {b['peak_rss_ratio']:.2f}",
                    a["target"], _yes_no(a["met"])))
    sv = S.get("service", [])
    if len(sv) == 4 and "latency_ms_p99" in sv[0]:
        r = sv[0]
        out.append((f"edge service, {r['cameras']} cameras x {r['fps_per_camera']:.0f} frames/s x {r['objects']} "
                    f"objects via Mosquitto ({r['seconds']:.0f} s)",
                    f"{r['sustained_frames_per_s']:.0f} frames/s out, dropped {r['frames_dropped']}; latency p50 "
                    f"{r['latency_ms_p50']:.1f} / p99 {r['latency_ms_p99']:.1f} ms; peak RSS {r['peak_rss_mb']:.0f} MB",
                    f"offered {r['offered_frames_per_s']:.0f} frames/s",
                    f"{r['sustained_frames_per_s'] / r['offered_frames_per_s']:.2f} of offered",
                    "all frames, p99 <= 20 ms", _yes_no(r["met"] and sv[1]["met"])))
        out.append(("edge service, one 100-object frame: parse + footprints / whole record with messages",
                    f"{sv[2]['median_us']:.0f} us / {sv[3]['median_us']:.0f} us",
                    f"FrameProcessor alone {sv[2]['in_process']['frame_processor_us']:.0f} us", "",
                    sv[2]["target"], _yes_no(sv[2]["met"])))
    return out


def summary_markdown(results: dict) -> list[str]:
    rows = summary_rows(results)
    out = ["| benchmark | ours | reference, same run | ratio | target | met |", "|---|---|---|---|---|---|"]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return out


def to_markdown(results: dict) -> str:
    out = ["# footprint-uq benchmarks", "", *machine_markdown(results), "", "## Summary", "",
           *summary_markdown(results), ""]
    for section, rows in results["sections"].items():
        out += section_markdown(section, rows)
    return "\n".join(out)


def _section_fn(name: str):
    mod_name, fn_name = SECTIONS[name].split(":")
    if mod_name == "run":  # adapters in this file (also when run as __main__)
        return globals()[fn_name]
    return getattr(importlib.import_module(mod_name), fn_name)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smoke run: small sizes and few runs (under a minute)")
    ap.add_argument("--sections", default=",".join(SECTIONS),
                    help=f"comma-separated subset of: {', '.join(SECTIONS)}")
    ap.add_argument("--out", default=str(HERE / "results"), help="directory for latest.json / latest.md")
    ap.add_argument("--render", metavar="JSON", default=None,
                    help="run nothing: print the Markdown (summary and tables) of an existing results JSON")
    args = ap.parse_args(argv)
    if args.render:
        print(to_markdown(json.loads(Path(args.render).read_text())))
        return 0
    names = [s.strip() for s in args.sections.split(",") if s.strip()]
    unknown = [n for n in names if n not in SECTIONS]
    if unknown:
        ap.error(f"unknown section(s) {unknown}; available: {list(SECTIONS)}")
    t_start = time.perf_counter()
    results = {"quick": args.quick, "machine": machine_info(), "sections": {}, "section_seconds": {}}
    print(f"machine: {results['machine']['cpu']}, {results['machine']['cores']} cores, "
          f"load {results['machine']['load_average_1_5_15min']}", flush=True)
    failed = []
    for name in names:
        print(f"== {name}", flush=True)
        t0 = time.perf_counter()
        try:
            rows = _section_fn(name)(quick=args.quick)
        except Exception as exc:  # noqa: BLE001 -- report the failing section and go on with the others
            traceback.print_exc()
            rows = [{"case": "section failed", "error": f"{type(exc).__name__}: {exc}"}]
            failed.append(name)
        results["sections"][name] = rows
        results["section_seconds"][name] = round(time.perf_counter() - t0, 1)
        print("\n".join(section_markdown(name, rows)), flush=True)
    results["load_average_end"] = [round(x, 2) for x in os.getloadavg()]
    results["elapsed_s"] = round(time.perf_counter() - t_start, 1)
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "latest.json").write_text(json.dumps(results, indent=2, default=_json_default) + "\n")
    (out_dir / "latest.md").write_text(to_markdown(results))
    print("\n".join(machine_markdown(results)))
    print(f"wrote {out_dir / 'latest.json'} and {out_dir / 'latest.md'}")
    if failed:
        print(f"FAILED sections: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


if __name__ == "__main__":
    raise SystemExit(main())
