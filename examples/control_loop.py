"""A controller in a 1 kHz loop fed by a 30 Hz camera: the call pattern of a real arm's loop.

Every millisecond the loop reads the arm, hands the controller the newest skeleton it has
(the same one for about 33 ticks, until the camera delivers the next) and sends the
command. Nothing tells the controller which ticks bring a new frame: it sees that the
skeleton changed. The frame it holds grows old on its own clock (``control_period_s`` per
call), and one held past ``max_frame_age_s`` stops the robot; with the camera's frame
counter (``frame_id=``) or capture time (``frame_time_s=``) it knows for sure.

Here the arm is the kinematic simulation (``q += dq * dt``) and the camera films the paper's
Test 1 (a Kinect v2: 30 Hz, 60 ms latency, 2 mm noise). Run: ``python examples/control_loop.py``.
"""

from __future__ import annotations

import numpy as np

from qpavoid import ControllerConfig, load_robot
from qpavoid.arm.ik import inverse_kinematics
from qpavoid.control.analytic import AnalyticController
from qpavoid.loop.camera import Camera, CameraConfig
from qpavoid.scenarios.generated import make_scenario

RATE_HZ = 1000.0  # the arm's loop
DT = 1.0 / RATE_HZ


def run(seconds: float = 30.0) -> tuple[list[str], bool]:
    """Run Test 1 for ``seconds`` s of loop time; every stop reason, and whether the goal was
    reached."""
    robot = load_robot("iiwa14")
    ctrl = AnalyticController(robot, config=ControllerConfig(control_period_s=DT))
    camera = Camera(make_scenario("test1", robot), CameraConfig())  # 30 Hz, 60 ms late
    q = inverse_kinematics(robot, ctrl.path.reference(0.0)[0])  # on the path's start
    tau, stops = 0.0, []  # the path's clock: it waits while the robot is stopped
    for k in range(round(seconds * RATE_HZ)):
        frame, _captured = camera.frame_at(k * DT)  # the newest frame delivered by now
        joints = frame.joints.copy()  # as a camera SDK hands it over: a new array each time
        cmd = ctrl.step(q, joints, None, t=tau)  # age and freshness: the controller's own
        if cmd.stopped and (not stops or stops[-1] != cmd.reason):
            stops.append(cmd.reason)
        q = q + cmd.dq * DT  # the arm (here: exactly as commanded)
        tau = min(tau + cmd.time_scale * DT, ctrl.path.duration_s)
        if tau >= ctrl.path.duration_s and np.linalg.norm(cmd.ee_pos - cmd.ee_ref) < 1e-3:
            return stops, True
    return stops, False


if __name__ == "__main__":
    reasons, reached = run()
    print(f"goal reached: {reached}; stops: {reasons or 'none'}")
