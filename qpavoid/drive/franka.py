"""A Franka arm (FR3, Panda) driven through ``franky-control``: joint velocities at the
loop's rate, its measured state and clock, a stop at its own deceleration.

``franky-control`` (the extra ``franka``: ``pip install "qpavoid[franka]"``) bundles
libfranka, which talks to the arm's controller (or to franky-sim, its simulator:
:mod:`qpavoid.drive.franka_sim`) at 1 kHz from a real-time thread of its own. Each
:meth:`FrankaArm.send` hands that thread a new target (``robot.move(JointVelocityMotion,
asynchronous=True)`` replaces the running motion at the next 1 ms cycle); franky reaches
it along a Ruckig profile within the joint limits set here, so a command stream that keeps
those limits (checked by :class:`~qpavoid.drive.limits.CommandCheck`, never clipped) is
followed within a cycle or two. A target is held for :attr:`FrankaArm.watchdog_s` only:
when the loop stops sending (it hangs, its process dies), the arm ramps itself to rest.

Joints: the description's active joints are some of the arm's seven (``fr3_joint1`` ...
``fr3_joint7``); a locked joint (the FR3's ``fr3_joint3`` in the paper's six-joint mode)
is held at its lock angle (velocity 0), and streaming refuses to start unless the arm's
locked joint is within :data:`LOCK_TOLERANCE_RAD` of it (:meth:`FrankaArm.move_to` puts it
there). The fingers (``held``) are the gripper's, not driven here.

Limits: franky refuses (faults on) a velocity target beyond its own joint limits, which
for franky 2.0 are the Panda's (2.175 rad/s on joints 1-4, 2.61 on 5-7; 7.5 rad/s² on
joint 2), tighter than the FR3's published ones in places. The limits the adapter sets
in franky and checks every command against are, per joint, the tighter of the
description's (``CommandLimits.of``) and franky's maxima (:attr:`FrankaArm.limits`).
"""

from __future__ import annotations

import dataclasses
import ipaddress
import re
import threading
import time
from dataclasses import dataclass
from types import TracebackType
from typing import Any

import numpy as np

from qpavoid.arm.model import Robot
from qpavoid.core.errors import ArmError, InputError
from qpavoid.drive.interface import ArmState
from qpavoid.drive.limits import CommandCheck, CommandLimits

try:
    import franky  # type: ignore[import-untyped]
except ImportError:  # the extra `franka` is not installed
    franky = None

__all__ = ["LOCK_TOLERANCE_RAD", "FrankaArm", "FrankaJoints"]

#: How far the arm's locked joint may be from its lock angle for streaming to start, rad:
#: 3 mrad, 2.4 mm at the FR3's 0.8 m reach, within the 5 mm the capsules carry for their
#: fit (Z_r); franky-sim's position loop settles its joint 3 up to 1.4 mrad off a target.
LOCK_TOLERANCE_RAD = 3e-3
#: Joint speed below which the arm counts as at rest, rad/s, judged from its joint angles
#: over :data:`REST_WINDOW_S` (not its reported velocities: franky-sim's wrist, stopped after
#: moving, sticks and slips, reporting ±0.06-0.1 rad/s while it creeps at up to 0.016 rad/s;
#: a real arm holds still).
REST_RADPS = 0.02
#: Over this long, s.
REST_WINDOW_S = 0.1
#: The name of a Franka arm joint: ``<arm>_joint<k>``, k = 1..7 (not a finger's).
_ARM_JOINT = re.compile(r"(?P<arm>[A-Za-z0-9]+)_joint(?P<k>[1-7])")
#: The pause between reads while waiting for rest, s.
_POLL_S = 0.002


