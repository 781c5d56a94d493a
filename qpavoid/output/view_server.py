"""The live view's HTTP server (:class:`~qpavoid.output.live_view.LiveView` serves through it):
each connection in a thread of its own with a deadline, at most :data:`MAX_CONNECTIONS` at
once, and every request checked for its ``Host`` and its token before it is answered."""

from __future__ import annotations

import contextlib
import hmac
import io
import ipaddress
import socket
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any, Protocol

__all__ = [
    "MAX_CONNECTIONS",
    "REQUEST_DEADLINE_S",
    "Served",
    "ViewHandler",
    "ViewServer",
    "allowed_hosts",
]


#: What :meth:`ViewHandler._checked_path` returns for ``/TOKEN`` without its slash (no
#: path after a slash can hold this character).
_NO_SLASH = "\0"


class Served(Protocol):
    """What the server serves (a :class:`~qpavoid.output.live_view.LiveView`)."""

    page: bytes  # the page, at /TOKEN/
    token: str  # the URL's secret first segment
    hosts: frozenset[str]  # the Host headers answered
    clear_requested: threading.Event  # set by POST /TOKEN/clear

    def state(self) -> bytes:
        """The newest tick's JSON, at /TOKEN/state."""
        ...


# A browser polls ``state`` ten times a second on one or two connections and asks for the
# page now and then: 16 at once leaves it room while a crowd cannot spawn unbounded threads.
MAX_CONNECTIONS = 16
# From a connection's accept to the end of its request's headers, s: a browser on this
# machine takes milliseconds; a client sending a byte now and then is cut off after this.
REQUEST_DEADLINE_S = 2.0
# Longest time to hand over one answer, s (the page is a few hundred kB, on loopback
# milliseconds; a client that does not read its answer is cut off after this).
WRITE_TIMEOUT_S = 5.0
# Connections the kernel holds before they are accepted (above MAX_CONNECTIONS: the extra
# are accepted and closed at once rather than left hanging in the kernel).
LISTEN_BACKLOG = 64


def allowed_hosts(netloc: str, port: int) -> frozenset[str]:
    """The ``Host`` headers a browser sends for the served address (lower case): its IP
    literal, ``localhost`` and the loopback literals, with the port (without it too on port
    80, which browsers leave out)."""
    names = {netloc.lower(), "localhost", "127.0.0.1", "[::1]"}
    hosts = {f"{name}:{port}" for name in names}
    if port == 80:
        hosts |= names
    return frozenset(hosts)


def _family(host: str) -> socket.AddressFamily:
    """IPv6 for an IPv6 literal (``::1``), else IPv4 (``localhost`` too, as before)."""
    try:
        six = ipaddress.ip_address(host).version == 6
    except ValueError:
        six = False
    return socket.AF_INET6 if six else socket.AF_INET


class ViewServer(ThreadingHTTPServer):
    """Each connection in a daemon thread of its own, at most ``max_connections`` at once
    (one more is closed at once), each with its deadline (:class:`ViewHandler`); a client that
    goes away mid-answer is its own business: no traceback.

    Parameters
    ----------
    address
        ``(host, port)`` to bind.
    handler
        The request handler class (or a factory of handlers).
    max_connections
        Connections served at once.
    deadline_s
        Longest time from a connection's accept to the end of its request's headers, s.
    """

    daemon_threads = True
    block_on_close = False  # close() cuts open connections instead of waiting for them
    request_queue_size = LISTEN_BACKLOG

    def __init__(
        self, address: tuple[str, int], handler: Any, max_connections: int, deadline_s: float
    ):
        self.address_family = _family(address[0])
        self.deadline_s = deadline_s
        self._slots = threading.BoundedSemaphore(max_connections)
        self._open: dict[socket.socket, float] = {}  # connection -> its deadline (monotonic)
        self._open_lock = threading.Lock()
        super().__init__(address, handler)

    def process_request(self, request: Any, client_address: Any) -> None:
        """Serve ``request`` in a thread of its own if a slot is free, else close it."""
        if not self._slots.acquire(blocking=False):
            self.shutdown_request(request)
            return
        with self._open_lock:
            self._open[request] = time.monotonic() + self.deadline_s
        try:
            super().process_request(request, client_address)
        except BaseException:
            self._release(request)  # the caller closes it
            raise

    def process_request_thread(self, request: Any, client_address: Any) -> None:
        """Serve ``request``; free its slot before closing it (a client that saw the close
        finds the slot free)."""
        try:
            self.finish_request(request, client_address)
        except Exception:
            self.handle_error(request, client_address)
        finally:
            self._release(request)
            self.shutdown_request(request)

    def deadline(self, request: Any) -> float:
        """When ``request`` must have sent its headers (:func:`time.monotonic`)."""
        with self._open_lock:
            return self._open.get(request, time.monotonic() + self.deadline_s)

    def server_close(self) -> None:
        """Stop listening and cut the connections still open."""
        super().server_close()
        with self._open_lock:
            still_open = list(self._open)
        for request in still_open:
            with contextlib.suppress(OSError):  # closed meanwhile
                request.shutdown(socket.SHUT_RDWR)

    def handle_error(self, request: Any, client_address: Any) -> None:
        pass

    def _release(self, request: Any) -> None:
        with self._open_lock:
            if self._open.pop(request, None) is not None:
                self._slots.release()


