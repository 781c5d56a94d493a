"""The Panda's adapter (qpavoid.drive.panda): a Franka Emika Panda through panda-python.

No Panda and no simulator of its protocol (libfranka 0.9, robot server 5) is available
here, so the default suite checks the adapter's logic on a stand-in for panda-python that
records what it is given (the reference the commands integrate, the stop's ramp, the
arm's model against the description, errors), the missing extra (one line, exit 2 from
the command line), and panda-python's own libfranka 0.9.2 refused by a controller of
another version (an FR3's: tests/libfranka_handshake.py). The slow suite connects
panda-python to franky-sim's FR3, which it cannot speak to.
"""

from __future__ import annotations

import enum
import math
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from conftest import PYTHON
from libfranka_handshake import RefusingController, free_address, loopback_addresses

import qpavoid
from qpavoid.arm.model import Robot
from qpavoid.cli.commands import main
from qpavoid.core.errors import ArmError, InputError
from qpavoid.drive import franka_sim, panda
from qpavoid.drive.franka_model import PANDA_PY
from qpavoid.drive.interface import Arm
from qpavoid.drive.libfranka_connection import refused_versions
from qpavoid.drive.panda import MAX_STEP_PERIODS, PandaArm

DT = 0.002  # 500 Hz
#: The Panda's active joints (panda_joint3 locked at 0) among its seven.
ACTIVE = (0, 1, 3, 4, 5, 6)


@pytest.fixture(scope="module")
def robot() -> Robot:
    return qpavoid.load_robot("panda")


@pytest.fixture(scope="module")
def fr3() -> Robot:
    return qpavoid.load_robot("fr3")


# -- a stand-in for panda-python -----------------------------------------------------------


class Mode(enum.Enum):
    kIdle = 1
    kMove = 2
    kReflex = 4
    kUserStopped = 5


class Errors:
    def __init__(self, *set_: str):
        self.set = set_

    def __bool__(self) -> bool:
        return bool(self.set)

    def __repr__(self) -> str:
        return f"[{', '.join(self.set)}]"


class FakeJointPosition:
    """panda-python's joint impedance controller: what it was told, in order."""

    def __init__(self) -> None:
        self.controls: list[tuple[np.ndarray, np.ndarray]] = []

    def set_control(self, position: np.ndarray, velocity: np.ndarray) -> None:
        self.controls.append((np.array(position, float), np.array(velocity, float)))


class FakePanda:
    """panda_py.Panda's surface as the adapter uses it: a state whose clock advances 1 ms a
    read, the controllers started and stopped, the joint motions asked for."""

    server_version = 5

    def __init__(self, hostname: str, realtime_config: object = None):
        self.hostname, self.realtime_config = hostname, realtime_config
        self.q = np.zeros(7)
        self.ms = 0
        self.errors = Errors()
        self.mode = Mode.kIdle
        self.error: Exception | None = None
        self.controller: FakeJointPosition | None = None
        self.started: list[FakeJointPosition] = []
        self.stops = 0
        self.moves: list[tuple[np.ndarray, float]] = []

    def get_robot(self) -> SimpleNamespace:
        return SimpleNamespace(server_version=lambda: self.server_version)

    def get_state(self) -> SimpleNamespace:
        self.ms += 1
        return SimpleNamespace(
            time=SimpleNamespace(to_msec=lambda ms=self.ms: ms),
            q=self.q.copy(),
            dq=np.zeros(7),
            robot_mode=self.mode,
            current_errors=self.errors,
        )

    def raise_error(self) -> None:
        if self.error is not None:
            raise self.error

    def start_controller(self, controller: FakeJointPosition) -> None:
        self.controller = controller
        self.started.append(controller)

    def stop_controller(self) -> None:
        self.controller = None
        self.stops += 1

    def is_moving(self) -> bool:
        return self.controller is not None

    def move_to_joint_position(self, q7: np.ndarray, speed_factor: float = 0.2) -> bool:
        self.controller = None
        self.moves.append((np.array(q7, float), speed_factor))
        self.q = np.array(q7, float)  # there at once
        return True


