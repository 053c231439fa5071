"""The planner's page (``plan --serve``) against hostile requests, over raw sockets (issue 35, part 4):
DNS rebinding (a foreign ``Host``), cross-origin and token-less POSTs, malformed bodies (bad or missing
``Content-Length``, truncated, deeply nested, not UTF-8), clients that go away -- each answered with its
status and a one-line error, never a traceback, never a drawing for nobody.  The browser side (the page's
own requests still work) is ``tests/test_plan_browser.py``."""

from __future__ import annotations

import contextlib
import json
import socket
import threading
import time

import pytest

from footprint_uq.planning.coverage import CameraConfig
from footprint_uq.planning.layout import layout_from_configs
from footprint_uq.planning.site import site_from_dict
from footprint_uq.viz import plan_server as S
from test_planning import small_site_dict


@pytest.fixture(scope="module")
def session():
    site = site_from_dict(small_site_dict())
    cams = layout_from_configs(site, [CameraConfig("a", "hd", "n", 7.0, 120.0, 30.0)])
    return S.PlanSession(site, cams, dpi=30)


@pytest.fixture
def served(session, monkeypatch, capsys):
    """(port, session, drawings, stderr): the server in a thread; ``drawings`` counts the maps drawn,
    ``stderr()`` is what the process printed on stderr so far (tracebacks of the server's threads included)."""
    drawings = []
    real = S.PlanSession.map_png

    def counted(self):
        drawings.append(time.monotonic())
        return real(self)

    monkeypatch.setattr(S.PlanSession, "map_png", counted)
    monkeypatch.setattr(S, "READ_TIMEOUT_S", 1.0)
    monkeypatch.setattr(S._Handler, "timeout", 1.0)
    server = S.make_server(session, 0)
    th = threading.Thread(target=server.serve_forever, daemon=True)
    th.start()
    try:
        yield server.server_address[1], session, drawings, lambda: capsys.readouterr().err
    finally:
        server.shutdown()
        server.server_close()


def _raw(port, data: bytes, *, close_write=True, timeout=10.0) -> tuple[int | None, dict | str]:
    """Send ``data`` on a fresh connection; (status, JSON body or text) of the answer (None: no answer)."""
    with socket.create_connection(("127.0.0.1", port), timeout=timeout) as s:
        s.sendall(data)
        if close_write:
            s.shutdown(socket.SHUT_WR)
        chunks = []
        with contextlib.suppress(OSError):
            while chunk := s.recv(65536):
                chunks.append(chunk)
    text = b"".join(chunks)
    if not text:
        return None, ""
    head, _, body = text.partition(b"\r\n\r\n")
    code = int(head.split()[1])
    try:
        return code, json.loads(body)
    except ValueError:
        return code, body.decode("utf-8", "replace")


def _post(port, body: bytes, *, host=None, token=None, origin=None, ctype="application/json", length=None,
          session=None, extra=b""):
    hdr = [b"POST /api/update HTTP/1.1", b"Host: " + (f"127.0.0.1:{port}" if host is None else host).encode(),
           b"Connection: close",
           b"Content-Type: " + ctype.encode(),
           b"Content-Length: " + (str(len(body)) if length is None else length).encode()]
    if token is not False:
        hdr.append(S.TOKEN_HEADER.encode() + b": " + (token or session.token).encode())
    if origin is not None:
        hdr.append(b"Origin: " + origin.encode())
    return b"\r\n".join(hdr) + b"\r\n" + extra + b"\r\n" + body


GOOD = json.dumps({"camera": 0, "height_m": 7.5, "pan_deg": 110.0, "tilt_deg": 32.0}).encode()


def test_the_page_carries_its_token_and_its_own_requests_work(served):
    port, session, drawings, err = served
    code, page = _raw(port, f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nConnection: close\r\n\r\n".encode(),
                      close_write=False)
    assert code == 200 and f'<meta name="fuq-token" content="{session.token}">' in page
    assert "'X-FUQ-Token': token" in page and len(session.token) >= 40
    code, res = _raw(port, _post(port, GOOD, session=session, origin=f"http://127.0.0.1:{port}"), close_write=False)
    assert code == 200 and res["png"].startswith("data:image/png;base64,"), res
    code, res = _raw(port, _post(port, GOOD, session=session, host=f"localhost:{port}"), close_write=False)
    assert code == 200, res
    assert err() == ""


@pytest.mark.parametrize("host", ["evil.example:{port}", "127.0.0.1.nip.io:{port}", "127.0.0.1:1", "localhost",
                                  "127.0.0.1", "", "[::1]:{port}"])
def test_dns_rebinding_a_foreign_host_is_refused(served, host):
    port, session, drawings, err = served
    host = host.format(port=port)
    for req in (f"GET / HTTP/1.1\r\nHost: {host}\r\n\r\n".encode(),
                f"GET /api/state HTTP/1.1\r\nHost: {host}\r\n\r\n".encode(),
                _post(port, GOOD, host=host, session=session)):
        code, res = _raw(port, req, close_write=False)
        assert code == 421 and "is not this server" in res["error"], (host, code, res)
    assert _raw(port, b"GET /api/state HTTP/1.0\r\n\r\n", close_write=False)[0] == 421  # no Host at all
    assert drawings == [] and err() == ""


