"""Where the person really is: the yardstick every clearance is measured against.

The controller sees camera frames (sample and hold, possibly old); safety is judged
against the person's true position at each control tick. For a generated motion the
truth is the motion itself, sampled at the tick's time. For a recording it is the best
estimate between its frames: each joint interpolated linearly between the frames before
and after the tick (held after the last frame), so a fast strike between two 30 Hz frames
is not missed.

:class:`TrueClearance` measures, at each tick, the distance between every robot set and the
true person, whatever distance method the controller uses: against the arm's real geometry
where its URDF has collision meshes (:class:`MeshClearance`: coal, the person's capsules
against the meshes and shapes of the links each set covers), otherwise the exact capsule
distance (coal) of the set's capsule.
"""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin

from qpavoid.arm.meshes import collision_geometry, object_vertices
from qpavoid.arm.model import Kinematics, Robot
from qpavoid.distance.capsules import CapsuleDistance, axis_rotation
from qpavoid.human.body import BodyModel, HumanGeometry
from qpavoid.human.frames import HumanFrame, HumanMotion
from qpavoid.loop.crowd import Crowd
from qpavoid.sensing.recording import Recording


def true_frame(motion: HumanMotion, t: float) -> HumanFrame:
    """The person's true frame at time ``t`` on the motion's own clock.

    Recordings: joints interpolated linearly between the frames around ``t`` (a joint
    unusable in either frame takes the earlier frame's value and state); other motions:
    ``motion.frame_at(t)``.
    """
    if not isinstance(motion, Recording):
        assert not isinstance(motion, Crowd), "a crowd's people are sampled one by one"
        frame = motion.frame_at(t)
        return frame if isinstance(frame, HumanFrame) else HumanFrame.check(*frame)
    i = motion.index_at(t)
    if i + 1 >= motion.n_frames:
        return HumanFrame(motion.joints[i].copy(), motion.state[i].copy())
    t0, t1 = float(motion.t[i]), float(motion.t[i + 1])
    w = (t - t0) / (t1 - t0)
    a, b = motion.joints[i], motion.joints[i + 1]
    both = np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
    joints = np.where(both[:, None], (1.0 - w) * a + w * b, a)
    return HumanFrame(joints, motion.state[i].copy())


#: Below this lower bound of some set's objects' distance (m), :class:`MeshClearance`
#: measures the meshes; above it, the capsule distance (less how far the set's objects
#: stick out of its capsule: nothing, where the coverage check holds) is a lower bound of
#: the clearance and no contact is possible. 0.1 m: a hand at 2 m/s crosses it in 50 ms, five
#: ticks at 100 Hz, so the meshes are measured well before any contact.
MESH_MARGIN_M = 0.1


