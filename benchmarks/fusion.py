"""Skeleton fusion: its error against a known truth and its time per frame (docs/sensors.md).

    python benchmarks/fusion.py [--seeds 5] [--seconds 10] [--json FILE]
                                [--formats A,B ...] [--all-formats]

1. Error: two simulated Kinect v2 (50 mm mean error, occlusions, mirroring, a 13 ms phase
   and a 0.25 s clock offset; :mod:`qpavoid.sensing.synthetic_pair`) film a known motion; the mean
   and
   99th-percentile joint error of each sensor alone and of the fusion, raw (the sensors'
   weighted mean) and filtered (the default), over the fused frames.
2. Time: ``Fuser.add`` of one frame plus ``Fuser.fuse`` at every capture time, for 1 and 6
   people seen by two sensors, 4 s of each seed's data (median and p99 over the seeds'
   frames after warm-up), next to the paper's 4 ms.

``--formats A,B`` (any number of pairs) films with cameras of those skeleton formats
(:data:`~qpavoid.human.landmarks.FORMAT_NAMES`; default two Kinect v2, the numbers of
docs/sensors.md): each pair is measured as above, its keys prefixed with the pair.
``--all-formats``: each format alone (two cameras of it) and the mixed pairs
kinect_v2+k4abt and zed_body_34+k4abt.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from qpavoid.arm.model import load_robot
from qpavoid.fusion.fuser import Fuser, FusionConfig
from qpavoid.scenarios.generated import make_scenario
from qpavoid.scenarios.strikes import strike_case, strike_motion
from qpavoid.sensing.calibration import Calibration, known_formats
from qpavoid.sensing.synthetic_pair import TwoSensorConfig, two_sensor_data

BOTH = ("kinect_left", "kinect_right")
KINECT_PAIR = ("kinect_v2", "kinect_v2")
#: The mixed cells of ``--all-formats``.
MIXED = (("kinect_v2", "k4abt"), ("zed_body_34", "k4abt"))


class Shifted:
    """Another person: a motion moved along x, m."""

    def __init__(self, motion, dx: float):
        self.motion, self.dx = motion, dx

    def frame_at(self, t: float):
        joints, state = self.motion.frame_at(t)
        return joints + np.array([self.dx, 0.0, 0.0]), state


def play(data, names, config, truth=None):
    """Fuse ``names``' frames in capture order; errors (m) against ``truth`` and times (s)."""
    cal = Calibration({n: data.calibration[n] for n in names})
    rows = sorted(
        (f.t + cal[f.sensor].time_offset_s, f) for n in names for f in data.recordings[n].frames()
    )
    fuser = Fuser(cal, config)
    errors, times = [], []
    for t, f in rows:
        t0 = time.perf_counter()
        fuser.add(f)
        out = fuser.fuse(t)
        times.append(time.perf_counter() - t0)
        if truth is not None and out.people:
            joints = out.people[0].frame.joints
            true = truth.frame_at(t)[0]
            ok = np.isfinite(joints).all(axis=1)
            errors.extend(np.linalg.norm(joints[ok] - true[ok], axis=1))
    return np.array(errors), np.array(times[len(times) // 10 :])


def pair(text: str) -> tuple[str, str]:
    """``A,B``: two skeleton formats' names."""
    names = tuple(text.split(","))
    if len(names) != 2 or not all(n in known_formats() for n in names):
        raise argparse.ArgumentTypeError(
            f"expected two formats A,B of {', '.join(known_formats())}, got {text!r}"
        )
    return names  # type: ignore[return-value]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--json")
    ap.add_argument("--formats", type=pair, nargs="+", default=[KINECT_PAIR], metavar="A,B")
    ap.add_argument("--all-formats", action="store_true")
    args = ap.parse_args()
    pairs = args.formats
    if args.all_formats:
        pairs = [(name, name) for name in known_formats()] + list(MIXED)
    robot = load_robot("iiwa14")
    raw, filtered = FusionConfig(smooth=False), FusionConfig()
    errors: dict[str, list] = {}
    for formats in pairs:
        cell = "" if formats == KINECT_PAIR else f"{formats[0]}+{formats[1]}: "
        left, right = (
            (f"left ({formats[0]})", f"right ({formats[1]})") if cell else ("left", "right")
        )
        for seed in range(args.seeds):
            for name, motion in (
                ("free", make_scenario("free", robot)),
                ("strike 2 m/s", strike_motion(strike_case(seed, 2.0), robot)),
            ):
                config = TwoSensorConfig(seed=seed, formats=formats)
                data = two_sensor_data([motion], args.seconds, config)
                for label, names, cfg in (
                    (f"{left} alone (raw)", BOTH[:1], raw),
                    (f"{right} alone (raw)", BOTH[1:], raw),
                    ("fused, raw mean", BOTH, raw),
                    (f"{left} alone, filtered", BOTH[:1], filtered),
                    (f"{right} alone, filtered", BOTH[1:], filtered),
                    ("fused, filtered (default)", BOTH, filtered),
                ):
                    e, _ = play(data, names, cfg, motion)
                    errors.setdefault(f"{cell}{name}: {label}", []).append(e)
    result: dict = {"error_mm": {}, "time_us": {}}
    print("joint error against the truth, mm (mean / p99 / max)")
    for key, parts in errors.items():
        e = np.concatenate(parts) * 1e3
        stats = [float(np.mean(e)), float(np.percentile(e, 99)), float(e.max())]
        result["error_mm"][key] = dict(zip(("mean", "p99", "max"), stats, strict=True))
        print(f"  {key:60s} {stats[0]:6.1f} {stats[1]:6.1f} {stats[2]:6.1f}")
    print("time per frame (add + fuse), us (median / p99); the paper: 4000 us")
    base = make_scenario("free", robot)
    for formats in pairs:
        cell = "" if formats == KINECT_PAIR else f"{formats[0]}+{formats[1]}: "
        most = min(known_formats()[f].sensor.max_bodies for f in formats)
        for people in sorted({1, min(6, most)}):
            motions = [Shifted(base, 0.8 * k) for k in range(people)]
            t = np.concatenate(
                [
                    play(
                        two_sensor_data(motions, 4.0, TwoSensorConfig(seed=seed, formats=formats)),
                        BOTH,
                        filtered,
                    )[1]
                    for seed in range(args.seeds)
                ]
            )
            stats = [float(np.median(t) * 1e6), float(np.percentile(t, 99) * 1e6)]
            result["time_us"][f"{cell}{people} people, 2 sensors"] = dict(
                zip(("median", "p99"), stats, strict=True)
            )
            print(f"  {cell}{people} people, 2 sensors: {stats[0]:7.1f} {stats[1]:7.1f}")
    if args.json:
        with open(args.json, "w") as handle:
            json.dump(result, handle, indent=1)


if __name__ == "__main__":
    main()
