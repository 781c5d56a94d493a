"""Stand-ins for a ROS 2 cell's other processes, for the live tests and the hop benchmark
(issue 47): run as ``python tests/ros2_cell_standin.py camera|arm ...``.

``camera``: the body-tracking driver of the calibrated sensor's format. A scenario's
person (``--scenario``: ``test1``, ``random:SEED``, ... as ``qpavoid run`` names them)
filmed by the sensor's simulated camera (:func:`~qpavoid.loop.sender.sensor_frames`: the
format's joints, noise, frame rate), in the camera's frame, published on the sensor's
topic, reliable keep last 1, as its driver does (docs/ros2.md §2):

* ``k4abt``: the Azure Kinect ROS driver's ``bodyPublisherThread``, one
  ``visualization_msgs/MarkerArray`` per body frame, ids body × 100 + joint (the k4abt
  body id starts at 1), ``depth_camera_link``, metres, an empty array when nobody is seen;
* ``zed_body_34`` / ``zed_body_38``: the ZED ROS 2 wrapper's ``processBodies``, one
  ``zed_msgs/ObjectsStamped`` per body frame, an ``Object`` per body (its keypoints in the
  first slots of ``skeleton_3d``, metres, ROS axes: x forward, y left, z up; a joint not
  seen NaN; ``tracking_state`` OK while any joint is tracked, else SEARCHING; the
  format's ``body_format``), no object when nobody is seen.

The motion's time 0 is the wall time ``--start + --lead`` (before it the person stands in
its first pose); each frame is stamped with its capture time on the wall clock (the clock
the run's live source shares) and written its latency later.

``arm``: a kinematic ros2_control with a ``JointGroupVelocityController``: subscribes
(reliable, as the controller does) to ``<controller>/commands``, integrates
``q += dq · dt`` at ``--rate`` Hz from the start configuration and publishes the arm's
``sensor_msgs/JointState`` (the controller's joint order, stamped with the wall clock).
Like the real controller it has no timeout: it holds the last command. Every command it
received is recorded with its receive time (``--record``, an NPZ written on SIGTERM,
SIGINT or the end of ``--seconds``), with the states' times it published.
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))

from ros2_standin import marker_array, objects_stamped, to_ros_axes, zed_object

from qpavoid.arm.ik import inverse_kinematics
from qpavoid.arm.model import load_robot
from qpavoid.control.task import default_task
from qpavoid.sensing.calibration_file import load_calibration
from qpavoid.sensing.ros2_bodies import driver_of
from qpavoid.sensing.ros2_cell import (
    dds_message,
    load_cell,
    participant,
    take_raw,
    write_raw,
)
from qpavoid.sensing.ros2_types import dds_topic, dds_type, need, to_cdr

JS = "sensor_msgs/msg/JointState"
CMD = "std_msgs/msg/Float64MultiArray"
#: The Azure Kinect driver's first body id (k4abt numbers bodies from 1).
K4ABT_FIRST_ID = 1
#: zed_msgs/Object.tracking_state: the body tracked, or its trajectory estimated.
ZED_OK, ZED_SEARCHING = 1, 2


class HeldStart:
    """``motion`` from ``lead_s`` on, its first pose before: the person waits for the run."""

    def __init__(self, motion, lead_s: float):
        self.motion, self.lead_s = motion, lead_s

    def frame_at(self, t: float):
        return self.motion.frame_at(max(t - self.lead_s, 0.0))


class OnRunClock:
    """The truth of a live run: the motion the camera stand-in films (started at wall time
    ``start_s``, the person moving from ``start_s + lead_s``), at run time ``t`` (whose
    wall time is the live source's ``start_s + t``, known from its first tick on)."""

    def __init__(self, motion, start_s: float, lead_s: float, run_start):
        self.motion, self.start_s, self.lead_s, self.run_start = motion, start_s, lead_s, run_start

    def frame_at(self, t: float):
        wall = self.run_start() + t
        return self.motion.frame_at(max(wall - self.start_s - self.lead_s, 0.0))


def _qos(reliable: bool, depth: int):
    core = need("cyclonedds.core")
    p = core.Policy
    return core.Qos(
        p.Reliability.Reliable(0) if reliable else p.Reliability.BestEffort,
        p.History.KeepLast(depth),
        p.Durability.Volatile,
    )


def _endpoint(dp, distribution: str, topic: str, name: str, kind: str, reliable: bool, depth=1):
    topic_ = need("cyclonedds.topic").Topic(dp, dds_topic(topic), dds_type(distribution, name))
    if kind == "writer":
        return need("cyclonedds.pub").DataWriter(dp, topic_, qos=_qos(reliable, depth))
    return need("cyclonedds.sub").DataReader(dp, topic_, qos=_qos(reliable, depth))


def _sensor(args, calibration) -> str:
    """The sensor filmed: ``--sensor``, else the calibration's only one."""
    if args.sensor:
        return args.sensor
    if len(calibration.names) != 1:
        raise SystemExit(f"camera: give --sensor, one of {', '.join(calibration.names)}")
    return calibration.names[0]


def _message(fmt: str, t: float, bodies: dict[int, tuple[np.ndarray, np.ndarray]]):
    """The driver's message of one body frame captured at wall time ``t``: bodies are
    body number -> (joints (J, 3) in the format's camera frame, m, NaN where not seen;
    their states)."""
    driver = driver_of(fmt)
    if driver.marker_id_stride:  # the Azure Kinect ROS driver
        return marker_array(t, {K4ABT_FIRST_ID + b: j for b, (j, _) in bodies.items()})
    assert driver.body_format is not None
    objects = [
        zed_object(
            b,
            to_ros_axes(fmt, joints),
            driver.body_format[fmt],
            ZED_OK if (state == 2).any() else ZED_SEARCHING,
        )
        for b, (joints, state) in bodies.items()
    ]
    return objects_stamped(t, objects)


def camera_messages(args, distribution: str) -> list[tuple[float, bytes]]:
    """(send wall time, CDR) of every message, made before the first is due."""
    from qpavoid.loop.sender import sensor_frames, sensor_latency_s
    from qpavoid.scenarios.motions import load_motion

    calibration = load_calibration(args.sensors)
    sensor = _sensor(args, calibration)
    fmt = calibration[sensor].format
    kind = driver_of(fmt).message
    robot = load_robot(args.robot)
    motion = HeldStart(load_motion(robot, args.scenario), args.lead)
    latency = sensor_latency_s(calibration, sensor)
    rate = calibration[sensor].skeleton.sensor.frame_rate_hz
    frames: dict[float, dict[int, tuple[np.ndarray, np.ndarray]]] = {}
    for f in sensor_frames(motion, calibration, sensor, args.seconds):
        joints = np.where(f.state[:, None] > 0, f.joints, np.nan)  # not seen: no joint
        frames.setdefault(f.t, {})[f.body] = (joints, f.state)
    out = []
    for k in range(int(args.seconds * rate)):
        t = k / rate
        message = _message(fmt, args.start + t, frames.get(t, {}))
        out.append((args.start + t + latency, to_cdr(distribution, message, kind)))
    return out


def run_camera(args) -> int:
    cell = load_cell(args.cell)
    calibration = load_calibration(args.sensors)
    sensor = _sensor(args, calibration)
    topic = calibration[sensor].topic
    kind = driver_of(calibration[sensor].format).message
    messages = camera_messages(args, cell.distribution)
    dp = participant(cell.domain_id)
    w = _endpoint(dp, cell.distribution, topic, kind, "writer", True)  # the driver's QoS
    stop = _stop_flag()
    print(f"camera: {len(messages)} messages on {topic}", flush=True)
    sent = 0
    for due, cdr in messages:
        if stop:
            break
        wait = due - time.time()
        if wait > 0:
            time.sleep(wait)
        if wait < -1.0:  # more than a second behind (a slow start): not sent
            continue
        write_raw(w, cdr)
        sent += 1
    print(f"camera: sent {sent}", flush=True)
    return 0


def _stop_flag() -> list[int]:
    stop: list[int] = []

    def handler(signum, frame):
        stop.append(signum)

    signal.signal(signal.SIGTERM, handler)
    signal.signal(signal.SIGINT, handler)
    return stop


def run_arm(args) -> int:
    cell = load_cell(args.cell)
    robot = load_robot(args.robot)
    order = cell.arm.joints or tuple(robot.joint_names)
    if args.q0:  # the description's order
        q0 = np.array([float(v) for v in args.q0.split(",")])
    else:  # where a run starts: the IK of its path's start, as the run computes it
        q0 = inverse_kinematics(robot, default_task(robot).path.reference(0.0)[0])
    q = q0[[robot.joint_names.index(j) for j in order]].copy()
    dp = participant(cell.domain_id)
    commands = _endpoint(dp, cell.distribution, cell.arm.commands, CMD, "reader", True, 64)
    states = _endpoint(dp, cell.distribution, cell.arm.joint_states, JS, "writer", True, 10)
    kind = dds_type(cell.distribution, CMD)
    header = dds_message(cell.distribution, "std_msgs/msg/Header")
    stamp_type = type(header.stamp)
    js = dds_type(cell.distribution, JS)
    names = list(order)
    dq = np.zeros(len(q))
    received_t: list[float] = []
    received: list[list[float]] = []
    wrong = 0
    state_t: list[float] = []
    stop = _stop_flag()
    period = 1.0 / args.rate
    start = last = time.time()
    next_due = time.perf_counter()
    end = start + args.seconds
    print(f"arm: {args.rate:g} Hz on {cell.arm.joint_states}", flush=True)
    while not stop and time.time() < end:
        for data in take_raw(commands, 64):
            now = time.time()
            values = list(kind.deserialize(data).data)
            received_t.append(now)
            received.append(values)
            if len(values) == len(q) and all(math.isfinite(v) for v in values):
                dq = np.array(values)
            else:
                wrong += 1  # the controller refuses a command of the wrong size
        now = time.time()
        q += dq * (now - last)
        last = now
        header.stamp = stamp_type(sec=int(now), nanosec=int((now % 1.0) * 1e9))
        states.write(
            js(header=header, name=names, position=q.tolist(), velocity=dq.tolist(), effort=[])
        )
        state_t.append(now)
        next_due += period
        wait = next_due - time.perf_counter()
        if wait > 0:
            time.sleep(wait)
        elif wait < -0.05:  # far behind: do not try to catch up in a burst
            next_due = time.perf_counter()
    if args.record:
        np.savez(
            args.record,
            t=np.array(received_t),
            commands=np.array(received, dtype=float).reshape(len(received), -1),
            state_t=np.array(state_t),
            joints=np.array(names),
            wrong_size=wrong,
        )
    ts = np.diff(state_t)
    print(
        f"arm: {len(state_t)} states at {1 / np.mean(ts):.0f} Hz (p99 period "
        f"{1e3 * np.percentile(ts, 99):.2f} ms), {len(received_t)} commands",
        flush=True,
    )
    return 0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="what", required=True)
    cam = sub.add_parser("camera")
    cam.add_argument("--cell", required=True)
    cam.add_argument("--sensors", required=True)
    cam.add_argument("--sensor", default="", help="default: the calibration's only one")
    cam.add_argument("--robot", default="iiwa14")
    cam.add_argument("--scenario", default="test1", help="test1, random:SEED, ...")
    cam.add_argument("--start", type=float, required=True, help="wall time of frame 0, s")
    cam.add_argument("--lead", type=float, default=0.0, help="s before the person moves")
    cam.add_argument("--seconds", type=float, default=30.0)
    arm = sub.add_parser("arm")
    arm.add_argument("--cell", required=True)
    arm.add_argument("--robot", default="iiwa14")
    arm.add_argument(
        "--q0",
        default="",
        help="start angles, rad, the description's order (default: the "
        "run's start, the IK of the robot's task's first waypoint)",
    )
    arm.add_argument("--rate", type=float, default=1000.0)
    arm.add_argument("--seconds", type=float, default=60.0)
    arm.add_argument("--record", default="")
    args = p.parse_args(argv)
    return run_camera(args) if args.what == "camera" else run_arm(args)


if __name__ == "__main__":
    sys.exit(main())
