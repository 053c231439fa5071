"""The interactive planning page: one camera's height, pan and tilt on sliders, the map re-drawn by a small
local server (``footprint-uq plan --serve``).

The server is :class:`http.server.ThreadingHTTPServer` from the standard library, bound to
``127.0.0.1`` only (never another interface).  Routes:

* ``GET /``: the page (self-contained: inline CSS and script, the first map embedded);
* ``GET /api/state``: the layout and its evaluation (JSON);
* ``POST /api/update`` with ``{"camera": k, "height_m": h, "pan_deg": p, "tilt_deg": t}``: moves camera
  ``k`` and returns the new evaluation and map (a PNG data URI).  Bad input: status 400 and a one-line
  ``{"error": ...}``.

Safe on a laptop, where any web page the user visits can make the browser send requests to the loopback
interface:

* the ``Host`` header must name the address and port served (``127.0.0.1:PORT`` or ``localhost:PORT``):
  anything else -- a DNS-rebinding page, whose ``Host`` is its own name -- is answered 421;
* a POST must carry the session's token (:attr:`PlanSession.token`, random, embedded in the page and sent
  back in the ``X-FUQ-Token`` header) and ``Content-Type: application/json``, and an ``Origin`` header,
  when present, must be the page's own: a cross-origin page can neither read the token nor send the header
  without a CORS preflight, which the server never grants (403 otherwise);
* bodies are at most :data:`MAX_BODY_BYTES`, strict UTF-8 JSON nested at most :data:`MAX_JSON_DEPTH` deep;
  a malformed request (bad or missing ``Content-Length``, a body shorter than it says within
  :data:`READ_TIMEOUT_S`, deep nesting, bytes that are not UTF-8) is answered 400 with a one-line error;
* a client that goes away is quiet (no traceback), and a request whose client has gone by the time its
  map would be drawn costs no drawing (the move is applied; the map is drawn for the next request).

The page sets ``document.body.dataset.redraws`` (a counter) and ``dataset.lastRedrawMs`` after each
re-draw and fires a ``fuq-redrawn`` event: the browser test waits on them.
"""

from __future__ import annotations

import hmac
import json
import math
import secrets
import socket
import sys
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

__all__ = ["PlanSession", "make_server", "serve_plan", "HOST", "MAX_BODY_BYTES", "MAX_JSON_DEPTH", "READ_TIMEOUT_S",
           "TOKEN_HEADER", "json_depth"]

#: the only interface the server listens on
HOST = "127.0.0.1"
#: largest request body (bytes; an update is about 80)
MAX_BODY_BYTES = 4096
#: deepest nesting of arrays and objects in a request body (an update is one object: depth 1)
MAX_JSON_DEPTH = 4
#: a connection that sends nothing for this long (seconds) is answered 400 (a body shorter than it said) or closed
READ_TIMEOUT_S = 10.0
#: the header a POST carries the session's token in
TOKEN_HEADER = "X-FUQ-Token"


