"""The interactive planning page: one camera's height, pan and tilt on sliders, the map re-drawn by a small
local server (``footprint-uq plan --serve``).

The server is :class:`http.server.ThreadingHTTPServer` from the standard library, bound to
``127.0.0.1`` only (never another interface).  Routes:

* ``GET /``: the page (self-contained: inline CSS and script, the first map embedded);
* ``GET /api/state``: the layout and its evaluation (JSON);
* ``POST /api/update`` with ``{"camera": k, "height_m": h, "pan_deg": p, "tilt_deg": t}``: moves camera
  ``k`` and returns the new evaluation and map (a PNG data URI).  Bad input: status 400 and a one-line
  ``{"error": ...}``.

The page sets ``document.body.dataset.redraws`` (a counter) and ``dataset.lastRedrawMs`` after each
re-draw and fires a ``fuq-redrawn`` event: the browser test waits on them.
"""

from __future__ import annotations

import json
import math
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import numpy as np

from ..errors import InputError
from ..planning.geometry import ground_samples
from ..planning.layout import LayoutCamera, evaluate_cameras, layout_from_configs, perturbed_camera, read_layout
from ..planning.optimise import plan
from ..planning.site import load_site
from .planning import plot_semi_major
from .report import esc, fig_to_png_bytes, png_data_uri

__all__ = ["PlanSession", "make_server", "serve_plan", "HOST"]

#: the only interface the server listens on
HOST = "127.0.0.1"
_MAX_BODY = 4096


class PlanSession:
    """The state behind the page: the site, its samples and the current layout (thread-safe updates)."""

    def __init__(self, site, cameras: list[LayoutCamera], *, fusion: bool = True, dpi: int = 70):
        self.site, self.fusion, self.dpi = site, fusion, dpi
        self.samples = ground_samples(site)
        self.base = list(cameras)
        self.cameras = list(cameras)
        self.lock = threading.Lock()
        self.evaluation, self.infos = evaluate_cameras(site, self.samples, self.cameras, fusion=fusion)

    def _ranges(self, k: int) -> dict:
        lc = self.base[k]
        if lc.config is not None:
            lo, hi = self.site.mount(lc.config.mount).height_range_m
        else:
            lo, hi = max(1.0, lc.camera.height_m - 3.0), lc.camera.height_m + 3.0
        return {"height_min_m": lo, "height_max_m": max(hi, lo + 0.5)}

    def state(self) -> dict:
        ev = self.evaluation
        return {"fraction_met": ev.fraction,
                "zones": [{k: (v if not isinstance(v, float) or math.isfinite(v) else None) for k, v in z.row().items()}
                          for z in ev.zones],
                "cameras": [{"name": lc.name, "height_m": lc.camera.height_m,
                             "pan_deg": float(np.mod(lc.camera.pan_deg, 360.0)), "tilt_deg": lc.camera.tilt_deg,
                             **self._ranges(k)} for k, lc in enumerate(self.cameras)]}

    def map_png(self) -> bytes:
        fig = plot_semi_major(self.site, self.samples, self.evaluation.semi_major_m, self.cameras,
                              title=f"Fused 95 % semi-major axis: {100 * self.evaluation.fraction:.1f} % met",
                              )
        return fig_to_png_bytes(fig, dpi=self.dpi)

    def update(self, body: dict) -> dict:
        """Move one camera (see the module docstring); returns the new state and map."""
        if not isinstance(body, dict):
            raise InputError("request", body, "a JSON object")
        k = body.get("camera")
        if isinstance(k, bool) or not isinstance(k, int) or not 0 <= k < len(self.cameras):
            raise InputError("camera", k, f"an index in [0, {len(self.cameras) - 1}]")
        vals = {}
        for f, lo, hi in (("height_m", 0.1, 500.0), ("pan_deg", -360.0, 720.0), ("tilt_deg", 0.5, 89.5)):
            v = body.get(f)
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) or not lo <= v <= hi:
                raise InputError(f, v, f"a number in [{lo:g}, {hi:g}]")
            vals[f] = float(v)
        with self.lock:
            b = self.base[k].camera
            cam = perturbed_camera(b, height_m=vals["height_m"] - b.height_m, tilt_deg=vals["tilt_deg"] - b.tilt_deg,
                                   pan_deg=vals["pan_deg"] - b.pan_deg)
            lc = self.cameras[k]
            self.cameras[k] = LayoutCamera(lc.name, cam, lc.budget, lc.config, lc.budget_spec)
            self.evaluation, self.infos = evaluate_cameras(self.site, self.samples, self.cameras, fusion=self.fusion)
            return {**self.state(), "png": png_data_uri(self.map_png())}


