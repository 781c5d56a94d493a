"""A camera held back on the path, live: what counting each person at their oldest frame costs
and buys (issue 46; docs/sensors.md §8).

    python benchmarks/live_ages.py [--repeats 3] [--delay 0.09] [--out FILE.json]

Each run: two simulated Kinects film the operator's right hand reaching onto the arm's path
(the network adversary's honest run, tests/test_attacks.py), replayed over loopback UDP to
a live listener whose frames drive the QP controller (speed and separation) and the
simulated arm at 100 Hz in real time; a device on the path forwards one camera's datagrams
at once and holds the other's back by ``--delay`` s. Each tick's clearance is judged
afterwards against the truth, the motion at the tick's wall time, and the arm's capsules.

Five ways, each ``--repeats`` times:

* ``on time``: no delay, each person at their oldest frame (the code as it is);
* ``held back, oldest``: the delay, each person at their oldest frame (as it is);
* ``held back, newest``: the delay, each person at the newest frame behind them (the code
  before issue 46: the fused frame as old as its newest camera frame);
* ``held back, told``: the delay, and the held-back camera's calibration saying so
  (``latency_s`` = the delay: its age limit 0.13 s), each person at their oldest frame;
* ``held back, told, newest``: the same, each person at the newest frame behind them.

(The cameras stamp each frame when it is sent: on time they are 0 s old, held back 0.09 s;
a Kinect v2's age limit is 0.1 s, so a held-back frame is used for its first 10 ms only,
unless its calibration gives its latency.)

Prints and writes the least true clearance while the arm moved, the ticks moving in true
contact, the time stopped, the frame ages counted (median, p99) and how far from its goal
the arm ended.
"""

from __future__ import annotations

import argparse
import dataclasses
import heapq
import json
import os
import socket
import time
from pathlib import Path

import numpy as np

import qpavoid
from qpavoid.control.path import ArcPath
from qpavoid.control.qp import QPController
from qpavoid.control.tick import ControllerConfig
from qpavoid.human.body import KinectHuman
from qpavoid.human.people import People
from qpavoid.human.posture import Operator
from qpavoid.loop.live_input import Listener, LiveSource
from qpavoid.loop.simulation import SimConfig, simulate
from qpavoid.loop.truth import TrueClearance
from qpavoid.scenarios.generated import nominal_configurations, reach_and_return
from qpavoid.sensing.signing import fields
from qpavoid.sensing.streamer import stream
from qpavoid.sensing.synthetic_pair import TwoSensorConfig, two_sensor_data

RUN_S, FILMED_S, START_S = 6.5, 5.0, 0.6  # as the network adversary's runs


class NewestAge(LiveSource):
    """The code before issue 46: people as old as the newest frame behind them."""

    def frame_at(self, t: float) -> tuple[People, float]:
        people, captured = super().frame_at(t)
        return People(people.ids, people.frames), captured


def hold_back(sock: socket.socket, to: tuple, late: str, delay_s: float, until: float) -> None:
    """A device on the path: ``late``'s datagrams forwarded ``delay_s`` after they came,
    the others at once, until ``until`` (wall time)."""
    sock.settimeout(0.001)
    held: list[tuple[float, int, bytes]] = []
    n = 0
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as out:
        while time.time() < until:
            try:
                data = sock.recv(65536)
                if fields(data)[0] == late:
                    heapq.heappush(held, (time.time() + delay_s, n, data))
                    n += 1
                else:
                    out.sendto(data, to)
            except TimeoutError:
                pass
            while held and held[0][0] <= time.time():
                out.sendto(heapq.heappop(held)[2], to)