class PlanSession:
    """The state behind the page: the site, its samples and the current layout (thread-safe updates)."""

    def __init__(self, site, cameras: list[LayoutCamera], *, fusion: bool = True, dpi: int = 70):
        self.site, self.fusion, self.dpi = site, fusion, dpi
        self.samples = ground_samples(site)
        self.base = list(cameras)
        self.cameras = list(cameras)
        self.lock = threading.Lock()
        #: the per-session secret a POST must carry (embedded in the page, never in a URL)
        self.token = secrets.token_urlsafe(32)
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

    def update(self, body: dict, still_wanted=None) -> dict | None:
        """Move one camera (see the module docstring); returns the new state and map.

        ``still_wanted`` (a callable, optional) is asked before the map is drawn: False (the client has gone)
        returns None after the move, without drawing.
        """
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
            if still_wanted is not None and not still_wanted():
                return None
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
    var token = document.querySelector('meta[name="fuq-token"]').content;
    fetch('api/update', {method: 'POST', headers: {'Content-Type': 'application/json', 'X-FUQ-Token': token},
                         body: JSON.stringify(body)})
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
            f'<meta name="fuq-token" content="{esc(session.token)}">'
            f"<title>Site plan (interactive): {esc(session.site.name)}</title><style>{_PAGE_CSS}</style></head>"
            f"<body><h1>Site plan: {esc(session.site.name)}</h1>"
            f'<p>Weighted met area: <b id="fraction"></b> <span id="status"></span></p>'
            f'<div id="controls"><label for="camera">camera</label><select id="camera">{opts}</select><span></span>'
            f"{sliders}</div>"
            f'<img id="map" alt="fused semi-major map" src="{png_data_uri(session.map_png())}">'
            f'<table id="zones"></table>'
            f'<script type="application/json" id="initial-state">{state_json}</script>'
            f"<script>{_PAGE_JS}</script></body></html>\n")


def json_depth(text: str) -> int:
    """The deepest nesting of arrays and objects in JSON ``text`` (brackets inside strings not counted);
    linear, no recursion: checked before ``json.loads``, whose parser recurses once per level."""
    depth = deepest = 0
    in_str = esc_next = False
    for ch in text:
        if in_str:
            if esc_next:
                esc_next = False
            elif ch == "\\":
                esc_next = True
            elif ch == '"':
                in_str = False
        elif ch == '"':
            in_str = True
        elif ch in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif ch in "]}":
            depth -= 1
    return deepest


class _Refused(Exception):
    """A request refused with an HTTP status and a one-line message."""

    def __init__(self, code: int, message: str):
        super().__init__(message)
        self.code = code


