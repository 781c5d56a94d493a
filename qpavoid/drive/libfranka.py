"""What the adapters of a Franka arm share, whichever binding of libfranka drives it.

A Franka arm's controller speaks libfranka's protocol in the version of its robot system
(its "robot server" version, told at every connection): the Panda (Franka Emika Robot,
FER) versions 2-5, which only libfranka < 0.10 speaks, the FR3 versions 6-10, which only
libfranka >= 0.10 speaks, one version per libfranka release (Franka's compatibility
matrix; each description's ``franka.toml``, :data:`MODEL_FILE`). Two adapters drive them,
each through the binding its extra installs (:data:`BINDINGS`):

* ``--arm franka:HOST``, :class:`~qpavoid.drive.franka.FrankaArm`: franky-control 2
  (libfranka 0.21, version 10: an FR3 on robot system 5.9.0 or later);
* ``--arm panda:HOST``, :class:`~qpavoid.drive.panda.PandaArm`: panda-python 1
  (libfranka 0.9.2, version 5: a Panda on robot system 4.2.1 or later).

At connect, the version the arm's controller speaks is checked against the description
the run was given (:meth:`FrankaModel.check`): a Panda answering for ``--robot fr3``, or
an FR3 for ``--robot panda``, is refused in one line naming both before anything moves;
an arm of the right model whose version the binding does not speak is refused naming the
adapter that does, if any.

:class:`LibfrankaArm` is the :class:`~qpavoid.drive.interface.Arm` both adapters are: the
description's joints among the arm's seven (:class:`FrankaJoints`), the connection within
a bounded time (:func:`connect_within`), every command checked against the limits before
it is sent (never clipped), the arm's clock watched for a stall, its errors kept (its
connection is not used again), rest judged from the joint angles, a locked joint held at
its angle. A binding implements how the arm is reached, its state read, a velocity
streamed, the arm stopped and moved (the methods marked "binding" below).
"""

from __future__ import annotations

import ipaddress
import math
import re
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from types import TracebackType
from typing import Any, ClassVar, TypeVar

import numpy as np

from qpavoid.arm.fields import unknown_keys
from qpavoid.arm.model import Robot
from qpavoid.core.checks import one_line
from qpavoid.core.errors import ArmError, InputError, RobotDescriptionError
from qpavoid.core.file_bounds import NotTOMLError, read_toml
from qpavoid.drive.interface import ArmState
from qpavoid.drive.limits import CommandCheck, CommandLimits

__all__ = [
    "BINDINGS",
    "LOCK_TOLERANCE_RAD",
    "MODEL_FILE",
    "REST_RADPS",
    "Binding",
    "FrankaJoints",
    "FrankaModel",
    "LibfrankaArm",
    "RawState",
    "connect_within",
    "refused_versions",
]

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
#: The file of a description folder that says which Franka arm it is (``model``, a name for
#: messages; ``server_versions``, the versions of libfranka's protocol its controllers
#: speak; ``[sources]``): ``robots/fr3/franka.toml``, ``robots/panda/franka.toml``.
MODEL_FILE = "franka.toml"
#: Most bytes a model file may have (each bundled one has under 2 kB).
MAX_MODEL_BYTES = 64 * 1024
#: The keys of a model file.
MODEL_KEYS = ("model", "server_versions", "sources")
#: The name of a Franka arm joint: ``<arm>_joint<k>``, k = 1..7 (not a finger's).
_ARM_JOINT = re.compile(r"(?P<arm>[A-Za-z0-9]+)_joint(?P<k>[1-7])")
#: libfranka's refusal of a connection, in every release from 0.9 to 0.21 (its
#: ``IncompatibleVersionException``; panda-python 1.0 passes it on as a RuntimeError).
_REFUSAL = re.compile(r"server version: (\d+), library version: (\d+)")
#: The pause between reads while waiting for rest, s.
_POLL_S = 0.002

T = TypeVar("T")


