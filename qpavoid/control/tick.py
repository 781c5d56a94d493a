"""What flows through one control tick: the shared settings, the measurements, the command.

:class:`ControllerConfig` holds what every controller shares; :class:`Tick` is what the
shared prelude measured (:meth:`~qpavoid.control.controller.Controller.measure`) and each
controller's own part reads; :class:`Command` is what a tick returns.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from qpavoid.arm.model import Kinematics
from qpavoid.arm.roles import Roles
from qpavoid.core.errors import InputError
from qpavoid.distance.methods import DistanceTable
from qpavoid.human.body import HumanGeometry
from qpavoid.human.frames import HumanFrame
from qpavoid.laws.avoidance import AvoidanceConfig
from qpavoid.laws.pfl import PFLConfig
from qpavoid.laws.ssm import SSMConfig, hold_distance
from qpavoid.perception.tracker import Perceived, PerceptionConfig

#: What ``ControllerConfig.safety`` may be: the paper's rules as written, speed and
#: separation monitoring on top of them, or power and force limiting beside it.
SAFETY_MODES = ("paper", "ssm", "pfl")


@dataclass(frozen=True)
class ControllerConfig:
    """Settings shared by the controllers.

    Attributes
    ----------
    distance
        Distance method: ``"capsules"`` (exact, one compiled pass; the default, because it
        covers every robot surface a person can reach, the shoulder included),
        ``"capsules-coal"`` (the same table by coal, its judge) or ``"spheres"`` (the
        paper's eq. 1 as published: blind at the shoulder, docs/distances.md).
    avoidance
        Constants of the avoidance laws (eqs. 2-7) and the stop rules.
    gain_position, gain_orientation
        Diagonal of K in eq. (8) for the position and orientation error, 1/s.
    sigma_min, lambda_max
        Damped inverse of eqs. (6) and (8): no damping while the smallest singular value
        is above ``sigma_min``; damping up to ``lambda_max`` at a singularity.
    control_period_s
        Period of the control loop, s: a command that would carry a joint past its
        position limit within one period stops the robot instead.
    compute_budget_s
        In a real-time loop, the longest a tick may take from reading the arm's state to
        sending its command, s (the loop's deadline: a later command is replaced by a
        braking step); speed and separation counts it in its reaction time. 0 (the
        default): offline, where computing takes no simulated time.
    scaled_joints
        Joints whose limits eq. (3) scales by (1 − f); None (the default): the robot
        description's, the joints that move its scaled set (``Roles.scaled_joints``).
    require_human
        Stop when no body part is tracked at all (the safe reading of "nobody seen").
    max_frame_age_s
        Stop when the human frame is older than this, s (default 0.1 s: the Kinect v2
        latency and one frame period, with 6 ms to spare).
    safety
        ``"paper"``: the paper's laws and stop rules as written; ``"ssm"``: speed and
        separation monitoring on top of them (:mod:`qpavoid.laws.ssm`): each robot point's
        approach speed towards each body part bounded so that it can be stationary before
        the person arrives, joint speeds kept within the stopping-time budget, and (QP)
        the velocity damper reduced by the part's own approach speed; ``"pfl"``: power
        and force limiting beside it (:mod:`qpavoid.control.contact`): speed and
        separation for the parts whose Annex A region permits no contact (head, trunk),
        and for the arms and hands a transient contact at up to their region's speed
        limit; the paper's stop rules then hold for the head and trunk only.
    ssm
        Constants of speed and separation monitoring (used with ``safety="ssm"`` and
        ``"pfl"``).
    pfl
        The payload and the body regions' limits (used with ``safety="pfl"``).
    perception
        How frames are judged: lost and inferred joints, frozen frames, the person's
        velocity (:mod:`qpavoid.perception.tracker`).
    smooth
        Commands a real arm accepts (:mod:`qpavoid.control.smoothing`; the default): each
        command within the arm's acceleration (and jerk) limits of the last, starting from
        rest, with room to brake before a joint limit, and a stop commanded as a braking
        ramp (category 2). False: the paper's commands as published, where a stop is a
        step to zero; a real arm faults on them (for checking the laws tick by tick).
    """

    distance: str = "capsules"
    avoidance: AvoidanceConfig = field(default_factory=AvoidanceConfig)
    gain_position: float = 5.0
    gain_orientation: float = 5.0
    sigma_min: float = 0.02
    lambda_max: float = 0.05
    control_period_s: float = 0.002
    compute_budget_s: float = 0.0
    scaled_joints: tuple[str, ...] | None = None
    require_human: bool = True
    max_frame_age_s: float = 0.1
    safety: str = "paper"
    ssm: SSMConfig = field(default_factory=SSMConfig)
    pfl: PFLConfig = field(default_factory=PFLConfig)
    perception: PerceptionConfig = field(default_factory=PerceptionConfig)
    smooth: bool = True

    def __post_init__(self) -> None:
        if self.safety not in SAFETY_MODES:
            raise InputError(
                f"safety must be one of {SAFETY_MODES}, got {self.safety!r}",
                name="safety",
                value=self.safety,
            )

    @property
    def monitors_separation(self) -> bool:
        """True if speed and separation bounds the approach speeds (``"ssm"``, ``"pfl"``)."""
        return self.safety != "paper"


@dataclass(frozen=True)
class Command:
    """One tick's output.

    Attributes
    ----------
    dq
        (nv,) commanded joint velocities, rad/s. While stopped: the braking ramp, exactly
        zero once at rest (at once with ``ControllerConfig.smooth=False``).
    stopped
        True if a stop rule (or the last-resort layer) holds: the arm brakes to rest.
    reason
        Why the robot stops ("" while it moves).
    time_scale
        Rate in [0, 1] at which the path clock should advance (0 when stopped).
    f
        The factor of eq. (2), from the scaled set's distance.
    distance
        (S,) minimum distance per robot set (in the description's order), m, of the method
        in use.
    table
        The full distance table.
    v_repelled, v_end_effector
        (3,) repulsive velocities of the repelled set (eq. 5) and of the end effector
        (eq. 7), m/s.
    limits
        (nv,) joint velocity limits in force this tick (eq. 3), rad/s.
    ee_pos, ee_ref
        (3,) end-effector position and its reference, m.
    info
        Controller-specific extras (e.g. solver status and iterations).
    """

    dq: np.ndarray
    stopped: bool
    reason: str
    time_scale: float
    f: float
    distance: np.ndarray
    table: DistanceTable
    v_repelled: np.ndarray
    v_end_effector: np.ndarray
    limits: np.ndarray
    ee_pos: np.ndarray
    ee_ref: np.ndarray
    info: dict = field(default_factory=dict)


@dataclass(kw_only=True)
class Tick:
    """One tick's measurements (:meth:`Controller.measure`), given to :meth:`Controller.act`:
    built by keyword from the records of the tick's stages (:mod:`qpavoid.control.stages`).

    The state every piece of the QP reads, as mink's ``Configuration``: the robot sets are
    rows of the distance table, found by the part they play (``roles``), never by name.

    Attributes
    ----------
    q
        (nq,) joint angles, rad.
    kin
        Kinematics at ``q`` (points, Jacobians, end-effector placement).
    frame, human
        The human frame as given, and the geometry of what the tracker made of it.
    perceived
        The tracker's view of the frame (filled-in lost joints, uncertainties, velocities).
    frame_age_s
        Age of the newest frame the tracker accepted, s.
    table
        The distance table (sets × parts) of the configured method.
    distance
        (S,) minimum distance per set, m.
    f
        The factor of eq. (2), from the scaled set's distance.
    limits
        (nv,) joint velocity limits of eq. (3), rad/s.
    roles
        Which row of ``table`` plays which part (the robot description's).
    repelled_part
        Column of the human part closest to the repelled set.
    v_repelled, v_end_effector
        (3,) repulsive velocities of the repelled set (eqs. 4-5) and of the end effector
        (eq. 7), m/s.
    ref_pose, ref_twist
        The planned end-effector pose (4, 4) and twist (6,) at the path time.
    error
        (6,) pose error e of eq. (8).
    task_twist
        (6,) ``v_PL + K e``: eq. (8)'s target without the EE repulsion.
    approach_limit
        (S, K) speed and separation bound on each pair's robot approach speed, m/s
        (:func:`~qpavoid.laws.ssm.max_approach_speed`; +inf with ``safety="paper"``; with
        ``"pfl"`` the larger of it and ``contact_limit``).
    human_approach
        (S, K) each part's own speed towards each set, m/s (≥ 0; 0 with ``"paper"``).
    reason
        Why a stop rule holds ("" if none).
    contact_limit
        (S, K) each pair's permitted contact speed with ``safety="pfl"``, m/s
        (:class:`~qpavoid.control.contact.ContactLimits`: −inf where no contact is
        permitted), or None.
    command_box
        ``(lo, hi)`` (nv,) each the reachable box of this tick's command, rad/s
        (:meth:`~qpavoid.control.smoothing.CommandRamp.box`), or None (``smooth=False``).
    """

    q: np.ndarray
    kin: Kinematics
    frame: HumanFrame
    human: HumanGeometry
    table: DistanceTable
    distance: np.ndarray
    f: float
    limits: np.ndarray
    roles: Roles
    repelled_part: int
    v_repelled: np.ndarray
    v_end_effector: np.ndarray
    ref_pose: np.ndarray
    ref_twist: np.ndarray
    error: np.ndarray
    task_twist: np.ndarray
    reason: str
    perceived: Perceived
    frame_age_s: float
    approach_limit: np.ndarray
    human_approach: np.ndarray
    command_box: tuple[np.ndarray, np.ndarray] | None = None
    contact_limit: np.ndarray | None = None
    ssm: SSMConfig | None = None

    def separation_reason(self) -> str:
        """Why speed and separation monitoring holds the robot, in the operator's words:
        the tightest pair, its clearance and the clearance a robot at rest needs there
        (the protective distance at v_r = 0, :func:`~qpavoid.laws.ssm.hold_distance`),
        e.g. "speed and separation: person's head 0.300 m from robot link 'hand', needs
        0.340 m: holding"."""
        table = self.table
        i, j = np.unravel_index(int(np.argmin(self.approach_limit)), table.distance.shape)
        d = float(table.distance[i, j])
        needs = ""
        if self.ssm is not None:
            part = table.part_names[j]
            need = hold_distance(d, self.frame_age_s, self.ssm, part in self.ssm.body_parts)
            needs = f", needs {need:.3f} m" if np.isfinite(need) else ", its frame's age unknown"
        return (
            f"speed and separation: person's {table.part_names[j]} {d:.3f} m from robot "
            f"link {table.set_names[i]!r}{needs}: holding"
        )
