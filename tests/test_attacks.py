"""An attacker on the cell's network, live on loopback (issues 24 and 40; slow suite).

Each run: two simulated Kinects film a known motion and are replayed in real time over
UDP to a listener (:class:`~qpavoid.loop.live_input.Listener`), whose frames drive the QP controller
(SSM on) and a simulated arm at 100 Hz; an attacker sends from another process at the
same time, or sits on the path between the sensors and the listener (a proxy process that
forwards what it chooses). Safety is judged afterwards against the truth: the motion at
each tick's wall time, against the arm's real geometry
(:class:`~qpavoid.loop.truth.TrueClearance`).
"""

from __future__ import annotations

import dataclasses
import json
import os
import socket
import struct
import time
from collections.abc import Callable

import numpy as np
import pytest

from qpavoid.control.path import ArcPath
from qpavoid.control.qp import QPController
from qpavoid.control.tick import ControllerConfig
from qpavoid.fusion.association import torso_centre
from qpavoid.human.body import KinectHuman
from qpavoid.human.posture import Operator
from qpavoid.loop.crowd import Crowd
from qpavoid.loop.live_input import Listener, LiveSource
from qpavoid.loop.simulation import SimConfig, simulate
from qpavoid.loop.truth import TrueClearance
from qpavoid.scenarios.generated import Working, nominal_configurations, reach_and_return
from qpavoid.sensing.calibration import Calibration
from qpavoid.sensing.keys import SensorKeys
from qpavoid.sensing.per_sensor import BodyFrame
from qpavoid.sensing.signing import Signer, fields
from qpavoid.sensing.streamer import stream
from qpavoid.sensing.synthetic_pair import TwoSensorConfig, two_sensor_data
from qpavoid.sensing.wire import encode

pytestmark = pytest.mark.slow

RUN_S = 6.5  #: the run's length, s
FILMED_S = 5.0  #: the motion filmed and replayed, s (it ends before the run does)
START_S = 0.6  #: when the replay begins after the run is set up, s


def hand_on_the_path(robot, back=(60.0, 61.0)):
    """The operator's right hand reaches, by 1.5 s, to where the end effector's planned
    path will be at 4 s, and holds it there (until ``back[0]``, at rest again by
    ``back[1]``, s): the robot must stop before it."""
    q = nominal_configurations(robot, ArcPath(), np.array([4.0]))[0]
    target = robot.end_effector(q)[:3, 3]
    return reach_and_return(Operator(), "right", target, (0.3, 1.5, *back))


def camera_frame(calibration: Calibration, sensor: str, joints: np.ndarray, t: float, body=0):
    """A body frame of base-frame ``joints`` as ``sensor`` would see them."""
    T = np.linalg.inv(calibration[sensor].base_from_camera)
    state = np.full(25, 2, dtype=np.int8)
    return BodyFrame(sensor, body, t, joints @ T[:3, :3].T + T[:3, 3], state)


class Attacker:
    """Datagrams an attacker sends without the sensors' keys.

    Parameters
    ----------
    calibration
        The cell (only the public part is used: names and poses, which an attacker may
        learn by watching).
    signed
        Send signed-looking datagrams under a key of the attacker's own (the cell accepts
        only signed ones), else unsigned version-1 datagrams.
    """

    def __init__(self, calibration: Calibration, signed: bool):
        self.calibration, self.signed = calibration, signed
        self.signers = {
            name: Signer(calibration.cell, SensorKeys(name, ((1, os.urandom(32)),)))
            for name in calibration.names
        }

    def datagram(self, sensor: str, joints: np.ndarray, t: float, body: int = 0) -> bytes:
        """A frame of ``joints`` (base frame) captured at ``t`` on the listener's clock
        (the sensor's own clock, which the attacker has watched, is behind or ahead)."""
        t -= self.calibration[sensor].time_offset_s
        frame = camera_frame(self.calibration, sensor, joints, t, body)
        return self.signers[sensor].encode(frame) if self.signed else encode(frame)


def far_person(shift=(0.0, 1.8, 0.0)) -> np.ndarray:
    """The operator's body moved 1.8 m away from the table (2.6 m from the robot)."""
    return Operator().rest() + np.asarray(shift)


