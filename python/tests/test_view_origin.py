"""Who may open ``palpate view``'s page and WebSocket (issue 35, item 2; palpate/viewer/origin.py).

The issue's attack: the viewer, bound to 127.0.0.1, took a WebSocket with ``Origin:
http://evil.example`` that moved the hand (0.18 N, 14 mm), and served its page to a foreign
``Host`` (DNS rebinding). Each test below makes one such attack and checks that it is refused with
403 before viser sees it and that the tool did not move; and that what must work still does (the
viewer's own page, a tunnel, the token).

What a wrong implementation would do:
- check the page but not the WebSocket upgrade, or the Host but not the Origin: the foreign
  Origin's gizmo messages move the hand (``test_websocket_from_another_origin_*``, the browser
  test); a control in the same tests sends the same messages from the viewer's own origin and
  with the token, and they do move it, so the refusal is what stopped the attack;
- take any token, or the cookie from any origin (``test_token_*``, ``test_require_token_*``);
- serve anything before the check is in place, or serve unchecked when viser changes
  (``test_viser_hook_*``);
- a command that prints no token where one is required (``test_cli_*``).
"""
from __future__ import annotations

import http.client
import http.server
import inspect
import os
import re
import socket
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request

import numpy as np
import pytest

import palpate
from palpate import _palpate as _p
from palpate.viewer import origin
from palpate.viewer.origin import (BAD_HOST, BAD_ORIGIN, FOREIGN_HOST, NO_TOKEN, WRONG_TOKEN, RequestPolicy,
                                   cookie_name, policy_for)

viser = pytest.importorskip("viser", reason="the view extra (viser) is not installed: pip install 'palpate[view]'")
from websockets.datastructures import Headers  # noqa: E402 - websockets comes with viser

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SUBPROTOCOL = f"viser-v{viser.__version__}"


@pytest.fixture(scope="module")
def model():
    return palpate.hybrid.build_shape("ventricle")


def wait_for(pred, timeout=20.0, every=0.05):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if pred():
            return True
        time.sleep(every)
    return False


# ------------------------------------------------------------------------------- the decision alone

TOKEN = "s3cret-token_0123456789"


def decide(policy, path="/", port=8080, **headers):
    h = Headers([(k.replace("_", "-"), v) for k, vs in headers.items() for v in (vs if isinstance(vs, list) else [vs])])
    return policy.decide(path, h, port)


