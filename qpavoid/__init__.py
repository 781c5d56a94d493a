"""qpavoid: real-time collision avoidance between a cobot arm and the person beside it.

The modules follow the data flow of one control tick:

* :mod:`qpavoid.robot`     the arm (Pinocchio model, control points, capsules)
* :mod:`qpavoid.human`     the Kinect v2 skeleton and the upper-body model
* :mod:`qpavoid.distances` robot-human distance tables (spheres, capsules)
"""

from .distances import (CapsuleDistance, DistanceTable, SphereDistance, capsule_distances,
                        distance_method, sphere_distances)
from .errors import InputError, QpavoidError, RobotDescriptionError, SolverError
from .human import BodyPart, HumanGeometry, JointType, KinectHuman, TrackingState
from .robot import ControlSet, Kinematics, Robot, load_robot

__version__ = "0.1.0"

__all__ = [
    "BodyPart", "CapsuleDistance", "ControlSet", "DistanceTable", "HumanGeometry", "InputError",
    "JointType", "KinectHuman", "Kinematics", "QpavoidError", "Robot", "RobotDescriptionError",
    "SolverError", "SphereDistance", "TrackingState", "capsule_distances", "distance_method",
    "load_robot", "sphere_distances",
]
