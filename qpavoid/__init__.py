"""qpavoid: real-time collision avoidance between a cobot arm and the person beside it.

The modules follow the data flow of one control tick:

* :mod:`qpavoid.robot`      the arm (Pinocchio model, control points, capsules)
* :mod:`qpavoid.human`      the Kinect v2 skeleton and the upper-body model
* :mod:`qpavoid.distances`  robot-human distance tables (spheres, capsules)
* :mod:`qpavoid.laws`       the paper's eqs. (2)-(9)
* :mod:`qpavoid.task`       the planned path and its inverse kinematics
* :mod:`qpavoid.controller` what controllers share; :mod:`qpavoid.analytic` the paper's
  controller; :mod:`qpavoid.qp` the QP controller
* :mod:`qpavoid.simulation`, :mod:`qpavoid.scenarios`, :mod:`qpavoid.recording`,
  :mod:`qpavoid.io`, :mod:`qpavoid.compare`, :mod:`qpavoid.sweep`, :mod:`qpavoid.cli`
"""

from .analytic import AnalyticConfig, AnalyticController
from .controller import Command, ControllerConfig
from .distances import (
    CapsuleDistance,
    DistanceTable,
    SphereDistance,
    capsule_distances,
    distance_method,
    sphere_distances,
)
from .errors import (
    IKNotConvergedError,
    InputError,
    QpavoidError,
    RecordingError,
    RobotDescriptionError,
    SolverError,
)
from .frames import HumanFrame
from .human import BodyPart, HumanGeometry, JointType, KinectHuman, TrackingState
from .laws import AvoidanceConfig
from .qp import QPConfig, QPController
from .robot import ControlSet, Kinematics, Robot, load_robot
from .simulation import SimConfig, simulate
from .task import ArcPath, inverse_kinematics

__version__ = "0.1.0"

__all__ = [
    "AnalyticConfig",
    "AnalyticController",
    "ArcPath",
    "AvoidanceConfig",
    "BodyPart",
    "CapsuleDistance",
    "Command",
    "ControlSet",
    "ControllerConfig",
    "DistanceTable",
    "HumanFrame",
    "HumanGeometry",
    "IKNotConvergedError",
    "InputError",
    "JointType",
    "KinectHuman",
    "Kinematics",
    "QPConfig",
    "QPController",
    "QpavoidError",
    "RecordingError",
    "Robot",
    "RobotDescriptionError",
    "SimConfig",
    "SolverError",
    "SphereDistance",
    "TrackingState",
    "capsule_distances",
    "distance_method",
    "inverse_kinematics",
    "load_robot",
    "simulate",
    "sphere_distances",
]