def impersonate(attacker: Attacker, joints: np.ndarray, start_s: float) -> Callable:
    """From ``start_s`` after the replay's start: ``joints`` (base frame) as body 0 of
    every sensor, every 2 ms, stamped 4 ms ahead (within the receiver's tolerance)."""

    def attack(sock: socket.socket, address: tuple, go: float, until: float) -> None:
        while time.time() < go + start_s:
            time.sleep(0.005)
        while time.time() < until:
            for sensor in attacker.calibration.names:
                sock.sendto(attacker.datagram(sensor, joints, time.time() + 0.004), address)
            time.sleep(0.002)

    return attack


def hide(attacker: Attacker) -> Callable:
    """From the start, a person far away in the place of the real one."""
    return impersonate(attacker, far_person(), 0.0)


def take_over(attacker: Attacker) -> Callable:
    """From 1 s on, the operator at rest in their seat (inside the association gate): the
    fusion would track the forgery and miss the reaching hand."""
    return impersonate(attacker, Operator().rest(), 1.0)


def phantom_burst(attacker: Attacker) -> Callable:
    """At 1 s: a phantom 0.9 m from the base, three frames a sensor over 0.1 s."""

    def attack(sock: socket.socket, address: tuple, go: float, until: float) -> None:
        while time.time() < go + 1.0:
            time.sleep(0.005)
        joints = Operator().rest() + np.array([0.0, -0.1, 0.3])
        for _ in range(3):
            for sensor in attacker.calibration.names:
                sock.sendto(attacker.datagram(sensor, joints, time.time(), body=4), address)
            time.sleep(0.033)

    return attack


def blind(attacker: Attacker) -> Callable:
    """144 datagrams a second (every body of both sensors at 12 Hz) of empty frames
    stamped 95 ms ahead."""

    def attack(sock: socket.socket, address: tuple, go: float, until: float) -> None:
        nobody = np.full((25, 3), np.nan)
        while time.time() < until:
            for sensor in attacker.calibration.names:
                for body in range(6):
                    frame = camera_frame(attacker.calibration, sensor, nobody, 0.0, body)
                    t = time.time() + 0.095 - attacker.calibration[sensor].time_offset_s
                    frame = frame._replace(t=t, state=np.zeros(25, np.int8))
                    signer = attacker.signers[sensor]
                    data = signer.encode(frame) if attacker.signed else encode(frame)
                    sock.sendto(data, address)
            time.sleep(1 / 12)

    return attack


def scatter(attacker: Attacker) -> Callable:
    """1200 datagrams a second of whole people at random places 2-5 m from the robot."""

    def attack(sock: socket.socket, address: tuple, go: float, until: float) -> None:
        rng = np.random.default_rng(0)
        while time.time() < until:
            for _ in range(12):
                shift = (rng.uniform(-2, 2), rng.uniform(1.5, 4), 0.0)
                sensor = attacker.calibration.names[int(rng.integers(2))]
                body = int(rng.integers(6))
                data = attacker.datagram(sensor, far_person(shift), time.time(), body)
                sock.sendto(data, address)
            time.sleep(0.01)

    return attack


def tamper(calibration: Calibration) -> Callable[[int, bytes], list[bytes]]:
    """What a man on the path does with the real datagrams he sees, besides letting them
    through: sends each again later (replayed), re-stamped 4 ms ahead, re-slotted as
    another body, and as the other sensor (impersonating), all with the tag unchanged."""
    held: list[bytes] = []
    names = calibration.names

    def changed(datagram: bytes, change=None, dt: float = 0.0) -> bytes:
        """The datagram with its payload or capture time changed, its tag kept."""
        _, _, _, t, payload = fields(datagram)
        msg = json.loads(payload)
        if change is not None:
            change(msg)
        new = json.dumps(msg, separators=(",", ":")).encode()
        head = datagram[: len(datagram) - len(payload) - 32 - 8] + struct.pack("!d", t + dt)
        return head + new + datagram[-32:]

    def impersonate(datagram: bytes) -> bytes:
        sensor = fields(datagram)[0]
        other = names[1 - names.index(sensor)].encode()
        return datagram[:5] + bytes([len(other)]) + other + datagram[6 + datagram[5] :]

    def mangle(i: int, datagram: bytes) -> list[bytes]:
        out = [datagram]
        if i % 3 == 0:
            out.append(changed(datagram, dt=0.004))
            out.append(changed(datagram, lambda m: m.__setitem__("body", (m["body"] + 1) % 6)))
            out.append(impersonate(datagram))
        held.append(datagram)
        if len(held) > 6:
            out.append(held.pop(0))  # seen six datagrams ago: a replay
        return out

    return mangle


