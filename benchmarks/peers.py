"""qpavoid against pink and mink: on every shipped arm, its path and moving hand, in one process.

    pip install ".[peers]"          # pin-pink, mink and mujoco (and ".[robots]": the arms)
    python benchmarks/peers.py [--seconds 15] [--arms iiwa14 panda ...] [--json FILE]

On each arm of ``--arms`` (default: every shipped description, :func:`bundled_robots`,
the iiwa first; any name or folder :func:`load_robot` takes), each variant tracks the
arm's own planned end-effector path (its task file's, :func:`default_task`: for the iiwa
the paper's ``ArcPath``), pose and twist, at 100 Hz in closed loop (``q += v dt``) while
the hand of the paper's Test 1, as made for that arm (:func:`make_scenario`), moves near
the end effector and the repelled set; all variants of an arm step in one loop,
interleaved tick by tick, so they share the machine's state, in a new (seeded) order
every tick, so that none always runs after the same neighbour (one of ours right after
another of ours would find its code warm in the caches; until 2026-11-24 the order was
fixed). Per variant: the time of one tick (median, p99, µs) and the clearance it keeps
from the moving hand (the distance from the hand point to the nearest capsule of the arm,
minus a 0.05 m hand radius, m), the largest distance of the end effector from its
reference (mm) and how far its path clock is behind at the end (s: qpavoid's waits while
it stops; the peers always chase the reference of the moment).

* **qpavoid**: ``QPController.step``, on spheres and on capsules, with the paper's rules
  (``safety="paper"``) and with speed and separation monitoring on top of them
  (``safety="ssm"``, docs/safety.md), each on the persistent OSQP and on the daqp backend
  (``QPConfig(backend="daqp")``: daqp called directly); one person (the whole skeleton,
  as every tick sees it); and, in a second interleaved phase of the same arm, six people
  (the same person and five others standing 0.8 m apart along the table, every skeleton
  new every tick), on the persistent OSQP, with either rules. Every tick hands it a new
  frame (``frame_time_s``: the tick's time); by its content alone, a still person's frame
  would be the frame in hand, held until stale, and the arm would stop.
* **floor**: at the q of qpavoid's sphere tick (paper's rules; its tick before), only the
  library calls such a tick cannot do without (:class:`Floor`: Pinocchio's kinematics and
  the control frames' placements and Jacobians, OSQP's update and solve of that tick's
  own data): the time left to qpavoid's own code is the difference. A time only (it
  commands nothing).
* **pink**: ``solve_ik`` with a ``FrameTask`` (the end effector), a ``PostureTask``
  (1e-3), configuration and velocity limits and **one** ``BodySphericalBarrier`` between
  the end effector and a frame placed at the hand each tick (d_min 0.15 m), on our
  reduced Pinocchio model (the description's locked joint locked, as qpavoid's), on osqp
  and daqp.
* **mink**: ``solve_ik`` with a ``FrameTask`` (a site at the end effector), a
  ``PostureTask``, configuration and velocity limits (the URDF's; on the iiwa 1.4 rad/s
  on every joint, as in its older numbers) and a ``CollisionAvoidanceLimit`` between the
  collision geometry of the moving links but the first (on the iiwa link_2 to link_7, as
  in its older numbers) and a mocap sphere at the hand, on osqp and daqp. Its MuJoCo
  model is the arm's own URDF (:func:`mujoco_urdf`: the URDF qpavoid loads, its meshes'
  ``package://`` and relative paths resolved as qpavoid resolves them, visuals dropped,
  the joints the description holds, the fingers, fixed where it holds them); the locked
  joint is free (MuJoCo has no locked joint). An arm whose model cannot be built gets the
  reason in place of its numbers.

Neither peer puts the hand's own motion into its constraints.

The JSON (``--json``) holds one object per arm, by the name given to ``--arms``, and in
it one row per variant by its name (the variants the iiwa had when it was the only arm
keep their names, so that older numbers, the iiwa's alone at the top level, compare)::

    {"iiwa14": {"qpavoid QP, spheres (persistent OSQP)": {"median_us": ..., "p99_us": ...,
                    "min_clearance_m": ..., "max_path_error_mm": ...,
                    "path_time_behind_s": ...},
                "floor: Pinocchio + OSQP calls of that tick": {"median_us": ..., "p99_us": ...},
                "mink + CollisionAvoidanceLimit, osqp": {"error": "why it did not run"}, ...},
     "panda": {...}, ...}

Printed per arm: a markdown table of the rows, the fastest peer against qpavoid's QP
tick with speed and separation (spheres, capsules) and the issue's bars: at least 2x
faster than the fastest peer on any solver, p99 ≤ 300 µs on the iiwa and ≤ 400 µs on every
other arm, and ≤ 500 µs with six people.
"""

