"""The validation report (``footprint-uq validate``) opened in headless Chromium: it loads without errors, every
figure is displayed and nothing overflows horizontally (the project's way: tests/test_report_browser.py)."""

from __future__ import annotations

import json
import os
import re
import subprocess

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from footprint_uq.io import save_camera
from footprint_uq.uncertainty.budget import ErrorBudget
from footprint_uq.validation.synthetic import campaign_table, random_cameras
from footprint_uq.viz.validation_run import run_validation
from test_report_browser import CHROMIUM, FLAGS

pytestmark = pytest.mark.browser

CHECK = """<script>
window.__fuq = {errors: []};
window.addEventListener('error', function (e) {
  var t = e.target || {};
  window.__fuq.errors.push(e.message || ('resource failed: ' + (t.src || t.href || t.tagName)));
}, true);
window.addEventListener('load', function () {
  var imgs = Array.prototype.slice.call(document.images);
  var d = document.documentElement;
  var wide = Array.prototype.slice.call(document.body.querySelectorAll('*')).filter(function (el) {
    return el.getBoundingClientRect().right > d.clientWidth + 1; }).map(function (el) { return el.tagName; });
  var out = {n_img: imgs.length, errors: window.__fuq.errors, scroll_w: d.scrollWidth, client_w: d.clientWidth,
             wide: wide, h2: document.querySelectorAll('h2').length,
             imgs: imgs.map(function (i) { return {complete: i.complete, w: i.naturalWidth,
                                                   shown_w: i.getBoundingClientRect().width}; })};
  var pre = document.createElement('pre');
  pre.id = 'fuq-check';
  pre.textContent = JSON.stringify(out);
  document.body.appendChild(pre);
});
</script>"""


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    if CHROMIUM is None:
        if os.environ.get("CI"):
            pytest.fail("chromium not found in CI (.ci/run should have installed it)")
        pytest.skip("chromium not installed (apt-get install -y chromium); the browser check needs it")
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


def _probe(html: str, tmp_path, width: int) -> dict:
    probe = tmp_path / "probe.html"
    probe.write_text(html.replace("<head>", "<head>" + CHECK, 1), encoding="utf-8")
    cmd = [CHROMIUM, *FLAGS, f"--user-data-dir={tmp_path / 'profile'}", "--virtual-time-budget=10000",
           f"--window-size={width},900", "--dump-dom", probe.as_uri()]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env={**os.environ, "HOME": str(tmp_path)})
    assert p.returncode == 0, p.stderr[-2000:]
    m = re.search(r'<pre id="fuq-check">(.*?)</pre>', p.stdout, re.S)
    assert m, "the page did not finish loading (no check output)\n" + p.stderr[-2000:]
    return json.loads(m.group(1).replace("&quot;", '"').replace("&amp;", "&"))


@pytest.mark.parametrize("width", [1200, 800])
def test_validation_report_loads_figures_and_fits_the_width(report, tmp_path, width):
    summary, files = report
    assert summary["n_pairs"] == 240 and summary["n_groups"] == 6
    res = _probe(files["report"].read_text(encoding="utf-8"), tmp_path, width)
    assert res["errors"] == []
    assert res["n_img"] == 4
    for img in res["imgs"]:
        assert img["complete"] and img["w"] > 100 and img["shown_w"] > 100, img
    assert res["scroll_w"] <= res["client_w"], res["wide"][:10]
    assert res["h2"] >= 6


def test_probe_sees_an_overflow(report, tmp_path):
    """Negative control: a page with a too-wide element is caught."""
    html = report[1]["report"].read_text(encoding="utf-8")
    html = html.replace("</body>", '<div style="width:3000px">x</div></body>')
    res = _probe(html, tmp_path, 1200)
    assert res["scroll_w"] > res["client_w"] and "DIV" in res["wide"]