@pytest.mark.parametrize("path, headers, reason", [
    # The viewer's own pages, under each loopback name, and through a tunnel on another port.
    ("/", {"Host": "127.0.0.1:8080"}, None),
    ("/", {"Host": "localhost:8080", "Origin": "http://localhost:8080"}, None),
    ("/", {"Host": "[::1]:8080", "Origin": "http://[::1]:8080"}, None),
    ("/", {"Host": "LOCALHOST:8080", "Origin": "http://localhost:8080"}, None),
    ("/", {"Host": "127.0.0.2:8080"}, None),
    ("/", {"Host": "localhost:9000", "Origin": "http://localhost:9000"}, None),     # ssh -L 9000:...:8080
    # DNS rebinding: a foreign name resolved to 127.0.0.1, same-origin with itself.
    ("/", {"Host": "evil.example:8080"}, FOREIGN_HOST),
    ("/", {"Host": "evil.example:8080", "Origin": "http://evil.example:8080"}, FOREIGN_HOST),
    ("/", {"Host": "localhost.evil.example:8080"}, FOREIGN_HOST),
    ("/", {"Host": "0.0.0.0:8080"}, FOREIGN_HOST),
    # A foreign page's WebSocket: the Host is the viewer's, the Origin says who asks.
    ("/", {"Host": "127.0.0.1:8080", "Origin": "http://evil.example"}, BAD_ORIGIN),
    ("/", {"Host": "127.0.0.1:8080", "Origin": "http://127.0.0.1:9999"}, BAD_ORIGIN),   # another local server
    ("/", {"Host": "127.0.0.1:8080", "Origin": "http://localhost:8080"}, BAD_ORIGIN),   # not the page's own
    ("/", {"Host": "127.0.0.1:8080", "Origin": "null"}, BAD_ORIGIN),                     # a sandboxed frame, file:
    ("/", {"Host": "127.0.0.1:8080", "Origin": "file://"}, BAD_ORIGIN),
    ("/", {"Host": "127.0.0.1:8080", "Origin": ["http://127.0.0.1:8080", "http://evil.example"]}, BAD_ORIGIN),
    # Malformed or duplicated Hosts.
    ("/", {}, BAD_HOST),
    ("/", {"Host": ["127.0.0.1:8080", "evil.example"]}, BAD_HOST),
    ("/", {"Host": "127.0.0.1:8080@evil.example"}, BAD_HOST),
    ("/", {"Host": "127.0.0.1:port"}, BAD_HOST),
    ("/", {"Host": ""}, BAD_HOST),
    # The token in the URL admits from anywhere; a wrong one is refused whatever else is right.
    (f"/?token={TOKEN}", {"Host": "evil.example:8080", "Origin": "http://evil.example"}, None),
    ("/?token=guess", {"Host": "127.0.0.1:8080", "Origin": "http://127.0.0.1:8080"}, WRONG_TOKEN),
    ("/?token=", {"Host": "127.0.0.1:8080"}, WRONG_TOKEN),
    (f"/?token={TOKEN[:-1]}", {"Host": "evil.example"}, WRONG_TOKEN),
    # The cookie admits the page's own origin only (a browser sends it to every port of the host).
    ("/", {"Host": "192.168.1.2:8080", "Cookie": f"a=b; {cookie_name(8080)}={TOKEN}"}, None),
    ("/", {"Host": "192.168.1.2:8080", "Origin": "http://192.168.1.2:8080", "Cookie": f"{cookie_name(8080)}={TOKEN}"},
     None),
    ("/", {"Host": "localhost:8080", "Origin": "http://localhost:9000", "Cookie": f"{cookie_name(8080)}={TOKEN}"},
     BAD_ORIGIN),
    # Another viewer's cookie (another port), or a stale one, is no token.
    ("/", {"Host": "192.168.1.2:8080", "Cookie": f"{cookie_name(8081)}={TOKEN}"}, FOREIGN_HOST),
    ("/", {"Host": "127.0.0.1:8080", "Origin": "http://evil.example", "Cookie": f"{cookie_name(8080)}=stale"},
     BAD_ORIGIN),
])
def test_request_policy_decisions(path, headers, reason):
    d = decide(RequestPolicy(TOKEN), path, **headers)
    assert (d.reason or None) == reason and d.ok == (reason is None), d
    assert d.set_cookie == (d.ok and "token=" in path)


def test_require_token_refuses_even_the_loopback_origin():
    p = RequestPolicy(TOKEN, require_token=True)
    assert decide(p, Host="127.0.0.1:8080", Origin="http://127.0.0.1:8080").reason == NO_TOKEN
    assert decide(p, Host="127.0.0.1:8080").reason == NO_TOKEN
    assert decide(p, f"/?token={TOKEN}", Host="192.168.1.2:8080").ok
    assert decide(p, Host="192.168.1.2:8080", Origin="http://192.168.1.2:8080",
                  Cookie=f"{cookie_name(8080)}={TOKEN}").ok


def test_policy_for_requires_the_token_beyond_loopback():
    for host in ("127.0.0.1", "::1", "localhost"):
        p = policy_for(host)
        assert not p.require_token and not p.show_token
    for host in ("0.0.0.0", "::", "192.168.1.2"):
        p = policy_for(host)
        assert p.require_token and p.show_token, host
    # Random, URL-safe and long; per viewer.
    a, b = policy_for("127.0.0.1").token, policy_for("127.0.0.1").token
    assert a != b and re.fullmatch(r"[A-Za-z0-9_-]{32}", a)
    # A token of the user's: shown in the URL, required only when asked or beyond loopback.
    p = policy_for("127.0.0.1", token=TOKEN)
    assert p.token == TOKEN and p.show_token and not p.require_token
    assert policy_for("127.0.0.1", require_token=True).require_token
    for bad in ("short", "has space in it", "x" * 257, "tok&en=12345", ""):
        with pytest.raises(ValueError):
            policy_for("127.0.0.1", token=bad)


# ------------------------------------------------------------------------------- a running viewer