from __future__ import annotations

import argparse
import json
import os
import time
import warnings
from functools import cache
from pathlib import Path
from typing import Any
from xml.etree import ElementTree

import numpy as np
import pinocchio as pin

import qpavoid
from qpavoid.arm.description import bundled_robots
from qpavoid.arm.ik import inverse_kinematics
from qpavoid.arm.model import Robot, load_robot
from qpavoid.control.path import PlannedPath
from qpavoid.control.qp import QPConfig, QPController
from qpavoid.control.qp.backends import WARM_START_FLOOR, PersistentOSQP
from qpavoid.control.qp.solver_kernels import flush_tiny
from qpavoid.control.task import default_task
from qpavoid.human._kernels import point_segment_distance
from qpavoid.human.kinect_v2 import JointType
from qpavoid.human.people import People
from qpavoid.perception.tracker import PerceptionConfig
from qpavoid.scenarios.generated import make_scenario

RATE_HZ = 100.0
#: The reference arm: first in the default ``--arms``, its p99 bar the tighter.
REFERENCE = "iiwa14"
#: The issue's bars: qpavoid's QP tick with speed and separation at least this many times
#: faster than the fastest peer (medians), and its p99 at most these, µs.
SPEEDUP = 2.0
P99_US = {REFERENCE: 300.0}
P99_OTHER_US = 400.0
P99_CROWD_US = 500.0


def ideal(**kw):
    """qpavoid's settings for a noise-free hand given every tick: no frozen-frame check
    (a perfect sensor films a still person bit for bit)."""
    return qpavoid.ControllerConfig(
        control_period_s=1.0 / RATE_HZ,
        perception=PerceptionConfig(max_identical_frames=None),
        **kw,
    )


HAND_RADIUS_M = 0.05
#: Where the five other people of the six-people variants stand, relative to the first, m.
OTHERS = [np.array([0.7 * i, 0.4 * i, 0.0]) for i in range(1, 6)]
#: mink's velocity limit on every joint of an arm, rad/s, where not the URDF's.
MINK_VELOCITY = {"iiwa14": 1.4}


@cache
def full_arm(description: str | Path) -> Robot:
    """The arm with no joint locked (the joints it holds, fingers, still held): the
    model the clearance and the path error are measured on, and mink's joints."""
    return load_robot(description, locked=(), coverage=False)


def _description(robot: Robot) -> str | Path:
    """What :func:`load_robot` reloads ``robot`` from: its control-point file, or its name."""
    return robot.path if robot.path is not None else robot.name


def full_q(robot: Robot, full: Robot, q: np.ndarray) -> np.ndarray:
    """``robot``'s q on ``full`` (the locked joints at their angles)."""
    out = np.array([robot.locked.get(name, 0.0) for name in full.joint_names])
    out[[full.joint_names.index(name) for name in robot.joint_names]] = q
    return out


class Pink:
    def __init__(self, robot, solver: str):
        import pink
        from pink.barriers import BodySphericalBarrier
        from pink.tasks import FrameTask, PostureTask

        self.pink, self.solver = pink, solver
        self.model = robot.model.copy()
        self.hand = self.model.addFrame(
            pin.Frame("person_hand", 0, 0, pin.SE3.Identity(), pin.FrameType.OP_FRAME)
        )
        self.data = self.model.createData()
        ee = robot.model.frames[robot.ee_frame].name
        self.task = FrameTask(ee, position_cost=1.0, orientation_cost=1.0)
        self.posture = PostureTask(cost=1e-3)
        self.barrier = BodySphericalBarrier((ee, "person_hand"), d_min=0.15)

    def step(self, q, hand, target: pin.SE3) -> np.ndarray:
        self.model.frames[self.hand].placement = pin.SE3(np.eye(3), hand)
        conf = self.pink.Configuration(self.model, self.data, q)
        self.task.set_target(target)
        self.posture.set_target(q)
        return self.pink.solve_ik(
            conf,
            [self.task, self.posture],
            1.0 / RATE_HZ,
            solver=self.solver,
            barriers=[self.barrier],
            safety_break=False,
        )


