"""The in-page probe shared by the browser tests (test_report_browser, test_validation_browser, test_plan_browser).

A copy of a page gets a small inline checking script (the pages themselves have none): it records every error
event (script errors and failed resources, captured at the window) and, after ``load``, each ``<img>``'s
``complete``/``naturalWidth``/``naturalHeight``/displayed width, the page's scroll and client widths, the
elements that stick out of the window without a scrolling box around them (``wide``) and the scrolling boxes
whose content is wider than the box (``scrolled``).  Chromium's ``--dump-dom`` prints the resulting page, and
:func:`probe` returns what the script recorded.

Needs Debian's ``chromium`` (``apt-get install -y chromium``; ``.ci/run`` and ``tools/sysdeps.sh`` install it).
"""

from __future__ import annotations

import html as _html
import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest


def _chromium() -> str | None:
    """Path of the chromium binary, or None."""
    for name in ("chromium", "chromium-browser"):
        p = shutil.which(name)
        if p:
            return p
    return "/usr/bin/chromium" if Path("/usr/bin/chromium").exists() else None


CHROMIUM = _chromium()
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-dev-shm-usage", "--allow-file-access-from-files"]

PROBE = """<script>
window.__fuq = {errors: []};
window.addEventListener('error', function (e) {
  var t = e.target || {};
  window.__fuq.errors.push(e.message || ('resource failed: ' + (t.src || t.href || t.tagName)));
}, true);
window.addEventListener('load', function () {
  var de = document.documentElement;
  var vw = de.clientWidth;
  var all = Array.prototype.slice.call(document.body.querySelectorAll('*'));
  var wide = all.filter(function (el) {
    var r = el.getBoundingClientRect();
    for (var p = el.parentElement; p && p !== document.body; p = p.parentElement) {
      if (getComputedStyle(p).overflowX !== 'visible') { return false; }
    }
    return r.width > 0 && r.right > vw + 1;
  }).slice(0, 20).map(function (el) { return el.tagName + ':' + (el.textContent || '').slice(0, 40); });
  var scrolled = all.filter(function (el) {
    return getComputedStyle(el).overflowX !== 'visible' && el.scrollWidth > el.clientWidth + 1;
  }).map(function (el) { return (el.textContent || '').slice(0, 60); });
  var imgs = Array.prototype.slice.call(document.images).map(function (i) {
    return {complete: i.complete, w: i.naturalWidth, h: i.naturalHeight, shown_w: i.getBoundingClientRect().width,
            alt: i.alt.slice(0, 40)};
  });
  var first = document.querySelector('h1') ? document.querySelector('h1').nextElementSibling : null;
  var lead = null;
  if (first) {
    var v = first.querySelector('p.verdict'), im = first.querySelector('figure img');
    lead = {tag: first.tagName, cls: first.className, verdict: v ? v.textContent : null,
            img_w: im ? im.naturalWidth : 0, img_top: im ? im.getBoundingClientRect().top : null,
            tables_before: first.querySelectorAll('table').length};
  }
  var out = {errors: window.__fuq.errors, n_img: imgs.length, imgs: imgs, scroll_w: de.scrollWidth, view_w: vw,
             wide: wide, scrolled: scrolled, title: document.title, h2: document.querySelectorAll('h2').length,
             lead: lead};
  var pre = document.createElement('pre');
  pre.id = 'fuq-check';
  pre.textContent = JSON.stringify(out);
  document.body.appendChild(pre);
});
</script>"""


def need_chromium() -> None:
    """Skip without chromium; in CI (where ``.ci/run`` installs it) a missing browser is a failure."""
    if CHROMIUM is None:
        if os.environ.get("CI"):
            pytest.fail("chromium not found in CI (.ci/run should have installed it)")
        pytest.skip("chromium not installed (apt-get install -y chromium); the browser check needs it")


def run_chromium(args, tmp_path, timeout: float = 120) -> subprocess.CompletedProcess:
    """Run headless chromium with the project's flags and a fresh profile under ``tmp_path``."""
    cmd = [CHROMIUM, *FLAGS, f"--user-data-dir={tmp_path / 'profile'}", *args]
    env = {**os.environ, "HOME": str(tmp_path)}
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env)


def probe(page_html: str, tmp_path, *, width: int = 1200, hide_scrollbars: bool = False) -> dict:
    """Open ``page_html`` (a copy with :data:`PROBE` in its head) in a ``width`` x 900 window; what it recorded."""
    path = tmp_path / "probe.html"
    path.write_text(page_html.replace("<head>", "<head>" + PROBE, 1), encoding="utf-8")
    args = ["--virtual-time-budget=10000", f"--window-size={width},900", *(["--hide-scrollbars"] if hide_scrollbars
                                                                         else []), "--dump-dom", path.as_uri()]
    p = run_chromium(args, tmp_path)
    assert p.returncode == 0, p.stderr[-2000:]
    m = re.search(r'<pre id="fuq-check">(.*?)</pre>', p.stdout, re.S)
    assert m, "the page did not finish loading (no check output)\n" + p.stderr[-2000:]
    return json.loads(_html.unescape(m.group(1)))


def assert_leads_with_figure_and_verdict(res: dict, window_h: int = 900) -> None:
    """The page opens (right under its title) with its main figure and a one-sentence verdict, no table before
    them, and the figure starts on the first screen."""
    lead = res["lead"]
    assert lead is not None and lead["tag"] == "SECTION" and lead["cls"] == "lead", lead
    assert lead["verdict"] and lead["verdict"].count(". ") == 0 and lead["verdict"].endswith("."), lead["verdict"]
    assert lead["img_w"] > 300 and lead["img_top"] < window_h and lead["tables_before"] == 0, lead


def keep_screenshot(path: Path, name: str, tmp_path) -> Path:
    """A full-page screenshot of ``path`` kept as a test artefact (``FOOTPRINT_UQ_TEST_OUT``, else ``tmp_path``)."""
    keep = Path(os.environ.get("FOOTPRINT_UQ_TEST_OUT", tmp_path))
    keep.mkdir(parents=True, exist_ok=True)
    shot = keep / f"{name.replace(' ', '_')}.png"
    p = run_chromium([f"--screenshot={shot}", "--window-size=1200,1600", "--hide-scrollbars", path.as_uri()],
                     tmp_path)
    assert p.returncode == 0, p.stderr[-2000:]
    assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    return shot
