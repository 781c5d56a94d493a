"""The controller's per-person tables follow each tick's person list (issue 40): people
entering and leaving the fusion, in any order, with capture times that advance, hold or
go backwards, never leave a table of an earlier tick behind."""

from __future__ import annotations

import numpy as np
import pytest

from qpavoid.control.analytic import AnalyticController
from qpavoid.control.qp import QPController
from qpavoid.control.task import inverse_kinematics
from qpavoid.control.tick import ControllerConfig
from qpavoid.fusion.fuser import Fuser, FusionConfig
from qpavoid.human.people import NOBODY, People
from qpavoid.human.posture import Operator
from qpavoid.sensing.calibration import Calibration, SensorCalibration
from qpavoid.sensing.per_sensor import BodyFrame
from qpavoid.sensing.synthetic_pair import look_at

CONTROLLERS = (AnalyticController, QPController)
DT = 0.01  # the control period, s (100 Hz)
TRACKED = np.full(25, 2, dtype=np.int8)


def calibration(n: int) -> Calibration:
    """``n`` sensors at different places, facing the cell."""
    sensors = {}
    for k in range(n):
        eye = np.array([1.5 * (-1) ** k, 2.5 - 0.5 * (k // 2), 1.3])
        sensors[f"s{k}"] = SensorCalibration(f"s{k}", look_at(eye, np.array([0.15, 1.0, 0.4])))
    return Calibration(sensors)


def seen_by(cal: Calibration, sensor: str, body: int, t: float, joints: np.ndarray) -> BodyFrame:
    """``joints`` (base frame, m) as ``sensor`` reports them: body ``body`` captured at ``t``."""
    T = np.linalg.inv(cal[sensor].base_from_camera)
    return BodyFrame(sensor, body, t, joints @ T[:3, :3].T + T[:3, 3], TRACKED.copy())


def people_of(fuser: Fuser, t: float) -> tuple[People, float]:
    """Everybody fused at ``t`` (as :class:`~qpavoid.loop.live_input.LiveSource` hands them
    on) and the fusion's capture time."""
    fused = fuser.fuse(t)
    people = People(tuple(p.id for p in fused.people), tuple(p.frame for p in fused.people))
    return people, fused.captured_s


@pytest.mark.parametrize("distance", ["capsules", "spheres"])
@pytest.mark.parametrize("kind", CONTROLLERS)
def test_a_person_leaving_in_a_tick_whose_capture_time_did_not_advance(robot, kind, distance):
    """Two people; the second walks out of view, far from the robot, and is dropped by the
    fusion 0.5 s later, in a tick with no new frame of the first (its capture time held).
    Unseen, the second was the nearest (their uncertainty grew for 0.5 s): the tick after
    must measure the one person left, not the two of the frame in hand."""
    cal = calibration(1)
    fuser = Fuser(cal, FusionConfig(person_timeout_s=0.5))
    ctrl = kind(robot, config=ControllerConfig(control_period_s=DT, distance=distance))
    q = inverse_kinematics(robot, ctrl.path.reference(0.0)[0])
    operator = Operator().rest()
    walker = operator + np.array([0.0, 1.2, 0.0])  # 1.9 m from the base: dropped when unseen
    captured, held = -np.inf, []
    for k in range(1, 100):
        t = k * DT
        if k % 4 == 0:  # a 25 Hz camera: three ticks of four hold its frame
            moved = np.array([0.0, 0.0, 0.001 * k])  # (never a frozen sensor)
            fuser.add(seen_by(cal, "s0", 0, t, operator + moved))
            if t < 0.2:
                fuser.add(seen_by(cal, "s0", 1, t, walker + moved))
        before = ctrl.perceiver.perceived
        people, now = people_of(fuser, t)
        if now == captured and len(before) == 2 and people.ids == (0,):
            held.append(k)  # the second dropped, the capture time held
        captured = max(captured, now)
        cmd = ctrl.step(q, people, None, 0.0, t - captured, captured)
        assert np.isfinite(cmd.dq).all()
        assert len(ctrl.perceiver.perceived) == len(ctrl.perceiver.geometry) == len(people.ids)
        assert any(ctrl.closest_frame is f for f in people.frames or (NOBODY,))
    assert held, "the second person was not dropped in a tick whose capture time held"