def mujoco_urdf(robot: Robot) -> str:
    """``robot``'s URDF as MuJoCo should read it: every mesh at its absolute path (a
    ``package://`` one looked for in the robot's mesh folders, as qpavoid's loader does; a
    relative one beside the URDF), no visuals (MuJoCo reads no Collada), the joints the
    description holds but does not lock (the fingers) fixed at their angle, and a compiler
    that keeps those paths and fuses the fixed links into their moving ones.

    Raises
    ------
    FileNotFoundError
        For a mesh that is in none of those folders.
    """
    if robot.urdf is None:
        raise FileNotFoundError(f"{robot.name}: the description has no URDF")
    root = ElementTree.parse(robot.urdf).getroot()
    for link in root.iter("link"):
        for visual in link.findall("visual"):
            link.remove(visual)
    for mesh in root.iter("mesh"):
        name = mesh.get("filename", "")
        if name.startswith("package://"):
            rel = name.removeprefix("package://")
            found = [d / rel for d in robot.mesh_dirs if (d / rel).is_file()]
        else:
            found = [p for p in (robot.urdf.parent / name,) if p.is_file()]
        if not found:
            raise FileNotFoundError(f"{robot.urdf}: mesh {name} not found")
        mesh.set("filename", str(found[0].resolve()))
    held = {
        n: v for n, v in robot.locked.items() if n not in full_arm(_description(robot)).joint_names
    }
    for joint in root.iter("joint"):
        if joint.get("name") in held:
            _fix(joint, held[joint.get("name", "")])
    for tag in ("gazebo", "transmission"):
        for element in root.findall(tag):
            root.remove(element)
    compiler = ElementTree.SubElement(ElementTree.SubElement(root, "mujoco"), "compiler")
    compiler.attrib.update(strippath="false", discardvisual="true", fusestatic="true")
    return ElementTree.tostring(root, encoding="unicode")


def _fix(joint: ElementTree.Element, angle: float) -> None:
    """Make a URDF ``joint`` (revolute or prismatic) a fixed one at ``angle`` (rad or m)."""

    def numbers(element: ElementTree.Element | None, key: str, default: str) -> np.ndarray:
        text = element.get(key, default) if element is not None else default
        return np.array([float(v) for v in text.split()])

    origin = joint.find("origin")
    axis = numbers(joint.find("axis"), "xyz", "1 0 0")
    placement = pin.SE3(
        pin.rpy.rpyToMatrix(*numbers(origin, "rpy", "0 0 0")), numbers(origin, "xyz", "0 0 0")
    )
    if joint.get("type") == "prismatic":
        placement = placement * pin.SE3(np.eye(3), axis * angle)
    else:
        placement = placement * pin.SE3(pin.exp3(axis * angle), np.zeros(3))
    for child in list(joint):
        if child.tag != "parent" and child.tag != "child":
            joint.remove(child)
    joint.set("type", "fixed")
    origin = ElementTree.SubElement(joint, "origin")
    origin.set("xyz", " ".join(f"{v:.17g}" for v in placement.translation))
    origin.set("rpy", " ".join(f"{v:.17g}" for v in pin.rpy.matrixToRpy(placement.rotation)))


