"""A browser view that follows a run as it happens (``qpavoid run ... --view``).

:class:`LiveView` serves, on localhost, the replay page (:mod:`qpavoid.output.replay_html`) in live
mode: the page asks for ``state`` ten times a second and draws the newest tick. The
simulation hands it each tick it logs, at most 30 a second (``simulate(watch=...)``);
keeping it costs the control loop a dictionary copy. The geometry is made only when the
page asks, in a server thread, on a robot model of its own (Pinocchio's data are not
shared across threads), one request at a time.

The view has no login, so it answers only what the operator's own browser would ask:

- the request's ``Host`` must name the served loopback address (its IP literal,
  ``localhost``, ``127.0.0.1`` or ``[::1]``, with the port): a page elsewhere whose name
  an attacker re-points at 127.0.0.1 (DNS rebinding) gets 403, not the skeleton;
- the path must start with a random token printed only to the terminal
  (``http://127.0.0.1:PORT/TOKEN/``): any other path gets 404;
- each connection is served in a thread of its own, has a deadline from its accept to the
  end of its headers however slowly it sends them, and only so many are served at once
  (:mod:`qpavoid.output.view_server`): a slow or crowding client cannot keep the browser's polls
  waiting for long.
"""

from __future__ import annotations

import secrets
import threading
from functools import partial
from typing import Any

import numpy as np

from qpavoid.arm.model import Robot
from qpavoid.core.checks import is_loopback
from qpavoid.core.errors import InputError
from qpavoid.human.body import BodyModel, KinectHuman
from qpavoid.human.frames import nobody
from qpavoid.human.skeleton import SkeletonFormat
from qpavoid.output.arm_shapes import arm_parts
from qpavoid.output.replay_html import encode, page_data, replay_html
from qpavoid.output.run_files import strict_json
from qpavoid.output.view_data import replay_data
from qpavoid.output.view_server import (
    MAX_CONNECTIONS,
    REQUEST_DEADLINE_S,
    ViewHandler,
    ViewServer,
    allowed_hosts,
)

__all__ = ["LiveView"]

# Bytes of URL-safe randomness in the token (128 bits: not guessed in a lifetime of tries).
TOKEN_BYTES = 16
#: How often the serving thread looks for :meth:`LiveView.close`'s shutdown, s: a run's end
#: waits at most this long for it (the standard library's 0.5 s held every run's end, and
#: every test of the view, for up to half a second; a wake-up every 50 ms costs nothing).
SHUTDOWN_POLL_S = 0.05


