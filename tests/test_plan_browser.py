"""The planner's pages in headless Chromium: the report (no horizontal overflow, every figure loaded) and the
interactive page of ``plan --serve`` (loads, a slider move re-draws the map, no console errors).

The report is checked with the probe of tests/browser_probe.py (a checking script in a copy, ``--dump-dom``).
The interactive page needs a live server, so it is driven through the Chrome DevTools protocol with the
small standard-library WebSocket client below (RFC 6455 text frames, client-masked).  Stated time for a
re-draw: within 20 s (a liveness bound for a loaded 2-core VM; a re-draw takes well under a second on a
quiet one -- the page reports its own time in ``data-last-redraw-ms``).
"""

from __future__ import annotations

import base64
import json
import os
import re
import socket
import struct
import subprocess
import threading
import time
import urllib.error
import urllib.request

import pytest
import yaml
from click.testing import CliRunner

from browser_probe import CHROMIUM, FLAGS, assert_leads_with_figure_and_verdict, keep_screenshot, need_chromium, probe
from footprint_uq.cli.main import main
from footprint_uq.planning.layout import read_layout
from footprint_uq.planning.site import load_site
from footprint_uq.viz.plan_server import HOST, PlanSession, make_server
from test_planning import small_site_dict

pytestmark = pytest.mark.browser
REDRAW_LIMIT_S = 20.0

@pytest.fixture(scope="module")
def planned(tmp_path_factory):
    d = tmp_path_factory.mktemp("plan")
    site = d / "site.yaml"
    site.write_text(yaml.safe_dump(small_site_dict()))
    out = d / "out"
    r = CliRunner().invoke(main, ["plan", "--site", str(site), "--out", str(out), "--no-progress",
                                  "--max-refine-evals", "5", "--no-sensitivity"])
    assert r.exit_code == 0, r.output
    return site, out


@pytest.mark.parametrize("width", [1200, 700])
def test_report_has_no_horizontal_overflow_and_every_figure_loads(planned, tmp_path, width):
    need_chromium()
    html = (planned[1] / "report.html").read_text(encoding="utf-8")
    res = probe(html, tmp_path, width=width)
    assert res["errors"] == []
    assert res["scroll_w"] <= res["view_w"], res
    assert len(res["imgs"]) == html.count("<img") >= 4
    for img in res["imgs"]:
        assert img["complete"] and img["w"] > 100 and 100 < img["shown_w"] <= res["view_w"], img
    assert_leads_with_figure_and_verdict(res)  # the met-area map and the verdict first, tables after
    assert "meets the accuracy requirement on" in res["lead"]["verdict"]
    if width == 1200:
        keep_screenshot(planned[1] / "report.html", "report_plan", tmp_path)


# -- a minimal DevTools-protocol client -------------------------------------------------------------------------
class _WebSocket:
    def __init__(self, url: str, timeout: float = 60.0):
        m = re.match(r"ws://([^/:]+):(\d+)(/.*)", url)
        self.sock = socket.create_connection((m.group(1), int(m.group(2))), timeout=timeout)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall((f"GET {m.group(3)} HTTP/1.1\r\nHost: {m.group(1)}:{m.group(2)}\r\nUpgrade: websocket\r\n"
                           f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n")
                          .encode())
        head = b""
        while b"\r\n\r\n" not in head:
            head += self.sock.recv(1)
        assert b" 101 " in head.split(b"\r\n")[0], head

    def _recv_exact(self, n: int) -> bytes:
        buf = b""
        while len(buf) < n:
            chunk = self.sock.recv(n - len(buf))
            if not chunk:
                raise ConnectionError("websocket closed")
            buf += chunk
        return buf

    def send(self, text: str):
        data = text.encode()
        mask = os.urandom(4)
        n = len(data)
        head = bytes([0x81]) + (bytes([0x80 | n]) if n < 126 else bytes([0x80 | 126]) + struct.pack(">H", n)
                                if n < 65536 else bytes([0x80 | 127]) + struct.pack(">Q", n))
        self.sock.sendall(head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(data)))

    def recv(self) -> str:
        parts = []
        while True:
            b0, b1 = self._recv_exact(2)
            n = b1 & 0x7F
            if n == 126:
                n = struct.unpack(">H", self._recv_exact(2))[0]
            elif n == 127:
                n = struct.unpack(">Q", self._recv_exact(8))[0]
            payload = self._recv_exact(n)
            if b0 & 0x0F in (0x9, 0xA):  # ping / pong: ignore
                continue
            parts.append(payload)
            if b0 & 0x80:
                return b"".join(parts).decode()


