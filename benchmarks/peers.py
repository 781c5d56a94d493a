"""qpavoid against pink and mink: the same arm, path and moving hand, in one process.

    pip install ".[peers]"          # pin-pink, mink and mujoco
    python benchmarks/peers.py [--seconds 15] [--json FILE]

Each variant tracks the same planned end-effector path (qpavoid's ``ArcPath``: pose and
twist) at 100 Hz in closed loop (``q += v dt``) while the hand of the paper's Test 1 moves
near the end effector and L2; all variants step in one loop, interleaved tick by tick, so
they share the machine's state, in a new (seeded) order every tick, so that none always
runs after the same neighbour (one of ours right after another of ours would find its
code warm in the caches; until 2026-11-24 the order was fixed). Per variant: the time
of one tick (median, p99, µs) and the clearance it keeps from the moving hand (the
distance from the hand point to the nearest capsule of the arm, minus a 0.05 m hand
radius, m), the largest distance of the flange from its reference (mm) and how far its
path clock is behind at the end (s: qpavoid's waits while it stops; the peers always
chase the reference of the moment).

* **qpavoid**: ``QPController.step`` (persistent OSQP), spheres and capsules, the paper's
  rules, one person (the whole skeleton, as every tick sees it); spheres on the
  daqp backend (``QPConfig(backend="daqp")``: daqp called directly); and, in a second interleaved
  phase of the same run, six people (the same person and five others standing 0.8 m
  apart along the table, every skeleton new every tick).
* **floor**: at the q of qpavoid's sphere tick (its tick before), only the library calls such a
  tick cannot do without (:class:`Floor`: Pinocchio's kinematics and the control frames'
  placements and Jacobians, OSQP's update and solve of that tick's own data): the time
  left to qpavoid's own code is the difference. A time only (it commands nothing).
* **pink**: ``solve_ik`` with a ``FrameTask`` (the flange), a ``PostureTask`` (1e-3),
  configuration and velocity limits and **one** ``BodySphericalBarrier`` between the
  flange and a frame placed at the hand each tick (d_min 0.15 m), on our reduced
  Pinocchio model (A3 locked, as qpavoid's), on osqp and daqp.
* **mink**: ``solve_ik`` with a ``FrameTask`` (a site at the flange), a ``PostureTask``,
  configuration and velocity limits and a ``CollisionAvoidanceLimit`` between the six
  moving links' collision cylinders and a mocap sphere at the hand (the URDF loaded into
  MuJoCo; A3 free: MuJoCo has no locked joint), on osqp and daqp.

Neither peer puts the hand's own motion into its constraints; qpavoid's numbers here are
with the paper's rules (``--safety ssm`` adds the separation rows: docs/safety.md).
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from importlib.resources import files
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

import qpavoid
from qpavoid.arm.ik import inverse_kinematics
from qpavoid.arm.model import load_robot
from qpavoid.control.path import ArcPath
from qpavoid.control.qp import QPConfig, QPController
from qpavoid.control.qp.backends import WARM_START_FLOOR, PersistentOSQP
from qpavoid.control.qp.solver_kernels import flush_tiny
from qpavoid.human._kernels import point_segment_distance
from qpavoid.human.kinect_v2 import JointType
from qpavoid.human.people import People
from qpavoid.perception.tracker import PerceptionConfig
from qpavoid.scenarios.generated import make_scenario

RATE_HZ = 100.0


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
URDF = Path(str(files("qpavoid.robots"))) / "iiwa14" / "iiwa14.urdf"


class Pink:
    def __init__(self, robot, solver: str):
        import pink
        from pink.barriers import BodySphericalBarrier
        from pink.tasks import FrameTask, PostureTask

        self.pink, self.solver = pink, solver
        self.model = robot.model.copy()
        self.hand = self.model.addFrame(
            pin.Frame("hand", 0, 0, pin.SE3.Identity(), pin.FrameType.OP_FRAME)
        )
        self.data = self.model.createData()
        self.task = FrameTask("flange", position_cost=1.0, orientation_cost=1.0)
        self.posture = PostureTask(cost=1e-3)
        self.barrier = BodySphericalBarrier(("flange", "hand"), d_min=0.15)

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


class Mink:
    def __init__(self, solver: str):
        import mink
        import mujoco

        spec = mujoco.MjSpec.from_file(str(URDF))
        # the flange (0.045 m beyond link_7, fused into it by MuJoCo) as a site to track
        spec.body("link_7").add_site(name="flange", pos=[0.0, 0.0, 0.045])
        body = spec.worldbody.add_body(name="hand", mocap=True)
        body.add_geom(name="hand", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[HAND_RADIUS_M, 0, 0])
        self.model = spec.compile()
        self.mink, self.solver = mink, solver
        self.conf = mink.Configuration(self.model)
        links = [
            self.model.geom(i).name or i
            for i in range(self.model.ngeom)
            if self.model.geom_bodyid[i] > 1 and self.model.geom(i).name != "hand"
        ]
        self.task = mink.FrameTask("flange", "site", position_cost=1.0, orientation_cost=1.0)
        self.posture = mink.PostureTask(self.model, cost=1e-3)
        self.limits = [
            mink.ConfigurationLimit(self.model),
            mink.VelocityLimit(self.model, {f"A{k}": 1.4 for k in range(1, 8)}),
            mink.CollisionAvoidanceLimit(
                self.model,
                [(links, ["hand"])],
                minimum_distance_from_collisions=0.05,
                collision_detection_distance=0.3,
            ),
        ]
        self.mocap = self.model.body("hand").mocapid[0]

    def step(self, q7, hand, target: pin.SE3) -> np.ndarray:
        self.conf.data.mocap_pos[self.mocap] = hand
        self.conf.update(q7)
        self.task.set_target(
            self.mink.SE3.from_rotation_and_translation(
                self.mink.SO3.from_matrix(target.rotation), target.translation
            )
        )
        self.posture.set_target(q7)
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


def setup(description: str) -> tuple[argparse.Namespace, Any, ArcPath, Any, np.ndarray]:
    """The command line (``--seconds``, ``--json``), the arm, the path, Test 1's person and
    the arm's start on the path: what every head-to-head here starts from."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--seconds", type=float, default=15.0)
    ap.add_argument("--json")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    robot = load_robot("iiwa14")
    path, motion = ArcPath(), make_scenario("test1", robot)
    return args, robot, path, motion, inverse_kinematics(robot, path.reference(0.0)[0])


