"""The Franka arm driven through a binding of libfranka: what the adapters share.

:class:`LibfrankaArm` is the :class:`~qpavoid.drive.interface.Arm` both adapters are
(:class:`~qpavoid.drive.franka.FrankaArm` on franky-control, the FR3;
:class:`~qpavoid.drive.panda.PandaArm` on panda-python, the Panda): the description's
joints among the arm's seven (:mod:`~qpavoid.drive.franka_joints`), the arm's model
checked at connect (:mod:`~qpavoid.drive.franka_model`), the connection within a bounded
time (:mod:`~qpavoid.drive.libfranka_connection`), every command checked against the
limits before it is sent (never clipped), the arm's clock watched for a stall, its errors
kept (its connection is not used again), rest judged from the joint angles
(:mod:`~qpavoid.drive.libfranka_state`), a locked joint held at its angle. A binding
implements how the arm is reached, its state read, a velocity streamed, the arm stopped
and moved (the methods marked "binding" below).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from types import TracebackType
from typing import Any, ClassVar, TypeVar

import numpy as np

from qpavoid.arm.model import Robot
from qpavoid.core.errors import ArmError
from qpavoid.drive.franka_joints import LOCK_TOLERANCE_RAD, FrankaJoints
from qpavoid.drive.franka_model import Binding, FrankaModel
from qpavoid.drive.interface import ArmState
from qpavoid.drive.libfranka_connection import (
    binding_error,
    connect_error,
    connect_within,
    is_loopback,
)
from qpavoid.drive.libfranka_state import RawState, wait_for_rest
from qpavoid.drive.limits import CommandCheck, CommandLimits

__all__ = ["LibfrankaArm"]

T = TypeVar("T")


class LibfrankaArm:
    """A Franka arm driven through a binding of libfranka, as an
    :class:`~qpavoid.drive.interface.Arm` (a base: :class:`~qpavoid.drive.franka.FrankaArm`,
    :class:`~qpavoid.drive.panda.PandaArm`).

    Parameters
    ----------
    robot
        The arm's description (``load_robot("fr3")``); its active joints are the vectors',
        its ``franka.toml`` says which arm must answer.
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
        How long a command is held without a newer one, at most, s (the loop's watchdog
        stops the arm after that long in any case).
    stop_timeout_s
        How long :meth:`stop` (and :meth:`move_to`'s settling) waits for rest, s.
    move_dynamics_factor
        The fraction of the arm's speed :meth:`move_to` moves at.
    realtime
        Require a real-time kernel (libfranka's ``RealtimeConfig`` Enforce); off, it runs
        on any kernel, with less timing margin on a real arm. None (the default): required
        for every address but a loopback one (franky-sim on this machine).

    Raises
    ------
    InputError
        The binding is not installed, the description is not a Franka arm's or does not
        say which one (no ``franka.toml``).
    ArmError
        "unreachable": no connection within ``connect_timeout_s`` (refused, unknown host,
        no answer, a version of libfranka's protocol the binding does not speak); "model":
        the arm is not the description's
        (:meth:`~qpavoid.drive.franka_model.FrankaModel.check`); "fault": the arm
        reports errors that its automatic recovery cannot clear.
    """

    #: The binding (a subclass's).
    binding: ClassVar[Binding]

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
        self._lib = self._require()
        self.name = f"{self.binding.kind}:{host}"
        self.host = host
        self.joint_names = tuple(robot.joint_names)
        self.joints = FrankaJoints.of(robot)
        self.model = FrankaModel.of(robot)
        self.period_s = float(period_s)
        self.stall_timeout_s = float(stall_timeout_s)
        self.watchdog_s = float(watchdog_s)
        self.stop_timeout_s = float(stop_timeout_s)
        self.move_dynamics_factor = float(move_dynamics_factor)
        #: The model the arm's controller names, if it names one (libfranka >= 0.15's URDF).
        self.reported_model: str | None = None
        self._q_min, self._q_max = robot.q_min.copy(), robot.q_max.copy()
        self._failure: ArmError | None = None
        self._streaming = False
        if realtime is None:  # a real arm needs a real-time kernel; franky-sim on loopback not
            realtime = not is_loopback(host)
        self._robot: Any = self._open(realtime, float(connect_timeout_s))
        try:
            self.model.check(self.name, self._server_version(), self.reported_model)
            self.limits = self._set_limits(robot)
            self._check = CommandCheck(self.limits)
            n = len(self.joint_names)
            self._sent = (np.zeros(n), np.zeros(n))
            self._prepare()
            state = self._state()
        except BaseException:
            self._release()
            raise
        self._last_time_ms = state.time_ms
        self._last_advance = time.monotonic()

    # -- the binding ------------------------------------------------------------------------

    def _require(self) -> Any:
        """Binding: its module, or :class:`InputError` naming the extra to install."""
        raise NotImplementedError

    def _make(self, realtime: bool) -> Any:
        """Binding: connect to ``self.host`` (blocking; libfranka's exceptions raised)."""
        raise NotImplementedError

    def _server_version(self) -> int:
        """Binding: the version of libfranka's protocol the connected arm speaks (and
        ``self.reported_model``, where the arm names its model)."""
        raise NotImplementedError

    def _set_limits(self, robot: Robot) -> CommandLimits:
        """Binding: the limits every command is checked against (set in the binding too,
        where it has its own)."""
        raise NotImplementedError

    def _prepare(self) -> None:
        """Binding: anything to do once connected, before the first state is read."""

    def _read(self) -> RawState:
        """Binding: the arm's newest state, after any error of the binding's control thread."""
        raise NotImplementedError

    def _stream(self, v7: np.ndarray) -> None:
        """Binding: command the arm's seven joint velocities ``v7`` (checked), rad/s, held
        until the next command (at most ``watchdog_s``)."""
        raise NotImplementedError

    def _halt(self) -> None:
        """Binding: bring a moving arm to rest at its own deceleration (returns once the
        binding's stop has ended; :meth:`stop` then waits for rest)."""
        raise NotImplementedError

    def _rested(self) -> None:
        """Binding: the arm is at rest after a stop (release what held it)."""

    def _move(self, q7: np.ndarray, timeout_s: float) -> None:
        """Binding: move the arm to the seven angles ``q7``, rad, slowly, and return once the
        motion has ended."""
        raise NotImplementedError

    def _in_control(self) -> bool:
        """Binding: whether a motion of this client runs on the arm."""
        raise NotImplementedError

    # -- connection and errors --------------------------------------------------------------

    def _open(self, realtime: bool, timeout_s: float) -> Any:
        """The binding's connection, or the :class:`ArmError` of its failure: "model" for an
        arm of another model than the description's, "unreachable" otherwise."""
        try:
            return connect_within(lambda: self._make(realtime), timeout_s, self.name, self.host)
        except ArmError:
            raise
        except Exception as e:
            raise connect_error(e, self.name, self.host, self.model, self.binding) from None

    def _release(self) -> None:
        """Drop the binding's robot (libfranka disconnects when it is released)."""
        robot, self._robot = self._robot, None
        del robot

    def _usable(self) -> Any:
        """The binding's robot, or the arm's standing failure raised."""
        if self._robot is None:
            raise ArmError(f"{self.name}: closed", arm=self.name, reason="unreachable")
        if self._failure is not None:
            raise self._failure
        return self._robot

    def _call(self, f: Callable[..., T], *args: Any, **kwargs: Any) -> T:
        """``f(*args)``, a binding's call: its exception becomes the arm's standing failure."""
        try:
            return f(*args, **kwargs)
        except Exception as e:
            if isinstance(e, ArmError):
                raise
            raise self._fail(e) from None

    def _fail(self, e: BaseException) -> ArmError:
        """The :class:`ArmError` of the binding's exception ``e``, kept: the connection is
        not used again (libfranka's robot is unusable after a network or control error)."""
        self._failure = binding_error(e, self.name)
        self._streaming = False
        return self._failure

    def _state(self) -> RawState:
        """The arm's newest state; "fault" if it reports one (kept)."""
        self._usable()
        state = self._read()
        if state.fault is not None:
            self._failure = ArmError(
                f"{self.name}: the arm reports {state.fault}",
                arm=self.name,
                reason="fault",
                value=state.fault,
            )
            raise self._failure
        return state

    # -- the Arm protocol -------------------------------------------------------------------

    def read(self) -> ArmState:
        """The arm's newest measured state and its time.

        While a motion runs this is the binding's newest 1 kHz state (no waiting); at rest
        it is read from the arm (about one period; libfranka gives up after 1 s).

        Raises
        ------
        ArmError
            "stalled" if the arm's clock has not advanced for ``stall_timeout_s`` (wall
            clock); "fault" (or "stalled"/"unreachable" for network errors) if the binding
            reports an error.
        """
        state = self._state()
        now = time.monotonic()
        if state.time_ms != self._last_time_ms:
            self._last_time_ms, self._last_advance = state.time_ms, now
        elif now - self._last_advance > self.stall_timeout_s:
            age = now - self._last_advance
            raise ArmError(
                f"{self.name}: the arm's state has not advanced for {age:.3f} s "
                f"(more than {self.stall_timeout_s:g} s)",
                arm=self.name,
                reason="stalled",
                value=age,
            )
        return self._arm_state(state)

    def _arm_state(self, state: RawState) -> ArmState:
        return ArmState(
            state.time_ms / 1000.0,
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
            angle; "fault" (or a network reason) if the binding fails.
        """
        self._usable()
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
        self._stream(self.joints.velocity(u))
        self._streaming = True
        self._sent = (u, self._sent[0])

    def _check_locked(self, q7: np.ndarray) -> None:
        errors = self.joints.lock_errors(np.asarray(q7, dtype=float))
        off = {n: e for n, e in errors.items() if not abs(e) <= LOCK_TOLERANCE_RAD}
        if off:
            raise ArmError(
                f"{self.name}: locked joint(s) off their lock angle by {off} rad (more than "
                f"{LOCK_TOLERANCE_RAD:g}): move the arm to a start configuration first "
                f"({type(self).__name__}.move_to; qpavoid run --arm does)",
                arm=self.name,
                reason="rejected",
                value=off,
            )

    def _at_rest(self, what: str) -> ArmState:
        """Wait (at most ``stop_timeout_s``) until the arm is at rest
        (:func:`~qpavoid.drive.libfranka_state.wait_for_rest`); the check's history is then
        rest."""
        state = wait_for_rest(self._state, self.stop_timeout_s, self.name, what)
        self._streaming = False
        n = len(self.joint_names)
        self._check, self._sent = CommandCheck(self.limits), (np.zeros(n), np.zeros(n))
        return self._arm_state(state)

    def stop(self) -> None:
        """Ramp the arm to rest at its own deceleration (within :attr:`limits`), and return
        once it is at rest.

        Raises
        ------
        ArmError
            The arm's standing failure; "stalled" if the stop does not end within
            ``stop_timeout_s``; what the binding reports.
        """
        self._usable()
        self._halt()
        self._at_rest("the stop")
        self._rested()

    def move_to(self, q: np.ndarray, *, timeout_s: float = 60.0) -> ArmState:
        """Move the arm to the active joints' angles ``q`` (nv,), rad, its locked joints to
        their lock angles, with the binding's joint motion at ``move_dynamics_factor`` of
        the arm's speed; return the state at rest there.

        Raises
        ------
        ArmError
            "limit" for ``q`` outside the description's joint limits; "stalled" if the
            motion does not end within ``timeout_s``; "rejected" if a locked joint ends
            more than :data:`LOCK_TOLERANCE_RAD` off its lock angle; what the binding
            reports.
        """
        self._usable()
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
            self._move(self.joints.position(target), float(timeout_s))
            errors = self.joints.lock_errors(self._state().q)
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
            if self._failure is None and self._call(self._in_control):
                self.stop()
        finally:
            self._release()

    def __enter__(self) -> LibfrankaArm:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
