"""A headless franky-sim server on a loopback address, for tests and CI.

franky-sim (the extra ``robots``, or ``dev``) simulates an FR3 in MuJoCo and speaks
libfranka's network protocol on port 1337, so :class:`~qpavoid.drive.franka.FrankaArm`
drives it exactly as it drives a real arm::

    with FrankySim("127.0.0.2") as sim:
        arm = FrankaArm(load_robot("fr3"), sim.host)

The server runs as a process group of its own (``franky-sim -s mujoco --hostname HOST``),
ended on exit with everything it started, even when the body raised. Each loopback
address (127.0.0.1, 127.0.0.2, ...) can hold one server, so parallel test workers each
start their own on an address of their own; a server takes one client at a time.

It is ready about 2 s after launch on an idle machine (MuJoCo's model compiled, the port
bound); :attr:`FrankySim.startup_timeout_s` bounds the wait. The joint states franky
reports (``robot.state``) are the simulator's MuJoCo physics: the truth of a test.
"""

from __future__ import annotations

import contextlib
import ipaddress
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import TracebackType
from typing import IO

from qpavoid.core.errors import InputError

__all__ = ["FCI_PORT", "FrankySim", "FrankySimError"]

#: The TCP port of libfranka's command connection (fixed by libfranka).
FCI_PORT = 1337
#: How often the start-up polls the port, s.
_POLL_S = 0.05
#: How long the server has to end on SIGTERM before it is killed, s.
_TERM_WAIT_S = 5.0


class FrankySimError(RuntimeError):
    """franky-sim did not start (missing, exited, or not serving in time); the message
    carries the end of its output."""


def _command(host: str) -> list[str]:
    """How to launch franky-sim with this Python: its console script beside the
    interpreter, or its module."""
    script = Path(sys.executable).parent / "franky-sim"
    if script.is_file():
        return [str(script), "-s", "mujoco", "--hostname", host]
    return [sys.executable, "-m", "franky_sim.run_server", "-s", "mujoco", "--hostname", host]


def _accepts(host: str, port: int, timeout_s: float = 0.2) -> bool:
    """Whether something accepts TCP connections on ``host:port`` now."""
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            return True
    except OSError:
        return False


class FrankySim:
    """A franky-sim server on ``host`` (loopback) for the length of a ``with`` block.

    Parameters
    ----------
    host
        A loopback address (``127.x.y.z``) no other server uses.
    startup_timeout_s
        How long to wait for the server to accept connections, s.

    Raises
    ------
    InputError
        ``host`` is not a loopback address.
    FrankySimError
        On entry: something already serves ``host:1337``, franky-sim is not installed or
        exited, or it did not serve within ``startup_timeout_s``.
    """

    def __init__(self, host: str = "127.0.0.1", *, startup_timeout_s: float = 60.0):
        try:
            loopback = ipaddress.ip_address(host).is_loopback
        except ValueError:
            loopback = False
        if not loopback:
            raise InputError(
                f"FrankySim serves on a loopback address (127.x.y.z), not {host!r}",
                name="host",
                value=host,
            )
        self.host = host
        self.startup_timeout_s = float(startup_timeout_s)
        self.startup_s = float("nan")
        self._process: subprocess.Popen[bytes] | None = None
        self._log: IO[bytes] | None = None

    @property
    def pid(self) -> int:
        """The server's process id (its process group's too)."""
        if self._process is None:
            raise FrankySimError(f"franky-sim on {self.host} is not running")
        return self._process.pid

    def running(self) -> bool:
        """Whether the server process is alive (paused counts as alive)."""
        return self._process is not None and self._process.poll() is None

    def output(self) -> str:
        """What the server printed so far."""
        if self._log is None:
            return ""
        self._log.flush()
        return Path(self._log.name).read_text(errors="replace")

    def start(self) -> None:
        """Launch the server and wait until it accepts connections on port 1337."""
        if self._process is not None:
            return
        if _accepts(self.host, FCI_PORT):
            raise FrankySimError(
                f"something already serves {self.host}:{FCI_PORT}; pick another loopback address"
            )
        # the server's output, kept (and deleted) with the server: closed by stop()
        self._log = tempfile.NamedTemporaryFile(prefix="franky-sim-", suffix=".log")  # noqa: SIM115
        t0 = time.monotonic()
        try:
            self._process = subprocess.Popen(
                _command(self.host),
                stdin=subprocess.DEVNULL,
                stdout=self._log,
                stderr=subprocess.STDOUT,
                start_new_session=True,  # a process group of its own, ended as one
                env={**os.environ, "PYTHONUNBUFFERED": "1"},
            )
        except OSError as e:
            self._close_log()
            raise FrankySimError(f"cannot launch franky-sim ({e}); pip install franky-sim") from e
        try:
            self._wait_serving(t0)
        except BaseException:
            self.stop()
            raise
        self.startup_s = time.monotonic() - t0

    def _wait_serving(self, t0: float) -> None:
        assert self._process is not None
        while not _accepts(self.host, FCI_PORT):
            if self._process.poll() is not None:
                tail = self.output().strip().splitlines()[-5:]
                raise FrankySimError(
                    f"franky-sim on {self.host} exited with code {self._process.returncode}: "
                    + " | ".join(tail)
                )
            if time.monotonic() - t0 > self.startup_timeout_s:
                raise FrankySimError(
                    f"franky-sim on {self.host} did not serve port {FCI_PORT} within "
                    f"{self.startup_timeout_s:g} s"
                )
            time.sleep(_POLL_S)

    def _signal(self, sig: signal.Signals) -> None:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(self.pid, sig)

    def pause(self) -> None:
        """Freeze the server (SIGSTOP): its state stops streaming, as a stalled arm's."""
        self._signal(signal.SIGSTOP)

    def resume(self) -> None:
        """Let a paused server go on (SIGCONT)."""
        self._signal(signal.SIGCONT)

    def kill(self) -> None:
        """Kill the server at once (SIGKILL), as an arm that drops off the network."""
        if self._process is not None:
            self._signal(signal.SIGKILL)
            self._process.wait()

    def stop(self) -> None:
        """End the server and its process group (SIGTERM, then SIGKILL); idempotent."""
        process = self._process
        if process is not None:
            if process.poll() is None:
                self._signal(signal.SIGTERM)
                self._signal(signal.SIGCONT)  # a paused server acts on SIGTERM only now
                with contextlib.suppress(subprocess.TimeoutExpired):
                    process.wait(_TERM_WAIT_S)
            # whatever is left of the group (the leader's children), killed in any case
            self._signal(signal.SIGKILL)
            process.wait()
            self._process = None
        self._close_log()

    def _close_log(self) -> None:
        if self._log is not None:
            self._log.close()
            self._log = None

    def __enter__(self) -> FrankySim:
        self.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()