def http_get(port, path="/", host=None, **headers):
    """``(status, body, headers)`` of a GET with exactly the Host given (default the viewer's)."""
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=15)
    try:
        c.putrequest("GET", path, skip_host=True, skip_accept_encoding=True)
        c.putheader("Host", host if host is not None else f"127.0.0.1:{port}")
        for k, v in headers.items():
            c.putheader(k.replace("_", "-"), v)
        c.endheaders()
        r = c.getresponse()
        return r.status, r.read(), r
    finally:
        c.close()


def raw_upgrade(port, path="/", host=None, origin=None, cookie=None, then=b""):
    """A WebSocket upgrade written by hand (any Host, any Origin), followed at once by ``then``
    (frames a client could pipeline behind its handshake); returns the status code and the body."""
    lines = [f"GET {path} HTTP/1.1", f"Host: {host or f'127.0.0.1:{port}'}", "Upgrade: websocket",
             "Connection: Upgrade", "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==", "Sec-WebSocket-Version: 13",
             f"Sec-WebSocket-Protocol: {SUBPROTOCOL}"]
    if origin is not None:
        lines.append(f"Origin: {origin}")
    if cookie is not None:
        lines.append(f"Cookie: {cookie}")
    with socket.create_connection(("127.0.0.1", port), timeout=15) as s:
        s.sendall(("\r\n".join(lines) + "\r\n\r\n").encode() + then)
        data = b""
        while b"\r\n\r\n" not in data:
            chunk = s.recv(65536)
            if not chunk:
                break
            data += chunk
    status = int(data.split(b" ", 2)[1]) if data.startswith(b"HTTP/1.1 ") else None
    return status, data


def gizmo_message(v, target_m):
    """What viser's page sends when the hand's gizmo is dragged to ``target_m`` [m]: the message
    the issue's attack sent (a TransformControlsUpdateMessage for ``/hand``, msgpack)."""
    import msgspec
    from viser import _messages

    msg = _messages.TransformControlsUpdateMessage(name="/hand", wxyz=(1.0, 0.0, 0.0, 0.0),
                                                   position=tuple(float(x) for x in np.asarray(target_m) * 1e3))
    return msgspec.msgpack.encode(msg.as_serializable_dict())


def masked_frame(payload):
    from websockets.frames import OP_BINARY, Frame

    return Frame(OP_BINARY, payload).serialize(mask=True)


def ws_connect(v, origin=None, path="/", cookie=None):
    from websockets.sync.client import connect

    headers = {}
    if origin is not None:
        headers["Origin"] = origin
    if cookie is not None:
        headers["Cookie"] = cookie
    return connect(f"ws://127.0.0.1:{v.port}{path}", subprotocols=[SUBPROTOCOL], additional_headers=headers,
                   open_timeout=15, max_size=None)


@pytest.fixture(scope="module")
def viewer(model):
    from palpate.viewer import Viewer

    v = Viewer(model, "ventricle", port=0, fps=10)
    assert v.wait_ready(60), v.loop_error
    yield v
    v.close()


def refused(v, reason):
    return v.status()["requests"]["refused"].get(reason, 0)


def test_page_is_refused_to_a_foreign_host(viewer):
    """DNS rebinding: the page asked for under a foreign name (or a malformed Host) is 403 and
    says why; under each loopback name it is served, with the anti-framing headers."""
    v = viewer
    assert v.url == f"http://127.0.0.1:{v.port}/"          # loopback: no token needed, none shown
    for host, reason in ((f"evil.example:{v.port}", FOREIGN_HOST), ("evil.example", FOREIGN_HOST),
                         (f"0.0.0.0:{v.port}", FOREIGN_HOST), ("bad host", BAD_HOST)):
        n = refused(v, reason)
        status, body, _ = http_get(v.port, host=host)
        assert status == 403 and body == f"palpate view: {reason}\n".encode(), (host, status, body[:80])
        assert refused(v, reason) == n + 1
    for host in (f"127.0.0.1:{v.port}", f"localhost:{v.port}", f"[::1]:{v.port}"):
        status, body, r = http_get(v.port, host=host)
        assert status == 200 and b"<html" in body.lower(), host
        assert r.getheader("Content-Security-Policy") == "frame-ancestors 'self'"
        assert r.getheader("Set-Cookie") is None              # no token asked for, no cookie given
    # A rebinding page's WebSocket (Host and Origin both the foreign name) is refused too.
    status, _ = raw_upgrade(v.port, host=f"evil.example:{v.port}", origin=f"http://evil.example:{v.port}")
    assert status == 403


