"""How well a camera's latency is measured: the estimator on simulated measurements.

    python benchmarks/latency.py [--seeds 3] [--robot iiwa14] [--out FILE.json]

For each skeleton format's simulated camera, at its own noise and at three times it, and
at true latencies of 0.03, 0.06, 0.10 and 0.15 s: the arm moves the default excitation
(30 s) while the operator holds its flange (:func:`qpavoid.loop.excitation.film_excitation`,
every frame stamped on arrival), and :func:`qpavoid.sensing.latency_fit.estimate_latency` fits
the lag. Printed as a Markdown table (docs/sensors.md §10), over ``--seeds`` seeds (the
camera's noise, swaps and anatomy; each case its own): for each true latency the mean
estimate and the error's RMS, then the mean reported uncertainty (one standard error), the
fit's residual and the frames left out as outliers. Accuracy, not timing: nothing here is
timed.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from qpavoid.arm.model import load_robot
from qpavoid.human.landmarks import FORMAT_NAMES, skeleton_format
from qpavoid.loop.camera import CameraConfig
from qpavoid.loop.excitation import film_excitation
from qpavoid.sensing.arm_log import flange_positions
from qpavoid.sensing.hand_track import camera_track
from qpavoid.sensing.latency_fit import estimate_latency

#: The true latencies measured, s: from a fast pipeline to beyond the formats' assumed ones.
LATENCIES_S = (0.03, 0.06, 0.10, 0.15)
#: The noise levels, as multiples of each format's own ``noise_m``.
NOISE_SCALES = (1.0, 3.0)


def one(robot, camera: CameraConfig) -> dict:
    """One simulated measurement, fitted."""
    recording, log = film_excitation(robot, camera)
    t, hand = camera_track(recording)
    e = estimate_latency(t, hand, log.t, flange_positions(robot, log.q))
    return {
        "latency_s": e.latency_s,
        "error_s": e.latency_s - camera.latency_s,
        "uncertainty_s": e.uncertainty_s,
        "residual_m": e.residual_m,
        "explained": e.explained,
        "frames": e.frames,
        "outliers": e.outliers,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5, help="measurements per case")
    ap.add_argument("--robot", default="iiwa14", help="the arm")
    ap.add_argument("--out", type=Path, help="write the results as JSON")
    args = ap.parse_args()
    robot = load_robot(args.robot)
    heads = " | ".join(f"{latency * 1e3:.0f} ms" for latency in LATENCIES_S)
    print(f"| camera | noise per axis | {heads} | uncertainty | residual | outliers |")
    print("|---|---|" + "---|" * len(LATENCIES_S) + "---|---|---|")
    out: dict = {}
    z = []
    for fmt in FORMAT_NAMES:
        own = skeleton_format(fmt).sensor.noise_m
        for scale in NOISE_SCALES:
            cells, runs_here = [], []
            for i, latency in enumerate(LATENCIES_S):
                runs = [  # a seed of its own for each case: independent noise
                    one(
                        robot,
                        CameraConfig.of(
                            fmt, latency_s=latency, noise_m=scale * own, seed=100 * i + s
                        ),
                    )
                    for s in range(args.seeds)
                ]
                err = np.array([r["error_s"] for r in runs])
                z.extend(err / np.array([r["uncertainty_s"] for r in runs]))
                out[f"{fmt}/noise x{scale:g}/{latency:g} s"] = runs
                mean = np.mean([r["latency_s"] for r in runs])
                cells.append(f"{mean * 1e3:.1f} ({math.sqrt(np.mean(err**2)) * 1e3:.1f})")
                runs_here += runs
            print(
                f"| {fmt} | {scale * own * 1e3:g} mm | " + " | ".join(cells) + " | "
                f"{np.mean([r['uncertainty_s'] for r in runs_here]) * 1e3:.1f} ms | "
                f"{np.mean([r['residual_m'] for r in runs_here]) * 1e3:.1f} mm | "
                f"{sum(r['outliers'] for r in runs_here)} |",
                flush=True,
            )
    z_rms = math.sqrt(float(np.mean(np.square(z))))
    print(
        f"\nestimate (RMS error) in ms over {args.seeds} seeds; uncertainty: the mean reported "
        f"standard error. Error / reported uncertainty over all {len(z)} measurements: RMS "
        f"{z_rms:.2f}, largest {np.abs(z).max():.2f} (Student's t with blocks - 1 = 9 degrees "
        "of freedom if the uncertainty is right: RMS 1.13, 1 in 100 beyond 3.25)"
    )
    if args.out:
        args.out.write_text(json.dumps({"z_rms": z_rms, "cases": out}, indent=1))


if __name__ == "__main__":
    main()