def live_run(robot, motion, attack=None, signed=True, mangle_real=None, bystander=None, path=None):
    """Replay ``motion`` (and ``bystander``'s, a second person, if given) filmed by two
    simulated Kinects to a live listener while ``attack(sock, address, go, until)`` runs
    in another process, the sensors' datagrams going through ``path(datagram, s since the
    replay's start) -> forward it?`` (a proxy process, if given); the run's log, the
    listener's report (with the proxy's ``path_forwarded``, ``path_dropped``, and
    ``run_start_s``: the run's time 0 after the replay's start, s), the number
    of real datagrams sent, and each tick's true distance per robot set (m, against the
    people's motion at the tick's wall time)."""
    motions = [motion] if bystander is None else [motion, bystander]
    data = two_sensor_data(motions, FILMED_S, TwoSensorConfig(seed=7))
    calibration = data.calibration
    if not signed:  # the opt-in: a calibration without keys
        calibration = dataclasses.replace(calibration, cell="", keys={})
    recordings = list(data.recordings.values())
    controller = QPController(
        robot, config=ControllerConfig(control_period_s=0.01, safety="ssm", max_frame_age_s=0.1)
    )
    with Listener(("127.0.0.1", 0), calibration, accept_unauthenticated=not signed) as listener:
        source = LiveSource(listener)
        go = time.time() + START_S
        until = go + RUN_S
        children = []
        to = listener.address
        if path is not None:  # the sensors send to the proxy, which forwards to the listener
            proxy = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            proxy.bind(("127.0.0.1", 0))
            to = proxy.getsockname()[:2]
            path_reader, path_writer = os.pipe()
            pid = os.fork()
            if pid == 0:  # the device on the path
                os.close(path_reader)
                counts = (0, 0)
                try:
                    counts = on_path(proxy, listener.address, path, go, until)
                finally:
                    os.write(path_writer, json.dumps(counts).encode())
                    os._exit(0)
            children.append(pid)
            proxy.close()
            os.close(path_writer)
        reader, writer = os.pipe()
        pid = os.fork()
        if pid == 0:  # the sensors
            os.close(reader)
            while time.time() < go:
                time.sleep(0.001)
            sent = [0]

            def count(i: int, datagram: bytes) -> list[bytes]:
                sent[0] += 1
                return mangle_real(i, datagram) if mangle_real else [datagram]

            stream(recordings, to, 30.0, calibration, mangle=count, unsigned=not signed)
            os.write(writer, str(sent[0]).encode())
            os._exit(0)
        children.append(pid)
        os.close(writer)
        if attack is not None:
            pid = os.fork()
            if pid == 0:  # the attacker
                try:
                    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
                        attack(sock, listener.address, go, until - 0.5)
                finally:
                    os._exit(0)
            children.append(pid)
        sim = simulate(
            controller,
            None,
            SimConfig(control_rate_hz=100.0, max_time_s=RUN_S, measure_truth=False),
            source=source,
            realtime=True,
        )
        for pid in children:
            os.waitpid(pid, 0)
        real_sent = int(os.read(reader, 64) or b"0")
        os.close(reader)
        time.sleep(0.2)  # the receiver's last counts
        report = source.report()
        report["run_start_s"] = source.start_s - go  # run time 0 on the replay's clock, s
        if path is not None:
            forwarded, dropped = json.loads(os.read(path_reader, 64) or b"[0, 0]")
            os.close(path_reader)
            report.update(path_forwarded=forwarded, path_dropped=dropped)
    people = motion if bystander is None else Crowd(dict(enumerate(motions)))
    truth = TrueClearance(robot, KinectHuman(), people)
    true = np.array(
        [
            truth(robot.kinematics(q, jacobians=False), source.start_s + t - go)
            for q, t in zip(sim.log["q"], sim.log["t"])
        ]
    )
    return sim, report, real_sent, true


def on_path(
    sock: socket.socket, to: tuple, forward: Callable[[bytes, float], bool], go: float, until: float
) -> tuple[int, int]:
    """A device on the path: each datagram that reaches ``sock`` is sent on to ``to`` if
    ``forward(datagram, s since go)``, until ``until`` (wall time); (forwarded, dropped)."""
    sock.settimeout(0.05)
    forwarded = dropped = 0
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as out:
        while time.time() < until:
            try:
                data = sock.recv(65536)
            except TimeoutError:
                continue
            if forward(data, time.time() - go):
                out.sendto(data, to)
                forwarded += 1
            else:
                dropped += 1
    return forwarded, dropped


