"""qpavoid: real-time collision avoidance between a cobot arm and the person beside it.

One subpackage per stage of the data flow, each importing only the stages above it in
this list (the contracts of ``pyproject.toml``, checked by import-linter):

* :mod:`qpavoid.core`         errors, argument checks, vector helpers, compiling, signals
* :mod:`qpavoid.arm`          the arm: its description, Pinocchio model, braking
* :mod:`qpavoid.human`        skeleton formats, frames, the body model, postures
* :mod:`qpavoid.sensing`      calibration, keys, recordings, the wire, the UDP receiver
* :mod:`qpavoid.fusion`       several sensors' bodies merged into people
* :mod:`qpavoid.perception`   tracked people as inflated capsules
* :mod:`qpavoid.distance`     robot-human distance tables (spheres, capsules)
* :mod:`qpavoid.laws`         the paper's eqs. (2)-(9) and speed and separation
* :mod:`qpavoid.control`      the tick's state, the paper's controller, the QP controller
* :mod:`qpavoid.loop`         the simulated and real-time loops, camera, truth, log, metrics
* :mod:`qpavoid.scenarios`    the people a run is about
* :mod:`qpavoid.output`       run files, plots, the browser replay, the live view
* :mod:`qpavoid.experiments`  runs, comparisons, campaigns, the benchmark
* :mod:`qpavoid.cli`          the command line
"""

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the names as type checkers and editors see them
    from .arm.control_points import ControlSet
    from .arm.ik import inverse_kinematics
    from .arm.model import Kinematics, Robot, load_robot
    from .control.analytic import AnalyticConfig, AnalyticController
    from .control.path import ArcPath
    from .control.qp import QPConfig, QPController
    from .control.tick import Command, ControllerConfig
    from .core.errors import (
        IKNotConvergedError,
        InputError,
        QpavoidError,
        RecordingError,
        RobotDescriptionError,
        SolverError,
    )
    from .distance.capsules import CapsuleDistance
    from .distance.coal_capsules import CoalCapsuleDistance
    from .distance.methods import (
        SphereDistance,
        capsule_distances,
        distance_method,
        sphere_distances,
    )
    from .distance.table import DistanceTable
    from .human.body import BodyModel, HumanGeometry, KinectHuman
    from .human.body_parts import BodyPart
    from .human.frames import HumanFrame
    from .human.kinect_v2 import JointType, TrackingState
    from .human.skeleton import SkeletonFormat
    from .laws.avoidance import AvoidanceConfig
    from .loop.simulation import SimConfig, simulate

#: Where each public name lives: imported on first use (PEP 562), so that `import qpavoid`
#: (and the command line's first moments, when Ctrl-C must already be handled) stays light.
_LAZY = {
    "AnalyticConfig": "control.analytic",
    "AnalyticController": "control.analytic",
    "ArcPath": "control.path",
    "AvoidanceConfig": "laws.avoidance",
    "BodyModel": "human.body",
    "BodyPart": "human.body_parts",
    "CapsuleDistance": "distance.capsules",
    "CoalCapsuleDistance": "distance.coal_capsules",
    "Command": "control.tick",
    "ControlSet": "arm.control_points",
    "ControllerConfig": "control.tick",
    "DistanceTable": "distance.table",
    "HumanFrame": "human.frames",
    "HumanGeometry": "human.body",
    "IKNotConvergedError": "core.errors",
    "InputError": "core.errors",
    "JointType": "human.kinect_v2",
    "KinectHuman": "human.body",
    "Kinematics": "arm.model",
    "QPConfig": "control.qp",
    "QPController": "control.qp",
    "QpavoidError": "core.errors",
    "RecordingError": "core.errors",
    "Robot": "arm.model",
    "RobotDescriptionError": "core.errors",
    "SimConfig": "loop.simulation",
    "SkeletonFormat": "human.skeleton",
    "SolverError": "core.errors",
    "SphereDistance": "distance.methods",
    "TrackingState": "human.kinect_v2",
    "capsule_distances": "distance.methods",
    "distance_method": "distance.methods",
    "inverse_kinematics": "arm.ik",
    "load_robot": "arm.model",
    "simulate": "loop.simulation",
    "sphere_distances": "distance.methods",
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
    "BodyModel",
    "BodyPart",
    "CapsuleDistance",
    "CoalCapsuleDistance",
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
    "SkeletonFormat",
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
