"""MediaPipe Pose with a depth camera: image landmarks + aligned depth -> a metric frame
-> the controller, without hardware (a synthetic person stands in for the camera).

    python examples/mediapipe_depth.py

With a real RGB-D camera, MediaPipe's Pose Landmarker (``pip install "qpavoid[mediapipe]"``)
gives per image ``result.pose_landmarks[0]``: 33 landmarks with ``x, y`` (normalised by the
image size), ``z`` (relative to the hips) and ``visibility``, ``presence``. Take

    image_xy = [[p.x, p.y] for p in landmarks]; z_rel = [p.z for p in landmarks]
    visibility = [min(p.visibility, p.presence) for p in landmarks]

with the depth image aligned to the colour image (metres) and the colour camera's
intrinsics, exactly as below. docs/sensors.md ("MediaPipe Pose with depth") says more.
"""

import numpy as np

import qpavoid
from qpavoid.arm.ik import inverse_kinematics
from qpavoid.control.analytic import AnalyticController
from qpavoid.human.landmarks import LandmarkMap, skeleton_format
from qpavoid.human.posture import Operator
from qpavoid.sensing.depth_lift import Intrinsics, lift_landmarks

mediapipe = skeleton_format("mediapipe_pose")
intrinsics = Intrinsics(fx=600.0, fy=600.0, cx=320.0, cy=240.0, width=640, height=480)
# the camera 2 m in front of the seated operator, looking at them (x right, y down, z forward)
base_from_camera = np.eye(4)
base_from_camera[:3, :3] = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]
base_from_camera[:3, 3] = [0.15, -0.9, 0.15]
camera_from_base = np.linalg.inv(base_from_camera)

# --- what MediaPipe and the depth camera would give (here: a synthetic seated operator) ---
body = Operator().rest()
truth = LandmarkMap.simulated(mediapipe).map(body, np.full(25, 2, dtype=np.int8)).joints
in_camera = truth @ camera_from_base[:3, :3].T + camera_from_base[:3, 3]
image_xy = intrinsics.project(in_camera)
hips = in_camera[mediapipe.indices(["LEFT_HIP", "RIGHT_HIP"]), 2].mean()
z_rel = (in_camera[:, 2] - hips) * intrinsics.fx / (intrinsics.width * hips)
depth = np.full((intrinsics.height, intrinsics.width), 4.0)  # a wall 4 m away...
for (u, v), z in zip(
    image_xy * [intrinsics.width, intrinsics.height], in_camera[:, 2], strict=True
):
    if 0 <= u < intrinsics.width and 0 <= v < intrinsics.height:  # ...and each landmark's
        depth[int(v) - 6 : int(v) + 7, int(u) - 6 : int(u) + 7] = z - 0.04  # body surface

# --- the library: lift to metres, place in the base frame, step the controller ---
joints, states = lift_landmarks(image_xy, z_rel, depth, intrinsics)
in_base = joints @ base_from_camera[:3, :3].T + base_from_camera[:3, 3]
robot = qpavoid.load_robot("iiwa14")
controller = AnalyticController(robot)
q = inverse_kinematics(robot, controller.path.reference(0.0)[0])
command = controller.step(q, in_base, states, 0.0, frame_age_s=0.0, camera_format=mediapipe)
seen = states > 0
print(
    f"{seen.sum()} of 33 landmarks lifted ({(states == 2).sum()} tracked); worst error "
    f"{np.nanmax(np.linalg.norm(in_base[seen] - truth[seen], axis=1)) * 1000:.1f} mm"
)
neck = controller.perceiver.perceived[0].joint_radius[controller.human.skeleton.index("Neck")]
print(
    f"first command {np.round(command.dq, 3)} rad/s (from rest); the neck, which MediaPipe "
    f"lacks, derived and widened by {neck * 1000:.0f} mm"
)
