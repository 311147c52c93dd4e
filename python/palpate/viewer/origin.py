"""Who may open the viewer's page and its WebSocket (issue 35, item 2).

A viewer bound to 127.0.0.1 is out of the network's reach but not of the user's browser: any page
the user visits may open ``ws://127.0.0.1:PORT`` (browsers do not apply the same-origin policy to
WebSockets) and drive the hand, and a site whose name the attacker rebinds to 127.0.0.1 (DNS
rebinding) is even same-origin with the viewer. The browser cannot be made to refuse; the server
can, because the browser always says who is asking: the ``Host`` header names the host the page
thinks it talks to (a rebinding site's own name), and the ``Origin`` header, sent on every
WebSocket upgrade and every cross-origin request, names the page that asks.

:class:`RequestPolicy` decides, for every HTTP request and WebSocket upgrade, before viser sees
it (:meth:`RequestPolicy.decide`):

- with ``?token=T`` in the URL: admitted if ``T`` is the viewer's token (whatever the Host and
  Origin: whoever has the token was given it), refused otherwise; a page loaded with the token
  gets it as a cookie (``HttpOnly; SameSite=Strict``), which its own WebSocket carries (viser's
  page connects to its own address without the query);
- with the token's cookie: admitted if the Origin, when there is one, is the page's own (the
  same host and port as the Host header), as Jupyter does: a browser sends the cookie with any
  request to that host, also from a page on another port of it;
- without a token: refused when the viewer requires one (it does when bound beyond loopback);
  otherwise admitted only if the Host is a loopback name (``localhost``, ``127.0.0.1`` or any
  loopback address, ``[::1]``) and the Origin, when there is one, is that same host and port.

The Host's port is not pinned to the viewer's: a tunnel (``ssh -L 9000:127.0.0.1:8080``) serves
the page as ``http://localhost:9000`` and its WebSocket says Host ``localhost:9000``, Origin
``http://localhost:9000``; a browser can only send a loopback Host to a loopback address it was
pointed at, so a foreign page cannot forge one, and the Origin check tells its requests apart.

A refused request gets ``403`` with a one-line reason and never reaches viser; refusals are
counted by reason and the first of each reason is logged (logger ``palpate.viewer``). Admitted
responses also carry ``Content-Security-Policy: frame-ancestors 'self'`` (no other site may frame
the viewer and have the user drag in it) and ``Referrer-Policy: no-referrer`` (a tokenised URL is
never sent on).

viser has no hook for requests: :func:`hook_viser_serve` is the one place that relies on viser's
internals (viser 1.1.1) and :class:`palpate.viewer.Viewer` refuses to serve when it did not take.
"""
from __future__ import annotations

import contextlib
import hmac
import http
import inspect
import ipaddress
import logging
import re
import secrets
import threading
from typing import Any, Callable, Dict, Iterator, List, NamedTuple, Optional, Tuple
from urllib.parse import parse_qs, urlsplit

LOG = logging.getLogger("palpate.viewer")

#: What a token given by the user may be made of: URL-safe characters, so that it goes into a URL
#: as it is, and at least 8 of them.
TOKEN_PATTERN = re.compile(r"[A-Za-z0-9._~-]{8,256}")
#: Random bytes of a generated token (``secrets.token_urlsafe``: 32 characters).
TOKEN_BYTES = 24

# The reasons of a refusal (each counted, the first of each logged).
BAD_HOST = "bad Host header"
FOREIGN_HOST = "Host is not a loopback name"
BAD_ORIGIN = "Origin is not the viewer's page"
WRONG_TOKEN = "wrong token"
NO_TOKEN = "token required"
REASONS = (BAD_HOST, FOREIGN_HOST, BAD_ORIGIN, WRONG_TOKEN, NO_TOKEN)

#: Headers added to every admitted HTTP response (not to a WebSocket's 101).
RESPONSE_HEADERS = (("Content-Security-Policy", "frame-ancestors 'self'"), ("X-Frame-Options", "SAMEORIGIN"),
                    ("Referrer-Policy", "no-referrer"))


class OriginCheckUnavailable(RuntimeError):
    """The viewer cannot check who opens its page (viser is not the version it hooks into)."""


def is_loopback_host(host: str) -> bool:
    """Whether ``host`` (a name or an address, IPv6 without brackets) is this machine's loopback."""
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def check_token(token: str) -> str:
    """``token`` if it is usable as a viewer's token (:data:`TOKEN_PATTERN`), else ``ValueError``."""
    if not isinstance(token, str) or not TOKEN_PATTERN.fullmatch(token):
        raise ValueError("a token must be 8 to 256 URL-safe characters (letters, digits, '-', '_', '.', '~')")
    return token


def parse_host(value: str) -> Optional[Tuple[str, int]]:
    """``(name, port)`` of a Host header (name lower-case, IPv6 without brackets, port 80 when
    absent), or None when it is not a plain ``host[:port]``."""
    if not value or any(c in value for c in " \t/\\@?#"):
        return None
    try:
        u = urlsplit("//" + value)
        name, port = u.hostname, u.port
    except ValueError:
        return None
    if not name:
        return None
    return name, 80 if port is None else port


