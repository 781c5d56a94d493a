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

import math
import multiprocessing
import os
import threading
import time
from collections import Counter
from collections.abc import Callable
from typing import Any

from qpavoid.core import signals
from qpavoid.core.checks import is_loopback
from qpavoid.core.errors import InputError
from qpavoid.fusion.fuser import Fuser, FusionConfig
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.human.people import People
from qpavoid.human.skeleton import SkeletonFormat
from qpavoid.loop.metrics import DROP_HINTS
from qpavoid.sensing.assembly import LossConfig, LossWatch
from qpavoid.sensing.calibration import Calibration
from qpavoid.sensing.dds_input import DdsListener
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


#: Late frames are said once at least this many came (and a tenth of all, or every frame
#: of a sensor so far): a single datagram a busy machine delayed says nothing of a camera.
LATE_SAID_AFTER = 3


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
        A frame captured more than this before now is dropped on arrival (``late``), s;
        None (the default): each sensor's own age limit, its camera's latency, a frame
        and a margin (:attr:`~qpavoid.sensing.calibration.SensorCalibration.age_limit_s`,
        the fusion's own).
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

    #: What its input arrives as (the summary's "input: N datagrams").
    unit = "datagrams"

    def __init__(
        self,
        address: tuple[str, int],
        calibration: Calibration,
        workspace: Workspace | None = None,
        max_age_s: float | None = None,
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
                calibration.age_limits_s if max_age_s is None else max_age_s,
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
    skeleton
        The skeleton the people are fused on (:class:`~qpavoid.fusion.fuser.Fuser`): the
        body's landmarks (the Kinect v2's, default), or the cell's one camera format,
        whose own body model the controller then uses.
    say
        Called with a line for the operator when something about the input changes: the
        first frame of each sensor taken, frames refused as late (with the age limit and
        how to set it), datagrams of another format than the calibration's
        (:meth:`ready_line`, said at the first :meth:`frame_at`: the loop ticks).

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
        listener: Listener | DdsListener,
        fusion: FusionConfig | None = None,
        clock: Callable[[], float] = time.time,
        clear: threading.Event | None = None,
        losses: LossConfig | None = None,
        say: Callable[[str], None] | None = None,
        skeleton: SkeletonFormat = KINECT_V2,
    ):
        self.listener = listener
        self.fuser = Fuser(listener.calibration, fusion, skeleton)
        self.say = say or (lambda line: None)
        self._talks = say is not None  # the ready line made only for someone to read it
        #: when each sensor's first frame was taken (run clock, s) and its age then, s
        self.first_taken: dict[str, tuple[float, float]] = {}
        self._said: set[tuple[str, str]] = (
            set()
        )  # what was said once (a sensor's late, wrong format)
        self._look_s = 0.0  # when the listener's counters are next looked at, run clock
        self._late_here: dict[str, float] = {}  # the age of each sensor's last late frame
        #: which fusion the people handed out are: it changes whenever their content does
        #: (a camera's new frame, a frame aged out, someone dropped), so the controller
        #: takes a later camera's frame as new though the newest capture time stands
        self.frame_id = 0
        self._content: tuple = ()
        self.clock = clock
        self.clear = clear
        self.start_s: float | None = None  # the wall time of run time 0, set on first use
        self.counters = self.fuser.counters  # out of order, duplicates, outliers, late
        self.alert = ""
        self._captured = float("-inf")
        self._losses = LossWatch(losses)
        self._stale_before = {name: float("-inf") for name in listener.calibration.names}

    @property
    def unit(self) -> str:
        """What the input arrives as: "datagrams" (UDP) or "messages" (ROS 2)."""
        return self.listener.unit

    def report(self) -> dict[str, int]:
        """What came in and what was dropped, by reason (``metrics.json``: ``input``)."""
        counts = Counter(self.listener.counters)
        counts.update({k: v for k, v in self.counters.items() if v})
        return dict(sorted(counts.items()))

    def frame_at(self, t: float) -> tuple[People, float]:
        """Everybody fused at run time ``t`` and the capture time (run clock) of the newest
        frame used (``-inf`` before the first)."""
        if self.start_s is None:  # the loop's first tick: ready now (not when bound: a
            self.start_s = self.clock() - t  # fresh install compiles for seconds between)
            if self._talks:
                self.say(self.ready_line())
        calibration = self.listener.calibration
        for frame in self.listener.drain():
            frame = frame._replace(t=frame.t - self.start_s)
            limit = self.fuser.max_age_s[frame.sensor]
            captured = frame.t + calibration[frame.sensor].time_offset_s
            if captured < t - limit:
                # accepted by the receiver, too old by the time the loop took it: counted
                # apart from the receiver's own "late" (refused on arrival), which a frame
                # accepted then dropped here was counted twice as (301 of 300 sent, once)
                self.counters["late_when_taken"] += 1
                self._late_here[frame.sensor] = t - captured  # said if late ones add up
            elif captured > t + limit:  # a clock ahead of ours: never trusted (counted
                self.counters["from_the_future_when_taken"] += 1  # apart: one of accepted)
            elif self.fuser.add(frame) and frame.sensor not in self.first_taken:
                self.first_taken[frame.sensor] = (t, t - captured)
                self.say(
                    f"{frame.sensor}: first frame taken at {t:.2f} s, "
                    f"{1e3 * (t - captured):.0f} ms old (its age limit "
                    f"{1e3 * limit:.0f} ms)"
                )
        if t >= self._look_s:  # what the receiver refused, looked at twice a second
            self._look_s = t + 0.5
            self._refusals()
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
            f"person {pid} unseen for {gone:.1f} s, their torso last seen {where:.2f} m from "
            "the robot's base: "
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
        content = (fused.captured_s, tuple((p.id, p.captured_s, p.sensors) for p in fused.people))
        if content != self._content:  # a later camera's frame, someone dropped: new
            self._content = content
            self.frame_id += 1
        lags = tuple(
            max(self._captured - p.captured_s, 0.0) if p.captured_s > -math.inf else 0.0
            for p in fused.people
        )
        people = People(
            tuple(p.id for p in fused.people), tuple(p.frame for p in fused.people), lags
        )
        return people, self._captured

    def sensors_report(self) -> dict[str, dict[str, Any]]:
        """Each sensor as the run used it (``metrics.json``: ``sensors``): its format,
        the latency and age limit counted, s, and when its first frame was taken (run
        clock, s) and how old it was then, s (None: no frame of it was taken)."""
        out: dict[str, dict[str, Any]] = {}
        for name, cal in self.listener.calibration.sensors.items():
            first = self.first_taken.get(name)
            out[name] = {
                "format": cal.format,
                "latency_s": cal.latency_used_s,
                "latency_from": "given" if cal.latency_s is not None else "format",
                "age_limit_s": self.fuser.max_age_s[name],
                "first_frame_taken_s": None if first is None else round(first[0], 6),
                "first_frame_age_s": None if first is None else round(first[1], 6),
            }
        return out

    def ready_line(self) -> str:
        """What the listener listens for, in one line: the address, each sensor with its
        format and age limit, and whether datagrams must be signed."""
        if hasattr(self.listener, "ready_line"):  # a ROS 2 input says its own
            return str(self.listener.ready_line())
        calibration = self.listener.calibration
        host, port = self.listener.address
        sensors = ", ".join(
            f"{name} ({cal.format}, age limit {1e3 * self.fuser.max_age_s[name]:.0f} ms)"
            for name, cal in calibration.sensors.items()
        )
        signed = (
            f"signed datagrams of cell {calibration.cell!r}"
            if calibration.authenticated
            else "unsigned datagrams (loopback only)"
        )
        return f"listening on {host}:{port} for {sensors}: {signed}"

    def _late(self, sensor: str, age_s: float | None) -> None:
        """Say once per sensor that its frames come older than its age limit."""
        if ("late", sensor) in self._said:
            return
        self._said.add(("late", sensor))
        cal = self.listener.calibration[sensor]
        seen = f" ({1e3 * age_s:.0f} ms old)" if age_s is not None else ""
        self.say(
            f"{sensor}: frames refused as late{seen}: {cal.age_limit_reason()}. If its "
            "latency is longer, measure it (qpavoid latency) and set latency_s for it in the "
            "calibration, or --latency; else check the clocks (time_offset_s) and the network"
        )

    def _refusals(self) -> None:
        """Say once what was refused that the operator can fix: late frames once they add
        up (at least :data:`LATE_SAID_AFTER` and a tenth of what came, or every frame of a
        sensor so far: one datagram the machine delayed is no camera's latency; by the
        sensor seen late here, else the first not yet taken), datagrams of another format,
        and each drop reason with a hint (a wrong key, unsigned datagrams, ...)."""
        counts = self.report()
        late = counts.get("late", 0) + counts.get("late_when_taken", 0)
        received = counts.get("received", 0)
        names = self.listener.calibration.names
        waiting = [n for n in names if n not in self.first_taken]
        if late >= LATE_SAID_AFTER and (late >= 0.1 * received or waiting):
            late_here = [n for n in names if n in self._late_here]
            for sensor in late_here or waiting[:1] or names[:1]:
                self._late(sensor, self._late_here.get(sensor))
        for reason, hint in DROP_HINTS.items():
            own_line = reason in ("late", "late_when_taken", "dropped_wrong_format")
            if counts.get(reason, 0) and not own_line and ("drop", reason) not in self._said:
                self._said.add(("drop", reason))
                self.say(f"datagrams dropped as {reason.removeprefix('dropped_')}: {hint}")
        for sensor, (arrived, expected) in self.listener.format_mismatches().items():
            if ("format", sensor) not in self._said:
                self._said.add(("format", sensor))
                self.say(
                    f"{sensor}: datagrams of {arrived} frames dropped: the calibration "
                    f"{self.listener.calibration.path or ''} says {expected} (its format "
                    f"key); send {expected} frames or set format = {arrived!r}"
                )
