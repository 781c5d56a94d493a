"""Write a human recording (NPZ and CSV, docs/formats.md) and replay it with the QP controller."""

import numpy as np

from qpavoid import load_robot
from qpavoid.control.qp import QPController
from qpavoid.loop.simulation import simulate
from qpavoid.scenarios.generated import make_scenario
from qpavoid.sensing.recording import Recording, load_recording, save_csv, save_npz

robot = load_robot("iiwa14")
motion = make_scenario("test2", robot)
t = np.arange(0.0, 12.0, 1 / 30)  # 30 Hz, like a Kinect v2
frames = [motion.frame_at(x) for x in t]
rec = Recording(t, np.array([f[0] for f in frames]), np.array([f[1] for f in frames]))
save_npz("test2.npz", rec)
save_csv("test2.csv", rec)

result = simulate(QPController(robot), load_recording("test2.npz"))
print({k: result.metrics[k] for k in ("reached_goal", "stopped_s", "stop_events", "max_f")})
