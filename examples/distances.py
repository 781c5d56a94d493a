"""Distances between the iiwa and a seated operator, both methods (paper eq. 1 and coal)."""

import numpy as np

import qpavoid
from qpavoid.human.posture import Operator

robot = qpavoid.load_robot("iiwa14")  # A3 locked: 6 joints
q = np.radians([60, 35.3, -82.7, 0, -58.0, 0])  # the paper's start configuration
operator = Operator()
joints = operator.reach(operator.rest(), "right", robot.control_points(q)[6] + [0, 0.35, 0])

human = qpavoid.KinectHuman()
for table in (
    qpavoid.sphere_distances(robot, q, human, joints),
    qpavoid.capsule_distances(robot, q, human, joints),
):
    i, j = np.unravel_index(np.argmin(table.distance), table.distance.shape)
    print(
        f"{table.method:8s} closest: {table.set_names[i]} - {table.part_names[j]} "
        f"at {table.distance[i, j]:.3f} m, push direction {table.vector[i, j].round(2)}"
    )