@dataclass(frozen=True)
class Binding:
    """A Python binding of libfranka, as an adapter's extra installs it.

    Attributes
    ----------
    kind
        The adapter's ``--arm`` kind (``franka:HOST``).
    package
        The binding's package on PyPI.
    extra
        qpavoid's extra that installs it.
    server_version
        The version of libfranka's protocol its bundled libfranka speaks (the only one it
        can connect to).
    libfranka
        That libfranka's release.
    """

    kind: str
    package: str
    extra: str
    server_version: int
    libfranka: str

    def install(self) -> str:
        """How to install it, for messages."""
        return f'pip install "qpavoid[{self.extra}]"'


#: franky-control 2.0's wheel bundles libfranka 0.21.2 and panda-python 1.x's PyPI wheels
#: libfranka 0.9.2 (read from the wheels); the versions they speak are what each offers
#: at connect (tests/test_franka.py and tests/test_panda.py check both on the bindings
#: themselves).
FRANKY = Binding("franka", "franky-control", "franka", 10, "0.21")
PANDA_PY = Binding("panda", "panda-python", "panda", 5, "0.9.2")
BINDINGS = (FRANKY, PANDA_PY)


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
                f"--arm franka and panda drive a Franka arm (--robot fr3 or panda): seven "
                f"joints <arm>_joint1 ... <arm>_joint7, which the description {robot.name!r} "
                f"has not (its joints: {list(robot.joint_names) + list(robot.locked)})",
                name="robot",
                value=robot.name,
            )
        names = tuple(found[k] for k in range(1, 8))
        others = [n for n in robot.joint_names if n not in names]
        if others:
            raise InputError(
                f"the Franka adapters drive the arm's seven joints only; the description "
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


@dataclass(frozen=True)
class FrankaModel:
    """Which Franka arm a description is: its folder's ``franka.toml`` (:data:`MODEL_FILE`).

    Attributes
    ----------
    name
        The arm's model, as Franka names it (``"FR3"``, ``"Panda (FER)"``).
    server_versions
        The versions of libfranka's protocol its controllers speak (one per robot system
        generation).
    robot
        The description's name, as ``--robot`` takes it.
    """

    name: str
    server_versions: tuple[int, ...]
    robot: str

    @classmethod
    def of(cls, robot: Robot) -> FrankaModel:
        """The model of a description, from the ``franka.toml`` beside its control-point file.

        Raises
        ------
        InputError
            The description has no ``franka.toml`` (a Franka arm it does not say which).
        RobotDescriptionError
            The file cannot be read, is not TOML, or its keys are not a model's.
        """
        folder = None if robot.path is None else Path(robot.path).parent
        if folder is None or not (folder / MODEL_FILE).is_file():
            raise InputError(
                f"the description {robot.name!r} does not say which Franka arm it is (no "
                f"{MODEL_FILE} beside its control-point file, as robots/fr3 and robots/panda "
                "have: docs/real-robot.md §1b)",
                name="robot",
                value=robot.name,
            )
        return cls.read(folder / MODEL_FILE, robot.name)

    @classmethod
    def read(cls, path: Path, robot: str) -> FrankaModel:
        """Read the model file at ``path`` of the description ``robot``.

        Raises
        ------
        RobotDescriptionError
            The file cannot be read, is not TOML, has an unknown key, no ``model`` text or
            no ``server_versions`` list of whole numbers from 1 to 65535.
        """
        try:
            data = read_toml(path, MAX_MODEL_BYTES)
        except NotTOMLError as exc:
            raise RobotDescriptionError(f"{path}: {one_line(exc)}", path=path) from None
        except (OSError, ValueError) as exc:
            raise RobotDescriptionError(
                f"{path}: cannot read the model file: {one_line(exc)}", path=path
            ) from None
        unknown_keys(data, MODEL_KEYS, "the top level", path, "")
        name, versions = data.get("model"), data.get("server_versions")
        if not isinstance(name, str) or not name.strip():
            raise RobotDescriptionError(
                f'{path}: model must name the arm (model = "FR3"), got {name!r}',
                path=path,
                name="model",
                value=name,
            )
        if not (
            isinstance(versions, list)
            and versions
            and all(
                isinstance(v, int) and not isinstance(v, bool) and 1 <= v <= 65535 for v in versions
            )
        ):
            raise RobotDescriptionError(
                f"{path}: server_versions must list the versions of libfranka's protocol the "
                f"arm speaks, whole numbers from 1 to 65535 (server_versions = [10]), got "
                f"{versions!r}",
                path=path,
                name="server_versions",
                value=versions,
            )
        return cls(name.strip(), tuple(sorted(set(versions))), robot)

    def speaks(self, version: int) -> bool:
        """Whether this model's controllers speak ``version`` of libfranka's protocol."""
        return version in self.server_versions

    def versions_text(self) -> str:
        """Its versions, for messages (``"2-5"``, ``"6-10"``, ``"3, 5"``)."""
        v = self.server_versions
        if len(v) > 1 and v == tuple(range(v[0], v[-1] + 1)):
            return f"{v[0]}-{v[-1]}"
        return ", ".join(map(str, v))

    def check(self, arm: str, version: int, reported: str | None = None) -> None:
        """Refuse the arm ``arm`` whose controller speaks ``version`` of libfranka's protocol
        (and names its model ``reported``, if it does) unless this model speaks it.

        Raises
        ------
        ArmError
            "model": another arm answered (:meth:`mismatch`).
        """
        error = self.mismatch(arm, version, reported)
        if error is not None:
            raise error

    def mismatch(self, arm: str, version: int, reported: str | None = None) -> ArmError | None:
        """None if this model speaks ``version``; else the error "model" for the arm ``arm``,
        in one line naming both (and the bundled description whose model speaks
        ``version``, if any)."""
        if self.speaks(version):
            return None
        says = f" and names its model {reported!r}" if reported else ""
        return ArmError(
            f"{arm}: the arm is not the {self.name} that --robot {self.robot} describes: its "
            f"controller speaks version {version} of libfranka's protocol ({_whose(version)})"
            f"{says}, where the {self.name}'s speaks {self.versions_text()}",
            arm=arm,
            reason="model",
            value=version,
        )


def bundled_models() -> tuple[FrankaModel, ...]:
    """The models of the bundled descriptions that have a ``franka.toml``."""
    root = Path(str(resources.files("qpavoid.robots")))
    return tuple(
        FrankaModel.read(folder / MODEL_FILE, folder.name)
        for folder in sorted(root.iterdir())
        if (folder / MODEL_FILE).is_file()
    )


def _whose(version: int) -> str:
    """Whose version ``version`` is among the bundled models, for messages."""
    for model in bundled_models():
        if model.speaks(version):
            return f"the {model.name}'s: --robot {model.robot}"
    known = ", ".join(f"{m.name} {m.versions_text()}" for m in bundled_models())
    return f"no bundled description's arm speaks it: {known}"


def refused_versions(exc: BaseException) -> tuple[int, int] | None:
    """The robot server's and the library's versions of libfranka's refusal ``exc`` of a
    connection to an arm of another version, or None if it is not one.

    libfranka's ``IncompatibleVersionException`` (franky-control's, panda-python 1.0's as
    a RuntimeError) says both in its text; panda-python 1.1's ``IncompatibleVersionError``
    carries them as attributes.
    """
    server = getattr(exc, "server_version", None)
    library = getattr(exc, "library_version", None)
    if isinstance(server, int) and isinstance(library, int):
        return server, library
    found = _REFUSAL.search(str(exc))
    return (int(found[1]), int(found[2])) if found else None


def is_loopback(host: str) -> bool:
    """Whether ``host`` is a loopback address (a simulator's, on this machine)."""
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


def connect_within(make: Callable[[], T], timeout_s: float, arm: str, host: str) -> T:
    """``make()`` (a binding's connection) within ``timeout_s`` s; what it raised, raised
    again; or :class:`ArmError` "unreachable" when it has not returned by then.

    libfranka refuses at once when nothing listens on the address but waits 60 s for an
    address that does not answer (its TCP timeout); the connection is made in a thread of
    its own, abandoned (its robot released when it comes) after ``timeout_s``.
    """
    box: dict[str, Any] = {}
    lock, done = threading.Lock(), threading.Event()

    def connect() -> None:
        try:
            robot = make()
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
        raise box["error"]
    raise ArmError(
        f"{arm}: no answer from {host} within {timeout_s:g} s "
        "(is the arm on, FCI enabled, the address right?)",
        arm=arm,
        reason="unreachable",
        value=host,
    )


@dataclass(frozen=True)
class RawState:
    """One state of the arm's seven joints, as a binding reads it.

    Attributes
    ----------
    time_ms
        The arm's clock, ms.
    q, dq
        (7,) joint angles, rad, and velocities, rad/s.
    fault
        What the arm reports, if it has errors, is in a reflex or stopped by its user.
    """

    time_ms: int
    q: np.ndarray
    dq: np.ndarray
    fault: str | None = None

    @classmethod
    def of(cls, state: Any, faulted: bool) -> RawState:
        """The state of libfranka's ``RobotState`` ``state`` (either binding's), with its
        errors and mode as the fault if ``faulted``."""
        fault = f"{state.current_errors!r} in mode {state.robot_mode.name}" if faulted else None
        return cls(
            int(state.time.to_msec()),
            np.asarray(state.q, dtype=float),
            np.asarray(state.dq, dtype=float),
            fault,
        )


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
        the arm is not the description's (:meth:`FrankaModel.check`); "fault": the arm
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
            versions = refused_versions(e)
            if versions is not None:
                raise self._refused(*versions) from None
            text = one_line(e)
            if "incorrect object size" in text:  # libfranka's ProtocolException, at connect
                text += (
                    f": the arm accepted version {self.binding.server_version} of libfranka's "
                    "protocol but does not speak it (a real controller refuses a version it "
                    "does not speak; franky-sim accepts every one)"
                )
            raise ArmError(
                f"{self.name}: cannot connect ({type(e).__name__}: {text})",
                arm=self.name,
                reason="unreachable",
                value=self.host,
            ) from None

    def _refused(self, server: int, library: int) -> ArmError:
        """The error of a connection the arm refused: its controller speaks version
        ``server`` of libfranka's protocol, the binding's libfranka ``library``."""
        another = self.model.mismatch(self.name, server)
        if another is not None:  # another arm answered: "model", naming both
            return another
        others = [b for b in BINDINGS if b.server_version == server]
        what = (
            f"drive it with --arm {others[0].kind}:{self.host} ({others[0].package}'s "
            f"libfranka {others[0].libfranka} speaks {server}: {others[0].install()})"
            if others
            else "no adapter here speaks it ("
            + ", ".join(f"{b.package} {b.server_version}" for b in BINDINGS)
            + "): update the arm's robot system, or install a build of a binding for it "
            "(docs/real-robot.md §1b)"
        )
        return ArmError(
            f"{self.name}: the {self.model.name} there speaks version {server} of libfranka's "
            f"protocol, {self.binding.package}'s libfranka {self.binding.libfranka} speaks "
            f"{library}: {what}",
            arm=self.name,
            reason="unreachable",
            value=self.host,
        )

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
        text = one_line(e)
        kind = type(e).__name__
        network = kind == "NetworkException" or text == "Net Exception"
        if network or text.startswith(("libfranka: UDP", "libfranka: TCP")):
            reason = "stalled" if "timeout" in text.lower() else "unreachable"
        else:
            reason = "fault"
        self._failure = ArmError(
            f"{self.name}: {kind}: {text}", arm=self.name, reason=reason, value=text
        )
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
            speed = float(np.max(np.abs(q7 - seen[0][1]))) / span if span > 0 else math.inf
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
