"""The benchmark registry runs end to end: ``bench/run.py --quick`` writes every section with numbers.

No timing is asserted (the figures depend on the machine and its load); this checks that the one
command of the README runs, that every registered section reports rows with finite measurements,
and that the JSON and Markdown results are written.
"""

from __future__ import annotations

import importlib.util
import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
RUN = ROOT / "bench" / "run.py"

#: a measurement every row of a section must carry (besides ``case``)
MEASURE_KEYS = ("median_ms", "median_us")


def _registry() -> dict:
    spec = importlib.util.spec_from_file_location("bench_run_registry", RUN)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.SECTIONS


def _finite_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


@pytest.fixture(scope="module")
def quick_results(tmp_path_factory):
    pytest.importorskip("dask")
    pytest.importorskip("uncertainties")
    out = tmp_path_factory.mktemp("bench")
    p = subprocess.run([sys.executable, str(RUN), "--quick", "--out", str(out)], capture_output=True, text=True,
                       cwd=ROOT, timeout=900)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-4000:]
    return out, json.loads((out / "latest.json").read_text()), (out / "latest.md").read_text(), p.stdout


def test_every_section_has_rows_with_numbers(quick_results):
    _, res, _, _ = quick_results
    sections = _registry()
    assert set(sections) >= {"maps", "uncertainties", "montecarlo", "footprints", "batch", "dask", "memory"}
    assert list(res["sections"]) == list(sections)
    assert res["quick"] is True
    for name, rows in res["sections"].items():
        assert rows, name
        for row in rows:
            assert "error" not in row, (name, row)
            assert isinstance(row["case"], str) and row["case"], (name, row)
            times = [row[k] for k in MEASURE_KEYS if k in row]
            assert times and all(_finite_number(t) and t > 0 for t in times), (name, row)


def test_section_specific_figures(quick_results):
    _, res, _, _ = quick_results
    s = res["sections"]
    # uncertainties: extrapolated and labelled so, and equal to ours on the measured subset
    unc = [r for r in s["uncertainties"] if r.get("extrapolated") and "uncertainties" in r["case"]]
    assert len(unc) == 1 and "EXTRAPOLATED" in unc[0]["case"]
    assert unc[0]["cov_max_rel_diff_vs_ours"] < 1e-9
    assert unc[0]["measured_pixels"] < unc[0]["pixels"]
    assert any("roofline" in r["case"] for r in s["uncertainties"])
    # Monte Carlo: agreement statistics are numbers in their ranges
    mc = [r for r in s["montecarlo"] if "sigma_ratio_median" in r]
    assert len(mc) == 2
    for r in mc:
        assert 0.5 < r["sigma_ratio_median"] < 2.0
        assert 0.0 <= r["within_1se"] <= r["within_2se"] <= 1.0
    assert all(_finite_number(r["speedup_vs_mc"]) for r in s["montecarlo"] if "speedup_vs_mc" in r)
    # throughput and memory
    for name in ("batch", "dask", "memory"):
        assert all(_finite_number(r["footprints_per_s"]) and r["footprints_per_s"] > 0 for r in s[name]), name
    assert len(s["dask"]) == 2 and s["dask"][1]["workers"] == 2
    mem = s["memory"]
    assert [r["factor"] for r in mem] == [1, 10]
    assert all(_finite_number(r["peak_rss_mb"]) and r["peak_rss_mb"] > 0 for r in mem)
    assert all(r["output_rows"] == r["rows"] for r in mem)
    fp = s["footprints"]
    assert all(r["items"] == 100 for r in fp)


def test_markdown_and_machine(quick_results):
    _, res, md, stdout = quick_results
    m = res["machine"]
    assert m["cores"] >= 1 and m["cpu"] and len(m["load_average_1_5_15min"]) == 3
    for name in res["sections"]:
        assert f"## {name}" in md
        assert f"## {name}" in stdout  # each section's table is printed as it finishes
    assert "| case |" in md and "CPU:" in md and "load average" in md
    assert "## Summary" in md and "| benchmark | ours | reference, same run |" in md


def test_render_reproduces_the_markdown(quick_results):
    out, _, md, _ = quick_results
    p = subprocess.run([sys.executable, str(RUN), "--render", str(out / "latest.json")], capture_output=True,
                       text=True, cwd=ROOT, timeout=120)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip() == md.strip()


def test_unknown_section_is_an_error(tmp_path):
    p = subprocess.run([sys.executable, str(RUN), "--sections", "nope", "--out", str(tmp_path)],
                       capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert p.returncode == 2 and "unknown section" in p.stderr
    assert not (tmp_path / "latest.json").exists()
