"""Capsules fitted to an arm's collision meshes, and a first control-point file from them.

The controllers see the arm as capsules and spheres (``docs/robot.md``); the URDF's
collision meshes are the arm itself. :func:`fit_capsule` finds the smallest capsule that
holds every vertex of a link's meshes, :func:`sphere_centres` spheres along its axis that
cover it, and :func:`fit_description` writes the first ``control_points.toml`` of any URDF
with collision geometry: one set per link, the roles left for the user to name.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin
from scipy.optimize import minimize, minimize_scalar
from scipy.spatial import ConvexHull, QhullError

from qpavoid.arm.joints import check_lock_angle
from qpavoid.arm.meshes import object_vertices, urdf_geometry
from qpavoid.arm.urdf import build_urdf_model, check_urdf_joints
from qpavoid.core.errors import InputError

__all__ = [
    "FitConfig",
    "FittedSet",
    "capsule_volume",
    "fit_capsule",
    "fit_description",
    "fit_sets",
    "sphere_centres",
]


@dataclass(frozen=True)
class FitConfig:
    """How :func:`fit_description` fits a link's capsule and covers it with spheres.

    Attributes
    ----------
    spacing_per_radius
        Largest spacing s of consecutive sphere centres along a capsule's axis, in capsule
        radii: spheres of radius R = sqrt(r² + (s/2)²) then cover the capsule. 1.5 r (R =
        1.25 r) is the paper's iiwa spacing (0.108 m for a 0.07 m capsule), a sphere
        model at most 25 % wider than the capsule with a handful of points per link.
    round_m
        Radii are rounded up to a multiple of this, m (0.1 mm: far below the meshes'
        detail, a round number in the file); the capsule ends are written to 1 µm.
    restarts
        Nelder-Mead restarts from the best point found (a simplex collapses on the
        volume's ridges; two restarts settle it in the tests' clouds).
    """

    spacing_per_radius: float = 1.5
    round_m: float = 1e-4
    restarts: int = 2


def capsule_volume(length_m: float, radius_m: float) -> float:
    """Volume of a capsule, m³: a cylinder of its length and two half-spheres,
    V = π r² L + 4/3 π r³."""
    return float(np.pi * radius_m**2 * length_m + 4.0 / 3.0 * np.pi * radius_m**3)


def _hull(points: np.ndarray) -> np.ndarray:
    """The vertices of the points' convex hull (a capsule is convex, so it holds the
    points exactly when it holds these), or all points for a flat or tiny cloud."""
    if len(points) < 5:
        return points
    try:
        return points[ConvexHull(points).vertices]
    except QhullError:  # coplanar or collinear: no 3-D hull
        return points


def _basis(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors orthogonal to the unit vector ``u`` and to each other."""
    helper = np.eye(3)[int(np.argmin(np.abs(u)))]
    e1 = np.cross(u, helper)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(u, e1)


def _ends(t: np.ndarray, d2: np.ndarray, radius: float) -> tuple[float, float]:
    """The shortest axis interval [t_a, t_b] whose capsule of ``radius`` holds points at
    axis coordinates ``t`` and squared distances ``d2`` from the axis; see
    :func:`fit_capsule`. Returns t_a = t_b for a sphere."""
    h = np.sqrt(np.maximum(radius**2 - d2, 0.0))
    ta, tb = float(np.min(t + h)), float(np.max(t - h))
    if ta > tb:  # a sphere suffices: centre it where every point's interval overlaps
        ta = tb = 0.5 * (ta + tb)
    return ta, tb


def _line(x: np.ndarray, frame: tuple[np.ndarray, ...]) -> tuple[np.ndarray, np.ndarray]:
    """The axis line of parameters ``x[:4]``: direction u0 + x0 e1 + x1 e2 (normalised)
    through origin + x2 e1 + x3 e2 (``frame`` is origin, u0, e1, e2 and the points'
    squared norms)."""
    origin, u0, e1, e2 = frame[:4]
    u = u0 + x[0] * e1 + x[1] * e2
    return origin + x[2] * e1 + x[3] * e2, u / np.linalg.norm(u)