def test_cross_origin_and_token_less_posts_are_refused(served):
    port, session, drawings, err = served
    before = session.cameras[0].camera.tilt_deg
    for kw in ({"token": False}, {"token": "x" * 43}, {"token": session.token[:-1]},
               {"origin": "http://evil.example"}, {"origin": f"http://evil.example:{port}"},
               {"origin": "null"}, {"ctype": "text/plain"}, {"ctype": "application/x-www-form-urlencoded"}):
        code, res = _raw(port, _post(port, GOOD, session=session, **kw), close_write=False)
        assert code in (400, 403) and "\n" not in res["error"], (kw, code, res)
        assert code == (400 if "ctype" in kw else 403), kw
    assert session.cameras[0].camera.tilt_deg == before and drawings == []
    assert err() == ""


@pytest.mark.parametrize("body,length,what", [
    (GOOD, "abc", "Content-Length"), (GOOD, "-5", "Content-Length"), (GOOD, "0", "Content-Length"),
    (GOOD, "99999999999999999999", "Content-Length"), (GOOD, "1e3", "Content-Length"),
    (b"x" * (S.MAX_BODY_BYTES + 1), None, "Content-Length"),
    (GOOD[:20], str(len(GOOD)), "body of 20 bytes"),            # truncated, the client half-closes
    (b"[" * 3000 + b"]" * 3000, "6000", "Content-Length"),
    (b"[" * 1000 + b"]" * 1000, None, "nested deeper"),
    (b'{"camera": [[[[[0]]]]]}', None, "nested deeper"),
    (b'{"camera": "\xff\xfe"}', None, "not UTF-8"),
    (b"\xef\xbb\xbf{}", None, "not JSON"),                       # a BOM
    (b'{"camera": 0, "height_m": NaN}', None, "height_m"),
    (b"[1, 2]", None, "request"),
])
def test_malformed_requests_are_400_with_one_line_and_no_traceback(served, body, length, what):
    port, session, drawings, err = served
    code, res = _raw(port, _post(port, body, session=session, length=length))
    assert code == 400 and what in res["error"] and "\n" not in res["error"], (code, res)
    assert drawings == [] and err() == ""


def test_missing_content_length_and_a_stalled_body(served):
    port, session, drawings, err = served
    req = _post(port, GOOD, session=session).replace(f"Content-Length: {len(GOOD)}\r\n".encode(), b"")
    code, res = _raw(port, req)
    assert code == 400 and "Content-Length missing" in res["error"], res
    t0 = time.monotonic()  # 20 bytes of 80 and the connection held open: the read timeout answers
    code, res = _raw(port, _post(port, GOOD[:20], session=session, length=str(len(GOOD))), close_write=False)
    assert code == 400 and "body of 20 bytes" in res["error"] and time.monotonic() - t0 < 8, res
    assert drawings == [] and err() == ""


def test_clients_that_go_away_are_quiet_and_cost_no_drawing(served, monkeypatch):
    port, session, drawings, err = served
    slow_host, slow_eval = S._Handler._check_host, S.evaluate_cameras

    def later(f):  # the server is slower than the client's close, however the threads are scheduled
        def w(*a, **kw):
            time.sleep(0.3)
            return f(*a, **kw)
        return w

    monkeypatch.setattr(S._Handler, "_check_host", later(slow_host))
    monkeypatch.setattr(S, "evaluate_cameras", later(slow_eval))
    # the whole request, then gone: the move is applied, no map is drawn for nobody
    for _ in range(3):
        with socket.create_connection(("127.0.0.1", port)) as s:
            s.sendall(_post(port, GOOD, session=session))
    with socket.create_connection(("127.0.0.1", port)) as s:  # the page asked for and left at once
        s.sendall(f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n\r\n".encode())
    with socket.create_connection(("127.0.0.1", port)) as s:  # reset in the middle of the headers
        s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, b"\x01\x00\x00\x00\x00\x00\x00\x00")
        s.sendall(b"POST /api/update HTTP/1.1\r\nHost: 127.0.0.1:")
    with socket.create_connection(("127.0.0.1", port)) as s:  # connects and says nothing
        pass
    for path in ("/api/state", "/nowhere"):  # the whole request, then a reset: the answer meets a closed socket
        with socket.create_connection(("127.0.0.1", port)) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, b"\x01\x00\x00\x00\x00\x00\x00\x00")
            s.sendall(f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n\r\n".encode())
    time.sleep(3.0)  # every handler done (the read timeout is 1 s here)
    assert drawings == [] and err() == ""
    code, res = _raw(port, _post(port, GOOD, session=session), close_write=False)
    assert code == 200 and len(drawings) == 1 and session.cameras[0].camera.tilt_deg == pytest.approx(32.0)


def test_json_depth_counts_brackets_outside_strings():
    assert S.json_depth('{"a": [1, {"b": "[[[[{{{{"}]}') == 3
    assert S.json_depth('"\\"[[["') == 0 and S.json_depth("[]") == 1 and S.json_depth("1") == 0
    assert S.json_depth("[" * 50_000) == 50_000  # no recursion