class _DevTools:
    def __init__(self, ws: _WebSocket):
        self.ws, self.next_id, self.events = ws, 0, []

    def call(self, method: str, **params):
        self.next_id += 1
        self.ws.send(json.dumps({"id": self.next_id, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv())
            if msg.get("id") == self.next_id:
                assert "error" not in msg, msg
                return msg.get("result", {})
            self.events.append(msg)

    def wait_event(self, method: str, timeout: float = 60.0):
        t0 = time.monotonic()
        while time.monotonic() - t0 < timeout:
            for e in self.events:
                if e.get("method") == method:
                    return e
            self.events.append(json.loads(self.ws.recv()))
        raise TimeoutError(method)


@pytest.fixture
def browser(tmp_path):
    need_chromium()
    profile = tmp_path / "profile"
    flags = [f for f in FLAGS if f != "--allow-file-access-from-files"]
    proc = subprocess.Popen([CHROMIUM, *flags, f"--user-data-dir={profile}", "--remote-debugging-port=0",
                             "--window-size=1200,900", "about:blank"], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, env={**os.environ, "HOME": str(tmp_path)})
    try:
        port_file = profile / "DevToolsActivePort"
        t0 = time.monotonic()
        while not (port_file.exists() and port_file.read_text().strip()) and time.monotonic() - t0 < 60:
            time.sleep(0.1)
        port = int(port_file.read_text().splitlines()[0])
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=30) as r:
            page = next(t for t in json.load(r) if t["type"] == "page")
        yield _DevTools(_WebSocket(page["webSocketDebuggerUrl"]))
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()


@pytest.fixture
def served(planned):
    site = load_site(planned[0])
    session = PlanSession(site, read_layout(planned[1] / "layout.yaml", site))
    server = make_server(session, 0)
    th = threading.Thread(target=server.serve_forever, daemon=True)
    th.start()
    yield f"http://{HOST}:{server.server_address[1]}/", session
    server.shutdown()
    server.server_close()


MOVE = """new Promise(function (resolve) {
  var s = document.getElementById('tilt_deg'), t0 = performance.now(), before = document.getElementById('map').src;
  document.addEventListener('fuq-redrawn', function () {
    var de = document.documentElement;
    resolve({ms: performance.now() - t0, redraws: document.body.dataset.redraws,
             changed: document.getElementById('map').src !== before, tilt: Number(s.value),
             scroll_w: de.scrollWidth, client_w: de.clientWidth});
  }, {once: true});
  s.value = String(Number(s.value) + 6);
  s.dispatchEvent(new Event('input', {bubbles: true}));
})"""


def test_interactive_page_redraws_on_a_slider_move(browser, served):
    url, session = served
    before = session.cameras[0].camera.tilt_deg
    browser.call("Runtime.enable")
    browser.call("Log.enable")
    browser.call("Page.enable")
    browser.call("Page.navigate", url=url)
    browser.wait_event("Page.loadEventFired")
    loaded = browser.call("Runtime.evaluate", returnByValue=True, expression=(
        "({n: document.images.length, w: document.getElementById('map').naturalWidth, "
        "fraction: document.getElementById('fraction').textContent})"))["result"]["value"]
    assert loaded["n"] == 1 and loaded["w"] > 100 and loaded["fraction"].endswith("%")
    res = browser.call("Runtime.evaluate", expression=MOVE, awaitPromise=True, returnByValue=True,
                       timeout=int(REDRAW_LIMIT_S * 1000))["result"]["value"]
    assert res["changed"] and res["redraws"] == "1", res
    assert res["ms"] < REDRAW_LIMIT_S * 1000, res
    assert res["scroll_w"] <= res["client_w"], res
    assert session.cameras[0].camera.tilt_deg == pytest.approx(res["tilt"]) != pytest.approx(before)
    bad = [e for e in browser.events if e.get("method") == "Runtime.exceptionThrown"
           or (e.get("method") == "Runtime.consoleAPICalled" and e["params"]["type"] in ("error", "assert"))
           or (e.get("method") == "Log.entryAdded" and e["params"]["entry"]["level"] == "error")]
    assert bad == []


def _post(url, body: bytes, token: str):
    req = urllib.request.Request(url + "api/update", data=body,
                                 headers={"Content-Type": "application/json", "X-FUQ-Token": token})
    try:
        with urllib.request.urlopen(req, timeout=60) as r:
            return r.status, json.load(r)
    except urllib.error.HTTPError as e:
        return e.code, json.load(e)


def test_server_is_loopback_only_and_rejects_bad_input(served):
    url, session = served
    assert url.startswith("http://127.0.0.1:")
    for body, field in ((b"not json", "request"), (json.dumps({"camera": 9}).encode(), "camera"),
                        (json.dumps({"camera": 0, "height_m": 8, "pan_deg": 0, "tilt_deg": 95}).encode(),
                         "tilt_deg")):
        code, res = _post(url, body, session.token)
        assert code == 400 and res["error"].startswith(field), res
    code, res = _post(url, json.dumps({"camera": 0, "height_m": 7.0, "pan_deg": 10.0, "tilt_deg": 30.0}).encode(),
                      session.token)
    assert _post(url, b"{}", "not-the-token")[0] == 403  # tests/test_plan_server.py: the hostile cases
    assert code == 200 and res["png"].startswith("data:image/png;base64,") and 0 <= res["fraction_met"] <= 1
    with urllib.request.urlopen(url + "api/state", timeout=30) as r:
        assert json.load(r)["cameras"][0]["tilt_deg"] == pytest.approx(30.0)
