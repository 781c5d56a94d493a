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

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the names as type checkers and editors see them
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

#: Where each public name lives: imported on first use (PEP 562), so that `import qpavoid`
#: (and the command line's first moments, when Ctrl-C must already be handled) stays light.
_LAZY = {
    "AnalyticConfig": "analytic",
    "AnalyticController": "analytic",
    "ArcPath": "task",
    "AvoidanceConfig": "laws",
    "BodyPart": "human",
    "CapsuleDistance": "distances",
    "Command": "controller",
    "ControlSet": "robot",
    "ControllerConfig": "controller",
    "DistanceTable": "distances",
    "HumanFrame": "frames",
    "HumanGeometry": "human",
    "IKNotConvergedError": "errors",
    "InputError": "errors",
    "JointType": "human",
    "KinectHuman": "human",
    "Kinematics": "robot",
    "QPConfig": "qp",
    "QPController": "qp",
    "QpavoidError": "errors",
    "RecordingError": "errors",
    "Robot": "robot",
    "RobotDescriptionError": "errors",
    "SimConfig": "simulation",
    "SolverError": "errors",
    "SphereDistance": "distances",
    "TrackingState": "human",
    "capsule_distances": "distances",
    "distance_method": "distances",
    "inverse_kinematics": "task",
    "load_robot": "robot",
    "simulate": "simulation",
    "sphere_distances": "distances",
}


def __getattr__(name: str) -> object:
    """``qpavoid.NAME`` for the public names, imported on first use."""
    if name in _LAZY:
        value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'qpavoid' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *_LAZY])


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