def _capsule_of(
    points: np.ndarray, x: np.ndarray, frame: tuple[np.ndarray, ...]
) -> tuple[np.ndarray, np.ndarray, float]:
    """The capsule of parameters ``x``: its axis line (:func:`_line`), radius
    r = max_i d_i + x4² (never below the farthest point's distance from the axis), ends
    from :func:`_ends`, with t_i = (p_i − c)·u and d_i² = |p_i − c|² − t_i²."""
    centre, u = _line(x, frame)
    pu, pc = (points @ np.stack([u, centre], axis=1)).T
    t = pu - centre @ u
    d2 = np.maximum(frame[4] - 2.0 * pc + centre @ centre - t * t, 0.0)
    radius = float(np.sqrt(d2.max()) + x[4] ** 2)
    ta, tb = _ends(t, d2, radius)
    return centre + ta * u, centre + tb * u, radius


def _volume(x: np.ndarray, points: np.ndarray, frame: tuple[np.ndarray, ...]) -> float:
    """Volume of the capsule of parameters ``x`` (:func:`_capsule_of`)."""
    a, b, r = _capsule_of(points, x, frame)
    return capsule_volume(float(np.linalg.norm(b - a)), r)


#: Nelder-Mead's settings: a first pass from each principal axis (loose), then the best
#: polished (tight) with restarts; tolerances in units of the cloud's size (its farthest
#: point from the centroid is 1).
FIRST_PASS = {"xatol": 1e-4, "fatol": 1e-7, "maxiter": 1000}
#: The first pass's initial simplex: steps of 0.1 (a tenth of the cloud's size) in each
#: parameter. SciPy's default steps 0.00025 from a zero parameter, which widens the radius
#: (x₄²) by 6e-8: the search never tried a wider, shorter capsule, and on the iiwa's squat
#: link 6 (a 0.06 m radius, 0.081 m cylinder) it ended, with scipy 1.17 and numpy 2.4, in
#: the 0.0724 m sphere instead of the 0.0661 m capsule.
FIRST_STEP = 0.1
POLISH = {"xatol": 1e-9, "fatol": 1e-12, "maxiter": 4000}


def fit_capsule(
    points: np.ndarray, restarts: int = FitConfig.restarts
) -> tuple[np.ndarray, np.ndarray, float]:
    """The smallest (least volume) capsule holding every point.

    A capsule is the set of points within r of a segment [a, b]. Given its axis line
    (a point c and a unit direction u), each point p_i has the axis coordinate
    t_i = (p_i − c)·u and the distance d_i = |(p_i − c) − t_i u| from the line. For a
    radius r ≥ max_i d_i, the point lies within r of the axis point c + t u exactly when
    |t − t_i| ≤ h_i = sqrt(r² − d_i²), so the shortest segment that holds every point
    runs from t_a = min_i (t_i + h_i) to t_b = max_i (t_i − h_i): a = c + t_a u,
    b = c + t_b u (when t_a > t_b a sphere at any t in [t_b, t_a] holds them: the
    mid-point is taken, length 0). The volume V = π r² (t_b − t_a) + 4/3 π r³ is then
    a function of the line and r alone, minimised with Nelder-Mead over five
    parameters: the direction's tilt from a start axis (2), the line's offset across it
    (2) and r = max_i d_i + x² (1). The starts are the cloud's three principal axes
    through its centroid, each with the radius of least volume on that axis (a bounded
    scalar search); a loose first pass from each (its initial simplex :data:`FIRST_STEP`
    wide), then each polished with restarts, the smallest kept. A search only ever keeps a
    smaller volume, so the result is never worse than the principal-axis capsule.
    Only the points' convex hull matters (a capsule is convex), so the search runs on
    the hull's vertices.

    Parameters
    ----------
    points
        (N, 3) points, N >= 1, m.
    restarts
        Nelder-Mead restarts from the best point found.

    Returns
    -------
    a, b, radius
        The capsule's two ends (3,) and its radius, m; a and b coincide for a sphere.
        Every point lies within ``radius`` of [a, b] (up to rounding, 1e-12 m at 1 m).
    """
    cloud = np.asarray(points, dtype=float).reshape(-1, 3)
    if len(cloud) == 0 or not np.isfinite(cloud).all():
        raise ValueError("fit_capsule needs at least one finite point")
    centroid = cloud.mean(axis=0)
    scale = float(np.max(np.linalg.norm(cloud - centroid, axis=1)))
    if scale == 0.0:
        return centroid.copy(), centroid.copy(), 0.0
    hull = (_hull(cloud) - centroid) / scale  # unit-sized, so the search's tolerances fit
    _, _, axes = np.linalg.svd(hull - hull.mean(axis=0), full_matrices=False)
    starts = []
    for u0 in axes:  # a first pass from each principal axis
        frame = (np.zeros(3), u0, *_basis(u0), np.einsum("ij,ij->i", hull, hull))
        x, value = np.zeros(5), _volume(np.zeros(5), hull, frame)
        # the radius first, on the axis as it is (a squat link's best capsule is wider
        # than its rim): a bounded scalar search over x₄ in [0, 1]
        widen = minimize_scalar(
            lambda s, f=frame: _volume(np.array([0.0, 0.0, 0.0, 0.0, s]), hull, f),
            bounds=(0.0, 1.0),
            method="bounded",
        )
        if widen.fun < value:
            x, value = np.array([0.0, 0.0, 0.0, 0.0, float(widen.x)]), float(widen.fun)
        simplex = np.vstack([x, x + FIRST_STEP * np.eye(5)])
        options = FIRST_PASS | {"initial_simplex": simplex}
        result = minimize(_volume, x, (hull, frame), method="Nelder-Mead", options=options)
        if result.fun < value:
            x, value = np.asarray(result.x), float(result.fun)
        starts.append((value, x, frame))
    polished = []
    for value, x, frame in starts:  # each polished: a loose pass may stop short of its best
        for _ in range(1 + restarts):
            result = minimize(_volume, x, (hull, frame), method="Nelder-Mead", options=POLISH)
            if result.fun < value:
                x, value = np.asarray(result.x), float(result.fun)
        polished.append((value, x, frame))
    best = min(polished, key=lambda start: start[0])
    a, b, r = _capsule_of(hull, best[1], best[2])
    a, b = centroid + scale * a, centroid + scale * b
    # the radius at the true scale, from every point (rounding of the scaling aside)
    r = max(r * scale, float(np.max(segment_distances(cloud, a, b))))
    return a, b, r