def main() -> None:
    args, robot, path, motion, q0 = setup(__doc__.splitlines()[0])

    def ours(kind: str, distance: str, **qp) -> tuple[str, QPController]:
        return kind, QPController(robot, config=ideal(distance=distance), qp=QPConfig(**qp))

    spheres = ours("qp", "spheres")
    variants = {
        "qpavoid QP, spheres (persistent OSQP)": spheres,
        # the floor of its libraries (see Floor)
        "floor: Pinocchio + OSQP calls of that tick": ("floor", Floor(robot, spheres[1])),
        "qpavoid QP, capsules (persistent OSQP)": ours("qp", "capsules"),
        "qpavoid QP, spheres (daqp)": ours("qp", "spheres", backend="daqp"),
    }
    for solver in ("osqp", "daqp"):
        variants[f"pink + 1 barrier, {solver}"] = ("pink", Pink(robot, solver))
        variants[f"mink + CollisionAvoidanceLimit, {solver}"] = ("mink", Mink(solver))
    crowds = {  # a second phase: their footprint would weigh on the head-to-head's caches
        "qpavoid QP, spheres, 6 people (persistent OSQP)": ours("qp6", "spheres"),
        "qpavoid QP, capsules, 6 people (persistent OSQP)": ours("qp6", "capsules"),
    }
    rows = {}
    for phase in (variants, crowds):
        rows.update(_interleaved(phase, robot, path, motion, q0, args.seconds))
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))


def _interleaved(variants: dict, robot, path, motion, q0, seconds: float) -> dict:
    """Step ``variants`` tick by tick in one loop; print and return their rows."""
    state = {
        name: q0.copy() if kind != "mink" else np.insert(q0, 2, 0.0)
        for name, (kind, _) in variants.items()
    }
    times: dict[str, list[float]] = {name: [] for name in variants}
    clock = dict.fromkeys(variants, 0.0)  # each variant's path time, s
    clear: dict[str, list[float]] = {name: [] for name in variants}
    error: dict[str, list[float]] = {name: [] for name in variants}
    robot7 = load_robot("iiwa14", locked=())
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
                cmd = ctrl.step(q, frame if kind == "qp" else crowd, None, tau)
                v, clock[name] = cmd.dq, tau + cmd.time_scale * dt
            else:  # the peers chase the reference of the moment
                v, clock[name] = ctrl.step(q, hand, target), t + dt
            times[name].append((time.perf_counter_ns() - t0) / 1e3)
            state[name] = q + v * dt
            q7 = state[name] if kind == "mink" else np.insert(state[name], 2, 0.0)
            clear[name].append(_clearance7(robot7, q7, hand))
            ref = path.reference(clock[name])[0][:3, 3]
            error[name].append(float(np.linalg.norm(robot7.end_effector(q7)[:3, 3] - ref)))
        for name, floor in floors.items():  # after every variant: outside any timing
            floor.take(stepped_at[source[name]])
        rng.shuffle(order)
    rows = {}
    print(f"\n{int(seconds * RATE_HZ)} ticks at {RATE_HZ:.0f} Hz, variants interleaved\n")
    print(
        f"{'variant':48s} {'median µs':>10s} {'p99 µs':>8s} {'clearance m':>12s} "
        f"{'path mm':>8s} {'behind s':>8s}"
    )
    for name in variants:
        tt = np.array(times[name][10:])
        rows[name] = {"median_us": float(np.median(tt)), "p99_us": float(np.percentile(tt, 99))}
        if not clear[name]:  # the floor: a time, no motion of its own
            print(f"{name:48s} {rows[name]['median_us']:10.0f} {rows[name]['p99_us']:8.0f}")
            continue
        rows[name] |= {
            "min_clearance_m": float(np.min(clear[name])),
            "max_path_error_mm": float(np.max(error[name]) * 1e3),
            "path_time_behind_s": float(seconds - clock[name]),
        }
        r = rows[name]
        print(
            f"{name:48s} {r['median_us']:10.0f} {r['p99_us']:8.0f} "
            f"{r['min_clearance_m']:12.3f} {r['max_path_error_mm']:8.1f} "
            f"{r['path_time_behind_s']:8.2f}"
        )
    return rows


def _clearance7(robot7, q7: np.ndarray, hand: np.ndarray) -> float:
    """The hand's clearance from the arm's capsules (qpavoid's 7-joint model), m."""
    seg = robot7.capsules(q7)
    radii = [s.capsule_radius_m for s in robot7.sets]
    return float(
        min(
            point_segment_distance(hand, a, b) - r - HAND_RADIUS_M
            for (a, b), r in zip(seg, radii, strict=True)
        )
    )


if __name__ == "__main__":
    main()
