"""A camera's side of a live run: sign each body frame with the sensor's key and send it.

    python examples/sensor_sender.py CALIB.toml SENSOR HOST:PORT [SECONDS]

Sends SENSOR's view of the seated operator at rest (one body, 30 frames a second) to a
`qpavoid run --listen HOST:PORT --sensors CALIB.toml`. A real camera's process does the
same with its body tracker's joints: joints in the camera's frame (m), its capture time
on the shared clock (s), and one `Signer` per sensor, kept for the process's life (its
sequence numbers count on). A frame of several bodies goes as
`signer.encode_frame(bodies)`, one datagram per body sent back to back: the listener takes
the frame only once all of them came. docs/security.md says what the signature covers.
"""

import socket
import sys
import time

import numpy as np

from qpavoid.human.posture import Operator
from qpavoid.loop.live_input import parse_address
from qpavoid.sensing.calibration_file import load_calibration
from qpavoid.sensing.per_sensor import BodyFrame
from qpavoid.sensing.signing import Signer

calib_file, sensor, to = sys.argv[1:4]
seconds = float(sys.argv[4]) if len(sys.argv) > 4 else 10.0
calibration = load_calibration(calib_file)
signer = Signer(calibration.cell, calibration.keys[sensor])  # refuses an unknown sensor
address = parse_address(to, "HOST:PORT")

camera_from_base = np.linalg.inv(calibration[sensor].base_from_camera)
R, p = camera_from_base[:3, :3], camera_from_base[:3, 3]
joints = Operator().rest() @ R.T + p  # what this camera sees, in its own frame, m
tracked = np.full(25, 2, dtype=np.int8)

sent = 0
with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
    start = time.time()
    while time.time() - start < seconds:
        captured = time.time() - calibration[sensor].time_offset_s  # on the sensor's clock
        frame = BodyFrame(sensor, 0, captured, joints, tracked)
        sock.sendto(signer.encode(frame), address)
        sent += 1
        time.sleep(1 / 30)
print(f"sent {sent} signed frames of {sensor} to {to}")
