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

:meth:`TrueClearance.contacts` judges each tick in true contact for power and force
limiting (ISO/TS 15066 Annex A): per robot set × body part pair in contact, the part's body
region, the robot point's true speed towards it (the arm's real joint velocity through the
point's Jacobian, along the normal from the part's axis to the point), the region's
transient speed limit at that point (the arm's true effective mass there, eq. A.5,
:mod:`qpavoid.laws.pfl`) and the force that speed would transfer.
"""

from __future__ import annotations

from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

from qpavoid.arm.inertia import EffectiveMass
from qpavoid.arm.meshes import collision_geometry, object_vertices
from qpavoid.arm.model import Kinematics, Robot
from qpavoid.core.errors import RobotDescriptionError
from qpavoid.core.geometry import unit
from qpavoid.distance.coal_capsules import CoalCapsuleDistance, axis_rotation
from qpavoid.human.body import BodyModel, HumanGeometry, KinectHuman
from qpavoid.human.frames import HumanFrame, HumanMotion
from qpavoid.laws.pfl import (
    PFLConfig,
    clampable,
    compression_allowance_m,
    contact_force_n,
    transient_speed_limit_mps,
)
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
            tf = self._placement(obj)
            for _, shape, tf_h in person:
                self.result.clear()
                d = coal.distance(obj.geometry, tf, shape, tf_h, self.request, self.result)
                distance[k] = min(distance[k], d)
        per_set = np.where(self.on_set, distance[None, :], np.inf).min(axis=1)
        return np.where(near, per_set, capsule)

    def pairs(
        self, q: np.ndarray, sets: np.ndarray, geo: HumanGeometry
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Each of ``sets``' true distance to each usable part, from its objects.

        Returns
        -------
        distance
            (len(sets), K) m (+inf for a part not usable).
        robot_point
            (len(sets), K, 3) the objects' witness point, base frame, m (NaN where +inf).
        joint
            (len(sets), K) the Pinocchio joint carrying that point (-1 where +inf).
        normal
            (len(sets), K, 3) the unit direction from the part to the object, coal's (also
            under penetration), NaN where +inf.
        """
        n_parts = len(self.radii)
        distance = np.full((len(sets), n_parts), np.inf)
        point = np.full((len(sets), n_parts, 3), np.nan)
        normal = np.full((len(sets), n_parts, 3), np.nan)
        joint = np.full((len(sets), n_parts), -1)
        pin.forwardKinematics(self.robot.model, self.data, q)
        person = self._person(geo)
        for i, s in enumerate(sets):
            for k in np.flatnonzero(self.on_set[s]):
                obj = self.objects[k]
                tf = self._placement(obj)
                for part, shape, tf_h in person:
                    self.result.clear()
                    d = coal.distance(obj.geometry, tf, shape, tf_h, self.request, self.result)
                    if d < distance[i, part]:
                        distance[i, part], joint[i, part] = d, obj.parentJoint
                        point[i, part] = self.result.getNearestPoint1()
                        normal[i, part] = -np.asarray(self.result.normal)  # (robot → part)
        return distance, point, joint, normal

    def _placement(self, obj: pin.GeometryObject) -> coal.Transform3s:
        """Where ``obj`` is at the joint placements last computed."""
        placement = self.data.oMi[obj.parentJoint] * obj.placement
        return coal.Transform3s(placement.rotation, placement.translation)

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

    def _person(self, geo: HumanGeometry) -> list[tuple[int, coal.Capsule, coal.Transform3s]]:
        """The person's usable parts (index, coal capsule, placement), radii widened by the
        fingers' reach (and the part margin, zero for the truth)."""
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
            out.append((int(k), shape, tf))
        return out


#: A robot point approaching a clamped part no faster than this is not pushing it, m/s
#: (1 mm/s: the residue of a braking ramp's other joints along the normal).
CREEP_MPS = 0.001
#: How much more than its allowance a robot may advance into a part over a contact, m
#: (0.5 mm: the integration of the approach speed tick by tick, not a motion).
ADVANCE_TOLERANCE_M = 0.0005