class MeshClearance:
    """The person's distance to the arm's real geometry: its URDF's collision objects.

    Each set stands for the collision objects on the body that carries its capsule (the
    fitted descriptions give a set per link); a set with none keeps its capsule distance.
    Objects on no set's body (the fixed base, which never moves towards anybody) are not
    judged. Each object's distance is coal's, between the object (mesh or shape, at the
    joint placements of ``kin.q``) and every usable capsule of the person, radii as the
    capsule method's (the fingers' reach included).

    Parameters
    ----------
    robot, human
        The arm and the body model.
    margin_m
        :data:`MESH_MARGIN_M`.
    """

    def __init__(self, robot: Robot, human: BodyModel, margin_m: float = MESH_MARGIN_M):
        self.robot, self.margin_m = robot, margin_m
        geometry = collision_geometry(robot)
        bodies = [robot.model.frames[s.capsule_frames[0]].parentJoint for s in robot.sets]
        self.objects = [o for o in geometry.geometryObjects if o.parentJoint in bodies]
        # (S, O): how far object o sticks out of set s's capsule, for the sets on its body
        gaps = np.array(
            [[self._gap(robot, s, o, b) for o in self.objects] for s, b in enumerate(bodies)]
        ).reshape(len(bodies), len(self.objects))
        #: (S, O) True where set s stands for object o: the set on o's body whose capsule
        #: holds it best (a locked joint puts two links, and two sets, on one body)
        self.on_set = np.zeros(gaps.shape, dtype=bool)
        if self.objects:
            self.on_set[np.argmin(gaps, axis=0), np.arange(len(self.objects))] = True
        #: (S,) how far, at most, a set's objects stick out of its capsule, m (0 where the
        #: coverage check holds): the capsule distance minus it bounds theirs from below
        self.excess = np.where(self.on_set, np.maximum(gaps, 0.0), 0.0).max(axis=1, initial=0.0)
        self.has_mesh = any(isinstance(o.geometry, coal.BVHModelBase) for o in self.objects)
        self.radii = human.capsule_radii
        self.data = robot.model.createData()
        self.request, self.result = coal.DistanceRequest(), coal.DistanceResult()

    def __call__(self, q: np.ndarray, capsule: np.ndarray, geo: HumanGeometry) -> np.ndarray:
        """(S,) each set's true distance, m: its objects' where the set's lower bound (its
        ``capsule`` (S,) distance less :attr:`excess`) is under the margin, the capsule's
        (a lower bound of its objects') elsewhere."""
        if not self.has_mesh:
            return capsule
        near = (capsule - self.excess <= self.margin_m) & self.on_set.any(axis=1)
        if not near.any():
            return capsule
        pin.forwardKinematics(self.robot.model, self.data, q)
        person = self._person(geo)
        distance = np.full(len(self.objects), np.inf)
        for k in np.flatnonzero(self.on_set[near].any(axis=0)):
            obj = self.objects[k]
            placement = self.data.oMi[obj.parentJoint] * obj.placement
            tf = coal.Transform3s(placement.rotation, placement.translation)
            for shape, tf_h in person:
                self.result.clear()
                d = coal.distance(obj.geometry, tf, shape, tf_h, self.request, self.result)
                distance[k] = min(distance[k], d)
        per_set = np.where(self.on_set, distance[None, :], np.inf).min(axis=1)
        return np.where(near, per_set, capsule)

    @staticmethod
    def _gap(robot: Robot, s: int, obj: pin.GeometryObject, body: int) -> float:
        """How far ``obj`` sticks out of set ``s``'s capsule at most, m: +inf if the set is
        on another body, or its capsule's ends on two bodies (the gap then changes with
        the configuration)."""
        cs = robot.sets[s]
        ends = [robot.model.frames[f] for f in cs.capsule_frames]
        if obj.parentJoint != body or ends[1].parentJoint != body:
            return np.inf
        a, b = (e.placement.translation for e in ends)  # both in the body's frame
        v = object_vertices(obj)
        t = np.clip((v - a) @ (b - a) / max(float((b - a) @ (b - a)), 1e-300), 0.0, 1.0)
        gap = np.linalg.norm(v - (a + t[:, None] * (b - a)), axis=1) - cs.capsule_radius_m
        return float(gap.max())

    def _person(self, geo: HumanGeometry) -> list[tuple[coal.Capsule, coal.Transform3s]]:
        """The person's usable parts as coal capsules, radii widened by the fingers'
        reach (and the part margin, zero for the truth)."""
        widen = np.zeros(len(self.radii))
        for extra in (geo.part_margin, geo.reach_margin):
            if extra is not None:
                widen = widen + extra
        out = []
        for k in np.flatnonzero(geo.segment_valid):
            a, b = geo.segments[k]
            axis = b - a
            half = 0.5 * float(np.linalg.norm(axis))
            tf = coal.Transform3s()
            tf.setQuatRotation(axis_rotation(axis / max(2.0 * half, 1e-300)))
            tf.setTranslation(0.5 * (a + b))
            shape = coal.Capsule(float(self.radii[k] + widen[k]), 0.0)
            shape.halfLength = half  # (the constructor takes the full length)
            out.append((shape, tf))
        return out


class TrueClearance:
    """The true distance from each robot set to the true person, m (build once).

    Against the arm's collision meshes where its URDF has them (:class:`MeshClearance`),
    else the exact capsule distance.

    Parameters
    ----------
    robot, human
        The arm and the body model.
    motion
        The true motion (a scenario or a recording).
    """

    def __init__(self, robot: Robot, human: BodyModel, motion: HumanMotion):
        self.human, self.motion = human, motion
        self.capsules = CapsuleDistance(robot, human)
        self.meshes = MeshClearance(robot, human)
        self.n_sets = len(robot.sets)
        self.t0 = float(np.asarray(getattr(motion, "t", [0.0]))[0])

    def __call__(self, kin: Kinematics, t: float) -> np.ndarray:
        """(S,) the smallest true distance of each robot set at run time ``t``, m."""
        if isinstance(self.motion, Crowd):  # the nearest of everybody present
            people = self.motion.true_frames(t, true_frame).frames
            per_person = [self._one(kin, self.human.geometry(f)) for f in people]
            return np.min(per_person, axis=0) if per_person else np.full(self.n_sets, np.inf)
        return self._one(kin, self.human.geometry(true_frame(self.motion, self.t0 + t)))

    def _one(self, kin: Kinematics, geometry: HumanGeometry) -> np.ndarray:
        """(S,) one person's true distance per set, m."""
        return self.meshes(kin.q, self.capsules(kin, geometry).min_per_set(), geometry)