def test_websocket_from_another_origin_cannot_move_the_tool(model):
    """The issue's attack: gizmo messages over a WebSocket from ``http://evil.example`` (and from
    another local port, and with a wrong token). Each upgrade is 403, frames sent behind it do
    nothing, the hand's target and the loop's tool do not move, the force stays zero. Then the
    same messages from the viewer's own origin, and from evil.example with the token, do move it."""
    from palpate.viewer import Viewer

    v = Viewer(model, "ventricle", port=0, fps=10)
    try:
        assert v.wait_ready(60), v.loop_error
        time.sleep(0.5)
        home = v.target.copy()
        tool0 = np.asarray(v.loop.snapshot()["tool"], dtype=np.float64)
        attack = gizmo_message(v, v.press_target(0.006))
        frames = masked_frame(attack) * 20
        own = f"http://127.0.0.1:{v.port}"
        for origin_, path, reason in (("http://evil.example", "/", BAD_ORIGIN),
                                      ("http://127.0.0.1:1", "/", BAD_ORIGIN),
                                      (f"http://localhost:{v.port}", "/", BAD_ORIGIN),
                                      ("null", "/", BAD_ORIGIN),
                                      ("http://evil.example", "/?token=guessed-token-123", WRONG_TOKEN),
                                      (own, "/?token=guessed-token-123", WRONG_TOKEN)):
            n = refused(v, reason)
            status, data = raw_upgrade(v.port, path=path, origin=origin_, then=frames)
            assert status == 403, (origin_, data[:200])
            assert refused(v, reason) == n + 1
            # The same with websockets' client, as a program would.
            from websockets.exceptions import InvalidStatus

            with pytest.raises(InvalidStatus) as e:
                ws_connect(v, origin=origin_, path=path)
            assert e.value.response.status_code == 403
        time.sleep(1.0)                        # what a taken target would need to reach the loop
        s = v.status()
        assert s["requests"]["admitted"]["websocket"] == 0, s["requests"]
        assert s["gizmo_moves"] == 0 and s["inputs"]["accepted"] == 0, s
        np.testing.assert_array_equal(v.target, home)
        tool = np.asarray(v.loop.snapshot()["tool"], dtype=np.float64)
        assert np.linalg.norm(tool - tool0) < 1e-6, (tool, tool0)
        assert s["force_n"] == 0.0 and s["max_force_n"] == 0.0 and s["max_surface_mm"] < 1e-6, s

        # Control: the very same messages from the viewer's own page move the hand...
        with ws_connect(v, origin=own) as ws:
            for _ in range(10):
                ws.send(attack)
                time.sleep(0.05)
            assert wait_for(lambda: v.status()["force_n"] > 0.02, 20), v.status()
        assert v.status()["gizmo_moves"] >= 1
        # ... and from evil.example with the token (what the token is for).
        v.reset()
        assert wait_for(lambda: v.status()["force_n"] == 0.0, 20)
        moves = v.status()["gizmo_moves"]
        with ws_connect(v, origin="http://evil.example", path=f"/?token={v.token}") as ws:
            for _ in range(10):
                ws.send(attack)
                time.sleep(0.05)
            assert wait_for(lambda: v.status()["force_n"] > 0.02, 20), v.status()
        assert v.status()["gizmo_moves"] > moves
    finally:
        v.close()