class Mink:
    """mink on ``robot``'s URDF in MuJoCo (:func:`mujoco_urdf`; default the iiwa). Its
    q is MuJoCo's: :meth:`qpos` and :meth:`full` convert from and to the full arm's."""

    def __init__(self, solver: str, robot: Robot | None = None):
        import mink
        import mujoco

        robot = robot or load_robot(REFERENCE)
        full = full_arm(_description(robot))
        spec = mujoco.MjSpec.from_string(mujoco_urdf(robot))
        model = spec.compile()
        # the end effector as a site on the body of its joint (the URDF's link there:
        # the joint's frame; fixed links are fused into it)
        ee = full.model.frames[full.ee_frame]
        joint = model.joint(full.model.names[ee.parentJoint])
        name = model.body(model.jnt_bodyid[joint.id]).name
        # (spec.body(name) raises for the last link on MuJoCo 3.3.0: looked up by hand)
        body = next(b for b in spec.bodies if b.name == name)
        quat = pin.Quaternion(ee.placement.rotation).coeffs()  # x, y, z, w
        body.add_site(name=ee.name, pos=ee.placement.translation, quat=np.roll(quat, 1))
        hand = spec.worldbody.add_body(name="person_hand", mocap=True)
        hand.add_geom(
            name="person_hand", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[HAND_RADIUS_M, 0, 0]
        )
        self.model = model = spec.compile()
        self.mink, self.solver = mink, solver
        self.conf = mink.Configuration(model)
        # the full arm's joints in MuJoCo's q (every joint a hinge: one number)
        self.index = np.array([model.joint(n).qposadr[0] for n in full.joint_names])
        first, mine = model.jnt_bodyid[0], model.geom("person_hand").id
        links = [  # the moving links' geometry but the first's
            g
            for g in range(model.ngeom)
            if model.body_weldid[model.geom_bodyid[g]] not in (0, first) and g != mine
        ]
        speed = MINK_VELOCITY.get(robot.name)
        velocity = {
            name: speed if speed is not None else float(full.dq_max[i])
            for i, name in enumerate(full.joint_names)
        }
        self.task = mink.FrameTask(ee.name, "site", position_cost=1.0, orientation_cost=1.0)
        self.posture = mink.PostureTask(model, cost=1e-3)
        self.limits = [
            mink.ConfigurationLimit(model),
            mink.VelocityLimit(model, velocity),
            mink.CollisionAvoidanceLimit(
                model,
                [(links, ["person_hand"])],
                minimum_distance_from_collisions=0.05,
                collision_detection_distance=0.3,
            ),
        ]
        self.mocap = model.body("person_hand").mocapid[0]

    def qpos(self, q_full: np.ndarray) -> np.ndarray:
        """MuJoCo's q of the full arm's ``q_full``."""
        out = np.zeros(self.model.nq)
        out[self.index] = q_full
        return out

    def full(self, qpos: np.ndarray) -> np.ndarray:
        """The full arm's q of MuJoCo's ``qpos``."""
        return qpos[self.index]

    def step(self, qpos, hand, target: pin.SE3) -> np.ndarray:
        self.conf.data.mocap_pos[self.mocap] = hand
        self.conf.update(qpos)
        self.task.set_target(
            self.mink.SE3.from_rotation_and_translation(
                self.mink.SO3.from_matrix(target.rotation), target.translation
            )
        )
        self.posture.set_target(qpos)
        return self.mink.solve_ik(
            self.conf, [self.task, self.posture], 1.0 / RATE_HZ, self.solver, limits=self.limits
        )


class Floor:
    """The library calls a qpavoid tick cannot do without, and nothing else: Pinocchio's
    joint Jacobians and frame placements, each control frame's position and Jacobian,
    then OSQP's update and solve of the data the sphere tick built (a second model and a
    second persistent problem of the same pattern), and the warm start's clean-up; it
    commands nothing. Left out: the pose error's ``pin.log3`` (about 1.5 µs alone).

    Each tick it solves what its source built in the tick before (:meth:`take`, copied
    after every variant ran: outside any timing), so that in the shuffled order it still
    solves each of the source's problems once, in the source's order."""

    def __init__(self, robot, source: QPController):
        self.model = robot.model.copy()
        self.data = self.model.createData()
        # the frames a tick reads, each once (Robot's own list: a capsule end that is a
        # control point is read once), each through a reference held into the data
        self.frames, self.ee = list(robot._frames), robot.ee_frame
        self.placements = [self.data.oMf[f] for f in self.frames]
        self.ee_placement = self.data.oMf[robot.ee_frame]
        self.controller = source
        self.osqp = PersistentOSQP(source.backend.n, source.backend.m, QPConfig())._native
        self.taken: tuple | None = None  # the source's last tick: q and its OSQP data

    def take(self, q: np.ndarray) -> None:
        """Copy the source's last tick: its q and OSQP data (its backend's buffers and its
        assembler's c; private: a benchmark's peek, not an interface)."""
        src = self.controller.backend
        c = self.controller.assembler._filled.c
        self.taken = tuple(a.copy() for a in (q, c, src._l, src._u, src._Px, src._Ax))

    def step(self, _q=None) -> None:
        assert self.taken is not None  # _interleaved steps a floor after a take
        model, data = self.model, self.data
        q, c, lower, upper, Px, Ax = self.taken
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        frames = [*self.frames, self.ee]
        self.kinematics = (  # what a tick reads: placements and Jacobians
            [m.translation for m in self.placements] + [self.ee_placement.homogeneous],
            [pin.getFrameJacobian(model, data, f, LWA) for f in frames],
        )
        self.osqp.update_data_vec(q=c, l=lower, u=upper)
        self.osqp.update_data_mat(P_x=Px, P_i=None, A_x=Ax, A_i=None)
        self.osqp.solve()
        self.status, solution = self.osqp.info.status, self.osqp.solution
        self.x, y = np.array(solution.x), np.array(solution.y)
        # as the tick does: no subnormal numbers left in the warm start (PersistentOSQP)
        if flush_tiny(self.x, WARM_START_FLOOR) | flush_tiny(y, WARM_START_FLOOR):
            self.osqp.warm_start(x=self.x, y=y)