def parse_origin(value: str) -> Optional[Tuple[str, int]]:
    """``(name, port)`` of an Origin header (``http(s)://host[:port]``), or None (``null``, a
    scheme other than http(s), anything malformed)."""
    try:
        u = urlsplit(value)
        name, port = u.hostname, u.port
    except ValueError:
        return None
    if u.scheme not in ("http", "https") or not name or u.path not in ("", "/") or u.query or u.username:
        return None
    return name, port if port is not None else (443 if u.scheme == "https" else 80)


def cookie_name(port: int) -> str:
    """The token's cookie for the viewer on ``port``: browsers key cookies by host, not port, so
    the name carries the port for two viewers on one host not to overwrite each other's."""
    return f"palpate-view-{port}"


class Decision(NamedTuple):
    ok: bool
    reason: str = ""
    detail: str = ""
    set_cookie: bool = False


class RequestPolicy:
    """The checks of the module for one viewer: ``token`` (``None``: a random one,
    ``secrets.token_urlsafe``) and ``require_token`` (no request without it, as beyond loopback).
    :meth:`wrap` puts the checks in front of a websockets ``process_request`` hook; :meth:`counts`
    says what was admitted and refused. ``show_token``: whether the viewer's URL carries the
    token (it is required, or the user chose it)."""

    def __init__(self, token: Optional[str] = None, require_token: bool = False):
        self.token = check_token(token) if token is not None else secrets.token_urlsafe(TOKEN_BYTES)
        self.require_token = bool(require_token)
        self.show_token = self.require_token or token is not None
        #: Set when the checks were put in front of a server (see :func:`hook_viser_serve`).
        self.installed = False
        self._lock = threading.Lock()
        self._refused: Dict[str, int] = {}
        self._admitted = {"http": 0, "websocket": 0}

    # -- the decision ---------------------------------------------------------------------------
    def _valid(self, token: Optional[str]) -> bool:
        # Constant time: the comparison does not tell a prober how many characters were right.
        return token is not None and hmac.compare_digest(token.encode("utf-8", "replace"), self.token.encode())

    def decide(self, path: str, headers: Any, port: int) -> Decision:
        """What to do with a request for ``path`` with ``headers`` (websockets ``Headers``) that
        reached the viewer on ``port``."""
        hosts = headers.get_all("Host")
        if len(hosts) != 1:
            return Decision(False, BAD_HOST, f"{len(hosts)} Host headers")
        host = parse_host(hosts[0])
        if host is None:
            return Decision(False, BAD_HOST, f"Host {ascii(hosts[0][:80])}")
        origins = headers.get_all("Origin")
        if len(origins) > 1:
            return Decision(False, BAD_ORIGIN, f"{len(origins)} Origin headers")
        origin = origins[0] if origins else None
        # A request without an Origin is not a cross-origin one from a browser (a navigation, a
        # same-origin GET, or not a browser: then it comes from this machine or has the token).
        same_origin = origin is None or parse_origin(origin) == host

        try:
            query = parse_qs(urlsplit(path).query, keep_blank_values=True).get("token")
        except ValueError:
            query = [""]
        if query is not None:
            if self._valid(query[0]):
                return Decision(True, set_cookie=True)
            return Decision(False, WRONG_TOKEN, f"from Origin {ascii(origin)}" if origin else "")
        if self._valid(self._cookie(headers, port)):
            if same_origin:
                return Decision(True)
            return Decision(False, BAD_ORIGIN, f"Origin {ascii(origin[:80])} with the token's cookie")
        if self.require_token:
            return Decision(False, NO_TOKEN, f"Host {ascii(hosts[0][:80])}")
        if not is_loopback_host(host[0]):
            return Decision(False, FOREIGN_HOST, f"Host {ascii(hosts[0][:80])}")
        if not same_origin:
            return Decision(False, BAD_ORIGIN, f"Origin {ascii(origin[:80])}, Host {ascii(hosts[0][:80])}")
        return Decision(True)

    @staticmethod
    def _cookie(headers: Any, port: int) -> Optional[str]:
        name = cookie_name(port)
        for line in headers.get_all("Cookie"):
            for part in line.split(";"):
                k, _, v = part.strip().partition("=")
                if k == name:
                    return v
        return None

    # -- in front of a server ---------------------------------------------------------------------
    def wrap(self, inner: Optional[Callable[..., Any]]) -> Callable[..., Any]:
        """A websockets ``process_request`` hook: the checks, then ``inner`` (viser's, which
        serves the page and lets WebSocket upgrades through) for what is admitted."""
        async def process_request(connection: Any, request: Any) -> Any:
            try:
                port = int(connection.local_address[1])
            except (AttributeError, IndexError, TypeError, ValueError, OSError):
                port = 0
            d = self.decide(request.path, request.headers, port)
            upgrade = any(v.strip().lower() == "websocket" for v in request.headers.get_all("Upgrade"))
            if not d.ok:
                self._refuse(d, upgrade)
                return connection.respond(http.HTTPStatus.FORBIDDEN, f"palpate view: {d.reason}\n")
            with self._lock:
                self._admitted["websocket" if upgrade else "http"] += 1
            response = inner(connection, request) if inner is not None else None
            if inspect.isawaitable(response):
                response = await response
            if response is not None:
                for k, v in RESPONSE_HEADERS:
                    response.headers[k] = v
                if d.set_cookie:
                    response.headers["Set-Cookie"] = (f"{cookie_name(port)}={self.token}; Path=/; HttpOnly; "
                                                      "SameSite=Strict")
            return response

        return process_request

    def _refuse(self, d: Decision, upgrade: bool) -> None:
        with self._lock:
            n = self._refused.get(d.reason, 0) + 1
            self._refused[d.reason] = n
        if n == 1:
            what = "a WebSocket" if upgrade else "a request"
            LOG.warning("refused %s to the viewer: %s%s; further refusals for this reason are only counted",
                        what, d.reason, f" ({d.detail})" if d.detail else "")

    def counts(self) -> Dict[str, Any]:
        """``{"admitted": {"http": n, "websocket": n}, "refused": {reason: n}}``."""
        with self._lock:
            return {"admitted": dict(self._admitted), "refused": dict(self._refused)}

    def refused(self) -> int:
        with self._lock:
            return sum(self._refused.values())


