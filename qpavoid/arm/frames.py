"""The control points and capsule ends as operational frames of the Pinocchio model.

Every point and capsule end of the control-point file becomes a frame named after its set
(``<set>_p<k>``, ``<set>_capsule_from``, ``<set>_capsule_to``), so positions and Jacobians
come from Pinocchio, in the axes of :data:`LWA`. A point is the centroid of frames of one
rigid body, or an offset from one frame in its axes; frames are placed at the neutral
configuration, before any joint is locked, and locking carries them over.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pinocchio as pin

from qpavoid.arm.control_points import ControlSet, Spot
from qpavoid.arm.description_schema import ControlSetTable, Offset
from qpavoid.core.errors import RobotDescriptionError

__all__ = ["LWA", "add_frames", "control_sets"]

#: Pinocchio's frame for every Jacobian of the arm: the point's velocity in base-frame axes.
LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


def _carriers(model: pin.Model, frame_id: int) -> set[int]:
    """Joints whose body carries the origin of a frame.

    The origin of a revolute joint's frame lies on its axis, so it is fixed on both the
    parent body and the joint's own body.
    """
    frame = model.frames[frame_id]
    carriers = {frame.parentJoint}
    if frame.type == pin.FrameType.JOINT:
        carriers.add(model.parents[frame.parentJoint])
    return carriers


def _frame_list(model: pin.Model, count: int) -> str:
    """The URDF's frame names (the first ``count`` frames of the model, the universe
    aside), shortened for a message."""
    names = [str(model.frames[i].name) for i in range(1, count)]
    shown = names if len(names) <= 20 else [*names[:20], f"... ({len(names)} in all)"]
    return "[" + ", ".join(shown) + "]"


def _add_point_frame(
    model: pin.Model,
    data: pin.Data,
    label: str,
    spot: Spot,
    where: tuple[str, str, Path, Path, int],
) -> int:
    """Add an operational frame at a spot of the file; return its id.

    A spot is the centroid of the named frames (``["A2", "A3"]``), or an offset from one
    frame in its axes (``{ frame = "panda_link4", xyz = [0.0, 0.0, 0.1] }``, m), which
    then moves with that frame's body. ``where`` says where in the file the spot is: the
    key as the file says it (``"[[sets]] entry 0 (L1) points[2]"``), as the error's
    ``name``, the file, the URDF and the number of the URDF's own frames (for the list in
    the message).
    """
    said, key, path, urdf, n_frames = where
    if isinstance(spot, Offset):
        names: Sequence[str] = [spot.frame]
        offset = np.asarray(spot.xyz, dtype=float)
    else:
        names, offset = spot, None
    ids = []
    for n in names:
        if not model.existFrame(n):
            raise RobotDescriptionError(
                f"{path}: {said}: no frame named {n!r} in {urdf.name}; its frames are "
                f"{_frame_list(model, n_frames)}",
                path=path,
                name=key,
                value=n,
            )
        ids.append(model.getFrameId(n))
    if offset is not None:  # off the frame's origin: only the frame's own body carries it
        _exists_free(model, label, said, key, path, urdf)
        frame = model.frames[ids[0]]
        placement = frame.placement * pin.SE3(np.eye(3), offset)
        return model.addFrame(
            pin.Frame(label, frame.parentJoint, placement, pin.FrameType.OP_FRAME)
        )
    common = set.intersection(*(_carriers(model, i) for i in ids))
    if not common:
        raise RobotDescriptionError(
            f"{path}: {said}: frames {list(names)} are not on one rigid body of {urdf.name}; "
            "a point is the centroid of frames of one link (or of the joints at its ends)",
            path=path,
            name=key,
            value=list(names),
        )
    _exists_free(model, label, said, key, path, urdf)
    parent = max(common)  # the deepest body carrying all of them
    centre = np.mean([data.oMf[i].translation for i in ids], axis=0)
    placement = data.oMi[parent].actInv(pin.SE3(np.eye(3), centre))
    return model.addFrame(pin.Frame(label, parent, placement, pin.FrameType.OP_FRAME))


def _exists_free(model: pin.Model, label: str, said: str, key: str, path: Path, urdf: Path) -> None:
    """Refuse a URDF that already has a frame of the name qpavoid gives a point."""
    if model.existFrame(label):
        raise RobotDescriptionError(
            f"{path}: {said}: {urdf.name} already has a frame named {label!r}, the name "
            "qpavoid gives this point; rename the set",
            path=path,
            name=key,
            value=label,
        )


def add_frames(model: pin.Model, sets: Sequence[ControlSetTable], path: Path, urdf: Path) -> None:
    """Operational frames for points and capsule ends, placed at the neutral configuration."""
    data = model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    n_frames = model.nframes
    for i, sc in enumerate(sets):
        name, cap = sc.name, sc.capsule
        entries: list[tuple[str, Spot, str]] = [
            (f"{name}_p{k}", spot, f"points[{k}]") for k, spot in enumerate(sc.points)
        ]
        entries += [
            (f"{name}_capsule_{end}", [spot] if isinstance(spot, str) else spot, f"capsule.{end}")
            for end, spot in (("from", cap.from_), ("to", cap.to))
        ]
        for label, spot, key in entries:
            said = f"[[sets]] entry {i} ({name}) {key}"
            _add_point_frame(
                model, data, label, spot, (said, f"sets[{i}].{key}", path, urdf, n_frames)
            )


def control_sets(
    model: pin.Model, tables: Sequence[ControlSetTable]
) -> tuple[list[ControlSet], list[int]]:
    """The control sets and the frame id of every control point, set after set."""
    sets: list[ControlSet] = []
    point_frames: list[int] = []
    for sc in tables:
        idx = []
        for k in range(len(sc.points)):
            idx.append(len(point_frames))
            point_frames.append(model.getFrameId(f"{sc.name}_p{k}"))
        sets.append(
            ControlSet(
                name=sc.name,
                sphere_radius_m=sc.sphere_radius_m,
                points=tuple(idx),
                capsule_frames=(
                    model.getFrameId(f"{sc.name}_capsule_from"),
                    model.getFrameId(f"{sc.name}_capsule_to"),
                ),
                capsule_radius_m=sc.capsule.capsule_radius_m,
            )
        )
    return sets, point_frames