LWA = pin.LOCAL_WORLD_ALIGNED


def arguments(description: str, arms: bool = False) -> argparse.Namespace:
    """The command line: ``--seconds``, ``--json`` and, with ``arms``, ``--arms``."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--seconds", type=float, default=15.0)
    ap.add_argument("--json")
    if arms:
        ap.add_argument(
            "--arms",
            nargs="+",
            metavar="ARM",
            default=sorted(bundled_robots(), key=lambda name: (name != REFERENCE, name)),
            help="descriptions to compare on, as load_robot takes them (default: every "
            "shipped arm: %(default)s)",
        )
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    return args


def arm(name: str | Path) -> tuple[Robot, PlannedPath, Any, np.ndarray]:
    """An arm (:func:`load_robot`), its task's path, its Test 1 person and its start on
    the path: what every head-to-head on it starts from."""
    robot = load_robot(name)
    task = default_task(robot)
    motion = make_scenario("test1", robot, task=task)
    return robot, task.path, motion, inverse_kinematics(robot, task.path.reference(0.0)[0])


def setup(description: str) -> tuple[argparse.Namespace, Robot, PlannedPath, Any, np.ndarray]:
    """The command line (``--seconds``, ``--json``), and the iiwa's :func:`arm`: what a
    head-to-head on the reference arm alone (``single_pass.py``) starts from."""
    return (arguments(description), *arm(REFERENCE))


def compare(name: str, seconds: float) -> dict[str, dict]:
    """Every variant on the arm ``name``, in two interleaved phases; its rows by variant
    (a variant that could not be built: ``{"error": why}``)."""
    robot, path, motion, q0 = arm(name)

    def ours(kind: str, distance: str, safety: str = "paper", **qp) -> tuple[str, QPController]:
        config = ideal(distance=distance, safety=safety)
        return kind, QPController(robot, config=config, qp=QPConfig(**qp))

    spheres = ours("qp", "spheres")
    variants = {  # the iiwa's names as when it was compared alone
        "qpavoid QP, spheres (persistent OSQP)": spheres,
        # the floor of its libraries (see Floor)
        "floor: Pinocchio + OSQP calls of that tick": ("floor", Floor(robot, spheres[1])),
        "qpavoid QP, capsules (persistent OSQP)": ours("qp", "capsules"),
        "qpavoid QP, spheres (daqp)": ours("qp", "spheres", backend="daqp"),
        "qpavoid QP, capsules (daqp)": ours("qp", "capsules", backend="daqp"),
    }
    for distance in ("spheres", "capsules"):
        variants[_ssm(distance)] = ours("qp", distance, "ssm")
        variants[_ssm(distance, backend="daqp")] = ours("qp", distance, "ssm", backend="daqp")
    peers: dict[str, tuple[str, Any, tuple]] = {}
    for solver in ("osqp", "daqp"):
        peers[f"pink + 1 barrier, {solver}"] = ("pink", Pink, (robot, solver))
        peers[f"mink + CollisionAvoidanceLimit, {solver}"] = ("mink", Mink, (solver, robot))
    failed: dict[str, str] = {}
    for peer, (kind, make, args) in peers.items():
        try:
            variants[peer] = kind, make(*args)
        except Exception as exc:  # an arm a peer cannot load: the reason is its result
            failed[peer] = f"{type(exc).__name__}: {exc}".splitlines()[0]
    crowds = {  # a second phase: their footprint would weigh on the head-to-head's caches
        "qpavoid QP, spheres, 6 people (persistent OSQP)": ours("qp6", "spheres"),
        "qpavoid QP, capsules, 6 people (persistent OSQP)": ours("qp6", "capsules"),
        _ssm("spheres", crowd=True): ours("qp6", "spheres", "ssm"),
        _ssm("capsules", crowd=True): ours("qp6", "capsules", "ssm"),
    }
    rows: dict[str, dict] = {}
    for phase in (variants, crowds):
        rows.update(_interleaved(phase, robot, path, motion, q0, seconds, show=False))
    rows.update({peer: {"error": why} for peer, why in failed.items()})
    return rows


def _ssm(distance: str, backend: str = "persistent OSQP", crowd: bool = False) -> str:
    """The name of qpavoid's variant with speed and separation on."""
    return f"qpavoid QP, {distance}, ssm{', 6 people' if crowd else ''} ({backend})"