def test_token_sets_a_cookie_that_admits_only_the_pages_own_origin(viewer):
    """A page loaded with ``?token=`` gets the cookie its WebSocket then carries; the cookie
    admits the page's own origin only, and a wrong token gets nothing."""
    v = viewer
    status, body, r = http_get(v.port, f"/?token={v.token}", host=f"myhost.example:{v.port}")
    assert status == 200 and b"<html" in body.lower()
    cookie = r.getheader("Set-Cookie")
    assert cookie == f"{cookie_name(v.port)}={v.token}; Path=/; HttpOnly; SameSite=Strict"
    assert r.getheader("Referrer-Policy") == "no-referrer"
    jar = cookie.split(";")[0]
    # The page under that name, and its WebSocket, with the cookie: admitted.
    assert http_get(v.port, host=f"myhost.example:{v.port}", Cookie=jar)[0] == 200
    with ws_connect(v, origin=f"http://127.0.0.1:{v.port}", cookie=jar):
        pass
    assert raw_upgrade(v.port, host=f"myhost.example:{v.port}", origin=f"http://myhost.example:{v.port}",
                       cookie=jar)[0] == 101
    # Another page of the same host (another port) gets the cookie from the browser: refused.
    assert raw_upgrade(v.port, host=f"myhost.example:{v.port}", origin="http://myhost.example:9999",
                       cookie=jar)[0] == 403
    # A wrong token: no page, no cookie.
    status, body, r = http_get(v.port, "/?token=not-the-token-0000")
    assert status == 403 and body == f"palpate view: {WRONG_TOKEN}\n".encode() and r.getheader("Set-Cookie") is None


def test_require_token_viewer_serves_nothing_without_it(model):
    from palpate.viewer import Viewer

    v = Viewer(model, "ventricle", port=0, fps=10, require_token=True, token=TOKEN)
    try:
        assert v.url == f"http://127.0.0.1:{v.port}/?token={TOKEN}" and v.token == TOKEN
        status, body, _ = http_get(v.port)
        assert status == 403 and body == f"palpate view: {NO_TOKEN}\n".encode()
        assert raw_upgrade(v.port, origin=f"http://127.0.0.1:{v.port}")[0] == 403
        status, _, r = http_get(v.port, f"/?token={TOKEN}")
        assert status == 200 and r.getheader("Set-Cookie").startswith(f"{cookie_name(v.port)}={TOKEN};")
        assert raw_upgrade(v.port, origin=f"http://127.0.0.1:{v.port}", cookie=f"{cookie_name(v.port)}={TOKEN}")[0] == 101
        assert v.status()["requests"]["refused"] == {NO_TOKEN: 2}
    finally:
        v.close()
    with pytest.raises(_p.ParameterError, match="token"):
        Viewer(model, port=0, token="short")


# ------------------------------------------------------------------------------- viser's internals

def test_viser_hook_is_in_place_for_this_viser():
    """The one reliance on viser's internals (origin.hook_viser_serve, written for viser 1.1.1):
    viser starts websockets' server from ``_infra`` with its page server as ``process_request``.
    If this fails after a viser upgrade, rewrite the hook; the viewer refuses to serve meanwhile."""
    import websockets
    from viser.infra import _infra

    src = inspect.getsource(_infra.WebsockServer._background_worker)
    assert "websockets.asyncio.server.serve(" in src and "process_request=" in src, \
        f"viser {viser.__version__} no longer starts its server as 1.1.1 did: palpate/viewer/origin.py's hook"
    assert origin.hook_viser_serve() is None
    assert isinstance(_infra.websockets, origin._Overlay)
    # Everything else viser's transport takes from websockets is websockets'.
    assert _infra.websockets.exceptions is websockets.exceptions
    assert _infra.websockets.asyncio.server.ServerConnection is websockets.asyncio.server.ServerConnection
    assert _infra.websockets.datastructures.Headers is websockets.datastructures.Headers
    # A viser server that is not a viewer's is as it was (the hook acts on the viewer's only).
    from websockets.sync.client import connect

    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        with connect(f"ws://127.0.0.1:{server.get_port()}", subprotocols=[SUBPROTOCOL],
                     additional_headers={"Origin": "http://evil.example"}, open_timeout=15):
            pass
    finally:
        server.stop()


def test_viser_hook_not_taken_refuses_to_serve(model, monkeypatch):
    """Should a viser release start its server otherwise, the viewer does not serve unchecked."""
    import websockets
    from viser.infra import _infra

    from palpate.viewer import OriginCheckUnavailable, Viewer

    monkeypatch.setattr(origin, "hook_viser_serve", lambda: "viser changed (test)")
    with pytest.raises(OriginCheckUnavailable, match="viser changed"):
        Viewer(model, port=0)
    # The hook "installed" but viser starting websockets' server some other way: not called.
    monkeypatch.setattr(origin, "hook_viser_serve", lambda: None)
    monkeypatch.setattr(_infra, "websockets", websockets)
    with pytest.raises(OriginCheckUnavailable, match="1.1.1"):
        Viewer(model, port=0)