class _DeadlineReader(io.RawIOBase):
    """The bytes of ``sock`` until ``deadline`` (:func:`time.monotonic`), then
    :class:`TimeoutError`: each read may wait only the time left, so a client sending a
    byte now and then does not restart the clock (as a socket timeout alone would)."""

    def __init__(self, sock: socket.socket, deadline: float):
        super().__init__()
        self._sock = sock
        self._deadline = deadline

    def readable(self) -> bool:
        return True

    def readinto(self, buffer: Any) -> int:
        left = self._deadline - time.monotonic()
        if left <= 0:
            raise TimeoutError("the request's deadline has passed")
        self._sock.settimeout(left)
        return self._sock.recv_into(buffer)


class ViewHandler(BaseHTTPRequestHandler):
    """``/TOKEN/``: the page; ``/TOKEN/state``: the newest tick; ``/TOKEN``: to the page;
    ``POST /TOKEN/clear``: clear the flagged people; a foreign ``Host``: 403; anything else:
    404 (each with a one-line reason only)."""

    protocol_version = "HTTP/1.0"  # one request per connection: each has its own deadline

    def __init__(self, view: Served, *args: Any):
        self.view = view
        super().__init__(*args)

    def setup(self) -> None:
        """Read the request through the connection's deadline (:class:`_DeadlineReader`)."""
        super().setup()
        self.rfile.close()  # the plain reader; the socket stays open
        deadline = self.server.deadline(self.request)  # type: ignore[attr-defined]
        self.rfile = io.BufferedReader(_DeadlineReader(self.connection, deadline))

    def do_POST(self) -> None:
        origin = self.headers.get("Origin")
        if origin is not None and origin.lower().split("://", 1)[-1] not in self.view.hosts:
            self.send_error(403, explain="a request from another site's page")
            return
        rest = self._checked_path()
        if rest == "clear":  # no body is read: the request line says it all
            self.view.clear_requested.set()
            self._send(b"clearing the flagged people\n", "text/plain; charset=utf-8")
        elif rest is not None:
            self.send_error(404)

    def _checked_path(self) -> str | None:
        """The path after ``/TOKEN/`` (None, answered already, for a foreign Host or a
        wrong token)."""
        if not self._host_allowed():
            self.send_error(403, explain="the Host header does not name this live view")
            return None
        path = self.path.partition("?")[0]  # a path only (not urlsplit: "//x" is no host)
        token, slash, rest = path.removeprefix("/").partition("/")
        if not hmac.compare_digest(token.encode("utf-8"), self.view.token.encode("ascii")):
            self.send_error(404)
            return None
        return rest if slash else _NO_SLASH

    def do_GET(self) -> None:
        rest = self._checked_path()
        if rest is None:
            return
        if rest == _NO_SLASH:  # the token without its "/": the page's relative "state" needs it
            self._send(b"", "text/plain", 301, location=f"/{self.view.token}/")
        elif rest in ("", "index.html"):
            self._send(self.view.page, "text/html; charset=utf-8")
        elif rest == "state":
            self._send(self.view.state(), "application/json")
        else:
            self.send_error(404)

    def send_error(self, code: int, message: str | None = None, explain: str | None = None) -> None:
        """A one-line plain-text reason, never a page (the HTML error page's ``message``
        may quote the client: left out)."""
        self.close_connection = True
        short = self.responses.get(code, ("error",))[0]
        reason = f"{code} {short}" + (f": {explain}" if explain else "")
        self._send(f"{reason}\n".encode(), "text/plain; charset=utf-8", code)

    def _host_allowed(self) -> bool:
        """One ``Host`` header, naming the served address (DNS rebinding: another name)."""
        hosts = self.headers.get_all("Host") or []
        return len(hosts) == 1 and hosts[0].strip().lower() in self.view.hosts

    def _send(self, body: bytes, kind: str, code: int = 200, location: str | None = None) -> None:
        self.connection.settimeout(WRITE_TIMEOUT_S)  # the read deadline no longer applies
        self.send_response(code)
        self.send_header("Content-Type", kind)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.send_header("X-Content-Type-Options", "nosniff")
        self.send_header("Referrer-Policy", "no-referrer")  # the token stays in the URL bar
        self.send_header("X-Frame-Options", "DENY")
        if location is not None:
            self.send_header("Location", location)
        self.end_headers()
        if self.command != "HEAD" and code >= 200 and code not in (204, 304):
            self.wfile.write(body)

    def log_message(self, format: str, *args: Any) -> None:
        """Quiet: the run's own output is what the terminal shows."""
