"""The command ramp's reachable box in one compiled pass, against its numpy terms.

:meth:`CommandRamp.box` (the compiled :func:`command_box`) must equal
:meth:`CommandRamp.box_numpy` (acceleration and jerk reach, the room to brake before the
joint limits with the commands in flight, the jerk's gain) to the last bit, on every arm
at 100 Hz and 1 kHz (where a Franka's jerk binds), with and without commands in flight,
after an interface's tighter limits, near the joint limits and past them.
"""

from __future__ import annotations

import numpy as np
import pytest

import qpavoid
from qpavoid.control.smoothing import CommandRamp


@pytest.mark.parametrize("arm", ["iiwa14", "panda", "fr3", "ur5"])
@pytest.mark.parametrize("rate_hz, reaction_s", [(100.0, 0.0), (1000.0, 0.003)])
def test_the_compiled_box_is_the_numpy_one(arm, rate_hz, reaction_s):
    robot = qpavoid.load_robot(arm)
    dt = 1.0 / rate_hz
    braking = tuple((n, 0.8 * a) for n, a in robot.arm.max_acceleration_radps2)
    rng = np.random.default_rng(31)
    for case in range(60):
        ramp = CommandRamp(robot, dt, braking, reaction_time_s=reaction_s)
        if case % 3 == 2:  # an interface's tighter limits
            nv = robot.nv
            ramp.tighten(
                np.asarray(robot.dq_max) * 0.5,
                rng.uniform(1.0, 10.0, nv),
                rng.uniform(50.0, 5000.0, nv),
                braking,
            )
        for _ in range(int(rng.integers(0, 4))):  # a few commands sent
            ramp.commit(rng.uniform(-1, 1, robot.nv) * np.asarray(robot.dq_max), stopping=False)
        span = robot.q_max - robot.q_min
        q = robot.q_min + rng.uniform(-0.02, 1.02, robot.nv) * span  # near and past limits
        lo, hi = ramp.box(q)
        lo_np, hi_np = ramp.box_numpy(q)
        np.testing.assert_array_equal(lo, lo_np)
        np.testing.assert_array_equal(hi, hi_np)
