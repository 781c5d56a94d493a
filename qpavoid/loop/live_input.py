"""Live skeletons over UDP: a listener for the controller, and the streamer that feeds it.

:class:`Listener` receives datagrams (:mod:`qpavoid.sensing.wire`) on a UDP socket in a process of
its own (:mod:`qpavoid.sensing.receiver`), which checks each (invalid ones dropped and counted by
reason: never a crash, never a stall) and keeps each body's newest frame in shared memory.
A flood therefore neither holds the interpreter lock of the control loop nor grows its
work: each tick takes at most one frame per (sensor, body), the newest (measured in
docs/sensors.md).

:class:`LiveSource` is what the control loop asks each tick: it takes those frames,
moves each frame's time stamp onto the run clock, makes the frames of a sensor that lost
one stale at once (:meth:`~qpavoid.fusion.fuser.Fuser.lose`: a frame missing or incomplete
on the way, :mod:`qpavoid.sensing.assembly`), fuses (:class:`~qpavoid.fusion.fuser.Fuser`)
and returns everybody with the capture time of the newest frame used, so the controller
judges the age of what it sees: no fresh frame for the stale limit, and it stops.

:func:`qpavoid.sensing.streamer.stream` streams per-sensor recordings to a listener in real time,
as live sensors would: the whole path runs on one machine over loopback.
"""

from __future__ import annotations

import multiprocessing
import os
import threading
import time
from collections import Counter
from collections.abc import Callable

from qpavoid.core import signals
from qpavoid.core.checks import is_loopback
from qpavoid.core.errors import InputError
from qpavoid.fusion.fuser import Fuser, FusionConfig
from qpavoid.human.people import People
from qpavoid.sensing.assembly import LossConfig, LossWatch
from qpavoid.sensing.calibration import Calibration
from qpavoid.sensing.per_sensor import BodyFrame
from qpavoid.sensing.receiver import KEY_CHECK_S, SensorLoss, SlotTable, serve
from qpavoid.sensing.signing import FUTURE_TOLERANCE_S
from qpavoid.sensing.wire import Workspace

__all__ = ["Listener", "LiveSource", "check_listening", "parse_address"]


def parse_address(text: str, name: str = "--listen", any_port: bool = False) -> tuple[str, int]:
    """``HOST:PORT`` as ``(host, port)``; :class:`InputError` if it is not one (``any_port``:
    port 0, any free one, is allowed too)."""
    host, sep, port = str(text).rpartition(":")
    ascii_port = port.isascii() and port.isdigit()  # "５００６" is a digit to Python
    low = 0 if any_port else 1
    if not sep or not host or not ascii_port or not low <= int(port) <= 65535:
        raise InputError(
            f"{name} must be HOST:PORT with a port from {low} to 65535 (e.g. 127.0.0.1:5005), "
            f"got {text!r}",
            name=name,
            value=text,
        )
    return host.strip("[]"), int(port)


