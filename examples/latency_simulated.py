"""A latency measurement without hardware: a simulated camera films a hand on the flange.

    python examples/latency_simulated.py [OUT_DIR] [--camera FORMAT] [--latency S]
                                         [--noise M] [--robot NAME]

The arm moves the latency excitation (``qpavoid.loop.excitation.Excitation``) while a
seated operator holds its flange; the library's simulated camera of FORMAT (default
k4abt), with its latency (default the format file's) and noise, films them
(``qpavoid.loop.excitation.film_excitation``). Writes OUT_DIR/camera.npz, the camera's
frames in the base frame, each stamped when it was delivered, and OUT_DIR/arm.npz, the
arm's joint angles at 500 Hz, on one clock. Then:

    qpavoid latency --camera-recording OUT_DIR/camera.npz --arm-log OUT_DIR/arm.npz

gives back the latency within its uncertainty (docs/sensors.md §10).
"""

import argparse
from pathlib import Path

from qpavoid.arm.model import load_robot
from qpavoid.human.landmarks import FORMAT_NAMES
from qpavoid.loop.camera import CameraConfig
from qpavoid.loop.excitation import film_excitation
from qpavoid.sensing.arm_log import save_arm_log
from qpavoid.sensing.recording import save_npz

parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
parser.add_argument("out", nargs="?", default="latency", help="the folder to write into")
parser.add_argument("--camera", choices=FORMAT_NAMES, default="k4abt")
parser.add_argument("--latency", type=float, help="its latency, s (default: its format's)")
parser.add_argument("--noise", type=float, help="its noise per axis, m (default: its format's)")
parser.add_argument("--robot", default="iiwa14")
args = parser.parse_args()

overrides = {"latency_s": args.latency, "noise_m": args.noise}
camera = CameraConfig.of(args.camera, **{k: v for k, v in overrides.items() if v is not None})
robot = load_robot(args.robot)
recording, log = film_excitation(robot, camera)
out = Path(args.out)
out.mkdir(parents=True, exist_ok=True)
save_npz(out / "camera.npz", recording)
save_arm_log(out / "arm.npz", log, robot)
print(
    f"wrote {out}/camera.npz ({recording.n_frames} frames of a simulated {args.camera} at "
    f"{camera.latency_s:g} s) and {out}/arm.npz ({log.t.size} states of {robot.name}); now\n"
    f"  qpavoid latency --camera-recording {out}/camera.npz --arm-log {out}/arm.npz "
    f"--robot {args.robot}"
)
