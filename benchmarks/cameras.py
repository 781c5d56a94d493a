"""What each camera costs: the time to the goal through each format's simulated camera.

    python benchmarks/cameras.py [--random 10] [--rate 100] [--out FILE.json]
    python benchmarks/cameras.py --terms      # what each term costs, in free at 60 ms

For each skeleton format (its latency, noise, joint set, derived landmarks widened by their
uncertainty, failure modes: docs/sensors.md §10), the QP controller with speed and
separation monitoring on the real bench: the time to the goal and the time stopped in
``free``, ``test1``, ``test2`` and ``--random`` random approaches, at the format's own
latency and at the Kinect v2's (60 ms), which tells the latency's share of the cost from
the derived landmarks'. With ``--terms``, ``free`` at 60 ms for each camera with one term
switched to the Kinect v2's at a time (noise, no landmark uncertainty, Z_d) and the
landmark uncertainty scaled by 0.5 and 0.25. The numbers of docs/safety.md §7b.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from qpavoid.control.qp import QPController
from qpavoid.experiments.runs import RunSpec, build_controller, simulate_one, spec_robot
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.human.landmarks import FORMAT_NAMES
from qpavoid.loop.camera import CameraConfig


def run(spec: RunSpec) -> dict:
    """One run's productivity and safety."""
    m = simulate_one(spec).metrics
    return {
        "reached_goal": m["reached_goal"],
        "duration_s": m["duration_s"],
        "stopped_s": m["stopped_s"],
        "ticks_moving_in_true_contact": m.get("ticks_moving_in_true_contact", 0),
    }


def terms(camera: str, rate_hz: float) -> dict:
    """``free`` at the Kinect v2's latency with one term at a time as the Kinect v2's."""
    latency = KINECT_V2.sensor.latency_s
    spec = RunSpec(
        "free", controller="qp", safety="ssm", camera=camera, latency_s=latency, rate_hz=rate_hz
    )
    robot = spec_robot(spec)
    base = build_controller(spec, robot)
    extra = base.config.perception.landmark_uncertainty_m
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
        controller = QPController(robot, config=config, qp=base.qp)
        cfg = CameraConfig.of(camera, latency_s=latency, **camera_fields)  # type: ignore[arg-type]
        m = simulate_one(spec, robot=robot, controller=controller, camera=cfg).metrics
        out[label] = {"duration_s": m["duration_s"], "stopped_s": m["stopped_s"]}
        print(
            f"{camera:15s} {label:28s} {m['duration_s']:.2f} s ({m['stopped_s']:.2f})", flush=True
        )
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--random", type=int, default=10, help="random approaches per camera")
    ap.add_argument("--rate", type=float, default=100.0, help="control rate, Hz")
    ap.add_argument("--out", type=Path, help="write the results as JSON")
    ap.add_argument("--terms", action="store_true", help="what each term costs (free, 60 ms)")
    args = ap.parse_args()
    if args.terms:
        found = {c: terms(c, args.rate) for c in FORMAT_NAMES if c != KINECT_V2.name}
        if args.out:
            args.out.write_text(json.dumps(found, indent=1))
        return
    scenarios = ["free", "test1", "test2"] + [f"random:{k}" for k in range(args.random)]
    out: dict = {}
    for camera in FORMAT_NAMES:
        latencies = {"own": None, "kinect_v2": KINECT_V2.sensor.latency_s}
        for which, latency in latencies.items():
            if camera == KINECT_V2.name and which != "own":
                continue
            runs = {
                s: run(
                    RunSpec(
                        s,
                        controller="qp",
                        safety="ssm",
                        camera=camera,
                        latency_s=latency,
                        rate_hz=args.rate,
                        max_time_s=40.0,
                    )
                )
                for s in scenarios
            }
            randoms = [r for s, r in runs.items() if s.startswith("random:")]
            row = {s: runs[s] for s in ("free", "test1", "test2")}
            row["random"] = {
                "mean_duration_s": float(np.mean([r["duration_s"] for r in randoms])),
                "mean_stopped_s": float(np.mean([r["stopped_s"] for r in randoms])),
                "reached_goal": sum(r["reached_goal"] for r in randoms),
                "runs": len(randoms),
                "ticks_moving_in_true_contact": sum(
                    r["ticks_moving_in_true_contact"] for r in randoms
                ),
            }
            out[f"{camera}/{which} latency"] = row
            cells = [
                f"{row[s]['duration_s']:.2f} s ({row[s]['stopped_s']:.2f})"
                + ("" if row[s]["reached_goal"] else " cap")
                for s in ("free", "test1", "test2")
            ]
            r = row["random"]
            print(
                f"{camera:15s} {which:9s} latency: " + " | ".join(cells) + f" | random "
                f"{r['mean_duration_s']:.2f} s / {r['mean_stopped_s']:.2f} s, "
                f"{r['reached_goal']}/{r['runs']}",
                flush=True,
            )
    if args.out:
        args.out.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
