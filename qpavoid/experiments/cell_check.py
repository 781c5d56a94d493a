"""Before the first motion: where the arm will stop beside its seated operator (``qpavoid check``).

Speed and separation lets no robot point come closer to a body part than the protective
distance a robot at rest needs there (ISO/TS 15066 eq. 1 at v_r = 0,
:func:`~qpavoid.laws.ssm.hold_distance`):

    S_p(0) = v_h (T_r + T_s + T_f) + C + Z_d + Z_r

with v_h ISO 13855's body speed, T_f the age of the frame the clearance was measured on
and the rest constants of the arm and the cell. Where the task's path passes closer than
that to an operator who sits still, the arm following it must hold (no approach speed is
allowed, :func:`~qpavoid.laws.ssm.max_approach_speed` < 0), and the operator never makes
room: the run stops there, for as long as they sit.

The check follows the path at its nominal configurations (tracked exactly, by IK from the
start, every :data:`SAMPLE_S` of path time) beside the task's seated operator at work (the
``free`` scenario: hands circling 5 cm around their rest, :data:`PHASES` frames over one
circle, each filmed by the camera as a run films it). Each sample is measured by the
controller the run would build (its body model, capsules, distances and speed and
separation constants), at the oldest a frame of the camera gets before the next arrives,
T_f = latency + one frame period. A **stretch** is a run of samples where some robot set ×
body part pair, at some phase, is closer than S_p(0) (or a stop rule of the safety mode
holds). For each stretch it gives:

* the pair, its clearance and the clearance it needs (the largest shortfall);
* the latency at which it would pass: the largest L with S_p(0) at T_f = L + a frame period
  within the clearance over the whole stretch (none if the fixed terms alone exceed it);
* how far the seat, or the waypoints, must move: the shortfall (a clearance grows by at
  most the distance either side moves), and the direction taking the body part away from
  the robot point, in the base frame's xy plane (a seat moves on the floor).

What it does not see (say so to an integrator): an operator who moves towards the arm
(the run's random approaches), a path the QP controller deflects around the operator
(which can pass where the check says stop, or stop a little before), and a robot slowed
before a stretch (never stopped there by this check's criterion).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from qpavoid.arm.model import Robot
from qpavoid.control.controller import Controller
from qpavoid.core.errors import InputError
from qpavoid.experiments.run_spec import RunSpec
from qpavoid.experiments.runs import build_controller, spec_robot
from qpavoid.laws.ssm import SSMConfig, fixed_terms, human_distance, human_speed
from qpavoid.loop.camera import Camera, CameraConfig
from qpavoid.scenarios.generated import make_scenario, nominal_configurations

__all__ = ["PHASES", "SAMPLE_S", "CellCheck", "Stretch", "check_cell"]

#: Path time between two samples, s (a 15 s path: 301 samples).
SAMPLE_S = 0.05
#: Frames of the operator at work over one circle of their hands (``free``'s 4 s period).
PHASES = 8
#: The stop reasons about the input stream (stale, frozen), which the check's held frames
#: would raise and a run's camera does not.
_INPUT = "human frame is"
#: The largest end-effector error, m, of a nominal configuration (else: unreachable).
REACH_TOLERANCE_M = 1e-3


@dataclass(frozen=True)
class Stretch:
    """A stretch of the path where the arm stops for the still operator.

    Attributes
    ----------
    start_s, end_s
        Its path times, s (the first and last samples in it).
    waypoints
        The task's waypoints it lies between (0 = the start), first and last.
    part, link
        The body part and robot set of the largest shortfall.
    clearance_m, needed_m
        Their clearance there and the one they need, m.
    passing_latency_s
        The largest camera latency at which the stretch passes, s (None: none does).
    away
        (2,) the unit direction, base frame xy, moving the part away from the link.
    reason
        A stop rule's reason where one holds instead ("" for speed and separation).
    """

    start_s: float
    end_s: float
    waypoints: tuple[int, int]
    part: str
    link: str
    clearance_m: float
    needed_m: float
    passing_latency_s: float | None
    away: np.ndarray
    reason: str = ""

    @property
    def shortfall_m(self) -> float:
        """How much closer than it needs the tightest pair comes, m (what the seat or the
        waypoints must move)."""
        return self.needed_m - self.clearance_m


@dataclass(frozen=True)
class CellCheck:
    """The check's result: the spec checked, the samples and the stretches.

    Attributes
    ----------
    spec
        The run it stands for (arm, task, camera and latency, safety, controller).
    frame_age_s
        The frame age the protective distance counts, s (latency + a frame period).
    times_s
        (N,) the path times sampled.
    clearance_m, needed_m
        (N,) the tightest pair's clearance at each sample (over the phases) and the
        clearance it needs; NaN where the safety mode has no protective distance.
    waypoint_times_s
        The path times of the task's waypoints.
    stretches
        Where the arm stops, in path order.
    """

    spec: RunSpec
    frame_age_s: float
    times_s: np.ndarray
    clearance_m: np.ndarray
    needed_m: np.ndarray
    waypoint_times_s: np.ndarray
    stretches: list[Stretch] = field(default_factory=list)

    @property
    def stops(self) -> bool:
        return bool(self.stretches)


def check_cell(spec: RunSpec, progress: Callable[[int, int], None] | None = None) -> CellCheck:
    """Where the arm of ``spec`` stops along its task beside the still operator (module
    docstring). ``spec``'s scenario is ignored (the operator is the task's, at work).
    ``progress(done, total)`` is called after each of the operator's phases has been
    followed along the whole path (total: the phases), for a command line's progress bar.

    Raises
    ------
    InputError
        For a task whose path the arm cannot follow (a waypoint out of reach), or the
        errors of ``spec`` itself (a task file naming a joint the arm lacks, a latency out
        of range), each one line.
    """
    if spec.safety == "pfl":
        raise InputError(
            "the cell check judges where speed and separation (--safety ssm) or the paper's "
            "stop rules (paper) hold the arm; under pfl it slows to a hand's contact speed "
            "instead of holding, which it does not model: check with --safety ssm (the "
            "head's and trunk's distances are the same)",
            name="--safety",
            value=spec.safety,
        )
    spec = replace(spec, scenario="free", human_file=None, measure_truth=False)
    robot = spec_robot(spec)
    controller = build_controller(spec, robot)
    path = controller.path
    times = np.linspace(0.0, path.duration_s, max(2, round(path.duration_s / SAMPLE_S) + 1))
    qs = nominal_configurations(robot, path, times)
    _check_reach(robot, path, times, qs)
    camera_cfg = CameraConfig.of(spec.camera, latency_s=spec.sensor_latency_s)
    period = 1.0 / camera_cfg.frame_rate_hz
    age = spec.sensor_latency_s + period
    motion = make_scenario("free", robot, task=spec.task_for(robot))
    camera = Camera(motion, camera_cfg, controller.human.skeleton)
    frames = [camera.frame_at(4.0 * k / PHASES)[0] for k in range(PHASES)]
    rows = _measure(controller, qs, times, frames, age, progress)
    waypoints = _waypoint_times(path)
    stretches = _stretches(rows, times, waypoints, age, period, controller)
    return CellCheck(spec, age, times, rows.clearance, rows.needed, waypoints, stretches)


@dataclass
class _Rows:
    """Per sample: the tightest pair (over the phases) and any stop rule's reason."""

    clearance: np.ndarray
    needed: np.ndarray
    margin: np.ndarray  # clearance − needed of the tightest pair
    pair: list[tuple[str, str]]
    vector: np.ndarray  # (N, 3) human → robot of the tightest pair
    reason: list[str]