def drop_the_near_person(calibration: Calibration, until_s: float) -> Callable:
    """The selective drop of issue 40: until ``until_s`` after the replay's start, the
    datagrams of any body whose torso is within 1.5 m of the robot's base are dropped, the
    others forwarded. The skeletons travel in clear: the device reads each datagram's
    joints and places them with the sensors' poses (public: an attacker can learn them by
    watching)."""

    def forward(datagram: bytes, since_go_s: float) -> bool:
        if since_go_s >= until_s:
            return True
        sensor, _, _, _, payload = fields(datagram)
        rows = np.array(json.loads(payload)["joints"], dtype=float)
        joints = calibration[sensor].to_base(rows[:, :3])
        joints[rows[:, 3] == 0] = np.nan
        return not np.linalg.norm(torso_centre(joints)) <= 1.5

    return forward


def bystander_far_away() -> Working:
    """A second person at work 1.9 m behind the operator's seat (2.95 m from the base)."""
    return Working(Operator(distance_m=2.95))


def every_real_frame_taken(report: dict, real_sent: int) -> bool:
    """Every real datagram accepted, or dropped as ``late`` (a receiver the machine kept
    from running for 0.1 s: the safe side), and at most one in ten late (a frame accepted
    and too old by the time the loop took it is one of the accepted: ``late_when_taken``,
    no longer counted twice, which once made 301 of 300). An attacker's
    datagram never counts as ``late`` (a copy of a real one is ``dropped_replayed``
    first), so nothing an attacker sent took a real frame's place."""
    late = report.get("late", 0)
    return report["accepted"] + late == real_sent and late <= real_sent // 10


def moving_in_contact(sim, true) -> int:
    moving = np.any(sim.log["dq"] != 0.0, axis=1)
    return int((moving & (true.min(axis=1) <= 0.0)).sum())


@pytest.fixture(scope="module")
def honest(robot):
    """The hand on the path, nobody attacking: the run every attack is compared with."""
    return live_run(robot, hand_on_the_path(robot))


def test_without_an_attacker_the_robot_works_and_stops_for_the_hand(honest):
    sim, report, real_sent, true = honest
    moving = np.any(sim.log["dq"] != 0.0, axis=1)
    assert moving.sum() > 50  # it works ...
    assert moving_in_contact(sim, true) == 0  # ... and never touches the hand
    assert true.min() < 0.1  # the hand really is on its path: it had to stop
    assert every_real_frame_taken(report, real_sent), report


@pytest.mark.parametrize("attack", ["hide", "take over"])
def test_a_forger_without_a_key_cannot_hide_the_hand(robot, attack):
    motion = hand_on_the_path(robot)
    data = two_sensor_data([motion], 0.1, TwoSensorConfig(seed=7))
    attacker = Attacker(data.calibration, signed=True)
    forge = hide(attacker) if attack == "hide" else take_over(attacker)
    sim, report, real_sent, true = live_run(
        robot, motion, forge, mangle_real=tamper(data.calibration)
    )
    assert moving_in_contact(sim, true) == 0
    assert every_real_frame_taken(report, real_sent), report  # and none of the others
    assert report["dropped_bad_tag"] > 1000 and report["dropped_replayed"] > 50, report
    assert not sim.log["input_alert"].any()  # no forged person ever reached the fusion


def test_without_authentication_the_same_forger_hides_the_hand(robot):
    """Why the keys: on the opt-in unsigned path the same forger is believed. The
    controller is shown the forged person, 2.6 m away, while the real one reaches into the
    robot's path (the issue measured 535 ticks moving in true contact; how many here
    depends on how fast this machine lets the forger and the receiver run, so the test
    asserts the deception, and reports the contact)."""
    motion = hand_on_the_path(robot)
    data = two_sensor_data([motion], 0.1, TwoSensorConfig(seed=7))
    attacker = Attacker(data.calibration, signed=False)
    sim, report, real_sent, true = live_run(robot, motion, hide(attacker), signed=False)
    assert report["accepted"] > real_sent + 100, report  # forgeries taken
    spine = sim.log["joints"][:, 0]  # SpineBase, base frame (NaN: nobody shown)
    shown = np.linalg.norm(spine[np.isfinite(spine).all(axis=1)], axis=1)  # m from the base
    assert (shown > 2.0).sum() > 50  # the controller saw the forged person ...
    assert true.min() < 0.1  # ... while the real hand was on its path
    print(f"unsigned: {moving_in_contact(sim, true)} ticks moving in true contact")


