"""Where a description's joints sit among a Franka arm's seven, and its locked joints.

A description may drive fewer joints than the arm has (a locked joint is held at its lock
angle): :class:`FrankaJoints` maps the active joints' vectors to the arm's seven and back;
streaming starts only with every locked joint within :data:`LOCK_TOLERANCE_RAD` of its
lock angle.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from qpavoid.arm.model import Robot
from qpavoid.core.errors import InputError

__all__ = ["LOCK_TOLERANCE_RAD", "FrankaJoints"]

#: How far the arm's locked joint may be from its lock angle for streaming to start, rad:
#: 3 mrad, 2.4 mm at the FR3's 0.8 m reach, within the 5 mm the capsules carry for their
#: fit (Z_r); franky-sim's position loop settles its joint 3 up to 1.4 mrad off a target.
LOCK_TOLERANCE_RAD = 3e-3
#: The name of a Franka arm joint: ``<arm>_joint<k>``, k = 1..7 (not a finger's).
_ARM_JOINT = re.compile(r"(?P<arm>[A-Za-z0-9]+)_joint(?P<k>[1-7])")


@dataclass(frozen=True)
class FrankaJoints:
    """Where the description's joints sit among the arm's seven.

    Attributes
    ----------
    names
        The arm's seven joints, in the arm's order (``fr3_joint1`` ... ``fr3_joint7``).
    active
        (nv,) the index among the seven of each active joint, in ``robot.joint_names``
        order.
    locked
        The index among the seven of each locked joint.
    locked_angles_rad
        Their lock angles, rad.
    """

    names: tuple[str, ...]
    active: tuple[int, ...]
    locked: tuple[int, ...]
    locked_angles_rad: tuple[float, ...]

    @classmethod
    def of(cls, robot: Robot) -> FrankaJoints:
        """The map of a description with the seven joints of a Franka arm.

        Raises
        ------
        InputError
            The description's joints (active and locked) are not one Franka arm's seven
            (``<arm>_joint1`` ... ``<arm>_joint7``), or an active joint is not one of them.
        """
        found: dict[int, str] = {}
        arms = set()
        for name in (*robot.joint_names, *robot.locked):
            m = _ARM_JOINT.fullmatch(name)
            if m:
                found[int(m["k"])] = name
                arms.add(m["arm"])
        if sorted(found) != list(range(1, 8)) or len(arms) != 1:
            raise InputError(
                f"--arm franka and panda drive a Franka arm (--robot fr3 or panda): seven "
                f"joints <arm>_joint1 ... <arm>_joint7, which the description {robot.name!r} "
                f"has not (its joints: {list(robot.joint_names) + list(robot.locked)})",
                name="robot",
                value=robot.name,
            )
        names = tuple(found[k] for k in range(1, 8))
        others = [n for n in robot.joint_names if n not in names]
        if others:
            raise InputError(
                f"the Franka adapters drive the arm's seven joints only; the description "
                f"{robot.name!r} also makes {others} active",
                name="robot",
                value=others,
            )
        locked = tuple(k for k, n in enumerate(names) if n in robot.locked)
        return cls(
            names,
            tuple(names.index(n) for n in robot.joint_names),
            locked,
            tuple(float(robot.locked[names[k]]) for k in locked),
        )

    def position(self, q: np.ndarray) -> np.ndarray:
        """The arm's seven angles (7,), rad, for the active joints' ``q`` (nv,) and the
        locked ones at their lock angles."""
        out = np.zeros(7)
        out[list(self.active)] = q
        out[list(self.locked)] = self.locked_angles_rad
        return out

    def velocity(self, dq: np.ndarray) -> np.ndarray:
        """The arm's seven joint velocities (7,), rad/s, for the active joints' ``dq``
        (nv,) and the locked ones still."""
        out = np.zeros(7)
        out[list(self.active)] = dq
        return out

    def active_of(self, v7: np.ndarray) -> np.ndarray:
        """The active joints' values (nv,) of the arm's seven (7,)."""
        return np.asarray(v7, dtype=float)[list(self.active)]

    def lock_errors(self, q7: np.ndarray) -> dict[str, float]:
        """How far each locked joint of the arm's angles ``q7`` (7,) is from its lock
        angle, rad, by name."""
        return {
            self.names[k]: float(q7[k] - angle)
            for k, angle in zip(self.locked, self.locked_angles_rad, strict=True)
        }