class LiveView:
    """The live view of one run, served at :attr:`url` until :meth:`close`.

    Parameters
    ----------
    address
        ``(host, port)`` to serve on, a loopback host (port 0: any free port).
    robot
        The run's robot (the view computes on a copy with its own Pinocchio data).
    method
        The run's distance method (the shapes drawn).
    title
        The page's title.
    max_connections
        Connections served at once; one more is closed at once.
    request_deadline_s
        Longest time from a connection's accept to the end of its request's headers, s.
    human
        The run's body model (the person's shapes; default: the paper's on the Kinect v2,
        :class:`~qpavoid.human.body.KinectHuman`).

    Attributes
    ----------
    url
        ``http://HOST:PORT/TOKEN/``, ending in ``/`` (``url + "state"``: the newest tick);
        printed for the user, never in a page.
    clear_requested
        Set when the operator asks, from the page (``POST url + "clear"``), to clear the
        people flagged as suspect (:meth:`qpavoid.fusion.fuser.Fuser.clear_flagged`); the live
        source acts on it at its next frame and clears it.

    Raises
    ------
    InputError
        If the host is not a loopback one, or the address cannot be served.
    """

    def __init__(
        self,
        address: tuple[str, int],
        robot: Robot,
        method: str,
        title: str,
        *,
        max_connections: int = MAX_CONNECTIONS,
        request_deadline_s: float = REQUEST_DEADLINE_S,
        human: BodyModel | None = None,
    ):
        _check_loopback(address)
        self.human = human or KinectHuman()
        self.robot = robot.for_thread()  # the server's threads compute on their own
        self.metrics = {"distance_method": method}
        self._latest: dict[str, Any] | None = None
        self._handed = 0
        self._lock = threading.Lock()  # _latest and _handed: the control loop and the server
        self._state: tuple[int, bytes] = (0, b"null")  # (ticks handed so far, its JSON)
        self._robot_lock = threading.Lock()  # self.robot (its data) and _state: one thread
        self.clear_requested = threading.Event()
        self.parts = arm_parts(robot)  # the URDF's meshes, read once
        start = _one_tick(self.robot, self.human.skeleton)
        first = replay_data(start, self.metrics, self.robot, human=self.human, parts=self.parts)
        self.page = replay_html(first, title, live=True).encode("utf-8")
        self.token = secrets.token_urlsafe(TOKEN_BYTES)
        try:
            self.server = ViewServer(
                address, partial(ViewHandler, self), max_connections, request_deadline_s
            )
        except OSError as exc:
            raise InputError(
                f"cannot serve the live view on {address[0]}:{address[1]}: {exc.strerror or exc}",
                name="--view",
                value=address,
            ) from None
        host, port = self.server.server_address[:2]
        host = host.decode() if isinstance(host, bytes) else str(host)
        netloc = f"[{host}]" if ":" in host else host
        self.hosts = allowed_hosts(netloc, port)
        self.url = "http" + f"://{netloc}:{port}/{self.token}/"
        self._thread = threading.Thread(
            target=partial(self.server.serve_forever, poll_interval=SHUTDOWN_POLL_S),
            name="qpavoid-view",
            daemon=True,
        )
        self._thread.start()

    def update(self, row: dict[str, Any]) -> None:
        """Keep ``row`` (one tick of the log, :func:`~qpavoid.loop.simulation.simulate`'s
        ``watch``) as the one to show."""
        with self._lock:
            self._latest = row
            self._handed += 1

    def state(self) -> bytes:
        """The newest tick as the page's JSON (``null`` before the first), made once per
        tick however many times, and from however many threads, it is asked for."""
        with self._lock:
            row, handed = self._latest, self._handed
        if row is None:
            return b"null"
        with self._robot_lock:  # the control loop never waits on this one
            if self._state[0] != handed:
                log = {key: np.asarray(value)[None] for key, value in row.items()}
                data = replay_data(
                    log, self.metrics, self.robot, human=self.human, parts=self.parts
                )
                state = strict_json(encode(page_data(data)), indent=None)  # no NaN
                self._state = (handed, state.encode())
            return self._state[1]

    def close(self) -> None:
        """Stop serving (and cut the connections still open)."""
        self.server.shutdown()
        self.server.server_close()
        self._thread.join()

    def __enter__(self) -> LiveView:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _one_tick(robot: Robot, skeleton: SkeletonFormat) -> dict[str, np.ndarray]:
    """A log of one tick with the robot at rest and nobody of ``skeleton``'s joints in view
    (the page's start)."""
    nan3 = np.full((1, len(robot.sets), 3), np.nan)  # no closest pair for any set
    joints, state = nobody(skeleton)
    return {
        "t": np.zeros(1),
        "q": robot.neutral()[None],
        "joints": joints[None],
        "state": state[None],
        "stopped": np.ones(1, dtype=bool),
        "stop_reason": np.array(["waiting for the run"]),
        "f": np.zeros(1),
        "distance": np.full((1, len(robot.sets)), np.inf),
        "robot_point": nan3,
        "human_point": nan3,
        "ee_pos": np.full((1, 3), np.nan),
        "ee_ref": np.full((1, 3), np.nan),
    }


def _check_loopback(address: tuple[str, int]) -> None:
    """The live view serves this machine only (no authentication): a loopback host."""
    host = address[0]
    if not is_loopback(host):
        raise InputError(
            f"--view serves this machine only: give a loopback host (127.0.0.1, localhost, "
            f"::1), got {host!r}",
            name="--view",
            value=address,
        )