# ------------------------------------------------------------------------------- the command

def test_cli_require_token_prints_the_tokenised_url(tmp_path, model):
    """``palpate view --require-token``: the URL printed carries a fresh random token; the page
    is 403 without it (one warning line on stderr, counted in the status lines) and 200 with it."""
    path = tmp_path / "ventricle.palpate"
    model.save(str(path))
    env = {k: v for k, v in os.environ.items() if k != "PALPATE_VIEW_TOKEN"}
    p = subprocess.Popen([sys.executable, "-m", "palpate", "view", str(path), "--port", "0", "--seconds", "6",
                          "--require-token"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
                         env=env)
    try:
        url = None
        for line in p.stdout:
            m = re.search(r" on (http://\S+) ", line)
            if m:
                url = m.group(1)
                break
        m = re.fullmatch(r"http://127\.0\.0\.1:(\d+)/\?token=([A-Za-z0-9_-]{32})", url or "")
        assert m, url
        port = int(m.group(1))
        with pytest.raises(urllib.error.HTTPError) as e:
            urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=10)
        assert e.value.code == 403
        with urllib.request.urlopen(url, timeout=10) as r:
            assert b"<html" in r.read().lower() and r.headers["Set-Cookie"].startswith(f"{cookie_name(port)}=")
        out, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 0, err
    assert err.count(f"palpate: warning: refused a request to the viewer: {NO_TOKEN}") == 1, err
    assert "requests refused 1" in out, out


def test_cli_token_options(monkeypatch, capsys):
    """``--token`` (or ``$PALPATE_VIEW_TOKEN``) reaches the viewer; a bad one is a usage error;
    beyond loopback the warning says the token is needed and the traffic is unencrypted."""
    import palpate.viewer
    from palpate.cli import build_parser, main

    monkeypatch.setenv("PALPATE_VIEW_TOKEN", TOKEN)
    a = build_parser().parse_args(["view"])
    assert a.token == TOKEN and not a.require_token
    monkeypatch.delenv("PALPATE_VIEW_TOKEN")
    assert build_parser().parse_args(["view"]).token is None
    assert main(["view", "ventricle", "--token", "short"]) == 2
    assert "--token" in capsys.readouterr().err
    seen = {}

    def refuse(*a, **k):
        seen.update(k)
        raise _p.ParameterError("refused by the test")

    monkeypatch.setattr(palpate.viewer, "Viewer", refuse)
    assert main(["view", "ventricle", "--host", "0.0.0.0", "--token", TOKEN]) == 1
    err = capsys.readouterr().err
    assert "warning: serving on 0.0.0.0" in err and "token" in err and "unencrypted" in err, err
    assert seen["host"] == "0.0.0.0" and seen["token"] == TOKEN
    assert policy_for(seen["host"], seen["token"], seen["require_token"]).require_token


# ------------------------------------------------------------------------------- in a real browser

ATTACK_PAGE = """<!doctype html><html><body><script>
window.result = {opened: false, closed: false, code: null, sent: 0};
const bytes = new Uint8Array(%(bytes)s);
const ws = new WebSocket(%(url)s, [%(proto)s]);
ws.binaryType = "arraybuffer";
ws.onopen = () => {
  window.result.opened = true;
  const t = setInterval(() => {
    if (ws.readyState !== 1 || window.result.sent >= 40) { clearInterval(t); return; }
    ws.send(bytes); window.result.sent++;
  }, 50);
};
ws.onclose = (e) => { window.result.closed = true; window.result.code = e.code; };
</script></body></html>"""


class AttackSite:
    """A web server on another port: ``/attack`` opens the viewer's WebSocket and sends the
    gizmo messages (``/attack-token`` the same with the viewer's token), ``/frame`` frames the
    viewer's page."""

    def __init__(self, v, attack):
        import json

        def page(url):
            return (ATTACK_PAGE % {"bytes": json.dumps(list(attack)), "url": json.dumps(url),
                                   "proto": json.dumps(SUBPROTOCOL)}).encode()

        pages = {"/attack": page(f"ws://127.0.0.1:{v.port}/"),
                 "/attack-token": page(f"ws://127.0.0.1:{v.port}/?token={v.token}"),
                 "/frame": f'<!doctype html><iframe src="http://127.0.0.1:{v.port}/" width=400 height=300>'
                           "</iframe>".encode()}

        class Handler(http.server.BaseHTTPRequestHandler):
            def do_GET(self):
                body = pages.get(self.path)
                self.send_response(200 if body else 404)
                self.send_header("Content-Type", "text/html")
                self.end_headers()
                self.wfile.write(body or b"")

            def log_message(self, *a):
                pass

        self.httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.port = self.httpd.server_address[1]
        threading.Thread(target=self.httpd.serve_forever, daemon=True).start()

    def close(self):
        self.httpd.shutdown()
        self.httpd.server_close()


