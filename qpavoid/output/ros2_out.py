"""What a live run publishes on its ROS 2 cell, for RViz and Foxglove: a
``diagnostic_msgs/DiagnosticArray`` (moving or stopped, the stop reason, the nearest part
of the robot and its clearance) and a ``visualization_msgs/MarkerArray`` of the robot's
capsules and the nearest person's, coloured by clearance (green beyond
:data:`CLEAR_M`, red at contact).

Off the loop's critical path: the loop hands its live rows (at most 30 a second,
:class:`~qpavoid.loop.run_log.RunLogger`'s ``watch``) to :meth:`Ros2Outputs.update`, which
only keeps the newest; a thread of its own builds and publishes the messages at the cell's
``[output] rate_hz`` (best effort, keep last 1: a slow viewer never holds the loop).
"""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np

from qpavoid.arm.model import Robot
from qpavoid.control.controller import Controller
from qpavoid.sensing.ros2_cell import Cell, dds_message, load_cell, participant, writer

__all__ = ["CLEAR_M", "Ros2Outputs", "clearance_colour", "ros2_cell"]

#: At this clearance and beyond a capsule is green, m; red at 0.
CLEAR_M = 0.5
#: Markers live this long in RViz unless refreshed, s (a stopped publisher's fade out).
LIFETIME_S = 0.5


def ros2_cell(spec: Any) -> Cell | None:
    """The ROS 2 cell of a run (its ``--listen ros2:`` or ``--arm ros2:`` file), or None."""
    for text in (getattr(spec, "listen", None), getattr(spec, "arm", None)):
        if text and str(text).startswith("ros2:"):
            return load_cell(str(text)[5:])
    return None


def clearance_colour(clearance_m: float) -> tuple[float, float, float]:
    """(r, g, b): red at contact, yellow half way, green from :data:`CLEAR_M` (grey: none)."""
    if not np.isfinite(clearance_m):
        return 0.6, 0.6, 0.6
    x = float(np.clip(clearance_m / CLEAR_M, 0.0, 1.0))
    return min(1.0, 2.0 * (1.0 - x)), min(1.0, 2.0 * x), 0.0


def _quaternion_z_to(axis: np.ndarray) -> tuple[float, float, float, float]:
    """(x, y, z, w) turning +z onto ``axis`` (a cylinder marker's axis)."""
    n = np.linalg.norm(axis)
    if n < 1e-12:
        return 0.0, 0.0, 0.0, 1.0
    a = axis / n
    w = 1.0 + a[2]
    if w < 1e-9:  # opposite: half a turn about x
        return 1.0, 0.0, 0.0, 0.0
    q = np.array([-a[1], a[0], 0.0, w])
    q /= np.linalg.norm(q)
    return float(q[0]), float(q[1]), float(q[2]), float(q[3])


