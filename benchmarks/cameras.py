"""What each camera costs: the time to the goal through each format's simulated camera.

    python benchmarks/cameras.py [--random 10] [--controllers qp analytic] [--safety ssm|pfl]
                                 [--at-kinect-latency] [--rate 100] [--robot iiwa14]
                                 [--out FILE.json]
    python benchmarks/cameras.py --budget     # the longest latency free passes, per camera
    python benchmarks/cameras.py --terms      # what each term costs, in free at 60 ms

For each skeleton format (its latency, noise, joint set, failure modes, and its body model on
its own joints: docs/sensors.md §10), both controllers with speed and separation monitoring
(or ``--safety pfl``) on the real bench: the time to the goal and the time stopped in
``free``, ``test1``, ``test2`` and ``--random`` random approaches, at the format's own latency
and (``--at-kinect-latency``) at the Kinect v2's (60 ms), which tells the latency's share.
With ``--budget``, the longest latency at which ``free`` reaches its goal within 16 s, under
ISO 13855's speeds or the human motion model's options (``--body-speed``,
``--body-acceleration``, ``--speed-error``). With ``--terms``, ``free`` at 60 ms on the body's
landmarks (issue 28's path) with one term switched to the Kinect v2's at a time (noise, no
landmark uncertainty, Z_d) and the landmark uncertainty scaled by 0.5 and 0.25. The numbers
of docs/safety.md §7b.

``--rate`` is the control rate (100 Hz by default, the rate of docs/safety.md §7b's first
tables; a real iiwa is driven at 500 Hz, a Franka at libfranka's 1 kHz), ``--robot`` the arm
(a bundled description: iiwa14, the default, panda, fr3, ur5), each with its own task and
seated operator. The rate matters: the arm's reaction time T_r is one control period plus
the arm's reaction in whole periods. The JSON's ``settings`` entry says the rate, the arm
and the options a file was made with; each run also counts its commands beyond the arm's
limits (``command_limit_violations``).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

from qpavoid.arm.description import bundled_robots
from qpavoid.arm.model import Robot
from qpavoid.control.analytic import AnalyticController
from qpavoid.control.controller import Controller
from qpavoid.control.qp import QPController
from qpavoid.control.tick import ControllerConfig
from qpavoid.experiments.runs import (
    RunSpec,
    build_controller,
    cell_uncertainty_m,
    simulate_one,
    spec_robot,
)
from qpavoid.human.body import BodyModel
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.human.landmarks import FORMAT_NAMES, skeleton_format
from qpavoid.loop.camera import CameraConfig


def rebuilt(
    base: Controller, robot: Robot, config: ControllerConfig, human: BodyModel | None
) -> Controller:
    """``base``'s controller again, of the same kind and settings, with ``config`` and
    ``human`` (None: the paper's model on the body's landmarks)."""
    if isinstance(base, QPController):
        return QPController(robot, config=config, human=human, qp=base.qp)
    assert isinstance(base, AnalyticController)
    return AnalyticController(robot, config=config, human=human, analytic=base.analytic)


def run(spec: RunSpec, ssm: dict | None = None) -> dict:
    """One run's productivity and safety; ``ssm``: speed and separation's constants to
    change (the human motion model's options, docs/safety.md §7b)."""
    if ssm:
        robot = spec_robot(spec)
        base = build_controller(spec, robot)
        config = replace(base.config, ssm=replace(base.config.ssm, **ssm))
        controller = rebuilt(base, robot, config, base.human)
        m = simulate_one(spec, robot=robot, controller=controller).metrics
    else:
        m = simulate_one(spec).metrics
    return {
        "reached_goal": m["reached_goal"],
        "duration_s": m["duration_s"],
        "stopped_s": m["stopped_s"],
        "ticks_moving_in_true_contact": m.get("ticks_moving_in_true_contact", 0),
        "command_limit_violations": sum(m.get("command_limit_violations", {}).values()),
    }


def terms(camera: str, rate_hz: float, robot_name: str = "iiwa14") -> dict:
    """``free`` at the Kinect v2's latency with one term at a time as the Kinect v2's, on
    the body's landmarks (issue 28's question: what the mapping's widening costs; a cell on
    the camera's own body has none)."""
    latency = KINECT_V2.sensor.latency_s
    spec = RunSpec(
        "free",
        controller="qp",
        safety="ssm",
        camera=camera,
        latency_s=latency,
        rate_hz=rate_hz,
        robot=robot_name,
    )
    robot = spec_robot(spec)
    native = build_controller(spec, robot)
    extra = cell_uncertainty_m([skeleton_format(camera)])
    on_landmarks = replace(
        native.config,
        perception=replace(native.config.perception, landmark_uncertainty_m=extra),
    )
    base = rebuilt(native, robot, on_landmarks, None)
    variants = {
        "as is": (base.config, {}),
        "kinect noise": (base.config, {"noise_m": KINECT_V2.sensor.noise_m}),
        "no landmark uncertainty": (
            replace(
                base.config, perception=replace(base.config.perception, landmark_uncertainty_m=())
            ),
            {},
        ),
        "kinect Z_d": (
            replace(
                base.config,
                ssm=replace(
                    base.config.ssm, sensing_uncertainty_m=KINECT_V2.sensor.tracked_uncertainty_m
                ),
            ),
            {},
        ),
    }
    for scale in (0.5, 0.25):
        scaled = tuple(scale * u for u in extra)
        perception = replace(base.config.perception, landmark_uncertainty_m=scaled)
        variants[f"landmark uncertainty x{scale}"] = (
            replace(base.config, perception=perception),
            {},
        )
    out = {}
    for label, (config, camera_fields) in variants.items():
        controller = rebuilt(base, robot, config, None)
        cfg = CameraConfig.of(camera, latency_s=latency, **camera_fields)
        m = simulate_one(spec, robot=robot, controller=controller, camera=cfg).metrics
        out[label] = {"duration_s": m["duration_s"], "stopped_s": m["stopped_s"]}
        print(
            f"{camera:15s} {label:28s} {m['duration_s']:.2f} s ({m['stopped_s']:.2f})", flush=True
        )
    return out


def _row(runs: dict[str, dict]) -> dict:
    """One camera's and controller's runs: the named scenarios and the random ones' sums."""
    randoms = [r for s, r in runs.items() if s.startswith("random:")]
    row = {s: runs[s] for s in ("free", "test1", "test2")}
    row["random"] = {
        "mean_duration_s": float(np.mean([r["duration_s"] for r in randoms])),
        "mean_stopped_s": float(np.mean([r["stopped_s"] for r in randoms])),
        "reached_goal": sum(r["reached_goal"] for r in randoms),
        "runs": len(randoms),
        "ticks_moving_in_true_contact": sum(r["ticks_moving_in_true_contact"] for r in randoms),
        "command_limit_violations": sum(r["command_limit_violations"] for r in randoms),
    }
    return row


def _print(label: str, row: dict) -> None:
    cells = [
        f"{row[s]['duration_s']:.2f} s ({row[s]['stopped_s']:.2f})"
        + ("" if row[s]["reached_goal"] else " cap")
        for s in ("free", "test1", "test2")
    ]
    r = row["random"]
    print(
        f"{label:38s} " + " | ".join(cells) + f" | random {r['mean_duration_s']:.2f} s / "
        f"{r['mean_stopped_s']:.2f} s, {r['reached_goal']}/{r['runs']}, "
        f"contact ticks {r['ticks_moving_in_true_contact']}, commands beyond limits "
        f"{sum(row[s]['command_limit_violations'] for s in ('free', 'test1', 'test2'))}"
        f"+{r['command_limit_violations']}",
        flush=True,
    )


def budget(
    camera: str,
    controller: str,
    safety: str,
    rate_hz: float,
    ssm: dict | None = None,
    robot_name: str = "iiwa14",
) -> float | None:
    """The longest latency (in 10 ms steps from 0) at which ``free`` reaches its goal within
    16 s through ``camera``, s; None if not even at 0."""
    best = None
    for ms in range(0, 200, 10):
        spec = RunSpec(
            "free",
            controller=controller,
            safety=safety,
            camera=camera,
            latency_s=ms / 1000.0,
            rate_hz=rate_hz,
            max_time_s=16.0,
            robot=robot_name,
        )
        if not run(spec, ssm)["reached_goal"]:
            break
        best = ms / 1000.0
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--random", type=int, default=10, help="random approaches per camera")
    ap.add_argument("--rate", type=float, default=100.0, help="control rate, Hz (100)")
    ap.add_argument("--robot", default="iiwa14", choices=bundled_robots(), help="the arm (iiwa14)")
    ap.add_argument("--out", type=Path, help="write the results as JSON")
    ap.add_argument("--terms", action="store_true", help="what each term costs (free, 60 ms)")
    ap.add_argument("--controllers", nargs="+", default=["qp"], choices=["qp", "analytic"])
    ap.add_argument("--safety", default="ssm", choices=["ssm", "pfl"])
    ap.add_argument("--cameras", nargs="+", default=list(FORMAT_NAMES), choices=FORMAT_NAMES)
    ap.add_argument(
        "--at-kinect-latency", action="store_true", help="also each camera at the Kinect v2's"
    )
    ap.add_argument(
        "--budget",
        action="store_true",
        help="the longest latency at which free reaches its goal within 16 s, per camera",
    )
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="worker processes")
    ap.add_argument("--body-speed", type=float, help="the head's and trunk's speed, m/s")
    ap.add_argument(
        "--body-acceleration", type=float, help="SaRA's acceleration model on, m/s² (off)"
    )
    ap.add_argument("--speed-error", type=float, help="its tracked speed's error, m/s")
    args = ap.parse_args()
    ssm = {
        key: value
        for key, value in (
            ("body_speed_mps", args.body_speed),
            ("body_acceleration_mps2", args.body_acceleration),
            ("speed_error_mps", args.speed_error),
        )
        if value is not None
    }
    settings = {
        "rate_hz": args.rate,
        "robot": args.robot,
        "safety": args.safety,
        "controllers": args.controllers,
        "random": args.random,
        "max_time_s": 16.0 if args.budget else 40.0,
        "ssm": ssm,
        "command": " ".join(["python benchmarks/cameras.py", *sys.argv[1:]]),
    }
    if args.terms:
        found: dict = {"settings": settings}
        found |= {c: terms(c, args.rate, args.robot) for c in args.cameras if c != KINECT_V2.name}
        if args.out:
            args.out.write_text(json.dumps(found, indent=1))
        return
    out: dict = {"settings": settings}
    if args.budget:
        with ProcessPoolExecutor(args.jobs) as pool:
            budgets = {
                (c, k): pool.submit(budget, c, k, args.safety, args.rate, ssm, args.robot)
                for c in args.cameras
                for k in args.controllers
            }
            for (c, k), job in budgets.items():
                out[f"{c}/{k}"] = job.result()
                print(f"{c:15s} {k:8s} free within 16 s up to {out[f'{c}/{k}']} s", flush=True)
        if args.out:
            args.out.write_text(json.dumps(out, indent=1))
        return
    scenarios = ["free", "test1", "test2"] + [f"random:{k}" for k in range(args.random)]
    cases = []
    for camera in args.cameras:
        latencies: dict[str, float | None] = {"own": None}
        if args.at_kinect_latency and camera != KINECT_V2.name:
            latencies["kinect_v2"] = KINECT_V2.sensor.latency_s
        for which, latency in latencies.items():
            for controller in args.controllers:
                cases.append((camera, which, latency, controller))
    print(f"{args.robot} at {args.rate:g} Hz, --safety {args.safety}", flush=True)
    with ProcessPoolExecutor(args.jobs) as pool:
        jobs = {
            (case, s): pool.submit(
                run,
                RunSpec(
                    s,
                    controller=case[3],
                    safety=args.safety,
                    camera=case[0],
                    latency_s=case[2],
                    rate_hz=args.rate,
                    max_time_s=40.0,
                    robot=args.robot,
                ),
                ssm,
            )
            for case in cases
            for s in scenarios
        }
        for case in cases:
            camera, which, _, controller = case
            row = _row({s: jobs[(case, s)].result() for s in scenarios})
            key = f"{camera}/{controller}/{which} latency"
            out[key] = row
            _print(key, row)
    if args.out:
        args.out.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
