"""The planned end-effector path (paper Sect. 3): arcs and lines with a quintic time law.

The paper gives the initial and final poses but not the curve. :class:`ArcPath` is a
circular arc through both positions in the vertical plane that contains them (y = 0.6105
for the paper's poses), bulging upwards by ``sagitta_m`` at its middle, traversed with
the quintic time law ``σ(τ) = 10τ³ − 15τ⁴ + 6τ⁵``, ``τ = t / T``: zero velocity and
acceleration at both ends. The orientation is the common orientation of both poses (or,
with ``turn``, turns from one to the other about a fixed axis). :class:`WaypointPath`
joins several such segments (a task file's waypoints, :mod:`qpavoid.control.task`).

The start configuration of a run is the inverse kinematics of the initial pose
(:func:`qpavoid.arm.ik.inverse_kinematics`, from the description's seed).
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np
import pinocchio as pin

from qpavoid.core.checks import as_array, finite_number
from qpavoid.core.errors import InputError
from qpavoid.core.geometry import orthonormalize, unit

#: The paper's initial and final end-effector poses (Sect. 3), base frame, m.
A_IN = np.array(
    [
        [0.25, -0.866, 0.433, 0.3524],
        [0.433, 0.5, 0.75, 0.6105],
        [-0.866, 0.0, 0.5, 0.5779],
        [0.0, 0.0, 0.0, 1.0],
    ]
)
A_FIN = np.array(
    [
        [0.25, -0.866, 0.433, -0.0476],
        [0.433, 0.5, 0.75, 0.6105],
        [-0.866, 0.0, 0.5, 0.6779],
        [0.0, 0.0, 0.0, 1.0],
    ]
)


def quintic(tau: float) -> tuple[float, float]:
    """Time law σ(τ) = 10τ³ − 15τ⁴ + 6τ⁵ and dσ/dτ, τ clipped to [0, 1].

    The quintic polynomial from 0 to 1 with zero velocity and acceleration at both ends:
    the minimum-jerk profile of Flash and Hogan, "The coordination of arm movements",
    J. Neurosci. 5(7), 1985. The planned path (:class:`ArcPath`) and the scripted hand
    reaches (:mod:`qpavoid.scenarios.generated`) both move with it.
    """
    t = min(max(tau, 0.0), 1.0)
    return t**3 * (10 - 15 * t + 6 * t * t), 30 * t * t * (1 - t) ** 2


def smoothstep(x: float) -> float:
    """σ(x) of :func:`quintic` alone: 0 → 1 on [0, 1], zero velocity and acceleration at
    both ends."""
    return quintic(x)[0]


@dataclass(frozen=True)
class ArcPath:
    """Circular-arc end-effector path with a quintic time law.

    Parameters
    ----------
    start, goal
        (4, 4) initial and final poses (their rotations taken as the nearest rotation
        matrices, :func:`orthonormalize`).
    duration_s
        Time to travel the path (paper: 15 s).
    sagitta_m
        Height of the arc above the chord at its middle, in the vertical plane through the
        chord (0 gives a straight line).
    turn
        False (the paper's: both its poses have one orientation): the start's orientation
        is held and the goal's ignored. True: the orientation turns from the start's
        ``R₀`` to the goal's ``R₁`` about one fixed axis with the same time law,
        ``R(σ) = R₀ exp(σ [w]×)``, ``w = log₃(R₀ᵀ R₁)``, at the angular velocity (base
        frame) ``ω = R₀ w dσ/dt`` (``R(σ) w = R₀ w``, as ``exp(σ [w]×) w = w``).
    """

    start: np.ndarray = field(default_factory=lambda: A_IN.copy())
    goal: np.ndarray = field(default_factory=lambda: A_FIN.copy())
    duration_s: float = 15.0
    sagitta_m: float = 0.08
    turn: bool = False
    _geom: dict[str, Any] = field(init=False, repr=False)
    _rotation: np.ndarray = field(init=False, repr=False)
    _pose: np.ndarray = field(init=False, repr=False)
    _turn: np.ndarray | None = field(init=False, repr=False)

    def __post_init__(self) -> None:
        finite_number(self.duration_s, "duration_s", positive=True)
        finite_number(self.sagitta_m, "sagitta_m")
        start = as_array(self.start, (4, 4), "start (pose)")
        p0 = start[:3, 3]
        p1 = as_array(self.goal, (4, 4), "goal (pose)")[:3, 3]
        chord = p1 - p0
        L = np.linalg.norm(chord)
        up = np.array([0.0, 0.0, 1.0])
        n = up - (up @ chord) / max(L * L, 1e-18) * chord  # in-plane normal, upwards
        if np.linalg.norm(n) < 1e-9 or L < 1e-9 or self.sagitta_m <= 0:
            geom = dict(kind="line", p0=p0, chord=chord)
        else:
            n = unit(n)
            s = self.sagitta_m
            R = (L * L / 4 + s * s) / (2 * s)
            centre = 0.5 * (p0 + p1) + (s - R) * n
            axis = unit(np.cross(p0 - centre, p1 - centre))
            angle = 2 * np.arcsin(min(L / (2 * R), 1.0))
            if s > R:  # more than a half circle
                angle = 2 * np.pi - angle
            e1 = (p0 - centre) / R
            geom = dict(
                kind="arc", centre=centre, radius=R, angle=angle, e1=e1, e2=np.cross(axis, e1)
            )
        object.__setattr__(self, "_geom", geom)
        object.__setattr__(self, "_rotation", orthonormalize(start[:3, :3]))
        turn = None
        if self.turn:
            goal_rotation = orthonormalize(as_array(self.goal, (4, 4), "goal (pose)")[:3, :3])
            turn = pin.log3(self._rotation.T @ goal_rotation)
        object.__setattr__(self, "_turn", turn)
        pose = np.eye(4)
        pose[:3, :3] = self._rotation
        object.__setattr__(self, "_pose", pose)

    @property
    def rotation(self) -> np.ndarray:
        """(3, 3) the start's end-effector orientation (held throughout unless ``turn``)."""
        return self._rotation

    def position(self, sigma: float) -> tuple[np.ndarray, np.ndarray]:
        """Point of the path at arc parameter σ in [0, 1] and its derivative dp/dσ."""
        g = self._geom
        if g["kind"] == "line":
            return g["p0"] + sigma * g["chord"], g["chord"].copy()
        phi = g["angle"] * sigma
        c, s = math.cos(phi), math.sin(phi)
        R, e1, e2 = g["radius"], g["e1"], g["e2"]
        return g["centre"] + R * (c * e1 + s * e2), (R * g["angle"]) * (c * e2 - s * e1)

    def reference(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Desired pose (4, 4) and twist (6,) ``[v; ω]`` (m/s, rad/s) at path time ``t`` (s).

        Before 0 the path waits at its start, after ``duration_s`` at its goal.
        """
        sigma, dsigma = quintic(t / self.duration_s)
        p, dp = self.position(sigma)
        T = self._pose.copy()
        T[:3, 3] = p
        twist = np.zeros(6)
        twist[:3] = dp * (dsigma / self.duration_s)
        if self._turn is not None:
            T[:3, :3] = self._rotation @ pin.exp3(sigma * self._turn)
            twist[3:] = self._rotation @ self._turn * (dsigma / self.duration_s)
        return T, twist

    def length_m(self, n: int = 2001) -> float:
        """Length of the path, m."""
        pts = np.array([self.position(s)[0] for s in np.linspace(0, 1, n)])
        return float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))


def pose_error(T_desired: np.ndarray, T: np.ndarray) -> np.ndarray:
    """(6,) error ``[p_d − p; log3(R_d Rᵀ)]``, both parts in the base frame (m, rad)."""
    e = np.empty(6)
    e[:3] = T_desired[:3, 3] - T[:3, 3]
    e[3:] = pin.log3(T_desired[:3, :3] @ T[:3, :3].T)
    return e


@runtime_checkable
class PlannedPath(Protocol):
    """What a controller and a run need of a planned path (:class:`ArcPath`,
    :class:`WaypointPath`): the reference at a path time, its length in time, its start."""

    @property
    def duration_s(self) -> float:
        """Time to travel the path, s."""
        ...

    @property
    def start(self) -> np.ndarray:
        """(4, 4) the first pose, as given."""
        ...

    def reference(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Desired pose (4, 4) and twist (6,) ``[v; ω]`` at path time ``t`` (s)."""
        ...


@dataclass(frozen=True)
class WaypointPath:
    """Poses joined one after the other by segments, each with its own quintic time law.

    Segment ``k`` runs from ``T_k = Σ_{i<k} d_i`` to ``T_k + d_k`` (``d_k`` its
    ``duration_s``) and is followed at ``τ = t − T_k``; the end effector stops (zero
    velocity and acceleration) at every waypoint. Before 0 the path waits at its start,
    after :attr:`duration_s` at its goal. A path of one segment is that segment exactly,
    bit for bit (``t − 0.0 = t``).

    Parameters
    ----------
    segments
        The segments in order (:class:`ArcPath`), each starting where the one before ends.
    """

    segments: tuple[ArcPath, ...]
    _starts: tuple[float, ...] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not self.segments:
            raise InputError("segments must hold at least one segment", name="segments")
        starts, t = [], 0.0
        for segment in self.segments:
            starts.append(t)
            t += segment.duration_s
        object.__setattr__(self, "_starts", tuple(starts))

    @property
    def duration_s(self) -> float:
        """Time to travel the whole path, s: the sum of the segments' durations."""
        return self._starts[-1] + self.segments[-1].duration_s

    @property
    def start(self) -> np.ndarray:
        """(4, 4) the first pose, as given."""
        return self.segments[0].start

    @property
    def goal(self) -> np.ndarray:
        """(4, 4) the last pose, as given."""
        return self.segments[-1].goal

    def reference(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Desired pose (4, 4) and twist (6,) ``[v; ω]`` (m/s, rad/s) at path time ``t``
        (s): that of the segment ``t`` falls in (the later one at a waypoint, where both
        give the waypoint at rest)."""
        k = max(bisect.bisect_right(self._starts, t) - 1, 0)
        return self.segments[k].reference(t - self._starts[k])

    def length_m(self) -> float:
        """Length of the path, m: the sum of the segments' lengths."""
        return float(sum(segment.length_m() for segment in self.segments))