@dataclass(frozen=True)
class FrankaJoints:
    """Where the description's joints sit among the arm's seven.

    Attributes
    ----------
    names
        The arm's seven joints, in the arm's order (``fr3_joint1`` ... ``fr3_joint7``).
    active
        (nv,) the index among the seven of each active joint, in ``robot.joint_names``
        order.
    locked
        The index among the seven of each locked joint.
    locked_angles_rad
        Their lock angles, rad.
    """

    names: tuple[str, ...]
    active: tuple[int, ...]
    locked: tuple[int, ...]
    locked_angles_rad: tuple[float, ...]

    @classmethod
    def of(cls, robot: Robot) -> FrankaJoints:
        """The map of a description with the seven joints of a Franka arm.

        Raises
        ------
        InputError
            The description's joints (active and locked) are not one Franka arm's seven
            (``<arm>_joint1`` ... ``<arm>_joint7``), or an active joint is not one of them.
        """
        found: dict[int, str] = {}
        arms = set()
        for name in (*robot.joint_names, *robot.locked):
            m = _ARM_JOINT.fullmatch(name)
            if m:
                found[int(m["k"])] = name
                arms.add(m["arm"])
        if sorted(found) != list(range(1, 8)) or len(arms) != 1:
            raise InputError(
                f"--arm franka drives a Franka arm (--robot fr3 or panda): seven joints "
                f"<arm>_joint1 ... <arm>_joint7, which the description {robot.name!r} has not "
                f"(its joints: {list(robot.joint_names) + list(robot.locked)})",
                name="robot",
                value=robot.name,
            )
        names = tuple(found[k] for k in range(1, 8))
        others = [n for n in robot.joint_names if n not in names]
        if others:
            raise InputError(
                f"the Franka adapter drives the arm's seven joints only; the description "
                f"{robot.name!r} also makes {others} active",
                name="robot",
                value=others,
            )
        locked = tuple(k for k, n in enumerate(names) if n in robot.locked)
        return cls(
            names,
            tuple(names.index(n) for n in robot.joint_names),
            locked,
            tuple(float(robot.locked[names[k]]) for k in locked),
        )

    def position(self, q: np.ndarray) -> np.ndarray:
        """The arm's seven angles (7,), rad, for the active joints' ``q`` (nv,) and the
        locked ones at their lock angles."""
        out = np.zeros(7)
        out[list(self.active)] = q
        out[list(self.locked)] = self.locked_angles_rad
        return out

    def velocity(self, dq: np.ndarray) -> np.ndarray:
        """The arm's seven joint velocities (7,), rad/s, for the active joints' ``dq``
        (nv,) and the locked ones still."""
        out = np.zeros(7)
        out[list(self.active)] = dq
        return out

    def active_of(self, v7: np.ndarray) -> np.ndarray:
        """The active joints' values (nv,) of the arm's seven (7,)."""
        return np.asarray(v7, dtype=float)[list(self.active)]

    def lock_errors(self, q7: np.ndarray) -> dict[str, float]:
        """How far each locked joint of the arm's angles ``q7`` (7,) is from its lock
        angle, rad, by name."""
        return {
            self.names[k]: float(q7[k] - angle)
            for k, angle in zip(self.locked, self.locked_angles_rad, strict=True)
        }


def _require_franky() -> Any:
    if franky is None:
        raise InputError(
            'the Franka adapter needs franky-control: pip install "qpavoid[franka]"',
            name="franky",
            value=None,
        )
    return franky


def _is_loopback(host: str) -> bool:
    """Whether ``host`` is a loopback address (a simulator's, on this machine)."""
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