def main() -> None:
    args = arguments(__doc__.splitlines()[0], arms=True)
    results = {}
    for name in args.arms:
        print(f"\n## {name}: {int(args.seconds * RATE_HZ)} ticks at {RATE_HZ:.0f} Hz\n")
        before = os.getloadavg()[0]
        results[name] = rows = compare(name, args.seconds)
        print(table(rows))
        print(f"\nload average (1 min) {before:.2f} before, {os.getloadavg()[0]:.2f} after")
        print("\n" + summary(name, rows))
        if args.json:  # after every arm: a run stopped later keeps the arms done
            Path(args.json).write_text(json.dumps(results, indent=1))


def table(rows: dict[str, dict]) -> str:
    """``rows`` as a markdown table."""
    lines = [
        "| variant | median µs | p99 µs | clearance m | path error mm | behind s |",
        "|---|--:|--:|--:|--:|--:|",
    ]
    for name, r in rows.items():
        if "error" in r:
            lines.append(f"| {name} | not run: {r['error']} | | | | |")
        elif "min_clearance_m" not in r:  # the floor: a time, no motion of its own
            lines.append(f"| {name} | {r['median_us']:.0f} | {r['p99_us']:.0f} | – | – | – |")
        else:
            lines.append(
                f"| {name} | {r['median_us']:.0f} | {r['p99_us']:.0f} | "
                f"{r['min_clearance_m']:.3f} | {r['max_path_error_mm']:.1f} | "
                f"{r['path_time_behind_s']:.2f} |"
            )
    return "\n".join(lines)


def summary(name: str, rows: dict[str, dict]) -> str:
    """The fastest peer against qpavoid's QP tick with speed and separation, and the
    issue's bars (:data:`SPEEDUP`, :data:`P99_US`, :data:`P99_CROWD_US`), on one arm."""
    peers = {
        n: r["median_us"]
        for n, r in rows.items()
        if n.startswith(("pink", "mink")) and "median_us" in r
    }
    lines = []
    for distance in ("spheres", "capsules"):
        ours = rows[_ssm(distance)]["median_us"]
        if not peers:
            lines.append(f"fastest peer: none ran; qpavoid QP {distance} ssm: {ours:.0f} µs")
            continue
        fastest = min(peers, key=peers.__getitem__)
        ratio = peers[fastest] / ours
        lines.append(
            f"fastest peer: {fastest} {peers[fastest]:.0f} µs; qpavoid QP {distance} ssm: "
            f"{ours:.0f} µs ({ratio:.1f}x; bar {SPEEDUP:.0f}x "
            f"{'holds' if ratio >= SPEEDUP else 'missed'})"
        )
    bar = P99_US.get(name, P99_OTHER_US)
    checks = [(_ssm(d), bar) for d in ("spheres", "capsules")]
    checks += [(_ssm(d, crowd=True), P99_CROWD_US) for d in ("spheres", "capsules")]
    held = [
        f"{variant.removeprefix('qpavoid QP, ').removesuffix(' (persistent OSQP)')} "
        f"{rows[variant]['p99_us']:.0f} ≤ {limit:.0f} "
        f"{'holds' if rows[variant]['p99_us'] <= limit else 'missed'}"
        for variant, limit in checks
    ]
    lines.append("p99 bars (µs): " + "; ".join(held))
    return "\n".join(lines)