class Listener:
    """UDP datagrams in, checked :class:`BodyFrame` s out (module docstring).

    The receiving runs in a process of its own (:mod:`qpavoid.sensing.receiver`, spawned: a
    script that makes a listener needs the ``if __name__ == "__main__":`` guard), started
    here and stopped by :meth:`close` (or the ``with`` block's end).

    Parameters
    ----------
    address
        ``(host, port)`` to bind (port 0: any free port; :attr:`address` tells which).
    calibration
        The sensors; a datagram from another is dropped (``unknown_sensor``).
    workspace
        Where a joint may be in the base frame; a datagram with a joint outside is dropped.
    max_age_s
        A frame captured more than this before now is dropped on arrival, s (the fusion's
        own limit, :class:`~qpavoid.fusion.fuser.FusionConfig`).
    start_timeout_s
        Longest wait for the receiver process to start and bind, s (it imports numpy and
        scipy: about 0.5 s; 30 leaves room on a loaded machine).
    accept_unauthenticated
        Also take unsigned version-1 datagrams (:mod:`qpavoid.sensing.wire`). Anybody who can
        send to the port can then hide a person (docs/security.md), so it is an explicit
        opt-in and only on a loopback address; without it the calibration must give every
        sensor a key.
    future_tolerance_s
        A frame captured more than this after now is dropped on arrival, s
        (:data:`~qpavoid.sensing.signing.FUTURE_TOLERANCE_S`).
    key_check_s
        How often the receiver looks whether the calibration or a key file changed, and
        reads them again if so (a key rotated without a stop), s.

    Raises
    ------
    InputError
        If the calibration has no keys and unsigned datagrams are not accepted, if they
        are and the address is not a loopback one, if the address cannot be bound (in
        use, not local) or the receiver does not start.
    """

    def __init__(
        self,
        address: tuple[str, int],
        calibration: Calibration,
        workspace: Workspace | None = None,
        max_age_s: float = FusionConfig.max_age_s,
        start_timeout_s: float = 30.0,
        accept_unauthenticated: bool = False,
        future_tolerance_s: float = FUTURE_TOLERANCE_S,
        key_check_s: float = KEY_CHECK_S,
    ):
        check_listening(address, calibration, accept_unauthenticated)
        self.calibration = calibration
        self.workspace = workspace or Workspace()
        context = multiprocessing.get_context("spawn")  # no fork of a threaded process
        self._table = SlotTable.create(context, calibration)  # each sensor's format's layout
        self._stop = context.Event()
        status, child_status = context.Pipe(duplex=False)
        self._process = context.Process(
            target=serve,
            args=(
                address,
                calibration,
                self.workspace,
                self._table,
                child_status,
                self._stop,
                max_age_s,
                os.getpid(),
                accept_unauthenticated,
                future_tolerance_s,
                key_check_s,
            ),
            name="qpavoid-udp",
            daemon=True,
        )
        # The receiver starts with Ctrl-C blocked (a terminal's Ctrl-C reaches the whole
        # process group; it is ours to handle, and we stop the receiver).
        with signals.blocked(signals.CTRL_C):
            self._process.start()
        child_status.close()
        try:
            if status.poll(start_timeout_s):
                outcome, value = status.recv()
            else:
                outcome, value = "error", f"the receiver did not start in {start_timeout_s} s"
        except EOFError:
            outcome, value = "error", "the receiver ended before it started"
        except BaseException:  # Ctrl-C while it starts: not left behind
            self.close()
            raise
        finally:
            status.close()
        if outcome != "ok":
            self.close()
            raise InputError(
                f"cannot listen on {address[0]}:{address[1]}: {value}",
                name="--listen",
                value=address,
            )
        self.address: tuple[str, int] = (str(value[0]), int(value[1]))

    @property
    def counters(self) -> Counter[str]:
        """Datagrams received and dropped, by reason (zeros left out)."""
        return Counter({k: v for k, v in self._table.counters().items() if v})

    def __enter__(self) -> Listener:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop the receiver process."""
        self._stop.set()
        self._process.join(timeout=2.0)
        if self._process.is_alive():
            self._process.kill()
            self._process.join()

    def drain(self) -> list[BodyFrame]:
        """Each body's newest valid frame received since the last call, oldest first (of
        whole frames only: :mod:`qpavoid.sensing.assembly`)."""
        return self._table.take()

    def losses(self) -> dict[str, SensorLoss]:
        """Each sensor's lost frames so far and the capture time before which its frames
        are stale (ask after :meth:`drain`: every loss of a frame drained is then seen)."""
        return self._table.losses()

    def format_mismatches(self) -> dict[str, tuple[str, str]]:
        """Each sensor whose datagrams came in another skeleton format than its calibrated
        one (dropped: ``dropped_wrong_format``): (the first format that arrived, the format
        expected), by name; to say once per sensor what the counter alone does not."""
        return self._table.format_mismatches()


def check_listening(
    address: tuple[str, int], calibration: Calibration, accept_unauthenticated: bool
) -> None:
    """Signed datagrams, or unsigned ones on loopback by explicit opt-in: else InputError."""
    where = f"{address[0]}:{address[1]}"
    if accept_unauthenticated and calibration.authenticated:
        raise InputError(
            "the sensors have keys: their unsigned datagrams are never believed, and "
            "--allow-unauthenticated is for a calibration without keys",
            name="--allow-unauthenticated",
            value=True,
        )
    if accept_unauthenticated and not is_loopback(address[0]):
        raise InputError(
            f"unsigned datagrams are accepted on loopback only (anybody who can send to the "
            f"port could hide a person): cannot listen on {where} with them",
            name="--listen",
            value=address,
        )
    if not accept_unauthenticated and not calibration.authenticated:
        raise InputError(
            f"the calibration{' ' + calibration.path if calibration.path else ''} gives the "
            "sensors no keys: give each a key_file (qpavoid keygen), or accept unsigned "
            "datagrams on loopback (--allow-unauthenticated)",
            name="--sensors",
            value=calibration.path,
        )


class LiveSource:
    """The control loop's view of live sensors: ``frame_at(t)`` → (people, capture time).

    Parameters
    ----------
    listener
        Where the frames come from.
    fusion
        Fusion settings.
    clock
        Wall clock (s) that datagram time stamps share; the run clock is its time since
        the first :meth:`frame_at`.
    clear
        An event another thread (the live view's server) sets to ask that the people
        flagged as suspect be cleared (:meth:`~qpavoid.fusion.fuser.Fuser.clear_flagged`); done
        at the next :meth:`frame_at`, in the control loop's thread.
    losses
        When a sensor's lost frames raise the alert
        (:class:`~qpavoid.sensing.assembly.LossConfig`).

    Attributes
    ----------
    alert
        Why the input is suspect, after the last :meth:`frame_at` ("" if it is not): a
        sensor that keeps losing frames, a sensor silent where another sees someone
        (:meth:`~qpavoid.fusion.fuser.Fuser.silent_sensors`), someone in view flagged,
        someone kept unseen near the robot
        (:meth:`~qpavoid.fusion.fuser.Fuser.kept_unseen`); logged every tick
        (``input_alert``) and shown by the live view.
    """

    def __init__(
        self,
        listener: Listener,
        fusion: FusionConfig | None = None,
        clock: Callable[[], float] = time.time,
        clear: threading.Event | None = None,
        losses: LossConfig | None = None,
    ):
        self.listener = listener
        self.fuser = Fuser(listener.calibration, fusion)
        self.clock = clock
        self.clear = clear
        self.start_s: float | None = None  # the wall time of run time 0, set on first use
        self.counters = self.fuser.counters  # out of order, duplicates, outliers, late
        self.alert = ""
        self._captured = float("-inf")
        self._losses = LossWatch(losses)
        self._stale_before = {name: float("-inf") for name in listener.calibration.names}

    def report(self) -> dict[str, int]:
        """What came in and what was dropped, by reason (``metrics.json``: ``input``)."""
        counts = Counter(self.listener.counters)
        counts.update({k: v for k, v in self.counters.items() if v})
        return dict(sorted(counts.items()))

    def frame_at(self, t: float) -> tuple[People, float]:
        """Everybody fused at run time ``t`` and the capture time (run clock) of the newest
        frame used (``-inf`` before the first)."""
        if self.start_s is None:
            self.start_s = self.clock() - t
        max_age = self.fuser.cfg.max_age_s
        for frame in self.listener.drain():
            frame = frame._replace(t=frame.t - self.start_s)
            offset = self.listener.calibration[frame.sensor].time_offset_s
            if frame.t + offset < t - max_age:
                self.counters["late"] += 1
            elif frame.t + offset > t + max_age:  # a clock ahead of ours: never trusted
                self.counters["from_the_future"] += 1
            else:
                self.fuser.add(frame)
        losses = self.listener.losses()  # after the frames: every loss they showed is seen
        for sensor, loss in losses.items():
            if loss.stale_before_s > self._stale_before[sensor]:
                self._stale_before[sensor] = loss.stale_before_s
                self.fuser.lose(sensor, loss.stale_before_s - self.start_s)
        if self.clear is not None and self.clear.is_set():
            self.clear.clear()
            self.fuser.clear_flagged()
        fused = self.fuser.fuse(t)
        lost = self._losses.alert(t, {sensor: loss.frames for sensor, loss in losses.items()})
        flags = [f"person {p.id}: {p.flag}" for p in fused.people if p.flag]
        unseen = [
            f"person {pid} unseen for {gone:.1f} s, last seen {where:.2f} m from the robot: "
            "it waits until a sensor sees them again"
            for pid, gone, where in self.fuser.kept_unseen(t)
        ]
        silent = [
            f"{sensor} sent nothing for {quiet:.1f} s while person {pid}, in its view, is "
            f"seen by {other} (the camera down, or its datagrams dropped on the way)"
            for sensor, quiet, pid, other in self.fuser.silent_sensors(t)
        ]
        self.alert = "; ".join(([lost] if lost else []) + silent + flags + unseen)
        if fused.captured_s > self._captured:
            self._captured = fused.captured_s
        people = People(tuple(p.id for p in fused.people), tuple(p.frame for p in fused.people))
        return people, self._captured