def one_run(robot, delay_s: float, newest: bool, told: bool) -> dict:
    """One live run; its figures (``told``: the held-back camera's calibration gives its
    latency, ``latency_s`` = the delay)."""
    q = nominal_configurations(robot, ArcPath(), np.array([4.0]))[0]
    motion = reach_and_return(Operator(), "right", robot.end_effector(q)[:3, 3], (0.3, 1.5, 60, 61))
    data = two_sensor_data([motion], FILMED_S, TwoSensorConfig(seed=7))
    calibration = data.calibration
    late = calibration.names[1]
    if told:
        sensors = dict(calibration.sensors)
        sensors[late] = dataclasses.replace(sensors[late], latency_s=delay_s)
        calibration = dataclasses.replace(calibration, sensors=sensors)
    limit = max(calibration.age_limits_s.values())
    config = ControllerConfig(control_period_s=0.01, safety="ssm", max_frame_age_s=limit)
    controller = QPController(robot, config=config)
    with Listener(("127.0.0.1", 0), calibration) as listener:
        source = (NewestAge if newest else LiveSource)(listener)
        go = time.time() + START_S
        until = go + RUN_S
        proxy = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        proxy.bind(("127.0.0.1", 0))
        children = []
        pid = os.fork()
        if pid == 0:  # the device on the path
            try:
                hold_back(proxy, listener.address, late, delay_s, until)
            finally:
                os._exit(0)
        children.append(pid)
        to = proxy.getsockname()[:2]
        proxy.close()
        pid = os.fork()
        if pid == 0:  # the cameras
            try:
                while time.time() < go:
                    time.sleep(0.001)
                stream(list(data.recordings.values()), to, 30.0, calibration)
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
        report = source.report()
    truth = TrueClearance(robot, KinectHuman(), motion)
    log = sim.log
    true = np.array(
        [
            truth(robot.kinematics(qk, jacobians=False), source.start_s + t - go).min()
            for qk, t in zip(log["q"], log["t"], strict=True)
        ]
    )
    moving = np.any(log["dq"] != 0.0, axis=1)
    filmed = (source.start_s + log["t"] - go >= 0.2) & (source.start_s + log["t"] - go <= FILMED_S)
    ages = log["frame_age_s"][filmed & np.isfinite(log["frame_age_s"])]
    closest = int(np.flatnonzero(moving)[np.argmin(true[moving])]) if moving.any() else 0
    return {
        "min_true_clearance_moving_m": float(true[moving].min()) if moving.any() else None,
        "there": {  # the tick of the least clearance while moving
            "t_s": float(log["t"][closest]),
            "seen_clearance_m": float(np.min(log["distance"][closest])),
            "frame_age_s": float(log["frame_age_s"][closest]),
        },
        "ticks_moving_in_true_contact": int((moving & (true <= 0.0)).sum()),
        "stopped_s": round(float(log["stopped"].sum()) * 0.01, 2),
        "frame_age_s": {  # while the motion is filmed
            "median": float(np.median(ages)),
            "p99": float(np.percentile(ages, 99)),
        },
        "final_position_error_m": sim.metrics["final_position_error_m"],
        "accepted": report.get("accepted", 0),
        "late": report.get("late", 0),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--delay", type=float, default=0.09)
    ap.add_argument("--out", default="benchmarks/results/live_ages.json")
    args = ap.parse_args()
    robot = qpavoid.load_robot("iiwa14")
    ways = {
        "on time": (0.0, False, False),
        "held back, oldest": (args.delay, False, False),
        "held back, newest": (args.delay, True, False),
        "held back, told": (args.delay, False, True),
        "held back, told, newest": (args.delay, True, True),
    }
    results: dict[str, list[dict]] = {name: [] for name in ways}
    for _ in range(args.repeats):  # interleaved: the machine's load falls on every way alike
        for name, (delay, newest, told) in ways.items():
            results[name].append(one_run(robot, delay, newest, told))
    print("way                      least clearance moving  in contact  stopped  age median/p99")
    for name, runs in results.items():
        clear = " ".join(
            "    -" if c is None else f"{1e3 * c:5.0f}"
            for c in (r["min_true_clearance_moving_m"] for r in runs)
        )
        print(
            f"{name:25s} {clear} mm"
            f"  {sum(r['ticks_moving_in_true_contact'] for r in runs):9d}"
            f"  {np.mean([r['stopped_s'] for r in runs]):6.2f} s"
            f"  {1e3 * np.median([r['frame_age_s']['median'] for r in runs]):4.0f}/"
            f"{1e3 * np.median([r['frame_age_s']['p99'] for r in runs]):4.0f} ms"
        )
    load = os.getloadavg()[0]
    Path(args.out).write_text(
        json.dumps({"load": load, "delay_s": args.delay, **results}, indent=1)
    )
    print(f"load {load:.1f}; wrote {args.out}")


if __name__ == "__main__":
    main()