def _interleaved(
    variants: dict, robot, path, motion, q0, seconds: float, show: bool = True
) -> dict:
    """Step ``variants`` tick by tick in one loop; return their rows (and print them as a
    table, if ``show``)."""
    full = full_arm(_description(robot))
    state = {
        name: ctrl.qpos(full_q(robot, full, q0)) if kind == "mink" else q0.copy()
        for name, (kind, ctrl) in variants.items()
    }
    times: dict[str, list[float]] = {name: [] for name in variants}
    clock = dict.fromkeys(variants, 0.0)  # each variant's path time, s
    clear: dict[str, list[float]] = {name: [] for name in variants}
    error: dict[str, list[float]] = {name: [] for name in variants}
    dt = 1.0 / RATE_HZ
    # A floor solves what its source built in the tick before (see Floor).
    floors = {name: ctrl for name, (kind, ctrl) in variants.items() if kind == "floor"}
    source = {}
    for name, floor in floors.items():
        found = [n for n, (_, c) in variants.items() if c is floor.controller]
        if not found:
            raise ValueError(f"{name}: its source controller is not stepped in this phase")
        source[name] = found[0]
    stepped_at: dict[str, np.ndarray] = {}
    # Each tick in a new order (the first as given): a variant's time depends on what ran
    # just before it (what is left in the caches; one of ours after another of ours finds
    # its code warm), so no variant keeps a neighbour.
    order, rng = list(variants), np.random.default_rng(0)
    for k in range(int(seconds * RATE_HZ)):
        t = k * dt
        frame = qpavoid.HumanFrame.check(*motion.frame_at(t))
        others = [qpavoid.HumanFrame.check(frame.joints + d, frame.state) for d in OTHERS]
        crowd = People(tuple(range(6)), (frame, *others))  # and five others at the table
        hand = frame.joints[JointType.HandRight]
        target = pin.SE3(path.reference(t)[0])
        for name in order:
            kind, ctrl = variants[name]
            if kind == "floor":  # its source's last tick: a time only
                if ctrl.taken is not None:  # (none in the first tick)
                    t0 = time.perf_counter_ns()
                    ctrl.step()
                    times[name].append((time.perf_counter_ns() - t0) / 1e3)
                continue
            stepped_at[name] = q = state[name]
            tau = clock[name]
            t0 = time.perf_counter_ns()
            if kind in ("qp", "qp6"):  # qpavoid's path clock waits while it stops
                # every tick a new frame, captured now (by its content, a still person's
                # frame would be the one in hand, held, until stale)
                cmd = ctrl.step(q, frame if kind == "qp" else crowd, None, tau, frame_time_s=t)
                v, clock[name] = cmd.dq, tau + cmd.time_scale * dt
            else:  # the peers chase the reference of the moment
                v, clock[name] = ctrl.step(q, hand, target), t + dt
            times[name].append((time.perf_counter_ns() - t0) / 1e3)
            state[name] = q + v * dt
            q_full = ctrl.full(state[name]) if kind == "mink" else full_q(robot, full, state[name])
            clear[name].append(_clearance(full, q_full, hand))
            ref = path.reference(clock[name])[0][:3, 3]
            error[name].append(float(np.linalg.norm(full.end_effector(q_full)[:3, 3] - ref)))
        for name, floor in floors.items():  # after every variant: outside any timing
            floor.take(stepped_at[source[name]])
        rng.shuffle(order)
    rows = {}
    for name in variants:
        tt = np.array(times[name][10:])
        rows[name] = {"median_us": float(np.median(tt)), "p99_us": float(np.percentile(tt, 99))}
        if clear[name]:  # not the floor: a time, no motion of its own
            rows[name] |= {
                "min_clearance_m": float(np.min(clear[name])),
                "max_path_error_mm": float(np.max(error[name]) * 1e3),
                "path_time_behind_s": round(seconds - clock[name], 9) + 0.0,  # no -0.0
            }
    if show:
        print(f"\n{int(seconds * RATE_HZ)} ticks at {RATE_HZ:.0f} Hz, variants interleaved\n")
        print(table(rows))
    return rows


def _clearance(full: Robot, q_full: np.ndarray, hand: np.ndarray) -> float:
    """The hand's clearance from the arm's capsules (on the full arm), m."""
    seg = full.capsules(q_full)
    radii = [s.capsule_radius_m for s in full.sets]
    return float(
        min(
            point_segment_distance(hand, a, b) - r - HAND_RADIUS_M
            for (a, b), r in zip(seg, radii, strict=True)
        )
    )


if __name__ == "__main__":
    main()
