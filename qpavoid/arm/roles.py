"""Which control set plays which part in the paper's laws: :class:`Roles`, read from the
``[roles]`` table of the control-point file (``docs/robot.md``: Roles).

The sets are checked against the file's ``[[sets]]`` and the joints against the URDF's;
whether a role's joints move its set, and stay free after locking, needs the model
(:mod:`qpavoid.arm.model_checks`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import msgspec

from qpavoid.arm.control_points import Spot
from qpavoid.arm.description_schema import ControlSetTable, Offset, RolesTable, SetRole
from qpavoid.arm.joints import joint_list
from qpavoid.core.errors import RobotDescriptionError

__all__ = ["ROLE_NAMES", "Roles", "read_roles"]

#: The parts a control set plays in the paper's laws (``[roles]`` of the control-point
#: file, :class:`Roles`), in the order of :attr:`Roles.rows`.
ROLE_NAMES = ("scaled", "repelled", "end_effector")


@dataclass(frozen=True)
class Roles:
    """Which control set plays which part in the paper's laws, and on which joints.

    The paper names its sets after the iiwa's links (L1, L2, EE); the controllers address
    them by the part they play, so that any arm's sets, named as its description likes,
    can play them. The parts are given by the ``[roles]`` table of the control-point file
    (``docs/robot.md``).

    Attributes
    ----------
    scaled
        Row (set index) of the set whose distance gives the factor f of eq. (2) (the
        paper's L1).
    scaled_joints
        Joints whose velocity limits eq. (3) scales by (1 − f): the joints that move the
        scaled set (the paper's A1 and A2).
    repelled
        Row of the set whose closest point is pushed away from the person at v_rep of
        eqs. (4)-(5), through eq. (6)'s square Jacobian and eq. (9) (the paper's L2).
    repelled_joints
        Joints of eq. (6)'s square Jacobian and of eq. (9)'s sum, as many as the three
        components of v_rep (the paper's A1, A2 and A4).
    end_effector
        Row of the set that carries the task of eq. (8) and the repulsion of eq. (7)
        (the paper's EE).
    elbow
        Index of the elbow among the control points (the redundancy mode keeps it away
        from the person, :class:`~qpavoid.control.qp.tasks.elbow.ElbowClearanceTask`), or
        None if the description names none.
    """

    scaled: int
    scaled_joints: tuple[str, ...]
    repelled: int
    repelled_joints: tuple[str, ...]
    end_effector: int
    elbow: int | None = None

    @property
    def rows(self) -> tuple[int, int, int]:
        """The rows of the scaled, repelled and end-effector sets (:data:`ROLE_NAMES`)."""
        return (self.scaled, self.repelled, self.end_effector)


def read_roles(
    table: RolesTable, path: Path, sets: Sequence[ControlSetTable], joints: Sequence[str]
) -> Roles:
    """The ``[roles]`` table (its shape checked by the file's schema): each role's set one
    of the file's, its joints the URDF's, each once, and the elbow one of the points."""
    names = [sc.name for sc in sets]
    rows: dict[str, int] = {}
    role_joints: dict[str, tuple[str, ...]] = {}
    for role in ROLE_NAMES:
        entry = getattr(table, role)
        if entry.set not in names:
            raise RobotDescriptionError(
                f"{path}: [roles] {role}: no set named {entry.set!r}; the sets are {names}",
                path=path,
                name=f"roles.{role}.set",
                value=entry.set,
            )
        rows[role] = names.index(entry.set)
        if isinstance(entry, SetRole):
            where = f"roles.{role}.joints"
            role_joints[role] = joint_list(entry.joints, where, path, joints)
            twice = sorted({n for n in role_joints[role] if role_joints[role].count(n) > 1})
            if not role_joints[role] or twice:
                raise RobotDescriptionError(
                    f"{path}: [roles] {role}.joints "
                    + (f"lists {twice} more than once" if twice else "is empty")
                    + f"; name each joint that moves the set {entry.set!r} once "
                    "(docs/robot.md: Roles)",
                    path=path,
                    name=where,
                    value=twice or [],
                )
    return Roles(
        scaled=rows["scaled"],
        scaled_joints=role_joints["scaled"],
        repelled=rows["repelled"],
        repelled_joints=role_joints["repelled"],
        end_effector=rows["end_effector"],
        elbow=_elbow(table.elbow, path, sets),
    )


def _elbow(spot: Spot | None, path: Path, sets: Sequence[ControlSetTable]) -> int | None:
    """Index of the control point ``[roles] elbow`` names: the list of its frames, or its
    offset table (``{ frame = "<frame>", xyz = [x, y, z] }``), as in its set's points."""
    if spot is None:
        return None
    points = [_spot_key(p) for sc in sets for p in sc.points]  # every point, set after set
    given = _spot_key(spot)
    if given in points:
        return points.index(given)
    shown = [key if isinstance(key, list) else msgspec.structs.asdict(key) for key in points]
    raise RobotDescriptionError(
        f"{path}: [roles] elbow must be one control point as its set's points give it (the "
        f"list of its frames, or its {{ frame, xyz }} table); {_shown(spot)!r} is none of "
        f"{shown}",
        path=path,
        name="roles.elbow",
        value=_shown(spot),
    )


def _spot_key(spot: Spot) -> list[str] | Offset:
    """A comparable form of a point: its frames sorted, or its offset (structs compare by
    value)."""
    return spot if isinstance(spot, Offset) else sorted(spot)


def _shown(spot: Spot) -> object:
    """A point as the file gives it (a list of frames, or a table)."""
    return msgspec.structs.asdict(spot) if isinstance(spot, Offset) else spot
