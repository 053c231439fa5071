"""footprint-uq benchmarks: one command, printed table, JSON + Markdown results.

Usage::

    .venv/bin/python bench/run.py [--quick] [--sections maps,...]

Each section is a function ``run(quick: bool) -> list[dict]`` in a module under
``bench/`` registered in :data:`SECTIONS`; every returned row is one line of the
results table (keys: ``section``, ``case`` and any of the measurement columns in
:data:`COLUMNS`).  Results go to ``bench/results/latest.json`` and
``bench/results/latest.md``.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import platform
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))  # section modules live next to this file

#: section name -> "module:function" (modules under bench/); add footprints, Monte Carlo, Dask here
SECTIONS: dict[str, str] = {
    "maps": "bench_maps:run",
}

#: (key, header, format) of the table columns, in order
COLUMNS = [
    ("case", "case", "{}"),
    ("pixels", "pixels", "{:,}"),
    ("median_ms", "median [ms]", "{:.2f}"),
    ("min_ms", "fastest [ms]", "{:.2f}"),
    ("cpu_ms", "CPU (all threads) [ms]", "{:.2f}"),
    ("runs", "runs", "{}"),
    ("mpx_per_s", "Mpx/s", "{:.1f}"),
    ("copy_ms", "copy same bytes [ms]", "{:.2f}"),
    ("copy_ratio", "copy / ours", "{:.2f}"),
    ("naive_mpx_per_s", "numpy propagate [Mpx/s]", "{:.3f}"),
    ("speedup_vs_naive", "speed-up", "{:,.0f}x"),
    ("target", "target", "{}"),
    ("met", "met", "{}"),
]


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
        "platform": platform.platform(),
        "load_average_1_5_15min": [round(x, 2) for x in load],
        "date_utc": time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime()),
    }


def _fmt(key, fmt, value):
    if value is None or value == "":
        return ""
    try:
        return fmt.format(value)
    except (ValueError, TypeError):
        return str(value)


def to_markdown(results: dict) -> str:
    m = results["machine"]
    out = ["# footprint-uq benchmarks", "",
           f"- date (UTC): {m['date_utc']}  mode: {'quick' if results['quick'] else 'full'}",
           f"- CPU: {m['cpu']}, {m['cores']} cores, numba threads: {m['numba_threads']}",
           f"- Python {m['python']}, numpy {m['numpy']}, numba {m['numba']}; {m['platform']}",
           f"- load average at start / end (1, 5, 15 min): {m['load_average_1_5_15min']} / "
           f"{results.get('load_average_end')}", ""]
    for section, rows in results["sections"].items():
        out += [f"## {section}", ""]
        cols = [c for c in COLUMNS if any(c[0] in r for r in rows)]
        out.append("| " + " | ".join(h for _, h, _ in cols) + " |")
        out.append("|" + "|".join("---" for _ in cols) + "|")
        for r in rows:
            out.append("| " + " | ".join(_fmt(k, f, r.get(k)) for k, _, f in cols) + " |")
        notes = [f"- {r['case']}: {r['notes']}" for r in rows if r.get("notes")]
        if notes:
            out += ["", *notes]
        out.append("")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer runs and a smaller grid for the numpy baseline")
    ap.add_argument("--sections", default=",".join(SECTIONS),
                    help=f"comma-separated subset of: {', '.join(SECTIONS)}")
    ap.add_argument("--out", default=str(HERE / "results"), help="directory for latest.json / latest.md")
    args = ap.parse_args(argv)
    names = [s.strip() for s in args.sections.split(",") if s.strip()]
    unknown = [n for n in names if n not in SECTIONS]
    if unknown:
        ap.error(f"unknown section(s) {unknown}; available: {list(SECTIONS)}")
    results = {"quick": args.quick, "machine": machine_info(), "sections": {}}
    print(f"machine: {results['machine']['cpu']}, {results['machine']['cores']} cores, "
          f"load {results['machine']['load_average_1_5_15min']}", flush=True)
    for name in names:
        mod_name, fn_name = SECTIONS[name].split(":")
        fn = getattr(importlib.import_module(mod_name), fn_name)
        print(f"== {name}", flush=True)
        rows = fn(quick=args.quick)
        results["sections"][name] = rows
    results["load_average_end"] = [round(x, 2) for x in os.getloadavg()]
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "latest.json").write_text(json.dumps(results, indent=2, default=str) + "\n")
    md = to_markdown(results)
    (out_dir / "latest.md").write_text(md)
    print()
    print(md)
    print(f"wrote {out_dir / 'latest.json'} and {out_dir / 'latest.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