def _need(distance: np.ndarray, age: float, ssm: SSMConfig, body: np.ndarray) -> np.ndarray:
    """S_p(0) of every pair, m: :func:`~qpavoid.laws.ssm.hold_distance`, vectorised."""
    return human_distance(human_speed(distance, ssm, body), age, ssm) + fixed_terms(ssm)


def _measure(
    controller: Controller,
    qs: np.ndarray,
    times: np.ndarray,
    frames: list,
    age: float,
    progress: Callable[[int, int], None] | None,
) -> _Rows:
    n = len(times)
    rows = _Rows(
        np.full(n, np.inf), np.full(n, np.nan), np.full(n, np.inf), [("", "")] * n,
        np.zeros((n, 3)), [""] * n,
    )  # fmt: skip
    for phase, frame in enumerate(frames):
        for k, (q, t) in enumerate(zip(qs, times, strict=True)):
            tick = controller.measure(q, frame, None, float(t), age, None, phase)
            # (a frame held over the samples grows old on the controller's clock, and one
            # alike at each call looks frozen: the input's checks, not the cell's layout)
            if tick.reason and not rows.reason[k] and not tick.reason.startswith(_INPUT):
                rows.reason[k] = tick.reason
            table = tick.table
            if tick.ssm is None:  # no protective distance: the stop rules alone
                i, j = np.unravel_index(int(np.argmin(table.distance)), table.distance.shape)
                if table.distance[i, j] < rows.clearance[k]:
                    rows.clearance[k] = table.distance[i, j]
                    rows.pair[k] = (table.part_names[j], table.set_names[i])
                    rows.vector[k] = table.vector[i, j]
                continue
            body = np.isin(table.part_names, tick.ssm.body_parts)[None, :]
            need = _need(table.distance, age, tick.ssm, body)
            margin = table.distance - need
            i, j = np.unravel_index(int(np.argmin(margin)), margin.shape)
            if margin[i, j] < rows.margin[k]:
                rows.margin[k] = margin[i, j]
                rows.clearance[k], rows.needed[k] = table.distance[i, j], need[i, j]
                rows.pair[k] = (table.part_names[j], table.set_names[i])
                rows.vector[k] = table.vector[i, j]
        if progress is not None:
            progress(phase + 1, len(frames))
    return rows


