"""The ROS 2 hops of a live run on a loopback DDS domain (issue 47).

    python benchmarks/ros2_hop.py [--messages 600] [--out benchmarks/results/ros2_hop.json]

* **camera hop**: another process stamps, serializes (rosbags, 32 markers) and writes the
  Azure Kinect driver's MarkerArray (one body) at 30 Hz;
  :class:`~qpavoid.sensing.dds_input.DdsListener` takes it (the wall time its reading
  thread takes the sample, before decoding). Reported from the stamp (the serialization
  of a Python driver included) and from the write (the DDS hop).
* **state to command**: the closed loop on the stand-in: the newest JointState read, a
  real controller tick, its command sent; from the state's stamp to the stand-in's take
  of that command, against the bar "no command later than the arm's period plus the
  tick" (counted, never asserted).
* **command hop**: :meth:`Ros2Arm.send <qpavoid.drive.ros2_arm.Ros2Arm.send>` at 500 Hz
  to the kinematic ros2_control stand-in (tests/ros2_cell_standin.py, a 1 kHz loop that
  takes what came each millisecond, as a controller's update does): its receive time
  − the send's wall time; it includes up to one stand-in period of waiting.

Both on this machine's wall clock (one clock for both processes). The machine's load is
written with the numbers.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
STANDIN = HERE.parent / "tests" / "ros2_cell_standin.py"
LOOPBACK = '<General><Interfaces><NetworkInterface name="lo"/></Interfaces></General>'
TOPIC = "/k4a/body_tracking_data"
MA = "visualization_msgs/msg/MarkerArray"


def publish(domain: int, n: int, log: str) -> None:
    """The driver's side: ``n`` MarkerArrays at 30 Hz, each stamped, serialized and
    written; each message's stamp and the wall time of its write go to the file ``log``
    (JSON), so that the hop is measured from the write, not from the stamp (a Python
    driver's serialization of 32 markers lies between them)."""
    sys.path.insert(0, str(STANDIN.parent))
    from ros2_standin import marker_array

    from qpavoid.sensing.ros2_cell import participant, write_raw, writer
    from qpavoid.sensing.ros2_types import to_cdr

    dp = participant(domain)
    w = writer(dp, "humble", TOPIC, MA)
    while not w.get_matched_subscriptions():
        time.sleep(0.01)
    time.sleep(0.5)
    joints = np.column_stack([np.linspace(-0.3, 0.3, 32), np.zeros(32), np.full(32, 2.0)])
    template = marker_array(0.0, {1: joints})
    written = []
    for _ in range(n):
        t = time.time()
        for m in template.markers:
            m.header.stamp.sec, m.header.stamp.nanosec = int(t), int((t % 1.0) * 1e9)
        data = to_cdr("humble", template, MA)
        now = time.time()
        write_raw(w, data)
        written.append((int(t), int((t % 1.0) * 1e9), now))
        time.sleep(1 / 30)
    Path(log).write_text(json.dumps(written))


def camera_hop(domain: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(from the stamp, from the write) to the read of each message taken, s."""
    from qpavoid.sensing.calibration import Calibration, SensorCalibration
    from qpavoid.sensing.dds_input import DdsListener
    from qpavoid.sensing.ros2_cell import Cell
    from qpavoid.sensing.ros2_types import from_cdr, stamp_s

    calibration = Calibration(
        {"femto": SensorCalibration("femto", np.eye(4), format="k4abt", topic=TOPIC)}
    )
    got: list[tuple[float, bytes]] = []
    with DdsListener(Cell(domain_id=domain), calibration, True) as listener:
        sample = listener._sample

        def timed(name: str, data: bytes, received_s: float) -> None:
            got.append((received_s, data))
            sample(name, data, received_s)

        listener._sample = timed  # type: ignore[method-assign]
        with tempfile.TemporaryDirectory() as tmp:
            log = Path(tmp) / "written.json"
            subprocess.run(
                [sys.executable, __file__, "--publish", str(domain), str(n), str(log)],
                check=True,
                env={**os.environ, "CYCLONEDDS_URI": LOOPBACK},
            )
            time.sleep(0.2)
            write_s = {(sec, ns): w for sec, ns, w in json.loads(log.read_text())}
    stamps = [from_cdr("humble", d, MA).markers[0].header.stamp for _, d in got]
    from_stamp = np.array([r - stamp_s(st) for (r, _), st in zip(got, stamps, strict=True)])
    from_write = np.array(
        [r - write_s[(st.sec, st.nanosec)] for (r, _), st in zip(got, stamps, strict=True)]
    )
    return from_stamp, from_write


def _standin_arm(robot, domain: int, q0: np.ndarray, tmp: str):
    """The kinematic ros2_control stand-in started at ``q0`` on ``domain`` (recording into
    ``tmp``) and a connected :class:`Ros2Arm` on it: (the process, the arm, the record)."""
    from qpavoid.drive.ros2_arm import Ros2Arm
    from qpavoid.sensing.ros2_cell import ArmTopics, Cell

    cell_file = Path(tmp) / "cell.toml"
    cell_file.write_text(f'distribution = "humble"\ndomain_id = {domain}\n')
    record = Path(tmp) / "arm.npz"
    command = [sys.executable, str(STANDIN), "arm", "--cell", str(cell_file)]
    command += ["--q0", ",".join(repr(float(v)) for v in q0)]
    command += ["--seconds", "60", "--record", str(record)]
    env = {**os.environ, "CYCLONEDDS_URI": LOOPBACK}
    proc = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, text=True)
    arm = Ros2Arm(
        robot, Cell(domain_id=domain, arm=ArmTopics(subscriber_timeout_s=20.0)), 0.002, True
    )
    arm.connect()
    return proc, arm, record


def command_hop(domain: int, n: int) -> tuple[np.ndarray, float]:
    from qpavoid.arm.model import load_robot

    robot = load_robot("iiwa14")
    with tempfile.TemporaryDirectory() as tmp:
        arm_proc, arm, record = _standin_arm(robot, domain, np.zeros(robot.nv), tmp)
        sent = []
        next_due = time.perf_counter()
        for k in range(n):
            dq = np.full(robot.nv, 1e-6 * (k + 1))
            sent.append(time.time())
            arm.send(dq)
            next_due += 0.002
            time.sleep(max(next_due - time.perf_counter(), 0.0))
        arm.stop()
        arm.close()
        time.sleep(0.3)
        arm_proc.terminate()
        out = arm_proc.communicate(timeout=20)[0]
        data = np.load(record)
    rate = float(out.split(" states at ")[1].split(" Hz")[0])
    index = np.rint(data["commands"][:, 0] / 1e-6).astype(int) - 1
    mine = index >= 0
    return data["t"][mine] - np.array(sent)[index[mine]], rate


def state_to_command(
    domain: int, n: int, fresh: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The closed loop on the stand-in arm: each tick reads the newest JointState
    (:meth:`Ros2Arm.read`; with ``fresh``, the next one to arrive), runs a real
    controller tick (the analytic controller, the iiwa, test1's person near the path) and
    sends its command. Per command: from the
    state's stamp (the arm's publication) to the arm's take of the command, and the tick's
    own time, s; the times the stand-in took them (wall clock, s); its rate, Hz."""
    from qpavoid.arm.ik import inverse_kinematics
    from qpavoid.arm.model import load_robot
    from qpavoid.control.analytic import AnalyticController
    from qpavoid.human.frames import HumanFrame
    from qpavoid.scenarios.generated import make_scenario

    robot = load_robot("iiwa14")
    controller = AnalyticController(robot)
    person = make_scenario("test1", robot)
    q0 = inverse_kinematics(robot, controller.path.reference(0.0)[0])
    with tempfile.TemporaryDirectory() as tmp:
        arm_proc, arm, record = _standin_arm(robot, domain, q0, tmp)
        stamps, ticks, sent = [], [], []
        next_due = time.perf_counter()
        for k in range(n):
            state = arm.read(fresh)
            t0 = time.perf_counter()
            frame = HumanFrame(*person.frame_at(0.002 * k))
            cmd = controller.step(state.q, frame, None, 0.002 * k, 0.07)
            dq = cmd.dq + 1e-9 * (k + 1)  # each command told apart by its last digits
            ticks.append(time.perf_counter() - t0)
            stamps.append(state.time_s)
            sent.append(dq[0])
            arm.send(dq)
            next_due += 0.002
            time.sleep(max(next_due - time.perf_counter(), 0.0))
        arm.stop()
        arm.close()
        time.sleep(0.3)
        arm_proc.terminate()
        out = arm_proc.communicate(timeout=20)[0]
        data = np.load(record)
    rate = float(out.split(" states at ")[1].split(" Hz")[0])
    index = {float(v): i for i, v in enumerate(sent)}
    taken = [(t, index.get(float(c[0]))) for t, c in zip(data["t"], data["commands"], strict=True)]
    mine = [(t, i) for t, i in taken if i is not None]
    delay = np.array([t - stamps[i] for t, i in mine])
    return delay, np.array([ticks[i] for _, i in mine]), np.array([t for t, _ in mine]), rate


def summary(hops: np.ndarray) -> dict[str, float]:
    ms = 1e3 * hops
    return {
        "n": len(hops),
        "median_ms": round(float(np.median(ms)), 3),
        "p99_ms": round(float(np.percentile(ms, 99)), 3),
        "max_ms": round(float(ms.max()), 3),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--messages", type=int, default=600)
    ap.add_argument("--out", default=str(HERE / "results" / "ros2_hop.json"))
    ap.add_argument("--publish", nargs=3, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.publish:
        publish(int(args.publish[0]), int(args.publish[1]), args.publish[2])
        return
    os.environ.setdefault("CYCLONEDDS_URI", LOOPBACK)
    domain = 200 + os.getpid() % 30
    stamped, written = camera_hop(domain, args.messages)
    camera, dds = summary(stamped), summary(written)
    hops, rate = command_hop(domain + 1, 5 * args.messages)
    command = summary(hops)
    period = 1.0 / rate
    closed = {}
    for fresh in (False, True):
        delay, ticks, taken, _ = state_to_command(domain + 2 + fresh, 5 * args.messages, fresh)
        over = delay - (period + ticks)  # beyond one arm period and the tick's own time
        # between two commands the arm takes: the loop's period (2 ms) plus the later tick's
        gaps = np.diff(taken) - (0.002 + ticks[1:])
        closed[fresh] = summary(delay) | {
            "tick_p99_ms": round(float(np.percentile(ticks, 99)) * 1e3, 3),
            "later_than_period_plus_tick": int(np.sum(over > 0)),
            "worst_excess_ms": round(float(over.max()) * 1e3, 3),
            "gap_median_ms": round(float(np.median(np.diff(taken))) * 1e3, 3),
            "gap_p99_ms": round(float(np.percentile(np.diff(taken), 99)) * 1e3, 3),
            "gaps_beyond_loop_period_plus_tick": int(np.sum(gaps > 0)),
        }
    load = os.getloadavg()[0]
    result = {
        "load": load,
        "cpus": os.cpu_count(),
        "camera_hop": camera,  # from the stamp: the driver's serialization included
        "camera_dds_hop": dds,  # from the write: DDS and the reading thread's wake
        "command_hop": command,
        "state_to_command": closed[False],  # the closed loop: the state's stamp to the take
        "state_to_command_fresh": closed[True],  # each tick on the next state to arrive
        "standin_rate_hz": rate,
    }
    print(
        f"camera hop (driver's stamp to DdsListener's read, 30 Hz): median "
        f"{camera['median_ms']} ms, p99 {camera['p99_ms']} ms, max {camera['max_ms']} ms "
        f"({camera['n']} messages); from the write (the DDS hop): median "
        f"{dds['median_ms']} ms, p99 {dds['p99_ms']} ms, max {dds['max_ms']} ms"
    )
    print(
        f"command hop (Ros2Arm.send to the {rate:g} Hz ros2_control stand-in's take, 500 Hz): "
        f"median {command['median_ms']} ms, p99 {command['p99_ms']} ms, "
        f"max {command['max_ms']} ms ({command['n']} commands)"
    )
    for fresh, c in closed.items():
        print(
            f"state to command ({'the next state to arrive' if fresh else 'the newest state'}"
            f": its JointState stamp to the arm's take of the command computed from it, a "
            f"controller tick between): median {c['median_ms']} ms, p99 {c['p99_ms']} ms, "
            f"max {c['max_ms']} ms; later than the arm's period ({1e3 * period:.2f} ms) + "
            f"the tick: {c['later_than_period_plus_tick']} of {c['n']} (worst by "
            f"{c['worst_excess_ms']} ms); between two commands taken: median "
            f"{c['gap_median_ms']} ms, p99 {c['gap_p99_ms']} ms, "
            f"{c['gaps_beyond_loop_period_plus_tick']} beyond the loop's 2 ms + the tick"
        )
    Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    print(f"load {load:.1f} on {os.cpu_count()} cores; wrote {args.out}")


if __name__ == "__main__":
    main()