class _Handler(BaseHTTPRequestHandler):
    session: PlanSession = None
    server_version = "footprint-uq-plan"
    timeout = READ_TIMEOUT_S  # socket timeout of every connection: a stalled client cannot hold a thread

    def log_message(self, fmt, *args):  # quiet: the CLI prints the URL, not every request
        return

    def _send(self, code: int, body: bytes, ctype: str):
        try:
            self.send_response(code)
            self.send_header("Content-Type", ctype)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.send_header("X-Content-Type-Options", "nosniff")
            self.send_header("X-Frame-Options", "DENY")  # no other page can frame the sliders
            self.end_headers()
            self.wfile.write(body)
        except OSError:  # the client went away: nothing to tell anyone
            self.close_connection = True

    def _json(self, code: int, data):
        if code >= 400:
            self.close_connection = True  # a refused request ends its connection
        self._send(code, json.dumps(data, allow_nan=False).encode(), "application/json")

    def _client_gone(self) -> bool:
        """True when the client has closed its side (or reset): what it asked for would be drawn for nobody."""
        sock = self.connection
        try:
            sock.setblocking(False)
            try:
                return sock.recv(1, socket.MSG_PEEK) == b""
            finally:
                sock.settimeout(self.timeout)
        except BlockingIOError:  # nothing to read and still open: the client waits for its answer
            return False
        except OSError:
            return True

    def _check_host(self) -> None:
        """421 unless ``Host`` names the address and port served (a DNS-rebinding page sends its own name)."""
        port = self.server.server_address[1]
        host = (self.headers.get("Host") or "").strip().lower()
        allowed = {f"{HOST}:{port}", f"localhost:{port}"} | ({HOST, "localhost"} if port == 80 else set())
        if host not in allowed:
            raise _Refused(421, f"Host {host[:80]!r} is not this server (http://{HOST}:{port}/)")

    def _check_post(self) -> None:
        """403 unless the request comes from the page: the session's token and, if sent, the page's Origin."""
        port = self.server.server_address[1]
        origin = self.headers.get("Origin")
        if origin is not None and origin.lower() not in (f"http://{HOST}:{port}", f"http://localhost:{port}"):
            raise _Refused(403, f"Origin {origin[:80]!r} is not this page's")
        token = self.headers.get(TOKEN_HEADER) or ""
        if not hmac.compare_digest(token.encode("utf-8", "replace"), self.session.token.encode()):
            raise _Refused(403, f"missing or wrong {TOKEN_HEADER} (send requests from the page)")
        ctype = (self.headers.get("Content-Type") or "").split(";")[0].strip().lower()
        if ctype != "application/json":
            raise _Refused(400, f"Content-Type {ctype[:60]!r}; expected application/json")

    def _read_body(self) -> dict:
        """The request's JSON body: bounded, complete, strict UTF-8, not deeper than MAX_JSON_DEPTH; else 400."""
        text = self.headers.get("Content-Length")
        try:
            n = int(text) if text is not None and text.strip().isdigit() else -1
        except ValueError:
            n = -1
        if not 0 < n <= MAX_BODY_BYTES:
            self.close_connection = True  # the rest of the stream cannot be framed
            shown = "missing" if text is None else repr(text[:40])
            raise _Refused(400, f"Content-Length {shown}; expected 1 to {MAX_BODY_BYTES} bytes")
        parts, got = [], 0
        try:
            while got < n:  # a client that stops sending: the socket's timeout ends the wait
                part = self.rfile.read1(n - got)
                if not part:
                    break
                parts.append(part)
                got += len(part)
        except OSError:
            pass
        if got != n:
            self.close_connection = True
            raise _Refused(400, f"body of {got} bytes; Content-Length said {n}")
        try:
            body = b"".join(parts).decode("utf-8")
        except UnicodeDecodeError:
            raise _Refused(400, "request: the body is not UTF-8; expected a JSON object") from None
        if json_depth(body) > MAX_JSON_DEPTH:
            raise _Refused(400, f"request: JSON nested deeper than {MAX_JSON_DEPTH}; expected a JSON object")
        try:
            return json.loads(body)
        except (ValueError, RecursionError):
            raise _Refused(400, "request: not JSON; expected a JSON object") from None

    def do_GET(self):  # noqa: N802 (http.server's name)
        try:
            self._check_host()
        except _Refused as e:
            self._json(e.code, {"error": str(e)})
            return
        if self.path in ("/", "/index.html"):
            if not self._client_gone():  # the page embeds a drawn map: not for a client that has gone
                self._send(200, page_html(self.session).encode(), "text/html; charset=utf-8")
        elif self.path == "/api/state":
            self._json(200, self.session.state())
        else:
            self._json(404, {"error": f"no such page: {self.path[:80]}"})

    def do_POST(self):  # noqa: N802
        try:
            self._check_host()
            if self.path != "/api/update":
                raise _Refused(404, f"no such endpoint: {self.path[:80]}")
            self._check_post()
            body = self._read_body()
            res = self.session.update(body, still_wanted=lambda: not self._client_gone())
            if res is not None:
                self._json(200, res)
        except _Refused as e:
            self._json(e.code, {"error": str(e)})
        except InputError as e:
            self._json(400, {"error": str(e)})


class _Server(ThreadingHTTPServer):
    daemon_threads = True

    def handle_error(self, request, client_address):
        """Quiet for a client that went away or stalled; one line (never a traceback) for anything else."""
        exc = sys.exc_info()[1]
        if isinstance(exc, OSError):  # resets, broken pipes, timeouts
            return
        print(f"footprint-uq plan --serve: request failed: {type(exc).__name__}: {exc}"[:300], file=sys.stderr,
              flush=True)


def make_server(session: PlanSession, port: int = 0) -> ThreadingHTTPServer:
    """A server for ``session`` on ``127.0.0.1:port`` (0: any free port; ``server.server_address[1]``)."""
    handler = type("PlanHandler", (_Handler,), {"session": session})
    return _Server((HOST, int(port)), handler)


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