def _stretches(
    rows: _Rows,
    times: np.ndarray,
    waypoint_times: np.ndarray,
    age: float,
    period: float,
    controller: Controller,
) -> list[Stretch]:
    stop = (rows.margin < 0.0) | np.array([bool(r) for r in rows.reason])
    out: list[Stretch] = []
    k = 0
    while k < len(times):
        if not stop[k]:
            k += 1
            continue
        end = k
        while end + 1 < len(times) and stop[end + 1]:
            end += 1
        span = np.arange(k, end + 1)
        worst = int(span[np.argmin(rows.margin[span])])
        reason = next((rows.reason[i] for i in span if rows.reason[i]), "")
        if not np.isfinite(rows.margin[worst]):  # a stop rule alone (no SSM pair short)
            worst = int(span[np.argmin(rows.clearance[span])])
        away = -rows.vector[worst][:2]
        norm = float(np.linalg.norm(away))
        ssm = controller.limits.ssm if controller.config.safety != "paper" else None
        out.append(
            Stretch(
                float(times[k]),
                float(times[end]),
                _between(waypoint_times, float(times[k]), float(times[end])),
                rows.pair[worst][0],
                rows.pair[worst][1],
                float(rows.clearance[worst]),
                float(rows.needed[worst]) if np.isfinite(rows.needed[worst]) else float("nan"),
                None if ssm is None or reason else _passing_latency(rows, span, ssm, period),
                away / norm if norm > 0 else np.zeros(2),
                reason if rows.margin[worst] >= 0.0 or not np.isfinite(rows.margin[worst]) else "",
            )
        )
        k = end + 1
    return out


def _passing_latency(rows: _Rows, span: np.ndarray, ssm: SSMConfig, period: float) -> float | None:
    """The largest latency L (s) at which every sample of ``span`` keeps its tightest pair's
    clearance, T_f = L + ``period``: S_p(0) is linear in T_f, so from the sample that binds."""
    best = np.inf
    for k in span:
        d = np.array([[rows.clearance[k]]])
        at_zero = float(_need(d, 0.0, ssm, np.array([[True]]))[0, 0])
        slope = float(_need(d, 1.0, ssm, np.array([[True]]))[0, 0]) - at_zero
        best = min(best, (float(d[0, 0]) - at_zero) / slope if slope > 0 else np.inf)
    latency = best - period
    return float(latency) if latency >= 0.0 else None


def _waypoint_times(path: object) -> np.ndarray:
    """The path times of the task's waypoints (a single segment: its start and end)."""
    segments = getattr(path, "segments", None)
    if segments is None:
        return np.array([0.0, float(path.duration_s)])  # type: ignore[attr-defined]
    return np.cumsum([0.0, *(float(s.duration_s) for s in segments)])


def _between(waypoint_times: np.ndarray, start: float, end: float) -> tuple[int, int]:
    """The waypoints before ``start`` and after ``end`` (indices into the task's list)."""
    first = int(np.searchsorted(waypoint_times, start, side="right")) - 1
    last = int(np.searchsorted(waypoint_times, end, side="left"))
    return max(first, 0), min(last, len(waypoint_times) - 1)


def _check_reach(robot: Robot, path: object, times: np.ndarray, qs: np.ndarray) -> None:
    for t, q in zip(times, qs, strict=True):
        want = path.reference(float(t))[0][:3, 3]  # type: ignore[attr-defined]
        got = robot.kinematics(q, jacobians=False).ee_placement[:3, 3]
        error = float(np.linalg.norm(got - want))
        if not error <= REACH_TOLERANCE_M:
            raise InputError(
                f"the task's path is out of the arm's reach at path time {t:.2f} s (the "
                f"nearest configuration ends {1e3 * error:.1f} mm from it): move its "
                "waypoints (docs/tasks.md)",
                name="task",
                value=float(t),
            )