class Clock:
    """The panda module's clock: monotonic time that only sleeps move on."""

    def __init__(self) -> None:
        self.now = 1000.0

    def monotonic(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        self.now += max(0.0, seconds)


@pytest.fixture
def fake(monkeypatch: pytest.MonkeyPatch) -> SimpleNamespace:
    """A stand-in for panda_py; its ``pandas`` are those made, its ``clock`` the adapter's."""
    pandas: list[FakePanda] = []
    module = SimpleNamespace(pandas=pandas, clock=Clock(), make_error=None)
    module.server_version = 5

    def make(hostname: str, realtime_config: object = None) -> FakePanda:
        if module.make_error is not None:
            raise module.make_error
        pandas.append(FakePanda(hostname, realtime_config))
        pandas[-1].server_version = module.server_version
        return pandas[-1]

    module.Panda = make
    module.controllers = SimpleNamespace(JointPosition=FakeJointPosition)
    module.libfranka = SimpleNamespace(
        RealtimeConfig=SimpleNamespace(kEnforce="enforce", kIgnore="ignore"), RobotMode=Mode
    )
    monkeypatch.setattr(panda, "_import_panda_py", lambda: module)
    monkeypatch.setattr(panda, "time", module.clock)
    return module


# -- the extra, imported when an arm is made -------------------------------------------------


def test_panda_python_is_imported_only_for_a_panda() -> None:
    code = (
        "import sys; import qpavoid.drive.connect, qpavoid.drive.panda; "
        "print('panda_py' in sys.modules)"
    )
    out = subprocess.run([*PYTHON, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.stdout.strip() == "False", out.stderr


def test_missing_extra(robot: Robot, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "panda_py", None)  # import panda_py: ImportError
    with pytest.raises(InputError) as e:
        PandaArm(robot, "127.0.0.1")
    assert str(e.value).startswith(
        '--arm panda drives a Panda through panda-python: pip install "qpavoid[panda]" '
        "(import panda_py: "
    )
    assert "\n" not in str(e.value)


def test_the_command_line_names_the_extra(tmp_path: Path, monkeypatch, capsys) -> None:
    """Without panda-python (its import made to fail, in-process as the console script
    runs): one line naming the extra, exit 2, nothing written."""
    out = tmp_path / "run"
    monkeypatch.setitem(sys.modules, "panda_py", None)
    status = main(
        [
            "run",
            "test1",
            "--robot",
            "panda",
            "--arm",
            "panda:127.0.0.1",
            "--out",
            str(out),
            "--no-plots",
            "--no-view",
            "-q",
        ]
    )
    stdout, stderr = capsys.readouterr()
    assert status == 2 and stdout == "", stderr
    assert stderr.strip().splitlines() == [
        "qpavoid: error: --arm panda drives a Panda through panda-python: pip install "
        '"qpavoid[panda]" (import panda_py: import of panda_py halted; None in sys.modules)'
    ]
    assert not out.exists()


# -- the arm's model ---------------------------------------------------------------------------


def test_connects_to_a_panda(robot: Robot, fake: SimpleNamespace) -> None:
    arm = PandaArm(robot, "fake")
    assert isinstance(arm, Arm) and arm.name == "panda:fake"
    assert fake.pandas[0].realtime_config == "enforce"  # not a loopback address
    assert PandaArm(robot, "127.0.0.1").model.name == "Panda (FER)"
    assert fake.pandas[1].realtime_config == "ignore"
    # the description's limits: panda-python sets none of its own
    np.testing.assert_array_equal(arm.limits.acceleration_radps2, [15, 7.5, 12.5, 15, 20, 20])
    np.testing.assert_array_equal(arm.limits.velocity_radps, [2.175] * 3 + [2.61] * 3)


def test_an_fr3_answering_for_a_panda_is_refused(
    robot: Robot, fr3: Robot, fake: SimpleNamespace
) -> None:
    # panda-python built for an FR3's libfranka (its release zips) connects; the version
    # the controller speaks decides
    fake.server_version = 10
    with pytest.raises(ArmError) as e:
        PandaArm(robot, "fake")
    assert e.value.reason == "model" and e.value.value == 10
    assert str(e.value) == (
        "panda:fake: the arm is not the Panda (FER) that --robot panda describes: its "
        "controller speaks version 10 of libfranka's protocol (the FR3's: --robot fr3), where "
        "the Panda (FER)'s speaks 2-5"
    )
    assert fake.pandas[0].started == []  # nothing moved
    fake.server_version = 5
    with pytest.raises(ArmError, match="not the FR3 that --robot fr3") as e:
        PandaArm(fr3, "fake")
    assert e.value.reason == "model"


@pytest.mark.parametrize(
    "refusal",
    [
        # panda-python 1.1's IncompatibleVersionError (its attributes) and 1.0's RuntimeError
        SimpleNamespace(server_version=10, library_version=5),
        RuntimeError(
            "libfranka: Incompatible library version (server version: 10, library version: 5). "
            "Please check https://frankaemika.github.io for Panda system updates"
        ),
    ],
)
def test_refused_by_an_fr3(robot: Robot, fake: SimpleNamespace, refusal: Any) -> None:
    if isinstance(refusal, SimpleNamespace):
        refusal = type("IncompatibleVersionError", (RuntimeError,), {})("refused")
        refusal.server_version, refusal.library_version = 10, 5
    fake.make_error = refusal
    with pytest.raises(ArmError, match=r"not the Panda \(FER\) that --robot panda") as e:
        PandaArm(robot, "fake")
    assert e.value.reason == "model" and e.value.value == 10


def test_a_panda_of_an_older_system_is_refused_by_version(
    robot: Robot, fake: SimpleNamespace
) -> None:
    fake.make_error = RuntimeError(
        "libfranka: Incompatible library version (server version: 4, library version: 5)."
    )
    with pytest.raises(ArmError) as e:
        PandaArm(robot, "fake")
    assert e.value.reason == "unreachable"
    assert str(e.value).startswith(
        "panda:fake: the Panda (FER) there speaks version 4 of libfranka's protocol, "
        "panda-python's libfranka 0.9.2 speaks 5: no adapter here speaks it"
    )


# -- streaming, stopping, moving ----------------------------------------------------------------


def _sent(fake: SimpleNamespace) -> list[tuple[np.ndarray, np.ndarray]]:
    return fake.pandas[0].started[-1].controls


def test_commands_move_the_reference_on(robot: Robot, fake: SimpleNamespace) -> None:
    arm = PandaArm(robot, "fake", period_s=DT)
    start = np.array([0.1, -0.7, 0.0, -2.3, 0.05, 1.6, 0.8])
    fake.pandas[0].q = start.copy()
    u1 = np.array([0.01, 0, 0, 0, 0, -0.01])
    arm.send(u1)
    ((q_d, dq_d),) = _sent(fake)
    np.testing.assert_array_equal(q_d, start)  # streaming starts where the arm is
    np.testing.assert_array_equal(dq_d, [0.01, 0, 0, 0, 0, 0, -0.01])  # joint 3 still
    fake.clock.sleep(DT)
    u2 = 2 * u1
    arm.send(u2)
    q_d, dq_d = _sent(fake)[-1]
    np.testing.assert_allclose(q_d, start + arm.joints.velocity(u1) * DT, atol=1e-15)
    np.testing.assert_array_equal(dq_d, arm.joints.velocity(u2))
    fake.clock.sleep(0.1)  # a stall: the reference moves on by two periods only
    arm.send(u2)
    np.testing.assert_allclose(
        _sent(fake)[-1][0], q_d + arm.joints.velocity(u2) * MAX_STEP_PERIODS * DT, atol=1e-15
    )
    assert len(fake.pandas[0].started) == 1
    state = arm.read()
    assert state.q.shape == (6,) and state.time_s > 0


def test_refuses_commands_beyond_limits(robot: Robot, fake: SimpleNamespace) -> None:
    arm = PandaArm(robot, "fake", period_s=DT)
    arm.send(np.array([5.0 * DT, 0, 0, 0, 0, 0]))
    with pytest.raises(ArmError, match="acceleration") as e:
        arm.send(np.array([0.5, 0, 0, 0, 0, 0]))  # 250 rad/s² on joint 1 (15)
    assert e.value.reason == "limit" and len(_sent(fake)) == 1  # nothing sent
    fake.pandas[0].q[2] = 0.01  # off the lock, but streaming: not checked again
    arm.send(np.array([10.0 * DT, 0, 0, 0, 0, 0]))
    assert len(_sent(fake)) == 2


def test_refuses_to_start_off_the_lock(robot: Robot, fake: SimpleNamespace) -> None:
    arm = PandaArm(robot, "fake")
    fake.pandas[0].q[2] = 0.01
    with pytest.raises(ArmError, match="panda_joint3") as e:
        arm.send(np.zeros(6))
    assert e.value.reason == "rejected" and fake.pandas[0].started == []


def test_stop_ramps_the_reference_to_rest(robot: Robot, fake: SimpleNamespace) -> None:
    arm = PandaArm(robot, "fake", period_s=DT)
    u = np.zeros(6)
    for k in range(1, 101):  # joint 2 up at 5 rad/s² to 0.5 rad/s, joint 1 at 0.1 rad/s
        u = np.array([min(0.1, 5.0 * k * DT), min(0.5, 5.0 * k * DT), 0, 0, 0, 0])
        arm.send(u)
        fake.clock.sleep(DT)
    before = len(_sent(fake))
    arm.stop()
    ramp = _sent(fake)[before:]
    v = np.array([c[1] for c in ramp])
    # a straight line in joint space to rest at joint 2's 7.5 rad/s²: 0.5 / 7.5 s
    steps = math.ceil(0.5 / 7.5 / DT)
    assert len(ramp) == steps + 1  # the steps, then held at rest
    expected = np.append(0.5 * (1 - np.arange(1, steps + 1) / steps), 0.0)
    np.testing.assert_allclose(v[:, 1], expected, atol=1e-15)
    np.testing.assert_allclose(v[:, 0], v[:, 1] / 5.0)  # joint 1 along the same line
    assert np.all(np.abs(np.diff(v[:, 1])) <= 7.5 * DT + 1e-12)
    q = np.array([c[0] for c in ramp])
    np.testing.assert_allclose(np.diff(q[:, 1]), v[:-1, 1] * DT, atol=1e-12)  # integrated
    assert fake.pandas[0].stops == 1 and not fake.pandas[0].is_moving()
    arm.send(np.zeros(6))  # streaming starts again, from rest
    assert len(fake.pandas[0].started) == 2


def test_stop_after_silence_holds_the_reference(robot: Robot, fake: SimpleNamespace) -> None:
    arm = PandaArm(robot, "fake", period_s=DT)
    arm.send(np.array([0.01, 0, 0, 0, 0, 0]))
    fake.clock.sleep(DT)
    arm.send(np.array([0.02, 0, 0, 0, 0, 0]))
    held = _sent(fake)[-1][0]
    fake.clock.sleep(0.2)  # the loop fell silent: the arm settled near the reference
    arm.stop()
    ((q_d, dq_d),) = _sent(fake)[2:]  # held where it was, at once: no ramp moving it on
    np.testing.assert_array_equal(q_d, held)
    np.testing.assert_array_equal(dq_d, np.zeros(7))


def test_stall_and_fault(robot: Robot, fake: SimpleNamespace) -> None:
    arm = PandaArm(robot, "fake")
    p = fake.pandas[0]
    p.error = RuntimeError("libfranka: UDP receive: Timeout")
    with pytest.raises(ArmError, match="Timeout") as e:
        arm.read()
    assert e.value.reason == "stalled"
    p.error = None
    with pytest.raises(ArmError, match="Timeout"):  # kept: the connection is not used again
        arm.read()
    arm = PandaArm(robot, "fake")
    fake.pandas[1].errors = Errors("joint_reflex")
    fake.pandas[1].mode = Mode.kReflex
    with pytest.raises(ArmError, match=r"reports \[joint_reflex\] in mode kReflex") as e:
        arm.read()
    assert e.value.reason == "fault"


def test_move_to_and_close(robot: Robot, fake: SimpleNamespace) -> None:
    with PandaArm(robot, "fake") as arm:
        q = np.array([0.1, -0.7, -2.3, 0.05, 1.6, 0.8])
        reached = arm.move_to(q)
        ((q7, speed),) = fake.pandas[0].moves
        np.testing.assert_array_equal(q7, [0.1, -0.7, 0.0, -2.3, 0.05, 1.6, 0.8])
        assert speed == 0.2
        np.testing.assert_array_equal(reached.q, q)
        arm.send(np.full(6, 0.005))
    assert fake.pandas[0].stops == 1  # closed while streaming: stopped, controller ended
    with pytest.raises(ArmError, match="closed"):
        arm.read()


# -- panda-python itself -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def addresses() -> Iterator[str]:
    """Loopback addresses of this process's own, after tests/test_franka.py's."""
    return loopback_addresses(200)


def test_panda_python_refused_by_an_fr3(robot: Robot, fr3: Robot, addresses: Iterator[str]) -> None:
    """panda-python's own libfranka 0.9.2 against a controller that refuses it as an FR3's
    (robot server 10) does."""
    pytest.importorskip("panda_py")
    host = free_address(addresses)
    with RefusingController(host, 10) as controller:
        with pytest.raises(ArmError) as e:
            PandaArm(robot, host)
        assert e.value.reason == "model"
        assert str(e.value) == (
            f"panda:{host}: the arm is not the Panda (FER) that --robot panda describes: its "
            "controller speaks version 10 of libfranka's protocol (the FR3's: --robot fr3), "
            "where the Panda (FER)'s speaks 2-5"
        )
        with pytest.raises(ArmError) as e:
            PandaArm(fr3, host)
        assert e.value.reason == "unreachable"
        assert str(e.value) == (
            f"panda:{host}: the FR3 there speaks version 10 of libfranka's protocol, "
            "panda-python's libfranka 0.9.2 speaks 5: drive it with "
            f"--arm franka:{host} (franky-control's libfranka 0.21 speaks 10: "
            'pip install "qpavoid[franka]")'
        )
    assert controller.offered == [PANDA_PY.server_version] * 2


@pytest.mark.slow
def test_panda_python_cannot_speak_to_franky_sim(robot: Robot, addresses: Iterator[str]) -> None:
    """franky-sim's FR3 accepts any client (it does not compare versions) and then streams
    libfranka 0.21's state, which libfranka 0.9.2 cannot read: refused at connect."""
    pytest.importorskip("panda_py")
    pytest.importorskip("franky_sim")
    with franka_sim.FrankySim(free_address(addresses)) as sim, pytest.raises(ArmError) as e:
        PandaArm(robot, sim.host, connect_timeout_s=10.0)
    assert e.value.reason == "unreachable" and "\n" not in str(e.value)
    assert str(e.value).startswith(
        f"panda:{sim.host}: cannot connect (RuntimeError: libfranka: incorrect object size: "
        "the arm accepted version 5 of libfranka's protocol but does not speak it"
    )


def test_the_shared_refusal_text() -> None:
    text = "libfranka: Incompatible library version (server version: 5, library version: 10)."
    assert refused_versions(RuntimeError(text)) == (5, 10)
    assert refused_versions(RuntimeError("libfranka: UDP receive: Timeout")) is None
