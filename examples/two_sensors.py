"""Two Kinect v2 without hardware: film a known motion, fuse, and compare with the truth.

    python examples/two_sensors.py [OUT_DIR]

Writes OUT_DIR/calib.toml, each Kinect's key file (its datagrams are signed: kept if
present) and one per-sensor recording per Kinect (joints in its own camera frame, its own
clock), then fuses them as `qpavoid fuse` does. Try next:

    cd OUT
    qpavoid fuse kinect_left.npz kinect_right.npz --sensors calib.toml --out fused.npz
    qpavoid run --human kinect_left.npz kinect_right.npz --sensors calib.toml --safety ssm
    qpavoid run --listen 127.0.0.1:5005 --sensors calib.toml --out live &
    qpavoid replay kinect_left.npz kinect_right.npz --to 127.0.0.1:5005 --sensors calib.toml
"""

import dataclasses
import sys
from pathlib import Path

import numpy as np

import qpavoid
from qpavoid.fusion.offline import fuse_recordings
from qpavoid.scenarios.generated import make_scenario
from qpavoid.sensing.keys import load_key_file, new_key_file
from qpavoid.sensing.per_sensor import save_sensor_npz
from qpavoid.sensing.synthetic_pair import TwoSensorConfig, two_sensor_data

out = Path(sys.argv[1] if len(sys.argv) > 1 else "two_sensors")
out.mkdir(parents=True, exist_ok=True)
robot = qpavoid.load_robot("iiwa14")
truth = make_scenario("test1", robot)  # the paper's Test 1, as the true motion

# 50 mm mean error per sensor, occlusions, left/right swaps, a 13 ms phase, a 0.25 s clock
data = two_sensor_data([truth], 20.0, TwoSensorConfig(seed=1))
key_files = {name: f"{name}.key" for name in data.recordings}
keys = {
    name: load_key_file(out / f, name) if (out / f).exists() else new_key_file(out / f, name)
    for name, f in key_files.items()
}
calibration = dataclasses.replace(data.calibration, keys=keys)
(out / "calib.toml").write_text(calibration.to_toml(key_files))
for name, recording in data.recordings.items():
    save_sensor_npz(out / f"{name}.npz", recording)

fused = fuse_recordings(list(data.recordings.values()), data.calibration)
true = np.array([truth.frame_at(t)[0] for t in fused.t])
error = np.linalg.norm(fused.joints - true, axis=2)
print(
    f"{len(fused.t)} fused frames, mean joint error {1e3 * np.nanmean(error):.1f} mm "
    f"(each sensor: 50 mm), mean confidence {np.nanmean(fused.confidence):.2f}"
)
written = [f"{n}.npz" for n in data.recordings] + list(key_files.values())
print(f"wrote {out}/calib.toml and {', '.join(written)}")