def policy_for(host: str, token: Optional[str] = None, require_token: bool = False) -> RequestPolicy:
    """The policy of a viewer bound to ``host``: beyond loopback the network can reach it, so the
    token is required whatever ``require_token`` says. ``ValueError`` for a bad ``token``."""
    return RequestPolicy(token, require_token=require_token or not is_loopback_host(host))


# -- the hook into viser -------------------------------------------------------------------------

class _Overlay:
    """A module seen through a few replaced attributes; every other attribute is the module's."""

    def __init__(self, module: Any, **replaced: Any):
        self.__dict__.update(replaced)
        self._module = module

    def __getattr__(self, name: str) -> Any:      # only for what is not replaced
        return getattr(self._module, name)


#: The policy of the viewer whose server is being started (see :func:`checking`).
_PENDING: List[Optional[RequestPolicy]] = [None]
_STARTING = threading.Lock()


def hook_viser_serve() -> Optional[str]:
    """Puts :data:`_PENDING`'s checks in front of viser's request handling. Returns None when
    hooked (or already), else why not.

    The one reliance on viser's internals, written against viser 1.1.1 (pinned ``==1.1.1`` in the
    Makefile, ``<1.2`` in pyproject.toml): viser's transport,
    ``viser.infra._infra.WebsockServer._background_worker``, starts websockets' server with
    ``websockets.asyncio.server.serve(ws_handler, host, port, ..., process_request=viser_http_server)``,
    ``viser_http_server`` serving the page and letting WebSocket upgrades through, and offers no
    hook of its own. Here ``_infra``'s global name ``websockets`` is replaced by an overlay whose
    ``asyncio.server.serve`` wraps that ``process_request`` with the pending viewer's checks,
    before the socket is bound, so no request is ever served unchecked; viser servers started by
    anyone else in the process, and everything else ``_infra`` takes from websockets, are as
    they were. Should a viser release start its server otherwise, the wrapper is not called,
    :attr:`RequestPolicy.installed` stays False and the viewer refuses to serve
    (``test_view_origin.py::test_viser_hook_*`` fails)."""
    try:
        from viser.infra import _infra
    except ImportError as e:
        return f"viser's transport (viser.infra._infra) is not importable ({e})"
    ws = getattr(_infra, "websockets", None)
    if isinstance(ws, _Overlay):
        return None
    serve = getattr(getattr(getattr(ws, "asyncio", None), "server", None), "serve", None)
    if serve is None:
        return "viser's transport does not start websockets' server as viser 1.1.1 does"

    def serve_checked(*args: Any, **kwargs: Any) -> Any:
        # Called in viser's server thread while the viewer's thread waits in ViserServer() (which
        # holds _STARTING); viser calls it again for each port it tries.
        policy = _PENDING[0]
        if policy is not None:
            kwargs["process_request"] = policy.wrap(kwargs.get("process_request"))
            policy.installed = True
        return serve(*args, **kwargs)

    _infra.websockets = _Overlay(ws, asyncio=_Overlay(ws.asyncio, server=_Overlay(ws.asyncio.server,
                                                                                  serve=serve_checked)))
    return None


@contextlib.contextmanager
def checking(policy: RequestPolicy) -> Iterator[None]:
    """Within it, a viser server started by this thread has ``policy``'s checks in front of it
    (the caller then checks :attr:`RequestPolicy.installed`). Raises
    :class:`OriginCheckUnavailable` when viser cannot be hooked."""
    why = hook_viser_serve()
    if why is not None:
        raise OriginCheckUnavailable(f"cannot check who opens the viewer: {why}; not serving")
    with _STARTING:
        _PENDING[0] = policy
        try:
            yield
        finally:
            _PENDING[0] = None
