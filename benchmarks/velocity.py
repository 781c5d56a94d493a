"""Lag and noise of the person's velocity estimate (qpavoid.perception.tracker), on a known truth.

    python benchmarks/velocity.py

A hand at rest starts moving at t = 1 s with a constant velocity (a step in velocity),
seen at 30 Hz with Kinect-like noise; and a hand oscillating at 1 Hz. Printed: the time
the estimate needs to reach 90 % of a step, the steady-state error and noise, and the
oscillation's amplitude ratio and phase lag.
"""

from __future__ import annotations

import numpy as np

from qpavoid.human.frames import HumanFrame
from qpavoid.human.kinect_v2 import JointType
from qpavoid.human.posture import Operator
from qpavoid.loop.camera import KINECT_V2_NOISE_M
from qpavoid.perception.tracker import Tracker

HAND = int(JointType.HandRight)
RATE = 30.0
AMP = 0.1  # m, the oscillation's amplitude


def estimate(hand_path, seconds: float, noise_m: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    tracker = Tracker()
    t = np.arange(0.0, seconds, 1 / RATE)
    out = []
    for tk in t:
        joints = Operator().rest()
        joints[HAND] += hand_path(tk)
        joints = joints + rng.normal(0.0, noise_m, joints.shape)
        out.append(tracker.update(HumanFrame.check(joints), float(tk)).joint_velocity[HAND, 0])
    return t, np.array(out)


def main() -> None:
    for noise in (0.0, KINECT_V2_NOISE_M, 0.005):
        rise, err, sd = [], [], []
        for seed in range(20):
            t, v = estimate(lambda s: np.array([max(s - 1.0, 0.0), 0, 0]), 3.0, noise, seed)
            after = t >= 1.0
            rise.append(t[after][np.argmax(v[after] >= 0.9)] - 1.0)
            steady = t > 1.5
            err.append(v[steady].mean() - 1.0)
            sd.append(v[steady].std())
        print(
            f"step 1 m/s, noise {noise * 1e3:.0f} mm: 90% after {np.mean(rise) * 1e3:.0f} ms, "
            f"steady error {np.mean(err):+.3f} m/s, noise {np.mean(sd):.3f} m/s"
        )
        t, v = estimate(lambda s: np.array([AMP * np.sin(2 * np.pi * s), 0, 0]), 6.0, noise, 0)
        true = AMP * 2 * np.pi * np.cos(2 * np.pi * t)
        k = t > 2.0
        lags = np.arange(0, 10)
        fit = [np.mean((v[k][lag:] - true[k][: len(true[k]) - lag]) ** 2) for lag in lags]
        best = int(np.argmin(fit))
        ratio = v[k].std() / true[k].std()
        print(
            f"  1 Hz, 0.1 m: amplitude ratio {ratio:.2f}, lag {best / RATE * 1e3:.0f} ms "
            f"(whole frames), rms error {np.sqrt(np.mean((v[k] - true[k]) ** 2)):.3f} m/s"
        )


if __name__ == "__main__":
    main()