def segment_distances(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance (N,) of each point from the segment [a, b], m: |p − (a + s (b − a))| with
    s = clip((p − a)·(b − a) / |b − a|², 0, 1) (s = 0 when a = b)."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    ab = np.asarray(b, dtype=float) - np.asarray(a, dtype=float)
    length2 = float(ab @ ab)
    rel = points - a
    s = np.clip(rel @ ab / length2, 0.0, 1.0) if length2 > 0.0 else np.zeros(len(points))
    return np.linalg.norm(rel - s[:, None] * ab, axis=1)


def sphere_centres(
    a: np.ndarray, b: np.ndarray, radius_m: float, spacing_per_radius: float = 1.5
) -> tuple[np.ndarray, float]:
    """Sphere centres along the axis [a, b] and the sphere radius that covers the capsule.

    n = ceil(L / s_max) + 1 centres evenly spaced from a to b (s = L / (n − 1) ≤ s_max =
    ``spacing_per_radius`` · r; one centre of radius r for a sphere, L = 0). A point x
    of the capsule lies within r of its closest axis point p; if p is an end, that end
    is a centre; if not, x − p is orthogonal to the axis and p lies within s/2 of a
    centre c along it, so |x − c|² = |p − c|² + |x − p|² ≤ (s/2)² + r²: spheres of
    R = sqrt(r² + (s/2)²) cover the capsule. (The ends must be centres: one centre in the
    middle of an axis of length L > 0 needs r + L/2, not sqrt(r² + (L/2)²), to hold the
    caps.)

    Returns
    -------
    centres, sphere_radius_m
        (n, 3) centres and R, m.
    """
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    length = float(np.linalg.norm(b - a))
    s_max = spacing_per_radius * radius_m
    if length == 0.0:  # a sphere
        return a[None, :].copy(), float(radius_m)
    if not s_max > 0.0:
        raise ValueError(f"sphere spacing {s_max} m: the radius and spacing must be above 0")
    n = int(np.ceil(length / s_max - 1e-12)) + 1
    s = length / (n - 1)
    centres = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
    return centres, float(np.hypot(radius_m, 0.5 * s))


@dataclass(frozen=True)
class FittedSet:
    """One link's fitted set: the capsule (ends in the link frame's axes) and its spheres.

    Attributes
    ----------
    name
        The set's name: the link's short name (``panda_link4`` -> ``link4``).
    link
        The URDF link whose frame the ends are given in.
    objects
        The collision objects fitted (the link's, and those of links merged into it).
    a_m, b_m
        Capsule ends in the link frame, m.
    capsule_radius_m
        Capsule radius, m (rounded up).
    centres_m
        Sphere centres in the link frame, m.
    sphere_radius_m
        Sphere radius R = sqrt(r² + (s/2)²), m (rounded up).
    spacing_m
        Spacing s of the sphere centres, m (0 for one sphere).
    """

    name: str
    link: str
    objects: tuple[str, ...]
    a_m: tuple[float, float, float]
    b_m: tuple[float, float, float]
    capsule_radius_m: float
    centres_m: tuple[tuple[float, float, float], ...]
    sphere_radius_m: float
    spacing_m: float


def _short_name(link: str, links: Sequence[str]) -> str:
    """The link's name without the prefix every link shares (``panda_link4`` -> ``link4``,
    ``upper_arm_link`` -> ``upper_arm``), made of the characters a set name may hold."""
    prefix = _common_prefix(links) if len(links) > 1 else ""
    name = link[len(prefix) :] if len(link) > len(prefix) else link
    if name.endswith("_link") and len(name) > 5:
        name = name[: -len("_link")]
    if name.isdigit():  # "link_1" -> "1" says nothing: keep the link's name
        name = link
    return "".join(ch if ch.isalnum() or ch in "_.-" else "_" for ch in name) or link


def _common_prefix(names: Sequence[str]) -> str:
    """The longest prefix of every name that ends at an underscore (``panda_``)."""
    first = min(names)
    last = max(names)
    k = 0
    while k < min(len(first), len(last)) and first[k] == last[k]:
        k += 1
    return first[: first[:k].rfind("_") + 1]


def _round_up(value: float, step: float) -> float:
    """``value`` rounded up to a multiple of ``step`` (and a whisker above the rounding of
    the written ends: 1 µm)."""
    return float(np.ceil((value + 1e-6) / step - 1e-9) * step)


def fit_sets(
    urdf: Path,
    package_dirs: Sequence[Path] = (),
    merge: Sequence[str] = (),
    angles: Mapping[str, float] | None = None,
    config: FitConfig | None = None,
) -> list[FittedSet]:
    """One fitted set per moving URDF link that has collision geometry.

    Each link's collision vertices (:func:`~qpavoid.arm.meshes.object_vertices`: mesh
    vertices, primitives' sample points) in its own frame are fitted with
    :func:`fit_capsule` and covered with :func:`sphere_centres`. Links on the base (no
    moving joint between them and the world) are left out: they never move, so the
    controllers need no model of them. The child links of the joints ``merge`` (a
    gripper's fingers, locked at ``angles``) join their parent link's set.
    """
    config = config or FitConfig()
    model, geometry = urdf_geometry(urdf, package_dirs)
    data = model.createData()
    q = pin.neutral(model)
    for joint, angle in (angles or {}).items():
        q[model.joints[model.getJointId(joint)].idx_q] = angle
    pin.framesForwardKinematics(model, data, q)
    groups: dict[str, list[tuple[str, np.ndarray]]] = {}
    for obj in geometry.geometryObjects:
        if obj.parentJoint == 0:
            continue  # on the base: it never moves
        frame_id = obj.parentFrame  # the link's frame; its parent, the joint's frame
        while model.frames[model.frames[frame_id].parentFrame].name in merge:
            frame_id = model.frames[model.frames[frame_id].parentFrame].parentFrame
        link = model.frames[frame_id]
        in_world = object_vertices(obj) @ data.oMi[obj.parentJoint].rotation.T
        in_world += data.oMi[obj.parentJoint].translation
        in_link = (in_world - data.oMf[frame_id].translation) @ data.oMf[frame_id].rotation
        groups.setdefault(str(link.name), []).append((str(obj.name), in_link))
    names = list(groups)
    sets = []
    for link, items in groups.items():
        cloud = np.concatenate([v for _, v in items])
        a, b, r = fit_capsule(cloud, config.restarts)
        a, b = np.round(a, 6), np.round(b, 6)
        radius = _round_up(r, config.round_m)
        centres, big = sphere_centres(a, b, radius, config.spacing_per_radius)
        count = len(centres)
        sets.append(
            FittedSet(
                name=_short_name(link, names),
                link=link,
                objects=tuple(name for name, _ in items),
                a_m=_triple(a),
                b_m=_triple(b),
                capsule_radius_m=radius,
                centres_m=tuple(_triple(np.round(c, 6)) for c in centres),
                sphere_radius_m=_round_up(big, config.round_m),
                spacing_m=float(np.linalg.norm(b - a)) / (count - 1) if count > 1 else 0.0,
            )
        )
    return sets


def _toml_value(value: str | Mapping[str, str]) -> str:
    """A text or a table of texts as TOML writes it (JSON's quoting is TOML's for text)."""
    if isinstance(value, str):
        return json.dumps(value)
    return "{ " + ", ".join(f"{k} = {json.dumps(v)}" for k, v in value.items()) + " }"


def _triple(v: np.ndarray) -> tuple[float, float, float]:
    """A point (3,) as three floats."""
    return (float(v[0]), float(v[1]), float(v[2]))


def _xyz(v: Sequence[float]) -> str:
    """A point as the file writes it: to the µm."""
    return "[" + ", ".join(f"{x:.6f}" for x in v) + "]"


def fit_description(
    urdf: Path,
    urdf_entry: str | Mapping[str, str] | None = None,
    package_dirs: Sequence[Path] = (),
    merge: Sequence[str] = (),
    locked: Mapping[str, float] | None = None,
    config: FitConfig | None = None,
) -> str:
    """The text of a first ``control_points.toml`` for a URDF with collision geometry.

    One set per moving link (:func:`fit_sets`), named after the link, its capsule's ends
    given as offsets in the link's frame (``{ frame = "<link>", xyz = [...] }``) and its
    spheres' centres along the axis. The roles, the arm's dynamics and the IK seed are
    left for the user, with comments saying what to fill in; the file loads once they
    are named.

    Parameters
    ----------
    urdf
        The URDF.
    urdf_entry
        What the file's ``urdf`` key says: a file name, or ``{"package": ..., "path":
        ...}`` (default: the URDF's path as given).
    package_dirs
        Folders where the URDF's ``package://`` meshes are looked for.
    merge
        Joints whose child links join their parent's set (a gripper's fingers); a moving
        one is ``held`` in the file (locked in every mode) at its ``locked`` angle
        (default 0), the one its set was fitted at.
    locked
        Joints the file locks (and angles, rad): the merged ones held, the others locked
        by default (the paper's third joint; the set of each link is fitted alone, so
        any angle of theirs is covered).
    config
        The fit's settings.

    Raises
    ------
    InputError
        For a joint of ``locked`` or ``merge`` that the URDF lacks.
    RobotDescriptionError
        If the URDF or its meshes cannot be loaded.
    """
    model = build_urdf_model(urdf)
    check_urdf_joints(model, urdf)
    locked = dict(locked or {})
    joints = [str(n) for n in model.names[1:]]
    fixed = [str(f.name) for f in model.frames if f.type == pin.FrameType.FIXED_JOINT]
    for key, names, known in (("locked", list(locked), joints), ("merge", merge, joints + fixed)):
        unknown = [n for n in names if n not in known]
        if unknown:
            raise InputError(
                f"{key}: {unknown} are not joints of {urdf.name}; its joints are {known}",
                name=key,
                value=unknown,
            )
    for joint in merge:
        if model.existJointName(joint):  # a moving joint merged: locked
            locked.setdefault(joint, 0.0)
    for joint, angle in locked.items():
        check_lock_angle(model, joint, angle)
    if set(joints) <= set(locked):
        raise InputError(
            f"locked: every joint of {urdf.name} would be locked, {joints}: nothing would move",
            name="locked",
            value=sorted(locked),
        )
    sets = fit_sets(urdf, package_dirs, merge, locked, config)
    free = [j for j in joints if j not in locked or j not in merge]
    lines = [
        f"# qpavoid control-point file fitted to the collision geometry of {urdf.name}",
        "# by `qpavoid robot fit` (format: docs/robot.md). Per moving link, the smallest",
        "# capsule holding every vertex of its collision meshes (ends in the link's frame,",
        "# m), and spheres centred along its axis at spacing s <= "
        f"{(config or FitConfig()).spacing_per_radius:g} r, of radius",
        "# R = sqrt(r^2 + (s/2)^2), which cover the capsule. Links fixed to the base never",
        "# move and have no set. TO DO: name the roles, give [arm] and [ik_seed].",
        "",
        f"urdf = {_toml_value(urdf_entry if urdf_entry is not None else str(urdf))}",
        f'end_effector = "TO DO: the tool or flange frame, e.g. {sets[-1].link if sets else ""}"',
    ]
    held = {j: a for j, a in locked.items() if j in merge}
    for key, table in (
        ("locked", {j: a for j, a in locked.items() if j not in held}),
        ("held", held),
    ):
        if table:
            lines.append(
                f"{key} = {{ " + ", ".join(f"{j} = {a!r}" for j, a in table.items()) + " }"
            )
    for fs in sets:
        lines += [
            "",
            "[[sets]]",
            f"# {fs.link}: {', '.join(fs.objects)}; capsule r = {fs.capsule_radius_m:.4f} m, "
            f"{len(fs.centres_m)} sphere(s) at s = {fs.spacing_m:.4f} m: "
            f"R = sqrt({fs.capsule_radius_m:.4f}^2 + {fs.spacing_m / 2:.4f}^2) <= "
            f"{fs.sphere_radius_m:.4f} m",
            f'name = "{fs.name}"',
            f"sphere_radius_m = {fs.sphere_radius_m:.4f}",
            "points = [",
            *(f'  {{ frame = "{fs.link}", xyz = {_xyz(c)} }},' for c in fs.centres_m),
            "]",
            f'capsule = {{ from = {{ frame = "{fs.link}", xyz = {_xyz(fs.a_m)} }}, '
            f'to = {{ frame = "{fs.link}", xyz = {_xyz(fs.b_m)} }}, '
            f"capsule_radius_m = {fs.capsule_radius_m:.4f} }}",
        ]
    model_geometry = urdf_geometry(urdf, package_dirs)[1]
    on_base = [str(o.name) for o in model_geometry.geometryObjects if o.parentJoint == 0]
    names = [fs.name for fs in sets]
    lines += [
        "",
        "# TO DO: which set plays which part in the paper's laws (docs/robot.md, Roles).",
        f"# The sets are {names}; the free joints {free}.",
        "[roles]",
        "# eqs. (2)-(3): an upper-arm set and the joints that move it (e.g. the first two)",
        'scaled = { set = "TO DO", joints = ["TO DO"] }',
        "# eqs. (4)-(6), (9): a forearm set and exactly three joints that move it, whose",
        "# 3x3 Jacobian is well conditioned over the task",
        'repelled = { set = "TO DO", joints = ["TO DO"] }',
        "# eqs. (7)-(8): the set whose capsule holds the end_effector frame",
        'end_effector = { set = "TO DO" }',
        "",
        "# TO DO: the maker's values, each with its source (docs/robot.md, Arm).",
        "[arm]",
        "reaction_time_s = 0.0  # TO DO: one control period of the arm's interface",
        "max_acceleration_radps2 = { " + ", ".join(f"{j} = 0.0" for j in joints) + " }  # TO DO",
        "max_point_speed_mps = 0.0  # TO DO",
        "",
        "[arm.sources]",
        'reaction_time_s = "TO DO"',
        'max_acceleration_radps2 = "TO DO"',
        'max_point_speed_mps = "TO DO"',
    ]
    if on_base:
        reason = "fixed to the base: it never moves, so no law can move it away from a person"
        lines += [
            "",
            "# Collision objects left outside the capsules and spheres, and why (checked at",
            "# load time: qpavoid.arm.coverage).",
            "[coverage]",
            "exclude = { "
            + ", ".join(f"{json.dumps(n)} = {json.dumps(reason)}" for n in on_base)
            + " }",
        ]
    return "\n".join(lines) + "\n"
