"""Reliability figures of docs/benchmarks.md (issue 11): hostile inputs, killed jobs, rows lost, tracebacks.

Usage::

    .venv/bin/python bench/reliability.py [--kills N] [--seed S] [--out DIR] [--update-readme]

* **hostile inputs**: every case of ``tests/hostile_cases.py`` through the CLI (in-process): bad
  files must give one error line and exit 2 with nothing written, bad rows must come out as
  error rows with none lost;
* **kills**: ``footprint-uq objects`` (Parquet, CSV, JSON Lines outputs; and a fleet job) in a
  subprocess, SIGKILLed at a random moment (seeded) after it starts writing, onto a previous
  output.  Survived = under the final name the previous file or a complete new one, a summary
  only beside the file it describes, and a re-run that succeeds with every row;
* **rows lost**: input rows (physical lines) minus output rows, over every case and re-run
  (must be 0); **tracebacks**: over every run (must be 0).

Results go to ``DIR/reliability.json`` and ``DIR/reliability.md`` (default ``bench/results``);
``--update-readme`` rewrites the block of docs/benchmarks.md between ``<!-- reliability:begin -->`` and
``<!-- reliability:end -->`` from them (``tests/test_readme.py`` checks the two agree).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "src"))

BEGIN, END = "<!-- reliability:begin -->", "<!-- reliability:end -->"


def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT / "src") + os.pathsep + env.get("PYTHONPATH", "")
    return env


def _cli(args) -> list[str]:
    return [sys.executable, "-c", "from footprint_uq.cli.main import main; main()", *[str(a) for a in args]]


def _rows(path: Path) -> int:
    import pyarrow.parquet as pq

    if path.suffix == ".parquet":
        return pq.ParquetFile(path).metadata.num_rows
    if path.suffix == ".csv":
        import pyarrow.csv as pcsv

        return pcsv.read_csv(path).num_rows
    return sum(1 for _ in path.open())


def _setup(d: Path, n_rows: int):
    import numpy as np
    import pyarrow as pa
    import pyarrow.parquet as pq

    from footprint_uq import PanTiltCamera, save_camera

    cam = PanTiltCamera(focal_px=1400.0, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)
    save_camera(cam, d / "cam.yaml")
    reg = d / "reg"
    reg.mkdir()
    save_camera(cam, reg / "cam1.yaml")
    save_camera(cam, reg / "cam2.yaml")
    rng = np.random.default_rng(0)

    def boxes(n):
        u, v = rng.uniform(100, 1700, n), rng.uniform(600, 1000, n)
        return {"frame": np.arange(n, dtype=np.int64), "u_min_px": u, "v_min_px": v - 40, "u_max_px": u + 80,
                "v_max_px": v}

    pq.write_table(pa.table(boxes(n_rows)), d / "big.parquet", row_group_size=20_000)
    pq.write_table(pa.table(boxes(100)), d / "small.parquet")
    data = d / "fleet"
    data.mkdir()
    for i in range(4):
        b = boxes(n_rows // 6)
        ids = np.where(np.arange(b["frame"].size) % 2 == 0, "cam1", "cam2").tolist()
        pq.write_table(pa.table({"camera_id": ids, **b}), data / f"part-{i}.parquet", row_group_size=10_000)
    return 4 * (n_rows // 6)


def _kill_after(proc, seen, delay_s: float, timeout_s: float = 180.0) -> bool:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        if proc.poll() is not None:
            return False
        if seen():
            time.sleep(delay_s)
            if proc.poll() is not None:
                return False
            proc.send_signal(signal.SIGKILL)
            proc.wait()
            return True
        time.sleep(0.002)
    proc.kill()
    return False


def _single_kill(d: Path, ext: str, delay_s: float, n_rows: int) -> dict:
    out = d / f"fp.{ext}"
    summ = Path(f"{out}.summary.json")
    base = ["objects", "--camera", d / "cam.yaml", "--budget", "basler1", "--quiet"]
    subprocess.run(_cli(base + ["--detections", d / "small.parquet", "--out", out]), env=_env(), check=True,
                   capture_output=True)
    old = out.read_bytes()
    proc = subprocess.Popen(_cli(base + ["--detections", d / "big.parquet", "--out", out, "--chunk-rows", "20000"]),
                            env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    killed = _kill_after(proc, lambda: any(p.name.startswith(".fp") for p in d.iterdir()), delay_s)
    try:
        intact = out.read_bytes() == old or _rows(out) == n_rows
        summary_ok = (not summ.exists()) or json.loads(summ.read_text())["rows_out"] == _rows(out)
    except Exception:  # noqa: BLE001 - an unreadable output is exactly what must not happen: not survived
        intact = summary_ok = False
    r = subprocess.run(_cli(base + ["--detections", d / "big.parquet", "--out", out]), env=_env(),
                       capture_output=True, text=True)
    rerun_rows = _rows(out) if r.returncode == 0 else 0
    js = json.loads(summ.read_text()) if summ.exists() else {}
    return {"job": f"objects -> .{ext}", "killed": killed, "delay_s": round(delay_s, 3),
            "survived": bool(killed and intact and summary_ok and r.returncode == 0 and js.get("consistent")),
            "rows_lost": n_rows - rerun_rows, "traceback": "Traceback" in r.stderr}


def _fleet_kill(d: Path, delay_s: float, n_rows: int) -> dict:
    out = d / "fleet_out"
    args = ["objects", "--registry", d / "reg", "--budget", "basler1", "--detections", d / "fleet", "--out", out,
            "--quiet", "--overwrite"]
    if not out.exists():
        subprocess.run(_cli(args), env=_env(), check=True, capture_output=True)

    def snapshot():
        return sorted((p.relative_to(out).as_posix(), p.read_bytes()) for p in out.rglob("*") if p.is_file())

    before = snapshot()
    proc = subprocess.Popen(_cli(args + ["--chunk-rows", "5000"]), env=_env(), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    killed = _kill_after(proc, lambda: any(p.name.startswith(".fleet_out") and any(p.rglob("*.parquet"))
                                           for p in d.iterdir()), delay_s)
    intact = snapshot() == before
    r = subprocess.run(_cli(args), env=_env(), capture_output=True, text=True)
    import pyarrow.dataset as ds

    rows = ds.dataset(out, format="parquet", partitioning="hive").to_table().num_rows if r.returncode == 0 else 0
    leftovers = [p.name for p in d.iterdir() if p.name.startswith(".fleet_out")]
    return {"job": "fleet objects -> partitions", "killed": killed, "delay_s": round(delay_s, 3),
            "survived": bool(killed and intact and r.returncode == 0 and not leftovers),
            "rows_lost": n_rows - rows, "traceback": "Traceback" in r.stderr}


def run(kills: int = 3, seed: int = 0, n_rows: int = 300_000) -> dict:
    import numpy as np

    import hostile_cases as H

    t0 = time.time()
    rng = np.random.default_rng(seed)
    with tempfile.TemporaryDirectory(prefix="reliability-") as tmp:
        tmp = Path(tmp)
        cases = H.build(tmp / "hostile")
        hostile = [H.run(c) for c in cases]
        d = tmp / "kills"
        d.mkdir()
        n_fleet = _setup(d, n_rows)
        kill_runs = []
        for ext in ("parquet", "csv", "jsonl"):
            for _ in range(kills):
                kill_runs.append(_single_kill(d, ext, float(rng.uniform(0.0, 0.3)), n_rows))
        for _ in range(kills):
            kill_runs.append(_fleet_kill(d, float(rng.uniform(0.0, 0.3)), n_fleet))
    killed = [k for k in kill_runs if k["killed"]]
    res = {
        "hostile_inputs": len(hostile),
        "hostile_ok": sum(h["ok"] for h in hostile),
        "hostile_failed": [h["name"] for h in hostile if not h["ok"]],
        "bad_file_cases": sum(h["expect"] == "exit2" for h in hostile),
        "bad_row_cases": sum(h["expect"] != "exit2" for h in hostile),
        "kills": len(killed),
        "kills_survived": sum(k["survived"] for k in killed),
        "kill_attempts": len(kill_runs),
        "rows_lost": int(sum(h["rows_lost"] for h in hostile) + sum(k["rows_lost"] for k in kill_runs)),
        "tracebacks": int(sum(h["traceback"] for h in hostile) + sum(k["traceback"] for k in kill_runs)),
        "exit3": sum(h["exit"] == 3 for h in hostile),
        "kill_runs": kill_runs,
        "hostile": [{k: h[k] for k in ("name", "expect", "exit", "ok", "rows_lost", "traceback")} for h in hostile],
        "seed": seed, "rows_per_killed_job": n_rows,
        "date_utc": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}",
        "elapsed_s": round(time.time() - t0, 1),
    }
    return res


def render(res: dict) -> str:
    """The README block (Markdown) of a results dict."""
    lines = [
        f"Last run: {res['date_utc']} ({res['machine']}; `bench/reliability.py --seed {res['seed']}`, "
        f"{res['elapsed_s']:.0f} s).",
        "",
        "| figure | value |",
        "|---|---|",
        f"| hostile inputs tried (bad files {res['bad_file_cases']}, bad rows {res['bad_row_cases']}) "
        f"| {res['hostile_inputs']} |",
        f"| ... handled as promised (one line + exit 2, or error rows) | {res['hostile_ok']} |",
        f"| jobs killed (SIGKILL while writing; Parquet, CSV, JSON Lines, fleet) | {res['kills']} |",
        f"| ... survived (previous output intact or complete new one, re-run succeeds) | {res['kills_survived']} |",
        f"| rows lost | {res['rows_lost']} |",
        f"| tracebacks | {res['tracebacks']} |",
    ]
    return "\n".join(lines)


def update_readme(res: dict, readme: Path = ROOT / "docs" / "benchmarks.md") -> None:
    text = readme.read_text(encoding="utf-8")
    i, j = text.index(BEGIN) + len(BEGIN), text.index(END)
    readme.write_text(text[:i] + "\n" + render(res) + "\n" + text[j:], encoding="utf-8")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kills", type=int, default=3, help="kills per job kind (Parquet, CSV, JSONL, fleet)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--rows", type=int, default=300_000, help="rows of the killed single-file jobs")
    ap.add_argument("--out", type=Path, default=HERE / "results")
    ap.add_argument("--update-readme", action="store_true")
    ap.add_argument("--from-json", type=Path, default=None, help="render (and --update-readme) a results file")
    a = ap.parse_args(argv)
    if a.from_json is not None:
        res = json.loads(a.from_json.read_text(encoding="utf-8"))
    else:
        res = run(a.kills, a.seed, a.rows)
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "reliability.json").write_text(json.dumps(res, indent=1) + "\n", encoding="utf-8")
    (a.out / "reliability.md").write_text(render(res) + "\n", encoding="utf-8")
    print(render(res))
    if res["hostile_failed"]:
        print("failed:", ", ".join(res["hostile_failed"]))
    if a.update_readme:
        update_readme(res)
    ok = (res["hostile_ok"] == res["hostile_inputs"] and res["kills_survived"] == res["kills"]
          and res["rows_lost"] == 0 and res["tracebacks"] == 0)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
