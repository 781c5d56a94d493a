"""Move the arm through the latency excitation and log its joint angles on the wall clock.

    python examples/latency_excitation.py ARM [--robot NAME] [--seconds 30] [--out arm.npz]

ARM is ``sim`` (the simulated arm on the wall clock: a dry run, no hardware) or
``franka:HOST`` (a Franka FR3 or Panda through franky-control, docs/real-robot.md: it is
first moved slowly to its task's first pose). The arm then moves a few slow sinusoids on
its first two joints (``qpavoid.loop.excitation.Excitation``: under 0.25 m/s at the flange,
faded in and out) while a person holds its flange, and each state read is stamped with
``time.time()``. Meanwhile the camera's recorder, on this machine's clock, writes each
frame stamped when it arrived (docs/sensors.md §10, "Measuring your camera's latency").
Then:

    qpavoid latency --camera-recording camera.npz --arm-log arm.npz --robot NAME \\
        --sensors calib.toml

Ctrl-C stops the arm (its own ramp to rest) and writes nothing.
"""

import argparse

from qpavoid.arm.ik import inverse_kinematics
from qpavoid.arm.model import load_robot
from qpavoid.control.task import default_task
from qpavoid.drive.connect import open_arm
from qpavoid.loop.excitation import Excitation, drive_excitation
from qpavoid.sensing.arm_log import save_arm_log

parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
parser.add_argument("arm", help="sim or franka:HOST")
parser.add_argument("--robot", default="iiwa14", help="the arm's description (default iiwa14)")
parser.add_argument("--seconds", type=float, default=30.0, help="the excitation's length, s")
parser.add_argument("--out", default="arm.npz", help="the arm log to write (NPZ)")
args = parser.parse_args()

robot = load_robot(args.robot)
start = inverse_kinematics(robot, default_task(robot).path.reference(0.0)[0])
excitation = Excitation(duration_s=args.seconds, ramp_s=min(2.0, args.seconds / 4))
period_s = 0.002  # the control loop's 500 Hz
with open_arm(args.arm, robot, start, period_s) as arm:
    print(f"{arm.name}: moving {', '.join(robot.joint_names[:2])} for {args.seconds:g} s")
    log = drive_excitation(arm, robot, excitation, period_s)
save_arm_log(args.out, log, robot)
print(f"wrote {args.out}: {log.t.size} states, t from {log.t[0]:.3f} to {log.t[-1]:.3f} s")