_PAGE_CSS = """
body { font-family: -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; max-width: 1100px; margin: 1.5em auto;
       padding: 0 1em; color: #222; }
#controls { display: grid; grid-template-columns: max-content 1fr max-content; gap: .4em .8em; align-items: center;
            max-width: 640px; }
input[type=range] { width: 100%; }
#map { max-width: 100%; border: 1px solid #ddd; }
table { border-collapse: collapse; font-size: .9em; margin: .6em 0; }
th, td { border: 1px solid #ccc; padding: .2em .5em; text-align: right; } td:first-child { text-align: left; }
#status { color: #555; font-size: .9em; }
"""

_PAGE_JS = """
(function () {
  var state = JSON.parse(document.getElementById('initial-state').textContent);
  var sel = document.getElementById('camera'), busy = false, again = false, timer = null;
  var ids = ['height_m', 'pan_deg', 'tilt_deg'];
  function el(id) { return document.getElementById(id); }
  function fmt(v, d) { return v === null ? '-' : Number(v).toFixed(d); }
  function table(s) {
    var rows = s.zones.map(function (z) {
      return '<tr><td>' + z.zone.replace(/[&<>]/g, '') + '</td><td>' + fmt(z.requirement_m, 2) + '</td><td>' +
        fmt(100 * z.fraction_met, 1) + ' %</td><td>' + fmt(z.worst_semi_major_m, 2) + '</td></tr>';
    }).join('');
    el('zones').innerHTML = '<tr><th>zone</th><th>requirement (m)</th><th>met</th><th>worst (m)</th></tr>' + rows;
    el('fraction').textContent = fmt(100 * s.fraction_met, 1) + ' %';
  }
  function load(k) {
    var c = state.cameras[k];
    el('height_m').min = c.height_min_m; el('height_m').max = c.height_max_m;
    ids.forEach(function (id) { el(id).value = c[id]; el(id + '_v').textContent = fmt(c[id], 1); });
  }
  function send() {
    if (busy) { again = true; return; }
    busy = true; again = false;
    var k = Number(sel.value), t0 = performance.now();
    var body = {camera: k};
    ids.forEach(function (id) { body[id] = Number(el(id).value); });
    el('status').textContent = 'computing...';
    fetch('api/update', {method: 'POST', headers: {'Content-Type': 'application/json'}, body: JSON.stringify(body)})
      .then(function (r) { return r.json().then(function (j) { if (!r.ok) { throw new Error(j.error); } return j; }); })
      .then(function (s) {
        state.cameras = s.cameras; state.zones = s.zones; state.fraction_met = s.fraction_met;
        var img = el('map');
        img.onload = function () {
          var ms = performance.now() - t0;
          document.body.dataset.redraws = String(Number(document.body.dataset.redraws || '0') + 1);
          document.body.dataset.lastRedrawMs = ms.toFixed(0);
          el('status').textContent = 're-drawn in ' + ms.toFixed(0) + ' ms';
          document.dispatchEvent(new CustomEvent('fuq-redrawn', {detail: {ms: ms}}));
        };
        img.src = s.png; table(s);
      })
      .catch(function (e) { el('status').textContent = 'error: ' + e.message; })
      .finally(function () { busy = false; if (again) { send(); } });
  }
  ids.forEach(function (id) {
    el(id).addEventListener('input', function () {
      el(id + '_v').textContent = fmt(el(id).value, 1);
      clearTimeout(timer); timer = setTimeout(send, 120);
    });
  });
  sel.addEventListener('change', function () { load(Number(sel.value)); });
  load(0); table(state);
})();
"""