class Ros2Outputs:
    """Publishes a run's diagnostics and capsules on its cell (module docstring).

    Parameters
    ----------
    cell
        The cell: distribution, domain, topics, rate.
    robot, controller
        The run's robot (its capsules) and controller (the body model of the people).
    frame_id
        The markers' frame: the robot's base.
    """

    def __init__(self, cell: Cell, robot: Robot, controller: Controller, frame_id: str = "world"):
        # its thread computes the capsules in Pinocchio data of its own (the loop's robot
        # computes the ticks: one data shared changed the run's commands)
        self.cell, self.robot, self.frame_id = cell, robot.for_thread(), frame_id
        self.human = controller.human
        self.published = self.errors = 0
        self._dp = participant(cell.domain_id)
        self._diag = writer(
            self._dp,
            cell.distribution,
            cell.output.diagnostics,
            "diagnostic_msgs/msg/DiagnosticArray",
            reliable=False,
        )
        self._markers = writer(
            self._dp,
            cell.distribution,
            cell.output.markers,
            "visualization_msgs/msg/MarkerArray",
            reliable=False,
        )
        self._row: dict[str, Any] | None = None
        self._fresh = False
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="qpavoid-ros2-out", daemon=True)

    def __enter__(self) -> Ros2Outputs:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        with self._lock:
            fresh = self._fresh
        if fresh:  # the run's last row, published once more
            self._publish()
        self._dp = None

    def update(self, row: dict[str, Any]) -> None:
        """Keep the loop's newest row (cheap: the loop's thread never builds a message)."""
        with self._lock:
            self._row, self._fresh = row, True

    def _serve(self) -> None:
        period = 1.0 / self.cell.output.rate_hz
        while not self._stop.wait(period):
            try:
                self._publish()
            except Exception:  # never the run's end: a viewer's output only
                self.errors += 1

    def _publish(self) -> None:
        with self._lock:
            row, fresh, self._fresh = self._row, self._fresh, False
        if row is None or not fresh:
            return
        now = time.time()
        self._diag.write(self.diagnostics(row, now))
        self._markers.write(self.markers(row, now))
        self.published += 1

    def _header(self, now: float, frame_id: str = "") -> Any:
        dist = self.cell.distribution
        sec = int(now)
        stamp = dds_message(
            dist, "builtin_interfaces/msg/Time", sec=sec, nanosec=int((now - sec) * 1e9)
        )
        return dds_message(dist, "std_msgs/msg/Header", stamp=stamp, frame_id=frame_id)

    def diagnostics(self, row: dict[str, Any], now: float) -> Any:
        """One status: OK moving, WARN stopped (the reason), the nearest part, its clearance."""
        dist = self.cell.distribution
        distance = np.asarray(row["distance"], dtype=float)
        finite = np.isfinite(distance)
        k = int(np.argmin(np.where(finite, distance, np.inf))) if finite.any() else -1
        nearest = float(distance[k]) if k >= 0 else float("nan")
        part = self._set_name(k) if k >= 0 else "none"
        stopped, reason = bool(row["stopped"]), str(row.get("stop_reason", ""))
        values = [
            dds_message(dist, "diagnostic_msgs/msg/KeyValue", key=key, value=value)
            for key, value in (
                ("stopped", str(stopped).lower()),
                ("stop_reason", reason),
                ("nearest_part", part),
                ("nearest_clearance_m", f"{nearest:.4f}" if np.isfinite(nearest) else "none"),
                ("input_alert", str(row.get("input_alert", ""))),
            )
        ]
        status = dds_message(
            dist,
            "diagnostic_msgs/msg/DiagnosticStatus",
            level=1 if stopped else 0,
            name="qpavoid: collision avoidance",
            message=(reason or "stopped") if stopped else "moving",
            hardware_id=self.robot.name,
            values=values,
        )
        return dds_message(
            dist, "diagnostic_msgs/msg/DiagnosticArray", header=self._header(now), status=[status]
        )

    def _set_name(self, k: int) -> str:
        return str(getattr(self.robot.sets[k], "name", f"set {k}"))

    def markers(self, row: dict[str, Any], now: float) -> Any:
        """The robot's capsules (each by its own clearance) and the nearest person's (by the
        run's nearest clearance): a cylinder and two spheres each."""
        kin = self.robot.kinematics(np.asarray(row["q"], dtype=float), jacobians=False)
        distance = np.asarray(row["distance"], dtype=float)
        out: list[Any] = []
        header = self._header(now, self.frame_id)
        for k, (segment, radius) in enumerate(
            zip(kin.segments, self.robot.capsule_radii, strict=True)
        ):
            out += self._capsule(
                "qpavoid_robot", 3 * k, header, segment, float(radius), float(distance[k])
            )
        joints, state = np.asarray(row["joints"], dtype=float), np.asarray(row["state"])
        if (state > 0).any() and np.isfinite(joints).any():
            geo = self.human.geometry(joints, state)
            nearest = float(np.nanmin(distance)) if np.isfinite(distance).any() else float("nan")
            for k in np.flatnonzero(geo.segment_valid).tolist():
                radius = float(self.human.capsule_radii[k])
                out += self._capsule(
                    "qpavoid_person", 3 * k, header, geo.segments[k], radius, nearest
                )
        return dds_message(
            self.cell.distribution, "visualization_msgs/msg/MarkerArray", markers=out
        )

    def _capsule(
        self,
        ns: str,
        first_id: int,
        header: Any,
        segment: np.ndarray,
        radius: float,
        clearance: float,
    ) -> list[Any]:
        dist = self.cell.distribution
        r, g, b = clearance_colour(clearance)
        a, c = np.asarray(segment[0], dtype=float), np.asarray(segment[1], dtype=float)
        axis = c - a
        shapes = [
            (
                3,
                (a + c) / 2,
                _quaternion_z_to(axis),
                (2 * radius, 2 * radius, float(np.linalg.norm(axis))),
            )
        ]
        shapes += [(2, p, (0.0, 0.0, 0.0, 1.0), (2 * radius,) * 3) for p in (a, c)]
        out = []
        for i, (kind, at, (qx, qy, qz, qw), (sx, sy, sz)) in enumerate(shapes):
            out.append(
                dds_message(
                    dist,
                    "visualization_msgs/msg/Marker",
                    header=header,
                    ns=ns,
                    id=first_id + i,
                    type=kind,
                    action=0,
                    pose=dds_message(
                        dist,
                        "geometry_msgs/msg/Pose",
                        position=dds_message(
                            dist,
                            "geometry_msgs/msg/Point",
                            x=float(at[0]),
                            y=float(at[1]),
                            z=float(at[2]),
                        ),
                        orientation=dds_message(
                            dist, "geometry_msgs/msg/Quaternion", x=qx, y=qy, z=qz, w=qw
                        ),
                    ),
                    scale=dds_message(dist, "geometry_msgs/msg/Vector3", x=sx, y=sy, z=sz),
                    color=dds_message(dist, "std_msgs/msg/ColorRGBA", r=r, g=g, b=b, a=0.6),
                    lifetime=dds_message(
                        dist,
                        "builtin_interfaces/msg/Duration",
                        sec=0,
                        nanosec=int(LIFETIME_S * 1e9),
                    ),
                )
            )
        return out