def _connect(host: str, timeout_s: float, realtime: bool, arm: str) -> Any:
    """``franky.Robot(host)`` within ``timeout_s`` s, or :class:`ArmError` "unreachable".

    libfranka refuses at once when nothing listens on the address but waits 60 s for an
    address that does not answer (its TCP timeout); the connection is made in a thread of
    its own, abandoned (its robot released when it comes) after ``timeout_s``.
    """
    fk = _require_franky()
    config = fk.RealtimeConfig.Enforce if realtime else fk.RealtimeConfig.Ignore
    box: dict[str, Any] = {}
    lock, done = threading.Lock(), threading.Event()

    def connect() -> None:
        try:
            robot = fk.Robot(host, realtime_config=config)
        except Exception as e:  # libfranka's: NetworkException, IncompatibleVersion, ...
            box["error"] = e
        else:
            with lock:
                if "abandoned" not in box:
                    box["robot"] = robot
            del robot  # if abandoned, released here: libfranka disconnects
        finally:
            done.set()

    threading.Thread(target=connect, name=f"connect {arm}", daemon=True).start()
    done.wait(timeout_s)
    with lock:
        box["abandoned"] = True
        if "robot" in box:
            return box["robot"]
    if "error" in box:
        error = box["error"]
        raise ArmError(
            f"{arm}: cannot connect ({type(error).__name__}: {error})",
            arm=arm,
            reason="unreachable",
            value=host,
        ) from None
    raise ArmError(
        f"{arm}: no answer from {host} within {timeout_s:g} s "
        "(is the arm on, FCI enabled, the address right?)",
        arm=arm,
        reason="unreachable",
        value=host,
    )


