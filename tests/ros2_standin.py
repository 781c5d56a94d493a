"""A stand-in for the ROS 2 body-tracking drivers: qpavoid's frames as the messages the
Azure Kinect ROS driver and the ZED ROS 2 wrapper publish (their conventions as
docs/ros2.md cites them), built with rosbags' classes. For the tests only."""

from __future__ import annotations

import numpy as np

from qpavoid.human.skeleton import AXIS_DIRECTIONS
from qpavoid.sensing.calibration import known_formats
from qpavoid.sensing.ros2_types import time_msg, typestore

DIST = "humble"


def make(type_name: str, /, **fields):
    return typestore(DIST).types[type_name](**fields)


def header(t: float, frame_id: str):
    return make("std_msgs/msg/Header", stamp=time_msg(DIST, t), frame_id=frame_id)


def marker(t: float, marker_id: int, xyz, frame_id: str = "depth_camera_link"):
    """One joint's sphere as the Azure Kinect ROS driver's getBodyMarker makes it."""
    x, y, z = (float(v) for v in xyz)
    empty = np.zeros(0, dtype=np.uint8)
    return make(
        "visualization_msgs/msg/Marker",
        header=header(t, frame_id),
        ns="",
        id=int(marker_id),
        type=2,
        action=0,
        pose=make(
            "geometry_msgs/msg/Pose",
            position=make("geometry_msgs/msg/Point", x=x, y=y, z=z),
            orientation=make("geometry_msgs/msg/Quaternion", x=0.0, y=0.0, z=0.0, w=1.0),
        ),
        scale=make("geometry_msgs/msg/Vector3", x=0.05, y=0.05, z=0.05),
        color=make("std_msgs/msg/ColorRGBA", r=1.0, g=0.0, b=0.0, a=1.0),
        lifetime=make("builtin_interfaces/msg/Duration", sec=0, nanosec=250_000_000),
        frame_locked=False,
        points=[],
        colors=[],
        texture_resource="",
        texture=make(
            "sensor_msgs/msg/CompressedImage", header=header(0.0, ""), format="", data=empty
        ),
        uv_coordinates=[],
        text="",
        mesh_resource="",
        mesh_file=make("visualization_msgs/msg/MeshFile", filename="", data=empty),
        mesh_use_embedded_materials=False,
    )


def marker_array(t: float, bodies: dict[int, np.ndarray]):
    """bodies: driver body id -> (32, 3) joints, m, depth camera frame (NaN: no marker)."""
    markers = [
        marker(t, body * 100 + j, p)
        for body, joints in bodies.items()
        for j, p in enumerate(joints)
        if np.isfinite(p).all()
    ]
    return make("visualization_msgs/msg/MarkerArray", markers=markers)


def to_ros_axes(fmt_name: str, joints: np.ndarray) -> np.ndarray:
    """A format's camera-frame points in ROS axes (x forward, y left, z up)."""
    fmt = known_formats()[fmt_name]
    ros = np.array([AXIS_DIRECTIONS[a] for a in ("forward", "left", "up")]).T
    return joints @ (np.asarray(fmt.axes_matrix).T @ ros)  # p_ros = R^T p_fmt


def zed_object(body_id: int, keypoints_ros: np.ndarray, body_format: int, tracking: int = 1):
    """One body as zed-ros2-wrapper's processBodies fills an Object."""
    kp3 = [make("zed_msgs/msg/Keypoint3D", kp=np.zeros(3, np.float32)) for _ in range(70)]
    for k, p in enumerate(keypoints_ros):
        kp3[k] = make("zed_msgs/msg/Keypoint3D", kp=np.asarray(p, np.float32))
    kp2 = [make("zed_msgs/msg/Keypoint2Df", kp=np.zeros(2, np.float32)) for _ in range(70)]
    box3 = make(
        "zed_msgs/msg/BoundingBox3D",
        corners=[make("zed_msgs/msg/Keypoint3D", kp=np.zeros(3, np.float32))] * 8,
    )
    return make(
        "zed_msgs/msg/Object",
        label=f"Body_{body_id}",
        label_id=int(body_id),
        sublabel="",
        confidence=90.0,
        position=np.zeros(3, np.float32),
        position_covariance=np.zeros(6, np.float32),
        velocity=np.zeros(3, np.float32),
        tracking_available=True,
        tracking_state=int(tracking),
        action_state=0,
        bounding_box_2d=make(
            "zed_msgs/msg/BoundingBox2Di",
            corners=[make("zed_msgs/msg/Keypoint2Di", kp=np.zeros(2, np.uint32))] * 4,
        ),
        bounding_box_3d=box3,
        dimensions_3d=np.zeros(3, np.float32),
        skeleton_available=True,
        body_format=int(body_format),
        head_bounding_box_2d=make(
            "zed_msgs/msg/BoundingBox2Df",
            corners=[make("zed_msgs/msg/Keypoint2Df", kp=np.zeros(2, np.float32))] * 4,
        ),
        head_bounding_box_3d=box3,
        head_position=np.zeros(3, np.float32),
        skeleton_2d=make("zed_msgs/msg/Skeleton2D", keypoints=kp2),
        skeleton_3d=make("zed_msgs/msg/Skeleton3D", keypoints=kp3),
    )


def objects_stamped(t: float, objects: list):
    return make(
        "zed_msgs/msg/ObjectsStamped", header=header(t, "zed_left_camera_frame"), objects=objects
    )
