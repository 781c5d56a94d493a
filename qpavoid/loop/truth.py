"""Where the person really is: the yardstick every clearance is measured against.

The controller sees camera frames (sample and hold, possibly old); safety is judged
against the person's true position at each control tick. For a generated motion the
truth is the motion itself, sampled at the tick's time. For a recording it is the best
estimate between its frames: each joint interpolated linearly between the frames before
and after the tick (held after the last frame), so a fast strike between two 30 Hz frames
is not missed.

:class:`TrueClearance` measures, at each tick, the exact capsule distance (coal) between
every robot set and the true person, whatever distance method the controller uses.
"""

from __future__ import annotations

import numpy as np

from qpavoid.arm.model import Kinematics, Robot
from qpavoid.distance.capsules import CapsuleDistance
from qpavoid.human.body import BodyModel
from qpavoid.human.frames import HumanFrame, HumanMotion
from qpavoid.loop.crowd import Crowd
from qpavoid.sensing.recording import Recording


def true_frame(motion: HumanMotion, t: float) -> HumanFrame:
    """The person's true frame at time ``t`` on the motion's own clock.

    Recordings: joints interpolated linearly between the frames around ``t`` (a joint
    unusable in either frame takes the earlier frame's value and state); other motions:
    ``motion.frame_at(t)``.
    """
    if not isinstance(motion, Recording):
        assert not isinstance(motion, Crowd), "a crowd's people are sampled one by one"
        frame = motion.frame_at(t)
        return frame if isinstance(frame, HumanFrame) else HumanFrame.check(*frame)
    i = motion.index_at(t)
    if i + 1 >= motion.n_frames:
        return HumanFrame(motion.joints[i].copy(), motion.state[i].copy())
    t0, t1 = float(motion.t[i]), float(motion.t[i + 1])
    w = (t - t0) / (t1 - t0)
    a, b = motion.joints[i], motion.joints[i + 1]
    both = np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
    joints = np.where(both[:, None], (1.0 - w) * a + w * b, a)
    return HumanFrame(joints, motion.state[i].copy())


class TrueClearance:
    """Exact capsule distances from each robot set to the true person, m (build once).

    Parameters
    ----------
    robot, human
        The arm and the body model.
    motion
        The true motion (a scenario or a recording).
    """

    def __init__(self, robot: Robot, human: BodyModel, motion: HumanMotion):
        self.human, self.motion = human, motion
        self.capsules = CapsuleDistance(robot, human)
        self.n_sets = len(robot.sets)
        self.t0 = float(np.asarray(getattr(motion, "t", [0.0]))[0])

    def __call__(self, kin: Kinematics, t: float) -> np.ndarray:
        """(S,) the smallest true distance of each robot set at run time ``t``, m."""
        if isinstance(self.motion, Crowd):  # the nearest of everybody present
            people = self.motion.true_frames(t, true_frame).frames
            per_person = [self.capsules(kin, self.human.geometry(f)).min_per_set() for f in people]
            return np.min(per_person, axis=0) if per_person else np.full(self.n_sets, np.inf)
        geometry = self.human.geometry(true_frame(self.motion, self.t0 + t))
        return self.capsules(kin, geometry).min_per_set()