def _axis_point(segment: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The point of the axis ``segment`` (2, 3) closest to ``p`` (m): where on the part a
    contact at the robot's point ``p`` is, also when ``p`` lies inside the part."""
    a, b = segment
    axis = b - a
    u = float(np.clip((p - a) @ axis / max(float(axis @ axis), 1e-300), 0.0, 1.0))
    return a + u * axis


@dataclass(frozen=True)
class TrueContact:
    """One robot set touching one body part at one tick, judged against the truth.

    Attributes
    ----------
    person
        Who: the person's stable id in a crowd (:class:`~qpavoid.human.people.People`),
        0 for the only one.
    set_name, part
        The pair.
    region
        The part's Annex A body region (:mod:`qpavoid.laws.pfl`; None if the body model
        names none).
    permitted
        The region permits transient contact (arms, hands); False for the head, face, neck
        and trunk.
    clamped
        The part could be pinned against the fixed surface at this contact
        (:func:`~qpavoid.laws.pfl.clampable`): quasi-static, its limit 0 (no approach).
    distance_m
        The true distance (≤ 0: touching or penetrating), m.
    approach_mps
        The robot point's true velocity towards the part, m/s (negative: moving away).
    limit_mps
        The region's transient contact speed at that point (eq. A.5, the arm's effective
        mass there along the normal), m/s; 0 for a clamped part; NaN if the arm has no
        inertias.
    allowance_m
        How far the robot may advance into a part that could not recoil before the force
        reaches F_T, δ = F_T / k (:func:`~qpavoid.laws.pfl.compression_allowance_m`), m; 0
        for a clamped part and a region that permits no contact.
    spring_n_per_m
        The region's k, N/m (NaN without a region).
    force_n
        The force the contact's speed transfers (:func:`~qpavoid.laws.pfl.contact_force_n`;
        a clamped part cannot recoil: μ = m_R), N.
    """

    person: int
    set_name: str
    part: str
    region: str | None
    permitted: bool
    clamped: bool
    distance_m: float
    approach_mps: float
    limit_mps: float
    allowance_m: float
    spring_n_per_m: float
    force_n: float

    @property
    def speed_mps(self) -> float:
        """The robot point's speed towards the part (≥ 0: 0 when moving away), m/s."""
        return max(self.approach_mps, 0.0)

    def within_limit(self, advance_m: float = 0.0) -> bool:
        """A permitted region touched no faster than its transient limit; a clamped one
        (pinned: quasi-static) neither approached faster than :data:`CREEP_MPS` nor
        advanced into since the contact began (``advance_m``, m, within
        :data:`ADVANCE_TOLERANCE_M`); False if unknown."""
        if not self.permitted or not self.speed_mps <= max(self.limit_mps, CREEP_MPS):
            return False
        return not self.clamped or advance_m <= ADVANCE_TOLERANCE_M

    def pushed(self, advance_m: float) -> bool:
        """The robot advanced ``advance_m`` (m) into a free part, further than its allowance
        δ (and :data:`ADVANCE_TOLERANCE_M`): it pushed the part along, which a free part
        bears as a transient contact (it recoils) but a pinned one would not."""
        return (
            self.permitted
            and not self.clamped
            and advance_m > self.allowance_m + ADVANCE_TOLERANCE_M
        )


def truth_body(human: BodyModel) -> BodyModel:
    """The body the truth is judged with: the controller's ``human`` where it is on the
    body's landmarks (the true motion's skeleton, the Kinect v2's), else the paper's model
    on them (:class:`~qpavoid.human.body.KinectHuman`): a controller on a camera's own
    joints is judged against the true body, not against its own model of it."""
    true_motion = KinectHuman()
    return human if human.skeleton.name == true_motion.skeleton.name else true_motion


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
    pfl
        The payload and the regions' limits the contacts are judged with (default:
        :class:`~qpavoid.laws.pfl.PFLConfig`'s).
    """

    def __init__(
        self, robot: Robot, human: BodyModel, motion: HumanMotion, pfl: PFLConfig | None = None
    ):
        self.robot, self.human, self.motion = robot, human, motion
        self.capsules = CoalCapsuleDistance(robot, human)  # coal's: the judge
        self.meshes = MeshClearance(robot, human)
        self.n_sets = len(robot.sets)
        self.t0 = float(np.asarray(getattr(motion, "t", [0.0]))[0])
        cfg = pfl or PFLConfig()
        try:  # an arm without inertias is judged on its speeds alone (limits NaN)
            self.mass: EffectiveMass | None = EffectiveMass(robot, cfg.payload_kg)
        except RobotDescriptionError:
            self.mass = None
        contact, force, spring, mass = cfg.part_limits(human.regions)
        self.permitted = np.asarray(contact, dtype=bool)
        self.force_n, self.spring_npm = np.asarray(force), np.asarray(spring)
        self.human_kg = np.asarray(mass)
        self.surface_z_m, self.clamp_gap_m = cfg.surface_z_m, cfg.clamp_gap_m

    def __call__(self, kin: Kinematics, t: float) -> np.ndarray:
        """(S,) the smallest true distance of each robot set at run time ``t``, m."""
        geos = self._geometries(t)
        per_person = [self._one(kin, g) for g in geos]
        return np.min(per_person, axis=0) if per_person else np.full(self.n_sets, np.inf)

    def _geometries(self, t: float) -> list[HumanGeometry]:
        """The true geometry of everybody present at run time ``t``."""
        return [geo for _, geo in self._people(t)]

    def _people(self, t: float) -> list[tuple[int, HumanGeometry]]:
        """Everybody present at run time ``t``: their stable id (0: the only person) and
        true geometry."""
        if isinstance(self.motion, Crowd):
            people = self.motion.true_frames(t, true_frame)
            return [
                (i, self.human.geometry(f)) for i, f in zip(people.ids, people.frames, strict=True)
            ]
        return [(0, self.human.geometry(true_frame(self.motion, self.t0 + t)))]

    def _one(self, kin: Kinematics, geometry: HumanGeometry) -> np.ndarray:
        """(S,) one person's true distance per set, m."""
        return self.meshes(kin.q, self.capsules(kin, geometry).min_per_set(), geometry)

    def contacts(
        self, q: np.ndarray, dq: np.ndarray, t: float, dq_before: np.ndarray | None = None
    ) -> list[TrueContact]:
        """Every set × part pair truly in contact at run time ``t`` (module docstring),
        with the arm at ``q`` moving at ``dq`` (rad/s, its real joint velocity); with
        ``dq_before``, the tick before's, each pair's approach is the faster of the two (the
        velocity that made the contact and the one after it)."""
        kin = self.robot.kinematics(q)
        out: list[TrueContact] = []
        for person, geo in self._people(t):
            table = self.capsules(kin, geo)
            distance, point = table.distance.copy(), table.robot_point.copy()
            normal = table.vector.copy()  # coal's, from the part to the robot
            joint = np.full(distance.shape, -1)  # -1: the capsule's point
            if self.meshes.has_mesh:
                near = (
                    table.min_per_set() - self.meshes.excess <= self.meshes.margin_m
                ) & self.meshes.on_set.any(axis=1)
                sets = np.flatnonzero(near)
                if len(sets):
                    found = self.meshes.pairs(q, sets, geo)
                    distance[sets], point[sets], joint[sets], normal[sets] = found
            for s, k in zip(*np.nonzero(distance <= 0.0), strict=True):
                if joint[s, k] < 0:
                    jac = kin.segment_point_jacobian(int(s), float(table.robot_s[s, k]))
                else:
                    jac = self._point_jacobian(q, int(joint[s, k]), point[s, k])
                velocities = (dq,) if dq_before is None else (dq, dq_before)
                approach = max(-float(normal[s, k] @ (jac @ v)) for v in velocities)
                axis_point = _axis_point(geo.segments[k], point[s, k])
                out.append(
                    self._contact(
                        q,
                        person,
                        int(s),
                        int(k),
                        distance[s, k],
                        approach,
                        normal[s, k],
                        jac,
                        geo,
                        axis_point,
                    )
                )
        return out

    def _point_jacobian(self, q: np.ndarray, joint: int, p: np.ndarray) -> np.ndarray:
        """(3, nv) the Jacobian of the point ``p`` (base frame, m) fixed to ``joint``:
        ``v_p = v_o + ω × (p − o)`` from Pinocchio's joint Jacobian (world-aligned)."""
        model, data = self.robot.model, self.meshes.data
        pin.computeJointJacobians(model, data, q)
        j6 = pin.getJointJacobian(model, data, joint, pin.LOCAL_WORLD_ALIGNED)
        return j6[:3] - pin.skew(p - data.oMi[joint].translation) @ j6[3:]

    def _contact(
        self,
        q: np.ndarray,
        person: int,
        s: int,
        k: int,
        distance: float,
        approach: float,
        normal: np.ndarray,
        jac: np.ndarray,
        geo: HumanGeometry,
        axis_point: np.ndarray,
    ) -> TrueContact:
        """The pair (set ``s``, part ``k`` of ``person``) touching along ``normal`` (unit,
        from the part to the arm: coal's, right under penetration too) at ``axis_point`` of
        the part's axis, the robot point (Jacobian ``jac``) approaching at ``approach``
        (m/s)."""
        n = unit(normal, np.array([0.0, 0.0, 1.0]))
        speed = max(0.0, approach)
        m_robot = float(self.mass(q, jac[None], n[None])[0]) if self.mass is not None else np.nan
        force, spring, m_h = self.force_n[k], self.spring_npm[k], self.human_kg[k]
        radius = self.human.capsule_radii[k] + np.asarray(geo.reach_margin)[k]
        clamped = bool(
            clampable(
                axis_point + radius * n,
                n,
                radius,
                self.surface_z_m,
                self.clamp_gap_m,
            )
        )
        limit = float(transient_speed_limit_mps(force, spring, m_h, m_robot))
        permitted = bool(self.permitted[k])
        return TrueContact(
            person,
            self.robot.set_names[s],
            self.human.part_names[k],
            self.human.regions[k],
            permitted,
            clamped,
            float(distance),
            approach,
            0.0 if clamped and np.isfinite(limit) else limit,
            float(compression_allowance_m(force, spring)) if permitted and not clamped else 0.0,
            float(spring),
            float(contact_force_n(speed, spring, m_h, m_robot, pinned=clamped)),
        )