def test_browser_page_from_another_origin_cannot_move_the_tool(model, chromium):
    """Chromium, with evil.example and rebind.example resolved to 127.0.0.1 (as DNS would for the
    attacker): a page of evil.example (and one of another local port) opens the viewer's WebSocket
    and sends the gizmo messages: the connection fails, the viewer counts an Origin refusal, the
    tool does not move. The viewer under rebind.example (DNS rebinding) is 403; framed by
    evil.example it never connects. The viewer's own page still loads and connects, and
    evil.example's page with the token does move the tool (so the browser would have)."""
    exe = chromium
    from playwright.sync_api import sync_playwright

    from palpate.viewer import Viewer
    from palpate.viewer.browser import CHROMIUM_ARGS

    v = Viewer(model, "ventricle", port=0, fps=10)
    site = None
    try:
        assert v.wait_ready(60), v.loop_error
        site = AttackSite(v, gizmo_message(v, v.press_target(0.006)))
        home = v.target.copy()
        args = list(CHROMIUM_ARGS) + ["--host-resolver-rules=MAP evil.example 127.0.0.1, MAP rebind.example 127.0.0.1"]
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=exe, headless=True, args=args)
            try:
                page = browser.new_page(viewport={"width": 800, "height": 500})
                for attacker in (f"http://evil.example:{site.port}", f"http://127.0.0.1:{site.port}"):
                    n = refused(v, BAD_ORIGIN)
                    page.goto(f"{attacker}/attack", wait_until="load", timeout=30_000)
                    page.wait_for_function("window.result.closed || window.result.sent >= 40", timeout=30_000)
                    r = page.evaluate("window.result")
                    assert not r["opened"] and r["sent"] == 0 and r["code"] == 1006, (attacker, r)
                    assert refused(v, BAD_ORIGIN) > n, v.status()["requests"]
                # DNS rebinding: the viewer's page under the attacker's name.
                resp = page.goto(f"http://rebind.example:{v.port}/", wait_until="load", timeout=30_000)
                assert resp.status == 403 and FOREIGN_HOST in page.content()
                # Framed by another site: the frame is blocked before the viewer's page runs.
                page.goto(f"http://evil.example:{site.port}/frame", wait_until="load", timeout=30_000)
                # (Chromium shows the blocked frame as its error page, whose URL it reports as
                # chrome-error://chromewebdata/ or, at times, as empty: never the viewer's.)
                time.sleep(3.0)
                frames = [f.url for f in page.frames[1:]]
                assert len(frames) == 1 and frames[0] in ("chrome-error://chromewebdata/", ""), frames
                assert v.status()["requests"]["admitted"]["websocket"] == 0, v.status()["requests"]
                s = v.status()
                assert s["gizmo_moves"] == 0 and s["max_force_n"] == 0.0, s
                np.testing.assert_array_equal(v.target, home)

                # The viewer's own page loads and connects.
                own = browser.new_page(viewport={"width": 800, "height": 500})
                own.goto(v.url, wait_until="load", timeout=60_000)
                assert wait_for(lambda: len(v.server.get_clients()) >= 1, 60), v.status()["requests"]
                own.close()
                assert v.status()["max_force_n"] == 0.0
                # The attacker's page with the token: the same messages move the tool.
                page.goto(f"http://evil.example:{site.port}/attack-token", wait_until="load", timeout=30_000)
                assert wait_for(lambda: v.status()["force_n"] > 0.02, 30), (page.evaluate("window.result"),
                                                                            v.status())
                assert page.evaluate("window.result")["opened"]
            finally:
                browser.close()
    finally:
        if site is not None:
            site.close()
        v.close()
