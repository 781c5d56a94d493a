"""A browser view that follows a run as it happens (``qpavoid run ... --view``).

:class:`LiveView` serves, on localhost, the replay page (:mod:`qpavoid.view_html`) in live
mode: the page asks for ``state`` ten times a second and draws the newest tick. The
simulation hands it each tick it logs, at most 30 a second (``simulate(watch=...)``);
keeping it costs the control loop a dictionary copy. The geometry is made only when the
page asks, in the server's thread, on a robot model of its own (Pinocchio's data are not
shared across threads).
"""

from __future__ import annotations

import copy
import ipaddress
import json
import socket
import threading
from functools import partial
from http.server import BaseHTTPRequestHandler, HTTPServer
from typing import Any

import numpy as np

from .errors import InputError
from .robot import Robot
from .view_data import replay_data
from .view_html import encode, replay_html

__all__ = ["LiveView"]


class LiveView:
    """The live view of one run, served at :attr:`url` until :meth:`close`.

    Parameters
    ----------
    address
        ``(host, port)`` to serve on (port 0: any free port).
    robot
        The run's robot (the view computes on a copy with its own Pinocchio data).
    method
        The run's distance method (the shapes drawn).
    title
        The page's title.
    """

    def __init__(self, address: tuple[str, int], robot: Robot, method: str, title: str):
        self.robot = copy.copy(robot)
        self.robot.data = robot.model.createData()  # the server's thread computes on its own
        self.metrics = {"distance_method": method}
        self._latest: dict[str, Any] | None = None
        self._lock = threading.Lock()
        _check_loopback(address)
        first = replay_data(_one_tick(self.robot), self.metrics, self.robot)
        self.page = replay_html(first, title, live=True).encode("utf-8")
        self._state: tuple[int, bytes] = (0, b"null")  # (ticks handed so far, its JSON)
        self._handed = 0
        try:
            # one request at a time: a browser polls ten times a second; a crowd of
            # clients waits in line instead of competing with the control loop
            self.server = _QuietServer(address, partial(_Handler, self))
        except OSError as exc:
            raise InputError(
                f"cannot serve the live view on {address[0]}:{address[1]}: {exc.strerror or exc}",
                name="--view",
                value=address,
            ) from None
        host, port = self.server.server_address[:2]
        host = host.decode() if isinstance(host, bytes) else str(host)
        self.url = "http" + f"://{host}:{port}/"  # printed for the user, never in a page
        self._thread = threading.Thread(
            target=self.server.serve_forever, name="qpavoid-view", daemon=True
        )
        self._thread.start()

    def update(self, row: dict[str, Any]) -> None:
        """Keep ``row`` (one tick of the log, :func:`~qpavoid.simulation.simulate`'s
        ``watch``) as the one to show."""
        with self._lock:
            self._latest = row
            self._handed += 1

    def state(self) -> bytes:
        """The newest tick as the page's JSON (``null`` before the first), made once per
        tick however many times it is asked for."""
        with self._lock:
            row, handed = self._latest, self._handed
        if row is None:
            return b"null"
        if self._state[0] != handed:
            log = {key: np.asarray(value)[None] for key, value in row.items()}
            data = replay_data(log, self.metrics, self.robot)
            self._state = (handed, json.dumps(encode(data), separators=(",", ":")).encode())
        return self._state[1]

    def close(self) -> None:
        """Stop serving."""
        self.server.shutdown()
        self.server.server_close()

    def __enter__(self) -> LiveView:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _one_tick(robot: Robot) -> dict[str, np.ndarray]:
    """A log of one tick with the robot at rest and nobody in view (the page's start)."""
    nan3 = np.full((1, 3, 3), np.nan)
    return {
        "t": np.zeros(1),
        "q": robot.neutral()[None],
        "joints": np.full((1, 25, 3), np.nan),
        "state": np.zeros((1, 25), dtype=np.int8),
        "stopped": np.ones(1, dtype=bool),
        "stop_reason": np.array(["waiting for the run"]),
        "f": np.zeros(1),
        "distance": np.full((1, 3), np.inf),
        "robot_point": nan3,
        "human_point": nan3,
        "ee_pos": np.full((1, 3), np.nan),
        "ee_ref": np.full((1, 3), np.nan),
    }


def _check_loopback(address: tuple[str, int]) -> None:
    """The live view serves this machine only (no authentication): a loopback host."""
    host = address[0]
    try:
        resolved = socket.getaddrinfo(host, None)[0][4][0]
        loopback = ipaddress.ip_address(resolved).is_loopback
    except (OSError, ValueError):
        loopback = False
    if not loopback:
        raise InputError(
            f"--view serves this machine only: give a loopback host (127.0.0.1, localhost, "
            f"::1), got {host!r}",
            name="--view",
            value=address,
        )


class _QuietServer(HTTPServer):
    """A client that goes away mid-answer is its own business: no traceback."""

    def handle_error(self, request: Any, client_address: Any) -> None:
        pass


class _Handler(BaseHTTPRequestHandler):
    """``/``: the page; ``/state``: the newest tick; anything else: 404."""

    timeout = 2.0  # a client that connects and says nothing does not hold the server

    def __init__(self, view: LiveView, *args: Any):
        self.view = view
        super().__init__(*args)

    def do_GET(self) -> None:
        if self.path in ("/", "/index.html"):
            self._send(self.view.page, "text/html; charset=utf-8")
        elif self.path.startswith("/state"):
            self._send(self.view.state(), "application/json")
        else:
            self.send_error(404)

    def _send(self, body: bytes, kind: str) -> None:
        self.send_response(200)
        self.send_header("Content-Type", kind)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, format: str, *args: Any) -> None:
        """Quiet: the run's own output is what the terminal shows."""