@pytest.mark.parametrize("flood", ["phantom burst", "blinding", "scatter"])
def test_a_flood_without_a_key_leaves_every_real_frame_accepted(robot, honest, flood):
    motion = hand_on_the_path(robot)
    data = two_sensor_data([motion], 0.1, TwoSensorConfig(seed=7))
    attacker = Attacker(data.calibration, signed=True)
    attack = {"phantom burst": phantom_burst, "blinding": blind, "scatter": scatter}[flood]
    sim, report, real_sent, true = live_run(robot, motion, attack(attacker))
    assert every_real_frame_taken(report, real_sent), report
    assert report["dropped_bad_tag"] >= 6, report
    assert moving_in_contact(sim, true) == 0
    # the attacker's own process shares the machine's two cores with the run: 2 % of the
    # ticks are left to it (before, a flood overran 434 of 1000)
    baseline = honest[0].metrics["realtime_overruns"]
    assert sim.metrics["realtime_overruns"] <= baseline + len(sim.log["t"]) // 50, flood
    assert not sim.log["input_alert"].any()


#: How long the device on the path drops the near person's datagrams, from the replay's
#: start, s: the whole time the hand is on the robot's path (from 1 s to 2.8 s).
SELECTIVE_DROP_S = 3.0


def stopped_s(sim, moving: np.ndarray, when: np.ndarray) -> float:
    """The time the robot stood still (no joint velocity) within the ticks ``when``, s."""
    return float(np.sum(np.diff(sim.log["t"], append=sim.log["t"][-1])[when & ~moving]))


def test_a_device_on_the_path_dropping_the_near_persons_datagrams_only_stops_the_robot(robot):
    """Issue 40: the skeletons travel in clear, one body per datagram; a device on the path
    dropped only the datagrams of the person near the robot and forwarded a bystander's:
    the input stayed fresh, the near person vanished, and the robot moved in true contact
    (the issue measured 492 ticks, -110 mm; this scene before the fix: 157, -75 mm). A
    frame now counts only when every body its sensor reported in it came, and a frame
    lost makes its sensor's older frames stale at once: the robot stops while datagrams
    are missing, says why, and works again once they come."""
    motion = hand_on_the_path(robot, back=(2.5, 3.0))
    bystander = bystander_far_away()
    data = two_sensor_data([motion, bystander], 0.1, TwoSensorConfig(seed=7))
    path = drop_the_near_person(data.calibration, SELECTIVE_DROP_S)
    sim, report, _, true = live_run(robot, motion, bystander=bystander, path=path)
    moving = np.any(sim.log["dq"] != 0.0, axis=1)
    since_go = sim.log["t"] + report["run_start_s"]  # each tick on the replay's clock, s
    during = (since_go >= 0.0) & (since_go < SELECTIVE_DROP_S)
    after = (since_go >= SELECTIVE_DROP_S) & (since_go < FILMED_S)  # the replay goes on
    alerted = np.char.find(sim.log["input_alert"].astype(str), "lost") >= 0
    contact = moving_in_contact(sim, true)
    print(
        f"selective drop: {report['path_dropped']} datagrams dropped, "
        f"{report['path_forwarded']} forwarded, {report.get('lost_frames', 0)} frames lost; "
        f"{contact} ticks moving in true contact; smallest true clearance moving "
        f"{true.min(axis=1)[moving].min() * 1000:.0f} mm; stopped "
        f"{stopped_s(sim, moving, during):.2f} s of the attack's {SELECTIVE_DROP_S} s, "
        f"{stopped_s(sim, moving, after):.2f} s of the {FILMED_S - SELECTIVE_DROP_S} s after "
        f"it; loss alert {alerted[during].sum()} ticks during, {alerted[after].sum()} after"
    )
    assert report["path_dropped"] > 100, report  # the device dropped the near person ...
    assert true.min() < 0.0  # ... whose hand went into the robot's path
    assert contact == 0
    assert moving[after].sum() > 50  # it works again once the datagrams come ...
    assert alerted[during].any() and report["lost_frames"] > 0  # ... and said why it stopped
