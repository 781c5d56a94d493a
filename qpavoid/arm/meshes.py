"""The arm's real geometry: the collision meshes and shapes of its URDF, on the robot's model.

The controllers reason about capsules and spheres (:mod:`qpavoid.arm.description`); the
URDF's ``<collision>`` elements are the arm itself. Pinocchio reads them
(``buildGeomFromUrdf``, meshes loaded by coal) on the URDF's full model; here each object
is moved onto the robot's own (reduced) model through the link frame that carries it, so
its placement follows :attr:`~qpavoid.arm.model.Robot.model`'s joints whatever the
description locks.

Used by the capsule fit and the coverage check (every vertex inside the model the
controller uses), by the true clearance (the person against the meshes, not the capsules)
and by the replay (the arm drawn as it is).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Protocol

import coal
import numpy as np
import pinocchio as pin

from qpavoid.core.checks import one_line
from qpavoid.core.errors import RobotDescriptionError

__all__ = ["RIM_SAMPLES", "ArmFiles", "collision_geometry", "object_vertices", "urdf_geometry"]


class ArmFiles(Protocol):
    """What :func:`collision_geometry` reads of a robot
    (a :class:`~qpavoid.arm.model.Robot`; named here without importing it, which
    imports this module's users)."""

    model: pin.Model
    urdf: Path | None
    mesh_dirs: tuple[Path, ...]


#: Points per circle where a round primitive (cylinder, sphere, capsule) stands for its
#: surface in :func:`object_vertices`: at 64, a chord misses the circle by
#: r (1 − cos(π/64)) = 0.0012 r (0.08 mm for a 7 cm link).
RIM_SAMPLES = 64


def collision_geometry(robot: ArmFiles) -> pin.GeometryModel:
    """The URDF's collision objects, placed on ``robot.model``'s joints.

    Returns an empty model for a robot built without a URDF file. Objects on a body that
    the robot's model does not keep (none: locking a joint keeps its links as frames) are
    an error.

    Raises
    ------
    RobotDescriptionError
        If the URDF's meshes cannot be loaded (a missing file, a ``package://`` that no
        folder of :attr:`~qpavoid.arm.model.Robot.mesh_dirs` holds).
    """
    if robot.urdf is None:
        return pin.GeometryModel()
    full, geometry = urdf_geometry(robot.urdf, robot.mesh_dirs)
    model = robot.model
    placed = pin.GeometryModel()
    for obj in geometry.geometryObjects:
        link = full.frames[obj.parentFrame]
        if not model.existFrame(link.name):
            raise RobotDescriptionError(
                f"{robot.urdf}: collision object {obj.name!r} hangs on {link.name!r}, "
                "which the robot's model lacks",
                path=robot.urdf,
                name="urdf",
                value=obj.name,
            )
        frame_id = model.getFrameId(link.name)
        frame = model.frames[frame_id]
        in_link = link.placement.actInv(obj.placement)  # the object in its link's frame
        copy = pin.GeometryObject(
            obj.name,
            frame.parentJoint,
            frame_id,
            frame.placement * in_link,
            obj.geometry,
            obj.meshPath,
            obj.meshScale,
        )
        placed.addGeometryObject(copy)
    return placed


def urdf_geometry(
    urdf: Path, package_dirs: Sequence[Path] = ()
) -> tuple[pin.Model, pin.GeometryModel]:
    """The URDF's full model (no joint locked) and its collision objects on it.

    Raises
    ------
    RobotDescriptionError
        If the URDF or its meshes cannot be loaded (a missing file, a ``package://`` that
        no folder of ``package_dirs`` holds).
    """
    try:
        full = pin.buildModelFromUrdf(str(urdf))
        geometry = pin.buildGeomFromUrdf(
            full,
            str(urdf),
            pin.GeometryType.COLLISION,
            package_dirs=[str(d) for d in package_dirs],
        )
    except (ValueError, RuntimeError, OSError) as exc:
        raise RobotDescriptionError(
            f"{urdf}: cannot load its collision geometry: {one_line(exc)}; give the folders "
            "that hold its package:// meshes",
            path=urdf,
            name="urdf",
        ) from exc
    return full, geometry


def object_vertices(obj: pin.GeometryObject) -> np.ndarray:
    """(V, 3) points of a collision object in its joint's frame, m.

    A mesh gives its vertices (scaled as the URDF says); a box its eight corners; a
    cylinder, capsule or sphere :data:`RIM_SAMPLES` points on each of its rims (and, for
    a capsule or sphere, on the circles of its caps at 0°, ±45°, ±90° latitude), which the
    convex hull of the object approaches within 0.12 % of its radius.
    """
    geo = obj.geometry
    if isinstance(geo, coal.BVHModelBase):
        local = np.array(geo.vertices(), dtype=float).reshape(-1, 3)
    else:
        local = _primitive_points(geo)
    placement = obj.placement
    return local @ placement.rotation.T + placement.translation


def _primitive_points(geo: coal.CollisionGeometry) -> np.ndarray:
    """Points on the surface of a coal primitive, in its own frame (z its axis)."""
    angle = np.linspace(0.0, 2.0 * np.pi, RIM_SAMPLES, endpoint=False)
    circle = np.stack([np.cos(angle), np.sin(angle), np.zeros_like(angle)], axis=1)
    if isinstance(geo, coal.Box):
        half = np.asarray(geo.halfSide, dtype=float)
        signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
        return signs * half
    if isinstance(geo, coal.Cylinder):
        return np.concatenate(
            [geo.radius * circle + [0.0, 0.0, h] for h in (-geo.halfLength, geo.halfLength)]
        )
    if isinstance(geo, (coal.Capsule, coal.Sphere)):
        length: float = geo.halfLength if isinstance(geo, coal.Capsule) else 0.0
        points = []
        for end in (-1.0, 1.0):
            for lat in (0.0, np.pi / 4, np.pi / 2):
                ring = geo.radius * np.cos(lat) * circle
                ring[:, 2] = end * (length + geo.radius * np.sin(lat))
                points.append(ring)
        return np.concatenate(points)
    raise RobotDescriptionError(
        f"collision shape {type(geo).__name__} is not supported (meshes, boxes, cylinders, "
        "capsules and spheres are)",
        name="urdf",
        value=type(geo).__name__,
    )
