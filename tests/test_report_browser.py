"""The case-study report opened in headless Chromium: loads without errors, every figure displayed.

Needs Debian's ``chromium`` (``apt-get install -y chromium``; ``.ci/run`` installs it).
A copy of the report gets a small inline checking script (the report itself has none):
it records every error event (script errors and failed resources, captured at the
window) and, after ``load``, each ``<img>``'s ``complete``/``naturalWidth``; Chromium's
``--dump-dom`` prints the resulting page.  A screenshot is kept in the test's directory
(``tmp_path``; set ``FOOTPRINT_UQ_TEST_OUT`` to keep it elsewhere).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

pytestmark = pytest.mark.browser


def _chromium() -> str | None:
    for name in ("chromium", "chromium-browser"):
        p = shutil.which(name)
        if p:
            return p
    return "/usr/bin/chromium" if Path("/usr/bin/chromium").exists() else None


CHROMIUM = _chromium()
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-dev-shm-usage", "--allow-file-access-from-files"]

CHECK = """<script>
window.__fuq = {errors: []};
window.addEventListener('error', function (e) {
  var t = e.target || {};
  window.__fuq.errors.push(e.message || ('resource failed: ' + (t.src || t.href || t.tagName)));
}, true);
window.addEventListener('load', function () {
  var imgs = Array.prototype.slice.call(document.images);
  var out = {n_img: imgs.length, errors: window.__fuq.errors,
             imgs: imgs.map(function (i) { return {complete: i.complete, w: i.naturalWidth, h: i.naturalHeight,
                                                   shown_w: i.getBoundingClientRect().width}; }),
             title: document.title, h2: document.querySelectorAll('h2').length};
  var pre = document.createElement('pre');
  pre.id = 'fuq-check';
  pre.textContent = JSON.stringify(out);
  document.body.appendChild(pre);
});
</script>"""


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    if CHROMIUM is None:
        if os.environ.get("CI"):  # .ci/run installs chromium: a missing browser in CI is a failure, not a skip
            pytest.fail("chromium not found in CI (.ci/run should have installed it)")
        pytest.skip("chromium not installed (apt-get install -y chromium); the browser check needs it")
    from footprint_uq.scenario import CaseStudyConfig
    from footprint_uq.viz.case_study_run import run_case_study

    out = tmp_path_factory.mktemp("report")
    cfg = CaseStudyConfig.from_dict({"trajectory": {"frame_rate_hz": 2.0}, "heatmap": {"step_m": 4.0}})
    paths = run_case_study(out, config=cfg, dpi=60)
    return paths


def _run(args, tmp_path, timeout=120):
    profile = tmp_path / "profile"
    cmd = [CHROMIUM, *FLAGS, f"--user-data-dir={profile}", *args]
    env = {**os.environ, "HOME": str(tmp_path)}
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env)


def _probe(html: str, tmp_path) -> dict:
    """Open ``html`` with the checking script; return what it recorded."""
    probe = tmp_path / "probe.html"
    probe.write_text(html.replace("<head>", "<head>" + CHECK, 1), encoding="utf-8")
    p = _run(["--virtual-time-budget=10000", "--window-size=1200,900", "--dump-dom", probe.as_uri()], tmp_path)
    assert p.returncode == 0, p.stderr[-2000:]
    m = re.search(r'<pre id="fuq-check">(.*?)</pre>', p.stdout, re.S)
    assert m, "the page did not finish loading (no check output)\n" + p.stderr[-2000:]
    return json.loads(m.group(1).replace("&quot;", '"').replace("&amp;", "&"))


def test_report_loads_and_every_figure_is_displayed(report, tmp_path):
    html = report["report"].read_text(encoding="utf-8")
    n_fig = len(report["figures"])
    res = _probe(html, tmp_path)
    assert res["errors"] == []
    assert res["n_img"] == n_fig == 10
    for i, img in enumerate(res["imgs"]):
        assert img["complete"] and img["w"] > 100 and img["h"] > 100, (i, img)
        assert img["shown_w"] > 100, (i, img)  # laid out, not hidden
    assert res["title"].startswith("Left-turn case study")
    assert res["h2"] >= 4


def test_probe_detects_a_broken_figure(report, tmp_path):
    """Negative control: the same check flags a figure that does not decode."""
    html = report["report"].read_text(encoding="utf-8")
    i = html.index("data:image/png;base64,") + len("data:image/png;base64,")
    broken = html[:i] + "AAAA" + html[i + 40:]
    res = _probe(broken, tmp_path)
    assert res["n_img"] == len(report["figures"])
    assert res["imgs"][0]["w"] == 0 and all(img["w"] > 0 for img in res["imgs"][1:])
    assert len(res["errors"]) == 1


def test_report_screenshot_kept(report, tmp_path):
    keep = Path(os.environ.get("FOOTPRINT_UQ_TEST_OUT", tmp_path))
    keep.mkdir(parents=True, exist_ok=True)
    shot = keep / "report_screenshot.png"
    p = _run([f"--screenshot={shot}", "--window-size=1200,2400", "--hide-scrollbars",
              report["report"].as_uri()], tmp_path)
    assert p.returncode == 0, p.stderr[-2000:]
    data = shot.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 50_000
