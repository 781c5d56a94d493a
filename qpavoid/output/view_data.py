"""What a replay shows of a run: its geometry frame by frame and its numbers tick by tick.

:func:`replay_data` turns a run's ``log.npz`` and ``metrics.json`` into the arrays the
browser replay (:mod:`qpavoid.output.replay_html`) draws and prints:

* **scene frames**, at most ``fps`` a second of run time: the arm's links (Pinocchio's
  joint placements), the pose of each joint that carries a collision object of the URDF
  (:mod:`qpavoid.output.arm_shapes`: the arm drawn as it is), the robot's safety shapes
  of the run's distance method (a capsule per set, or a sphere per control point: three
  and nine for the iiwa), the person's (the body model's part capsules, or its spheres),
  each robot set's closest pair (``robot_point``, ``human_point`` of the log) and the end
  effector;
* **ticks**, every one: time, f (eq. 2), the distance per set and its state (free,
  repulsion active, within the stop distance), the stop reason while stopped, the frame
  age and, where measured, the true clearance (docs/safety.md);
* the planned path and the end-effector trace, once;
* the scene's size: the floor (the table top, z = 0, under the base) and where the camera
  starts, both from the arm's reach and what the run shows.

Everything is plain numbers (float32, m and s) so that the HTML stays small: a 15 s run
at 500 Hz is about 2 MB with the viewer (docs/replay.md, "Size"). The collision objects
themselves (their meshes) are under the key ``"parts"``, which the page receives as scene
objects, not as numbers.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin

from qpavoid.arm.model import Robot
from qpavoid.arm.roles import Roles
from qpavoid.core.errors import InputError
from qpavoid.core.geometry import unit
from qpavoid.human.body import BodyModel, KinectHuman
from qpavoid.human.skeleton import SkeletonFormat
from qpavoid.laws.avoidance import AvoidanceConfig, distance_at_factor, set_stop_distances
from qpavoid.loop.run_log import TEXT_KEYS
from qpavoid.output.arm_shapes import ArmPart, arm_parts, reach_m

__all__ = ["PAIR_STATES", "camera_start", "floor_extent", "pair_states", "replay_data"]

#: A robot set's closest pair is in one of these states (the colours of its line).
PAIR_STATES = ("free", "repulsion active", "within the stop distance")
#: Most ticks a replay keeps (every tick up to this; beyond, evenly spaced ones): 40 s at
#: 500 Hz, about 3 MB of numbers. A run at 10 kHz would otherwise need 27 MB for 30 s.
MAX_TICKS = 20_000
#: Repulsion counts as active where the logistic of eqs. (2) and (4) exceeds this share of
#: its maximum (1 %: where it starts to move the robot visibly).
ACTIVE_SHARE = 0.01
#: Margin of the floor beyond everything the replay shows, m (a hand's width).
FLOOR_MARGIN_M = 0.1
#: The camera's elevation above the horizontal, rad (30°: the table seen from above, the
#: arm and the person upright).
CAMERA_ELEVATION_RAD = np.radians(30.0)
#: How far towards the robot's side the camera turns from the side view (the horizontal at
#: right angles to the line from the base to the person), rad (20°: the person's front and
#: the arm both in view, neither hiding the other).
CAMERA_TURN_RAD = np.radians(20.0)
#: Half of MeshCat's camera's vertical field of view, rad (its PerspectiveCamera is 75°).
CAMERA_HALF_FOV_RAD = np.radians(37.5)
#: How much farther than just in view the camera starts (1.3: room around the scene, and
#: for the panel that covers the page's top left).
CAMERA_ROOM = 1.3
#: How far the camera looks left of the scene's centre, in half diagonals (0.35: the
#: scene's centre about a tenth of the page right of its middle, clear of the panel).
CAMERA_SHIFT = 0.35
#: The smallest half diagonal the camera frames, m (a scene of the arm alone, at rest, is
#: still seen whole and from some way off).
CAMERA_MIN_RADIUS_M = 0.5


def pair_states(distance: np.ndarray, cfg: AvoidanceConfig, roles: Roles) -> np.ndarray:
    """(T, S) state of each set's closest pair (index into :data:`PAIR_STATES`).

    The sets play their parts of the robot description's ``roles``. Within the stop
    distance: the scaled set (L1) at or below the distance where f reaches ``f_stop``
    (eq. 2 inverted), the repelled and end-effector sets (L2, EE) at or below 0.05 m (the
    paper's rules), a set playing no part at or below 0 (contact). Repulsion active: where
    eq. (2) (scaled set) or eq. (4) (the others) is above :data:`ACTIVE_SHARE` of its
    maximum.
    """
    d = np.asarray(distance, dtype=float)
    stop = set_stop_distances(cfg, roles, d.shape[-1])
    active = np.full(d.shape[-1], distance_at_factor(ACTIVE_SHARE, cfg.rho_rep_m, cfg.alpha_rep))
    active[roles.scaled] = distance_at_factor(ACTIVE_SHARE, cfg.rho_L1_m, cfg.alpha_L1)
    return np.where(d <= stop, 2, np.where(d < active, 1, 0)).astype(np.int8)


#: The log arrays a replay needs, with the shape of one tick's row (``"S"``: one per robot
#: set; ``"nq"``: one per joint angle; ``"J"``: one per joint of the skeleton format).
_ROWS: dict[str, tuple[int | str, ...]] = {
    "q": ("nq",),
    "joints": ("J", 3),
    "state": ("J",),
    "stopped": (),
    "f": (),
    "distance": ("S",),
    "ee_pos": (3,),
    "ee_ref": (3,),
}
#: Optional arrays (older logs lack them), with their row shapes.
_OPTIONAL: dict[str, tuple[int | str, ...]] = {
    "stop_reason": (),
    "robot_point": ("S", 3),
    "human_point": ("S", 3),
    "frame_age_s": (),
    "true_distance": ("S",),
    "input_alert": (),
}


def checked_log(
    log: dict[str, np.ndarray], robot: Robot, skeleton: SkeletonFormat
) -> dict[str, np.ndarray]:
    """The arrays of ``log`` a replay uses, checked: ``t`` finite and increasing, every
    other array one row per tick of the right shape and kind (the robot's sets and joint
    angles, the skeleton format's joints).

    Raises
    ------
    InputError
        Naming the first array at fault.
    """

    def refuse(name: str, why: str) -> InputError:
        return InputError(f"log.npz: {name} {why}", name=name, value=why)

    t = np.asarray(log.get("t", np.zeros(0)))
    if t.ndim != 1 or len(t) == 0 or t.dtype.kind not in "fiu":
        raise refuse("t", "must be a non-empty 1-D array of times, s")
    if not np.isfinite(t).all() or np.any(np.diff(t) <= 0):
        raise refuse("t", "must be finite and strictly increasing")
    out = {"t": t.astype(float)}
    sizes = {"S": len(robot.sets), "nq": robot.nq, "J": skeleton.n_joints}
    for name, shape in (_ROWS | _OPTIONAL).items():
        if name not in log:
            if name in _ROWS:
                raise refuse(name, "is missing")
            continue
        value = np.asarray(log[name])
        row = tuple(sizes[n] if isinstance(n, str) else n for n in shape)
        text = name in TEXT_KEYS
        if value.shape != (len(t), *row) or (value.dtype.kind == "U") != text:
            expected = (len(t), *row)
            raise refuse(name, f"must be {'text' if text else 'numbers'} of shape {expected}")
        if not text and value.dtype.kind not in "fiub":
            raise refuse(name, "must be numbers")
        out[name] = value
    return out


def _links(robot: Robot, q: np.ndarray, carriers: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """(J + 2, 3) the base, every joint's origin and the end effector, m; and (C, 7) the
    pose of each joint of ``carriers`` in the base frame: its rotation as a unit
    quaternion (x, y, z, w) and its translation, m (Pinocchio's ``oMi``)."""
    model, data = robot.model, robot.data
    pin.forwardKinematics(model, data, q)
    pin.updateFramePlacement(model, data, robot.ee_frame)
    joints = [data.oMi[i].translation for i in range(1, model.njoints)]
    links = np.array([np.zeros(3), *joints, data.oMf[robot.ee_frame].translation])
    poses = [
        np.r_[pin.Quaternion(data.oMi[j].rotation).coeffs(), data.oMi[j].translation]
        for j in carriers
    ]
    return links, np.array(poses).reshape(len(carriers), 7)


def floor_extent(points: np.ndarray, reach: float) -> np.ndarray:
    """[x_min, x_max, y_min, y_max] of the floor (the plane z = 0 under the base), m: the
    square of half-side ``reach`` about the base, grown to hold every finite point of
    ``points`` (N, 3), and :data:`FLOOR_MARGIN_M` beyond."""
    xy = np.asarray(points, dtype=float).reshape(-1, 3)[:, :2]
    xy = np.vstack([xy[np.isfinite(xy).all(axis=1)], [[-reach, -reach], [reach, reach]]])
    low, high = xy.min(axis=0) - FLOOR_MARGIN_M, xy.max(axis=0) + FLOOR_MARGIN_M
    return np.array([low[0], high[0], low[1], high[1]])


def camera_start(arm: np.ndarray, person: np.ndarray) -> dict[str, list[float]]:
    """Where the replay's camera starts and the point it looks at, base frame, m.

    It looks at the centre c of the box that holds ``arm`` and ``person`` (N, 3 points;
    NaN rows ignored), from above (:data:`CAMERA_ELEVATION_RAD`) and in front: from the
    side of the line from the base to the person (the horizontal u from the base to the
    person's mean point; +y, the generated scenes' operator, if nobody is in view), turned
    :data:`CAMERA_TURN_RAD` towards the robot. Its distance d = k R / sin(φ/2), R the box's
    half diagonal (at least :data:`CAMERA_MIN_RADIUS_M`), φ MeshCat's vertical field of
    view and k = :data:`CAMERA_ROOM`, puts the
    whole box in view with room around it. The point looked at is moved
    :data:`CAMERA_SHIFT` R to the screen's left (h × z: the camera looks along −h, its
    right is −h × z), so that the scene sits right of the panel that covers the page's top
    left::

        h = cos(t) (u_y, −u_x, 0) − sin(t) u,   a = c + s R (h × z),
        p = a + d (cos(e) h + sin(e) z).
    """
    arm = np.asarray(arm, dtype=float).reshape(-1, 3)
    person = np.asarray(person, dtype=float).reshape(-1, 3)
    person = person[np.isfinite(person).all(axis=1)]
    points = np.vstack([arm[np.isfinite(arm).all(axis=1)], person, np.zeros((1, 3))])
    low, high = points.min(axis=0), points.max(axis=0)
    centre = (low + high) / 2
    radius = max(float(np.linalg.norm(high - low)) / 2, CAMERA_MIN_RADIUS_M)
    ahead = np.array([0.0, 1.0, 0.0])
    towards = person.mean(axis=0) if len(person) else ahead
    u = unit(towards * [1.0, 1.0, 0.0], fallback=ahead)  # right above the base: any side
    side = np.array([u[1], -u[0], 0.0])
    h = np.cos(CAMERA_TURN_RAD) * side - np.sin(CAMERA_TURN_RAD) * u
    d = CAMERA_ROOM * radius / np.sin(CAMERA_HALF_FOV_RAD)
    up = np.array([0.0, 0.0, 1.0])
    aim = centre + CAMERA_SHIFT * radius * np.cross(h, up)  # the scene right of the panel
    position = aim + d * (np.cos(CAMERA_ELEVATION_RAD) * h + np.sin(CAMERA_ELEVATION_RAD) * up)
    return {"position": position.tolist(), "target": aim.tolist()}


def replay_data(
    log: dict[str, np.ndarray],
    metrics: dict[str, Any],
    robot: Robot,
    cfg: AvoidanceConfig | None = None,
    fps: float = 30.0,
    human: BodyModel | None = None,
    parts: tuple[ArmPart, ...] | None = None,
) -> dict[str, Any]:
    """The replay of one run (module docstring): a dict of numbers, lists and arrays.

    Parameters
    ----------
    log, metrics
        The run's ``log.npz`` arrays and ``metrics.json``.
    robot
        The run's robot.
    cfg
        The avoidance constants the run used (the states of the closest pairs).
    fps
        Most scene frames per second of run time.
    human
        The run's body model (default: the paper's on the Kinect v2,
        :class:`~qpavoid.human.body.KinectHuman`).
    parts
        The arm's collision objects (default: read from the robot's URDF,
        :func:`~qpavoid.output.arm_shapes.arm_parts`; a caller that makes many replays of
        one robot reads them once).
    """
    cfg = cfg or AvoidanceConfig()
    parts = arm_parts(robot) if parts is None else parts
    carriers = sorted({p.joint for p in parts if p.joint != 0})  # the base's never move
    human = human or KinectHuman()
    log = checked_log(log, robot, human.skeleton)
    n_all = len(log["t"])
    keep = np.arange(0, n_all, -(-n_all // MAX_TICKS))  # every tick, up to MAX_TICKS
    log = {key: value[keep] for key, value in log.items()}
    t = log["t"]
    n = len(t)
    dt = float(np.median(np.diff(t))) if n > 1 else 1.0
    stride = max(1, round(1.0 / (fps * dt)))
    frames = np.arange(0, n, stride)
    method = str(metrics.get("distance_method", "capsules"))
    links, poses, robot_shapes, human_shapes = [], [], [], []
    for k in frames:
        kin = robot.kinematics(log["q"][k], jacobians=False)
        chain, pose = _links(robot, log["q"][k], carriers)
        links.append(chain)
        poses.append(pose)
        geo = human.geometry(log["joints"][k], log["state"][k])
        if method == "spheres":
            robot_shapes.append(kin.points)
            human_shapes.append(np.where(geo.point_valid[:, None], geo.points, np.nan))
        else:
            robot_shapes.append(kin.segments)
            segments = np.where(geo.segment_valid[:, None, None], geo.segments, np.nan)
            human_shapes.append(segments)
    if method == "spheres":
        robot_radii = robot.sphere_radii
        part_of_point = np.argmax(human.point_part, axis=1)
        human_radii = human.sphere_radii[part_of_point]
    else:
        robot_radii, human_radii = robot.capsule_radii, human.capsule_radii
    stopped = np.asarray(log["stopped"], dtype=bool)
    reason_text = log.get("stop_reason", np.full(n, "(reason not logged)"))
    reasons = sorted({str(r) for r in reason_text[stopped]})
    code = {r: i for i, r in enumerate(reasons)}
    alert_text = np.asarray(log.get("input_alert", np.full(n, "")), dtype=str)
    alerts = sorted({str(a) for a in alert_text if a})
    alert_code = {a: i for i, a in enumerate(alerts)}
    n_sets = len(robot.sets)
    true = np.asarray(log.get("true_distance", np.full((n, n_sets), np.nan)), dtype=float)
    f32 = np.float32
    if "robot_point" in log and "human_point" in log:  # older logs have no closest pairs
        pairs = np.stack([log["robot_point"][frames], log["human_point"][frames]], axis=2)
    else:
        pairs = np.full((len(frames), n_sets, 2, 3), np.nan)
    arm = np.array(links)
    person = np.array(human_shapes, dtype=float).reshape(-1, 3)  # NaN: not in view
    path = np.asarray(log["ee_ref"], dtype=float)
    return {
        "method": method,
        "controller": metrics.get("controller"),
        "scenario": metrics.get("scenario"),
        "safety": metrics.get("safety"),
        "set_names": list(robot.set_names),
        "part_names": list(human.part_names),
        "pair_states": list(PAIR_STATES),
        "robot_radii": robot_radii.astype(f32),
        "human_radii": human_radii.astype(f32),
        "frame_tick": frames.astype(np.int32),
        "links": arm.astype(f32),
        "parts": parts,
        "arm_parts": [p.name for p in parts],
        "mesh_joints": carriers,
        "mesh_poses": np.array(poses, dtype=f32).reshape(len(frames), len(carriers), 7),
        "floor": floor_extent(
            np.vstack([arm.reshape(-1, 3), person, path]), reach_m(robot)
        ).tolist(),
        "camera": camera_start(arm, person),
        "robot": np.array(robot_shapes, dtype=f32),
        "human": np.array(human_shapes, dtype=f32),
        "pairs": pairs.astype(f32),
        "t": t.astype(np.float64),
        "f": np.asarray(log["f"], dtype=f32),
        "distance": np.asarray(log["distance"], dtype=f32),
        "state": pair_states(log["distance"], cfg, robot.roles),
        "stopped": stopped.astype(np.int8),
        "reasons": reasons,
        "reason": np.array(
            [code[str(r)] if s else -1 for r, s in zip(reason_text, stopped, strict=True)],
            dtype=np.int32,
        ),
        "alerts": alerts,
        "alert": np.array([alert_code.get(str(a), -1) for a in alert_text], dtype=np.int32),
        "frame_age": np.asarray(log.get("frame_age_s", np.zeros(n)), dtype=f32),
        "true_distance": true.astype(f32),
        "path": np.asarray(log["ee_ref"], dtype=f32)[:: max(1, stride // 2)],
        "trace": np.asarray(log["ee_pos"], dtype=f32)[:: max(1, stride // 2)],
    }