def page_html(session: PlanSession) -> str:
    """The interactive page (self-contained; the first map embedded)."""
    st = session.state()
    opts = "".join(f'<option value="{k}">{esc(c["name"])}</option>' for k, c in enumerate(st["cameras"]))
    sliders = "".join(
        f'<label for="{i}">{lab}</label><input type="range" id="{i}" min="{lo}" max="{hi}" step="{step}">'
        f'<span id="{i}_v"></span>'
        for i, lab, lo, hi, step in (("height_m", "height (m)", 1, 20, 0.1), ("pan_deg", "pan (deg)", 0, 360, 1),
                                     ("tilt_deg", "tilt (deg, down)", 1, 89, 0.5)))
    state_json = json.dumps(st).replace("</", "<\\/")
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f'<meta name="viewport" content="width=device-width, initial-scale=1"><link rel="icon" href="data:,">'
            f"<title>Site plan (interactive): {esc(session.site.name)}</title><style>{_PAGE_CSS}</style></head>"
            f"<body><h1>Site plan: {esc(session.site.name)}</h1>"
            f'<p>Weighted met area: <b id="fraction"></b> <span id="status"></span></p>'
            f'<div id="controls"><label for="camera">camera</label><select id="camera">{opts}</select><span></span>'
            f"{sliders}</div>"
            f'<img id="map" alt="fused semi-major map" src="{png_data_uri(session.map_png())}">'
            f'<table id="zones"></table>'
            f'<script type="application/json" id="initial-state">{state_json}</script>'
            f"<script>{_PAGE_JS}</script></body></html>\n")


class _Handler(BaseHTTPRequestHandler):
    session: PlanSession = None
    server_version = "footprint-uq-plan"

    def log_message(self, fmt, *args):  # quiet: the CLI prints the URL, not every request
        return

    def _send(self, code: int, body: bytes, ctype: str):
        self.send_response(code)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        self.wfile.write(body)

    def _json(self, code: int, data):
        self._send(code, json.dumps(data, allow_nan=False).encode(), "application/json")

    def do_GET(self):  # noqa: N802 (http.server's name)
        if self.path in ("/", "/index.html"):
            self._send(200, page_html(self.session).encode(), "text/html; charset=utf-8")
        elif self.path == "/api/state":
            self._json(200, self.session.state())
        else:
            self._json(404, {"error": f"no such page: {self.path[:80]}"})

    def do_POST(self):  # noqa: N802
        if self.path != "/api/update":
            self._json(404, {"error": f"no such endpoint: {self.path[:80]}"})
            return
        try:
            n = int(self.headers.get("Content-Length", "0"))
            if not 0 < n <= _MAX_BODY:
                raise InputError("Content-Length", n, f"a JSON body of 1 to {_MAX_BODY} bytes")
            try:
                body = json.loads(self.rfile.read(n))
            except ValueError:
                raise InputError("request", "not JSON", "a JSON object") from None
            self._json(200, self.session.update(body))
        except InputError as e:
            self._json(400, {"error": str(e)})


def make_server(session: PlanSession, port: int = 0) -> ThreadingHTTPServer:
    """A server for ``session`` on ``127.0.0.1:port`` (0: any free port; ``server.server_address[1]``)."""
    handler = type("PlanHandler", (_Handler,), {"session": session})
    return ThreadingHTTPServer((HOST, int(port)), handler)


def session_from_files(site_path, layout_path=None, *, fusion: bool = True, progress: bool = True) -> PlanSession:
    """The session of a site and a layout file (without a layout: plan the site first, greedy)."""
    site = load_site(site_path)
    if layout_path is not None:
        cameras = read_layout(layout_path, site)
    else:
        cameras = layout_from_configs(site, plan(site, fusion=fusion, progress=progress).configs)
    return PlanSession(site, cameras, fusion=fusion)


def serve_plan(site_path, layout_path=None, *, port: int = 8765, fusion: bool = True) -> None:
    """Serve the interactive page until interrupted (Ctrl-C)."""
    session = session_from_files(site_path, layout_path, fusion=fusion)
    server = make_server(session, port)
    print(f"serving the interactive plan on http://{HOST}:{server.server_address[1]}/ (Ctrl-C to stop)", flush=True)
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        server.server_close()
