"""A camera's side of a live run, for a camera of any format: sign each frame and send it.

    python examples/sensor_sender.py CALIB.toml SENSOR HOST:PORT [SECONDS]

Plays SENSOR of CALIB.toml for a `qpavoid run --listen HOST:PORT --sensors CALIB.toml`: the
seated operator at rest, filmed by the simulated camera of the sensor's calibrated
`format` (kinect_v2, k4abt, zed_body_34, zed_body_38 or mediapipe_pose: its joints, noise
and frame rate), in the sensor's own frame (its `base_from_camera` inverted), each frame
sent when the camera would deliver it and stamped with its capture time (the send time
less the format's latency), signed with the sensor's key. `qpavoid send` does the same with
more choices (a scenario, a recording, --latency; docs/sensors.md §7, §11).

A real camera's process sends its body tracker's joints instead: per body, its SDK's
numbers made the wire's (metres, tracking states) by
`qpavoid.human.landmarks.camera_frame(format, joints, confidence)`, a
`qpavoid.sensing.per_sensor.BodyFrame(sensor, body, capture_time, joints, states, format)`,
and one `qpavoid.sensing.signing.Signer` per sensor, kept for the process's life (its
sequence numbers count on); a frame of several bodies goes as `signer.encode_frame(bodies)`,
one datagram per body sent back to back. docs/security.md says what the signature covers.
"""

import sys

from qpavoid.human.posture import Operator
from qpavoid.loop.live_input import parse_address
from qpavoid.loop.sender import AtRest, send, sensor_frames
from qpavoid.sensing.calibration_file import load_calibration

calib_file, sensor, to = sys.argv[1:4]
seconds = float(sys.argv[4]) if len(sys.argv) > 4 else 10.0
calibration = load_calibration(calib_file)
address = parse_address(to, "HOST:PORT")

# The operator where the paper seats them beside the iiwa; for another arm, its task's
# seat: qpavoid.control.task.default_task(load_robot("panda")).operator
frames = sensor_frames(AtRest(Operator()), calibration, sensor, seconds)  # refuses a stranger
sent = send(frames, calibration, sensor, address)
print(
    f"sent {sent.datagrams} signed datagrams ({sent.frames} frames of {sensor}, "
    f"{calibration[sensor].format}, stamped {sent.latency_s:.3f} s before sending) to {to}"
)
