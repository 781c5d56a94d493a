"""Coverage: does the model the controller uses hold the whole arm?

The controllers measure the person's distance to capsules (the exact method) or spheres
(the paper's eq. 1); the URDF's collision meshes are the arm itself. A vertex of a mesh
outside every capsule is a part of the arm the capsule method cannot see: the person may
touch it while the controller reads a positive distance. :func:`coverage` measures, per
collision object and per method, how many of its vertices (mesh vertices; primitives by
their sample points, :func:`~qpavoid.arm.meshes.object_vertices`) lie inside the model,
at the neutral configuration and a few fixed random ones within the joint limits;
:func:`check_coverage` refuses a description that leaves a vertex out without saying why
(its ``[coverage] exclude`` table).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from qpavoid.arm.meshes import ArmFiles, collision_geometry, object_vertices
from qpavoid.core.errors import RobotDescriptionError

__all__ = [
    "CONFIGURATIONS",
    "METHODS",
    "TOLERANCE_M",
    "CoverageRow",
    "check_coverage",
    "coverage",
    "coverage_table",
]

#: The two distance methods: the person against capsules (exact) and spheres (eq. 1).
METHODS = ("capsules", "spheres")
#: How far a vertex may lie outside the model and count as inside, m: the rounding of the
#: written capsule ends (1 µm), far below any mesh's detail.
TOLERANCE_M = 1e-6
#: Random configurations within the joint limits checked beside the neutral one (fixed:
#: the seed is 0). Sets fitted per link hold their link at every configuration; the
#: configurations catch capsules that span joints and vertices covered by another link's
#: capsule.
CONFIGURATIONS = 3


class _Shapes(Protocol):
    """The capsules' axes (S, 2, 3) and the spheres' centres (P, 3) at a configuration."""

    @property
    def segments(self) -> np.ndarray: ...

    @property
    def points(self) -> np.ndarray: ...


class CoveredRobot(ArmFiles, Protocol):
    """What the coverage reads of a robot (a :class:`~qpavoid.arm.model.Robot`, named
    here without importing it: :func:`~qpavoid.arm.model.load_robot` imports this module)."""

    coverage_exclude: dict[str, str]
    q_min: np.ndarray
    q_max: np.ndarray
    capsule_radii: np.ndarray
    sphere_radii: np.ndarray

    def neutral(self) -> np.ndarray: ...

    def kinematics(self, q: ArrayLike, jacobians: bool = True) -> _Shapes: ...


@dataclass(frozen=True)
class CoverageRow:
    """How much of one collision object one method's model holds.

    Attributes
    ----------
    object_name
        The collision object's name (Pinocchio's: ``<link>_<k>``).
    method
        ``"capsules"`` or ``"spheres"`` (:data:`METHODS`).
    vertices
        Vertices checked: the object's vertices times the configurations.
    covered
        Of those, how many lie inside the model (within :data:`TOLERANCE_M`).
    worst_excess_m
        The largest distance of a vertex outside the model, m (its distance to the
        nearest capsule or sphere surface; ≤ 0 when every vertex is inside).
    excluded
        The description's reason for leaving the object out (``[coverage] exclude``), or
        ``""``.
    moved_by
        The joints that move the object's body, base first (none for the base).
    """

    object_name: str
    method: str
    vertices: int
    covered: int
    worst_excess_m: float
    excluded: str = ""
    moved_by: tuple[str, ...] = ()

    @property
    def complete(self) -> bool:
        """Whether every vertex is inside the model."""
        return self.covered == self.vertices


def configurations(robot: CoveredRobot, count: int = CONFIGURATIONS) -> list[np.ndarray]:
    """The neutral configuration and ``count`` fixed random ones within the joint limits."""
    rng = np.random.default_rng(0)
    return [robot.neutral()] + [rng.uniform(robot.q_min, robot.q_max) for _ in range(count)]


def _segment_excess(vertices: np.ndarray, segments: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """(N,) how far each vertex lies outside the nearest capsule, m.

    A capsule of axis [a, b] and radius r holds x when |x − p(s*)| ≤ r, p(s) = a + s (b − a),
    s* = clip((x − a)·(b − a) / |b − a|², 0, 1): the excess is min over capsules of
    |x − p(s*)| − r (vertices × capsules at once).
    """
    a, ab = segments[:, 0], segments[:, 1] - segments[:, 0]  # (S, 3)
    rel = vertices[:, None, :] - a[None]  # (N, S, 3)
    length2 = np.einsum("sk,sk->s", ab, ab)
    s = np.einsum("nsk,sk->ns", rel, ab) / np.where(length2 > 0.0, length2, 1.0)
    s = np.clip(s, 0.0, 1.0)
    gap = np.linalg.norm(rel - s[..., None] * ab[None], axis=2) - radii[None]
    return gap.min(axis=1)


def _sphere_excess(vertices: np.ndarray, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """(N,) how far each vertex lies outside the nearest sphere, m: min over spheres of
    |x − c| − R (vertices × spheres at once)."""
    gap = np.linalg.norm(vertices[:, None, :] - centres[None], axis=2) - radii[None]
    return gap.min(axis=1)


def coverage(
    robot: CoveredRobot,
    exclude: Mapping[str, str] | None = None,
    geometry: pin.GeometryModel | None = None,
    count: int = CONFIGURATIONS,
    tolerance_m: float = TOLERANCE_M,
) -> tuple[CoverageRow, ...]:
    """Per collision object and method, how many of its vertices the model holds.

    Parameters
    ----------
    robot
        The robot (its model, capsules and spheres).
    exclude
        Objects the description leaves out and why (the rows say so); default the
        robot's own ``[coverage] exclude``.
    geometry
        Its collision objects (default :func:`~qpavoid.arm.meshes.collision_geometry`).
    count
        Random configurations checked beside the neutral one.
    tolerance_m
        How far outside a vertex may lie and count as inside, m.

    Returns
    -------
    tuple of CoverageRow
        Object after object (the URDF's order), capsules then spheres.
    """
    exclude = robot.coverage_exclude if exclude is None else exclude
    geometry = collision_geometry(robot) if geometry is None else geometry
    objects = list(geometry.geometryObjects)
    if not objects:
        return ()
    local = [object_vertices(o) for o in objects]
    owner = np.concatenate([np.full(len(v), k) for k, v in enumerate(local)])
    data = robot.model.createData()
    worst = {m: np.full(len(owner), -np.inf) for m in METHODS}  # per vertex, m
    outside = {m: np.zeros(len(owner), dtype=int) for m in METHODS}  # configurations
    for q in configurations(robot, count):
        pin.forwardKinematics(robot.model, data, q)
        world = np.concatenate(
            [
                v @ data.oMi[o.parentJoint].rotation.T + data.oMi[o.parentJoint].translation
                for o, v in zip(objects, local, strict=True)
            ]
        )
        kin = robot.kinematics(q, jacobians=False)
        for m, e in (
            ("capsules", _segment_excess(world, kin.segments, robot.capsule_radii)),
            ("spheres", _sphere_excess(world, kin.points, robot.sphere_radii)),
        ):
            worst[m] = np.maximum(worst[m], e)
            outside[m] += e > tolerance_m
    n_conf = count + 1
    rows = []
    for k, obj in enumerate(objects):
        mine = owner == k
        for m in METHODS:
            checked = int(mine.sum()) * n_conf
            rows.append(
                CoverageRow(
                    object_name=str(obj.name),
                    method=m,
                    vertices=checked,
                    covered=checked - int(outside[m][mine].sum()),
                    worst_excess_m=float(worst[m][mine].max()),
                    excluded=str(exclude.get(str(obj.name), "")),
                    moved_by=tuple(
                        str(robot.model.names[j]) for j in robot.model.supports[obj.parentJoint][1:]
                    ),
                )
            )
    return tuple(rows)


def check_coverage(
    robot: CoveredRobot, path: Path, rows: Sequence[CoverageRow] | None = None
) -> tuple[CoverageRow, ...]:
    """:func:`coverage` of the robot (or ``rows``, already measured), or the reason its
    description cannot be used.

    Raises
    ------
    RobotDescriptionError
        For an exclusion naming no collision object of the URDF, and for the object with
        the worst vertex outside a method's model that the description does not exclude:
        one line naming the file, the object, the method, the excess and the fixes.
    """
    rows = tuple(coverage(robot) if rows is None else rows)
    names = list(dict.fromkeys(r.object_name for r in rows))
    unknown = sorted(set(robot.coverage_exclude) - set(names))
    urdf = robot.urdf.name if robot.urdf is not None else "the URDF"
    if unknown:
        raise RobotDescriptionError(
            f"{path}: [coverage] exclude names {unknown}, which are not collision objects of "
            f"{urdf}; its objects are {names}: name those or remove the entries",
            path=path,
            name="coverage.exclude",
            value=unknown,
        )
    moving = [
        r
        for r in rows
        if r.method == "capsules" and r.excluded and not r.complete and len(r.moved_by) > 1
    ]
    if moving:
        row = max(moving, key=lambda r: r.worst_excess_m)
        raise RobotDescriptionError(
            f"{path}: [coverage] exclude: {row.object_name!r} moves with the joints "
            f"{list(row.moved_by)} and lies up to {row.worst_excess_m * 1e3:.2f} mm outside "
            "the capsules: only an object on the base, or on a link that only turns about "
            "the first joint, may be left out of the capsules (the distance method and the "
            "truth of every run); fit the sets to the meshes (`qpavoid robot fit "
            f"{robot.urdf} --out DIR`) or give the set that carries it a larger "
            "capsule_radius_m",
            path=path,
            name="coverage.exclude",
            value=row.object_name,
        )
    bad = [r for r in rows if not r.complete and not r.excluded]
    if bad:
        row = max(bad, key=lambda r: r.worst_excess_m)
        radius = "capsule_radius_m" if row.method == "capsules" else "sphere_radius_m"
        raise RobotDescriptionError(
            f"{path}: collision object {row.object_name!r} of {urdf} is not inside the "
            f"{row.method}: {row.vertices - row.covered} of {row.vertices} vertex checks "
            f"outside, the worst by {row.worst_excess_m * 1e3:.2f} mm; fit the sets to the "
            f"meshes (`qpavoid robot fit {robot.urdf} --out DIR`), give the set that carries it a "
            f"larger {radius}, or leave it out with its reason: [coverage] exclude = "
            f'{{ {row.object_name} = "<why>" }}',
            path=path,
            name=f"coverage.{row.object_name}",
            value=row.worst_excess_m,
        )
    return rows


def coverage_table(rows: Sequence[CoverageRow]) -> str:
    """The rows as a text table: object, method, vertex checks, covered, worst excess
    (mm), and the reason of an excluded object; a total per method below."""
    width = max([len("object"), *(len(r.object_name) for r in rows)])
    lines = [
        f"{'object':<{width}}  {'method':<8}  {'checked':>7}  {'covered':>7}  "
        f"{'worst (mm)':>10}  excluded because"
    ]
    for r in rows:
        lines.append(
            f"{r.object_name:<{width}}  {r.method:<8}  {r.vertices:>7}  {r.covered:>7}  "
            f"{r.worst_excess_m * 1e3:>10.2f}  {r.excluded}"
        )
    for m in METHODS:
        mine = [r for r in rows if r.method == m]
        checked = sum(r.vertices for r in mine)
        covered = sum(r.covered for r in mine)
        excluded = [r for r in mine if r.excluded]
        share = 100.0 * covered / checked if checked else 100.0
        lines.append(
            f"{m}: {covered} of {checked} vertex checks inside ({share:.2f} %), "
            f"{len(excluded)} object(s) excluded"
            + (
                f", {sum(r.vertices - r.covered for r in excluded)} outside among them"
                if excluded
                else ""
            )
        )
    return "\n".join(lines)
