"""The validation report (``footprint-uq validate``) opened in headless Chromium: it loads without errors, every
figure is displayed and nothing overflows horizontally (the probe of tests/browser_probe.py)."""

from __future__ import annotations

import json

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from browser_probe import assert_leads_with_figure_and_verdict, keep_screenshot, need_chromium, probe
from footprint_uq.io import save_camera
from footprint_uq.uncertainty.budget import ErrorBudget
from footprint_uq.validation.synthetic import campaign_table, random_cameras
from footprint_uq.viz.validation_run import run_validation

pytestmark = pytest.mark.browser

@pytest.fixture(scope="module")
def report(tmp_path_factory):
    need_chromium()
    out = tmp_path_factory.mktemp("validation")
    cams = random_cameras(6, seed=4)
    budget = ErrorBudget.preset("basler1@deg")
    tables = list(campaign_table(cams, budget, 40, seed=2))
    pq.write_table(pa.concat_tables(tables), out / "pairs.parquet")
    reg = out / "registry.json"
    for cid, cam in cams.items():
        save_camera(cam, out / f"{cid}.yaml")
    reg.write_text(json.dumps([{"camera_id": cid, "camera": f"{cid}.yaml"} for cid in cams]))
    summary, files = run_validation(out / "pairs.parquet", out / "report", budget, registry=reg, dpi=60, fsync=False)
    return summary, files


@pytest.mark.parametrize("width", [1200, 800])
def test_validation_report_loads_figures_and_fits_the_width(report, tmp_path, width):
    summary, files = report
    assert summary["n_pairs"] == 240 and summary["n_groups"] == 6
    res = probe(files["report"].read_text(encoding="utf-8"), tmp_path, width=width)
    assert res["errors"] == []
    assert res["n_img"] == 4
    assert_leads_with_figure_and_verdict(res)  # the coverage figure and the verdict first, tables after
    assert "Verdict:" in res["lead"]["verdict"]
    if width == 1200:
        keep_screenshot(files["report"], "report_validation", tmp_path)
    for img in res["imgs"]:
        assert img["complete"] and img["w"] > 100 and img["shown_w"] > 100, img
    assert res["scroll_w"] <= res["view_w"], res["wide"][:10]
    assert res["h2"] >= 6


def test_probe_sees_an_overflow(report, tmp_path):
    """Negative control: a page with a too-wide element is caught."""
    html = report[1]["report"].read_text(encoding="utf-8")
    html = html.replace("</body>", '<div style="width:3000px">x</div></body>')
    res = probe(html, tmp_path, width=1200)
    assert res["scroll_w"] > res["view_w"] and any(w.startswith("DIV:") for w in res["wide"])