class FrankaArm:
    """A Franka arm (or franky-sim) as an :class:`~qpavoid.drive.interface.Arm`.

    Parameters
    ----------
    robot
        The arm's description (``load_robot("fr3")``); its active joints are the vectors'.
    host
        The arm's FCI address (``"172.16.0.2"``; franky-sim's loopback address).
    period_s
        The period the loop sends commands at, s (the command checks' dt).
    connect_timeout_s
        How long to wait for the connection, s.
    stall_timeout_s
        How long the arm's clock may stand still (wall clock) before :meth:`read` raises
        "stalled", s.
    watchdog_s
        How long a command is held without a newer one before the arm ramps itself to
        rest, s (franky's hold duration; millisecond resolution).
    stop_timeout_s
        How long :meth:`stop` (and :meth:`move_to`'s settling) waits for rest, s.
    move_dynamics_factor
        The fraction of the joint limits :meth:`move_to` moves at (velocity, acceleration
        and jerk).
    realtime
        Require a real-time kernel (libfranka's ``RealtimeConfig.Enforce``); off, it runs
        on any kernel, with less timing margin on a real arm. None (the default): required
        for every address but a loopback one (franky-sim on this machine).

    Raises
    ------
    InputError
        franky-control is not installed, or the description is not a Franka arm's.
    ArmError
        "unreachable": no connection within ``connect_timeout_s`` (refused, unknown host,
        no answer); "fault": the arm reports errors that its automatic recovery cannot
        clear.
    """

    def __init__(
        self,
        robot: Robot,
        host: str,
        *,
        period_s: float = 0.002,
        connect_timeout_s: float = 5.0,
        stall_timeout_s: float = 0.05,
        watchdog_s: float = 0.1,
        stop_timeout_s: float = 5.0,
        move_dynamics_factor: float = 0.2,
        realtime: bool | None = None,
    ):
        fk = _require_franky()
        self.name = f"franka:{host}"
        self.host = host
        self.joint_names = tuple(robot.joint_names)
        self.joints = FrankaJoints.of(robot)
        self.period_s = float(period_s)
        self.stall_timeout_s = float(stall_timeout_s)
        self.watchdog_s = float(watchdog_s)
        self.stop_timeout_s = float(stop_timeout_s)
        self.move_dynamics_factor = float(move_dynamics_factor)
        self._q_min, self._q_max = robot.q_min.copy(), robot.q_max.copy()
        self._failure: ArmError | None = None
        self._streaming = False
        if realtime is None:  # a real arm needs a real-time kernel; franky-sim on loopback not
            realtime = not _is_loopback(host)
        self._robot: Any = _connect(host, float(connect_timeout_s), realtime, self.name)
        try:
            self.limits = self._set_limits(robot)
            self._check = CommandCheck(self.limits)
            self._sent = (np.zeros(len(self.joint_names)), np.zeros(len(self.joint_names)))
            self._hold = fk.Duration(max(1, round(self.watchdog_s * 1000)))
            self._call(setattr, self._robot, "relative_dynamics_factor", 1.0)
            if self._call(getattr, self._robot, "has_errors"):
                self._call(self._robot.recover_from_errors)
            state = self._call(getattr, self._robot, "state")
            self._check_errors(state)
        except BaseException:
            self._robot = None
            raise
        self._last_time_ms = int(state.time.to_msec())
        self._last_advance = time.monotonic()

    # -- limits ---------------------------------------------------------------------------

    def _set_limits(self, robot: Robot) -> CommandLimits:
        """Set franky's joint limits to the tighter of the description's and franky's, and
        return the active joints' (what every command is checked against)."""
        r = self._robot
        v_max = np.array(r.joint_velocity_limit.max, dtype=float)
        a_max = np.array(r.joint_acceleration_limit.max, dtype=float)
        j_max = np.array(r.joint_jerk_limit.max, dtype=float)
        mine = CommandLimits.of(robot, self.period_s)
        v, a, j = v_max.copy(), a_max.copy(), j_max.copy()
        described_v = dict(robot.arm.max_velocity_radps)
        described_a = dict(robot.arm.max_acceleration_radps2)
        described_j = dict(robot.arm.max_jerk_radps3)
        for k, n in enumerate(self.joints.names):
            v[k] = min(v[k], described_v.get(n, np.inf))
            a[k] = min(a[k], described_a.get(n, np.inf))
            j[k] = min(j[k], described_j.get(n, np.inf))
        active = list(self.joints.active)
        v[active] = np.minimum(v[active], mine.velocity_radps)
        a[active] = np.minimum(a[active], mine.acceleration_radps2)
        j[active] = np.minimum(j[active], mine.jerk_radps3)
        self._call(r.joint_velocity_limit.set, v.tolist())
        self._call(r.joint_acceleration_limit.set, a.tolist())
        self._call(r.joint_jerk_limit.set, j.tolist())
        return dataclasses.replace(
            mine,
            velocity_radps=v[active],
            acceleration_radps2=a[active],
            jerk_radps3=j[active],
        )

    # -- errors ---------------------------------------------------------------------------

    def _usable(self) -> Any:
        """The franky robot, or the arm's standing failure raised."""
        if self._robot is None:
            raise ArmError(f"{self.name}: closed", arm=self.name, reason="unreachable")
        if self._failure is not None:
            raise self._failure
        return self._robot

    def _call(self, f: Any, *args: Any, **kwargs: Any) -> Any:
        """``f(*args)``, a franky call: its exception becomes the arm's standing failure."""
        try:
            return f(*args, **kwargs)
        except Exception as e:
            if isinstance(e, ArmError):
                raise
            raise self._fail(e) from None

    def _fail(self, e: BaseException) -> ArmError:
        """The :class:`ArmError` of franky's exception ``e``, kept: the connection is not
        used again (libfranka's robot is unusable after a network or control error)."""
        text = str(e).strip() or type(e).__name__
        kind = type(e).__name__
        if kind == "NetworkException" or text == "Net Exception":
            reason = "stalled" if "timeout" in text.lower() else "unreachable"
        else:
            reason = "fault"
        self._failure = ArmError(
            f"{self.name}: {kind}: {text}", arm=self.name, reason=reason, value=text
        )
        self._streaming = False
        return self._failure

    def _check_errors(self, state: Any) -> None:
        """Raise "fault" if the state reports errors (a reflex) or the arm is stopped."""
        flags = state.current_errors.__getstate__()
        mode = state.robot_mode
        if any(flags) or mode in (franky.RobotMode.Reflex, franky.RobotMode.UserStopped):
            self._failure = ArmError(
                f"{self.name}: the arm reports {state.current_errors!r} in mode {mode.name}",
                arm=self.name,
                reason="fault",
                value=repr(state.current_errors),
            )
            raise self._failure

    # -- the Arm protocol -----------------------------------------------------------------

    def _state(self) -> Any:
        """franky's newest robot state, after any error of the motion thread."""
        robot = self._usable()
        self._call(robot.poll_motion)  # raises what the motion thread stored
        state = self._call(getattr, robot, "state")
        self._check_errors(state)
        return state

    def read(self) -> ArmState:
        """The arm's newest measured state and its time.

        While a motion runs this is franky's newest 1 kHz state (no waiting); at rest it
        is read from the arm (about one period; libfranka gives up after 1 s).

        Raises
        ------
        ArmError
            "stalled" if the arm's clock has not advanced for ``stall_timeout_s`` (wall
            clock); "fault" (or "stalled"/"unreachable" for network errors) if franky
            reports an error.
        """
        state = self._state()
        now, t_ms = time.monotonic(), int(state.time.to_msec())
        if t_ms != self._last_time_ms:
            self._last_time_ms, self._last_advance = t_ms, now
        elif now - self._last_advance > self.stall_timeout_s:
            age = now - self._last_advance
            raise ArmError(
                f"{self.name}: the arm's state has not advanced for {age:.3f} s "
                f"(more than {self.stall_timeout_s:g} s)",
                arm=self.name,
                reason="stalled",
                value=age,
            )
        return ArmState(
            t_ms / 1000.0,
            self.joints.active_of(state.q),
            self.joints.active_of(state.dq),
        )

    def send(self, dq: np.ndarray) -> None:
        """Stream the joint velocities ``dq`` (nv,), rad/s, to the arm.

        Raises
        ------
        ArmError
            "limit" (nothing sent) for a command beyond :attr:`limits` at ``period_s``
            from the previous one (velocity, acceleration, jerk; or not finite);
            "rejected" for a command of the wrong shape, or a first command from rest
            while a locked joint is more than :data:`LOCK_TOLERANCE_RAD` off its lock
            angle; "fault" (or a network reason) if franky fails.
        """
        robot = self._usable()
        u = np.array(dq, dtype=float)
        if u.shape != (len(self.joint_names),):
            raise ArmError(
                f"{self.name}: a command has {len(self.joint_names)} joint velocities, "
                f"not shape {u.shape}",
                arm=self.name,
                reason="rejected",
                value=u.shape,
            )
        if not self._streaming:
            self._check_locked(self._state().q)
        why = self._check(u)
        if why:
            # the check's history: the commands sent, not this one
            self._check = CommandCheck(self.limits)
            self._check(self._sent[1])
            self._check(self._sent[0])
            raise ArmError(
                f"{self.name}: command refused, {why}", arm=self.name, reason="limit", value=u
            )
        motion = franky.JointVelocityMotion(self.joints.velocity(u), duration=self._hold)
        self._call(robot.move, motion, asynchronous=True)
        self._streaming = True
        self._sent = (u, self._sent[0])

    def _check_locked(self, q7: np.ndarray) -> None:
        errors = self.joints.lock_errors(np.asarray(q7, dtype=float))
        off = {n: e for n, e in errors.items() if not abs(e) <= LOCK_TOLERANCE_RAD}
        if off:
            raise ArmError(
                f"{self.name}: locked joint(s) off their lock angle by {off} rad (more than "
                f"{LOCK_TOLERANCE_RAD:g}): move the arm to a start configuration first "
                "(FrankaArm.move_to; qpavoid run --arm does)",
                arm=self.name,
                reason="rejected",
                value=off,
            )

    def _at_rest(self, what: str) -> ArmState:
        """Wait (at most ``stop_timeout_s``) until every joint is slower than
        :data:`REST_RADPS`; the check's history is then rest."""
        t_end = time.monotonic() + self.stop_timeout_s
        seen: list[tuple[float, np.ndarray]] = []  # (wall time, the joint angles)
        while True:
            state = self._state()
            now, q7 = time.monotonic(), np.array(state.q, dtype=float)
            seen.append((now, q7))
            while len(seen) > 1 and seen[1][0] <= now - REST_WINDOW_S:
                seen.pop(0)
            span = now - seen[0][0]
            speed = float(np.max(np.abs(q7 - seen[0][1]))) / span if span > 0 else np.inf
            if span >= REST_WINDOW_S * 0.9 and speed < REST_RADPS:
                break
            if now > t_end:
                raise ArmError(
                    f"{self.name}: not at rest {self.stop_timeout_s:g} s after {what} "
                    f"(a joint at {speed:.4f} rad/s)",
                    arm=self.name,
                    reason="stalled",
                    value=speed,
                )
            time.sleep(_POLL_S)
        self._streaming = False
        n = len(self.joint_names)
        self._check, self._sent = CommandCheck(self.limits), (np.zeros(n), np.zeros(n))
        return ArmState(
            state.time.to_msec() / 1000.0,
            self.joints.active_of(state.q),
            self.joints.active_of(state.dq),
        )

    def stop(self) -> None:
        """Ramp the arm to rest at its own deceleration (franky's stop motion, at the
        joint limits of :attr:`limits`), and return once it is at rest.

        Raises
        ------
        ArmError
            The arm's standing failure; "stalled" if the stop does not end within
            ``stop_timeout_s``; what franky reports.
        """
        robot = self._usable()
        kind = self._call(getattr, robot, "current_control_signal_type")
        if kind is not None:
            stop = (
                franky.JointStopMotion()
                if kind == franky.ControlSignalType.JointPositions
                else franky.JointVelocityStopMotion()
            )
            self._call(robot.move, stop, asynchronous=True)
        if not self._call(robot.join_motion, self.stop_timeout_s):
            raise ArmError(
                f"{self.name}: the stop did not end within {self.stop_timeout_s:g} s",
                arm=self.name,
                reason="stalled",
                value=self.stop_timeout_s,
            )
        self._at_rest("the stop")

    def move_to(self, q: np.ndarray, *, timeout_s: float = 60.0) -> ArmState:
        """Move the arm to the active joints' angles ``q`` (nv,), rad, its locked joints to
        their lock angles, with franky's joint motion at ``move_dynamics_factor`` of the
        limits; return the state at rest there.

        Raises
        ------
        ArmError
            "limit" for ``q`` outside the description's joint limits; "stalled" if the
            motion does not end within ``timeout_s``; "rejected" if a locked joint ends
            more than :data:`LOCK_TOLERANCE_RAD` off its lock angle; what franky reports.
        """
        robot = self._usable()
        target = np.array(q, dtype=float)
        inside = (
            target.shape == self._q_min.shape
            and bool(np.all(target >= self._q_min))
            and bool(np.all(target <= self._q_max))
        )
        if not inside:
            raise ArmError(
                f"{self.name}: move_to target {target.tolist()} is not within the joint "
                "limits of the description",
                arm=self.name,
                reason="limit",
                value=target,
            )
        if self._streaming:
            self.stop()
        for _attempt in range(2):  # a second, short motion if the first settled off the lock
            motion = franky.JointMotion(
                self.joints.position(target), relative_dynamics_factor=self.move_dynamics_factor
            )
            self._call(robot.move, motion, asynchronous=True)
            if not self._call(robot.join_motion, float(timeout_s)):
                self._call(robot.move, franky.JointStopMotion(), asynchronous=True)
                raise ArmError(
                    f"{self.name}: move_to did not end within {timeout_s:g} s",
                    arm=self.name,
                    reason="stalled",
                    value=timeout_s,
                )
            errors = self.joints.lock_errors(np.array(self._state().q, dtype=float))
            if all(abs(e) <= LOCK_TOLERANCE_RAD for e in errors.values()):
                break
        reached = self._at_rest("move_to")
        self._check_locked(self._state().q)
        return reached

    def close(self) -> None:
        """Stop the arm if it moves and disconnect (idempotent)."""
        if self._robot is None:
            return
        try:
            if self._failure is None and self._call(getattr, self._robot, "is_in_control"):
                self.stop()
        finally:
            robot, self._robot = self._robot, None
            del robot  # libfranka disconnects when franky's robot is released

    def __enter__(self) -> FrankaArm:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
