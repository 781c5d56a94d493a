"""The arm as the outputs draw it: its URDF's collision objects, its base and its reach.

:func:`arm_parts` turns the collision objects of the robot's URDF
(:func:`qpavoid.arm.meshes.collision_geometry`: meshes loaded by coal, placed on the robot's
own joints) into plain numbers: each object's shape, size and placement in the frame of
the joint that carries it and, for a mesh, the vertices and triangles coal loaded. The
replay sends a mesh as those numbers (float32 vertices, uint32 triangles: 12 bytes a
vertex and 12 a triangle; a closed mesh has about half as many vertices as triangles, so
about 18 bytes a triangle against the 50 of the binary STL file); a primitive (box,
cylinder, sphere, capsule) as MeshCat's own shape of that size.

:func:`reach_m` bounds how far any point of the arm's model gets from the base, from the
description alone; :func:`base_extent` is the size of what the URDF puts on the base. The
figures and the replay size their scene with them, never with a particular arm's numbers.
"""

from __future__ import annotations

from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

from qpavoid.arm.meshes import collision_geometry, object_vertices
from qpavoid.arm.model import Robot
from qpavoid.core.errors import RobotDescriptionError

__all__ = ["SHAPES", "ArmPart", "arm_parts", "base_extent", "reach_m"]

#: The collision shapes drawn (coal's mesh, box, cylinder, sphere and capsule).
SHAPES = ("mesh", "box", "cylinder", "sphere", "capsule")


@dataclass(frozen=True, eq=False)
class ArmPart:
    """One collision object of the URDF, placed on a joint of the robot's model.

    Attributes
    ----------
    name
        The object's name (Pinocchio's: the link's name and a counter, ``link_1_0``).
    joint
        The joint of ``robot.model`` that carries it (0: the base, which never moves).
    placement
        (4, 4) the object's frame in its joint's frame (homogeneous, m); a cylinder's or
        capsule's axis is the object's z axis (coal's convention).
    shape
        One of :data:`SHAPES`.
    size
        Box: its three side lengths; cylinder and capsule: radius and length of the axis
        (a capsule adds a hemisphere of the radius at each end); sphere: the radius;
        mesh: empty. All in m.
    vertices, triangles
        A mesh's (V, 3) float32 vertices in the object's frame (m, scaled as the URDF
        says) and (F, 3) uint32 vertex indices of its triangles; empty otherwise.
    points
        (P, 3) points of the object's surface in its joint's frame, m
        (:func:`~qpavoid.arm.meshes.object_vertices`).
    """

    name: str
    joint: int
    placement: np.ndarray
    shape: str
    size: tuple[float, ...]
    vertices: np.ndarray
    triangles: np.ndarray
    points: np.ndarray


def arm_parts(robot: Robot) -> tuple[ArmPart, ...]:
    """The collision objects of ``robot``'s URDF, in the URDF's order (none without one).

    Raises
    ------
    RobotDescriptionError
        If the URDF's meshes cannot be loaded, or an object is a shape other than
        :data:`SHAPES` (naming the URDF and the object).
    """
    geometry = collision_geometry(robot)
    return tuple(_part(robot, obj) for obj in geometry.geometryObjects)


def _part(robot: Robot, obj: pin.GeometryObject) -> ArmPart:
    """:class:`ArmPart` of one placed collision object."""
    geo = obj.geometry
    no_vertices = np.zeros((0, 3), dtype=np.float32)
    no_triangles = np.zeros((0, 3), dtype=np.uint32)
    vertices, triangles = no_vertices, no_triangles
    size: tuple[float, ...]
    if isinstance(geo, coal.BVHModelBase):
        shape, size = "mesh", ()
        vertices = np.array(geo.vertices(), dtype=np.float32).reshape(-1, 3)
        rows = [geo.tri_indices(i) for i in range(geo.num_tris)]
        triangles = np.array([[t[0], t[1], t[2]] for t in rows], dtype=np.uint32).reshape(-1, 3)
    elif isinstance(geo, coal.Box):
        shape, size = "box", tuple(2.0 * float(h) for h in geo.halfSide)
    elif isinstance(geo, coal.Cylinder):
        shape, size = "cylinder", (float(geo.radius), 2.0 * float(geo.halfLength))
    elif isinstance(geo, coal.Capsule):
        shape, size = "capsule", (float(geo.radius), 2.0 * float(geo.halfLength))
    elif isinstance(geo, coal.Sphere):
        shape, size = "sphere", (float(geo.radius),)
    else:
        raise RobotDescriptionError(
            f"{robot.urdf}: collision object {obj.name!r} is a {type(geo).__name__}; the "
            f"outputs draw {', '.join(SHAPES)}: give it one of these in the URDF",
            path=robot.urdf,
            name="urdf",
            value=obj.name,
        )
    return ArmPart(
        name=str(obj.name),
        joint=int(obj.parentJoint),
        placement=np.array(obj.placement.homogeneous, dtype=float),
        shape=shape,
        size=size,
        vertices=vertices,
        triangles=triangles,
        points=object_vertices(obj),
    )


def reach_m(robot: Robot) -> float:
    """An upper bound of the distance from the base of any point of the arm's model, m.

    For each capsule end and control point at frame f on joint j, the triangle inequality
    along the chain of joints from the base (``model.supports[j]``) bounds its distance
    from the base by

        r(f) = Σ_{i ∈ supports(j)} (‖p_i‖ + m_i) + ‖p_f‖,

    p_i the translation of joint i's placement in its parent, m_i the largest travel of a
    prismatic joint i (0 for a revolute one), p_f the frame's translation in its joint. The
    reach is the largest r(f) plus the largest capsule or sphere radius.
    """
    model = robot.model
    travel = np.zeros(model.njoints)
    for i in range(1, model.njoints):
        if "Prismatic" in model.joints[i].shortname():
            q = model.joints[i].idx_q
            travel[i] = max(abs(model.lowerPositionLimit[q]), abs(model.upperPositionLimit[q]))
    frames = {*robot.point_frames, robot.ee_frame}
    frames |= {f for cs in robot.sets for f in cs.capsule_frames}
    longest = 0.0
    for f in frames:
        frame = model.frames[f]
        chain = model.supports[frame.parentJoint]
        along = sum(np.linalg.norm(model.jointPlacements[i].translation) + travel[i] for i in chain)
        longest = max(longest, float(along + np.linalg.norm(frame.placement.translation)))
    radii = np.r_[robot.capsule_radii, robot.sphere_radii]
    return longest + float(radii.max(initial=0.0))


def base_extent(parts: tuple[ArmPart, ...], floor_m: float) -> tuple[float, float]:
    """(radius, height) of the base, m: the smallest upright cylinder about the base's z
    axis, from the table (z = 0) up, that holds every point of the parts on the base
    (joint 0); ``(floor_m, 0)`` (a disc) if the URDF puts nothing there."""
    base = [p.points for p in parts if p.joint == 0]  # the base's joint frame is the base's
    if not base:
        return floor_m, 0.0
    points = np.vstack(base)
    return float(np.hypot(points[:, 0], points[:, 1]).max()), float(max(points[:, 2].max(), 0.0))
