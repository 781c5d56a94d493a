"""The library's own exceptions.

Every error names the bad value in its message, so that a log line is enough to find the
cause, and carries it as attributes, so that a program can act on it::

    try:
        q = inverse_kinematics(robot, target)
    except IKNotConvergedError as exc:
        q = exc.q if exc.residual < 1e-3 else fallback    # the last iterate, if close

The attributes are keyword arguments of the constructor (the message is the only
positional one) and every error survives pickling with them (errors cross process pools).
No ``numpy.linalg.LinAlgError`` leaves the library: a failed decomposition is a
:class:`SolverError`, or a stop with a reason inside a controller tick.
"""

from __future__ import annotations

import pickle
from pathlib import Path

__all__ = [
    "ArmError",
    "CalibrationError",
    "DataFileError",
    "IKNotConvergedError",
    "InputError",
    "QpavoidError",
    "RecordingError",
    "RobotDescriptionError",
    "SkeletonFormatError",
    "SolverError",
    "Terminated",
]


class QpavoidError(Exception):
    """Base class of every error raised by qpavoid.

    Subclasses take the message as their only positional argument and the offending
    values as keyword arguments stored as attributes; all of them pickle with those
    attributes.
    """

    def __reduce__(self) -> tuple[object, ...]:
        attrs = {k: _picklable(v) for k, v in self.__dict__.items()}
        return _rebuild, (type(self), self.args, attrs)


def _picklable(value: object) -> object:
    """``value``, or its ``repr`` if it cannot be pickled (an error must always cross)."""
    try:
        pickle.dumps(value)
    except Exception:
        return repr(value)
    return value


def _rebuild(cls: type, args: tuple, attrs: dict) -> QpavoidError:
    """Unpickle an error: the positional message, then the keyword attributes."""
    err = cls(*args)
    err.__dict__.update(attrs)
    return err


class InputError(QpavoidError, ValueError):
    """An argument has the wrong shape, a non-finite value or an unknown name.

    Attributes
    ----------
    name
        The argument (or option, e.g. ``"--rate"``) at fault, if known.
    value
        Its offending value as given (for an array, the array: ``value.shape`` is the
        shape it had), if known.
    """

    def __init__(self, message: str, *, name: str | None = None, value: object = None):
        super().__init__(message)
        self.name, self.value = name, value


class DataFileError(InputError):
    """A data file (or the object read from one) is missing, unreadable or inconsistent.

    Attributes
    ----------
    path
        The file at fault, if known.
    name, value
        The key, array or column at fault and its offending value (as for
        :class:`InputError`).
    """

    def __init__(
        self,
        message: str,
        *,
        path: str | Path | None = None,
        name: str | None = None,
        value: object = None,
    ):
        super().__init__(message, name=name, value=value)
        self.path = path


class RecordingError(DataFileError):
    """A recording (or run log) file is missing, unreadable or not in the expected format.

    Attributes
    ----------
    path
        The file at fault.
    name, value
        The array or column at fault and its value, when the file could be read but its
        content is invalid (as for :class:`InputError`).
    """


class SkeletonFormatError(DataFileError):
    """A skeleton format or body model (file or object) that is missing or inconsistent
    (:mod:`qpavoid.human.skeleton`); ``name`` is the key at fault (``"joints[3].parent"``)."""


class CalibrationError(InputError):
    """A sensor calibration file is missing, malformed, or does not fit the data.

    Attributes
    ----------
    path
        The calibration file, if known.
    sensor
        The sensor at fault (a name in the file or in the data), if known.
    name, value
        The key at fault and its value (as for :class:`InputError`).
    """

    def __init__(
        self,
        message: str,
        *,
        path: str | Path | None = None,
        sensor: str | None = None,
        name: str | None = None,
        value: object = None,
    ):
        super().__init__(message, name=name, value=value)
        self.path, self.sensor = path, sensor


class IKNotConvergedError(InputError):
    """Inverse kinematics did not reach its target within the tolerance.

    An :class:`InputError` (the target is unreachable, at least on the branch of the
    seed), so ``except InputError`` clauses also catch it.

    Attributes
    ----------
    target
        The target pose (4, 4) (or position) that was not reached.
    residual
        Norm of the final error ``log6`` (m and rad mixed, as the solver minimises it).
    iterations
        Number of iterations run.
    q
        The last iterate (nq,), rad: inside the joint limits, possibly usable if close.
    """

    def __init__(
        self,
        message: str,
        *,
        target: object = None,
        residual: float | None = None,
        iterations: int | None = None,
        q: object = None,
    ):
        super().__init__(message, name="target", value=target)
        self.target, self.residual, self.iterations, self.q = target, residual, iterations, q


class RobotDescriptionError(QpavoidError):
    """A robot description (URDF or control-point file) cannot be found or is inconsistent.

    Attributes
    ----------
    path
        The description file or folder at fault (or the name asked for), if known.
    name, value
        The key, frame or robot name at fault and its value, if known.
    """

    def __init__(
        self,
        message: str,
        *,
        path: str | Path | None = None,
        name: str | None = None,
        value: object = None,
    ):
        super().__init__(message)
        self.path, self.name, self.value = path, name, value


class SolverError(QpavoidError):
    """A numerical solver is unavailable or did not return a usable solution.

    Raised for a QP solver that is not installed or unknown, and for a failed matrix
    decomposition (LAPACK). Inside a controller tick it never escapes: the robot stops
    with the message as the reason.

    Attributes
    ----------
    solver
        The solver or routine (e.g. ``"osqp"``, ``"lapack.dgesdd"``), if known.
    status
        Its status or error code (e.g. LAPACK's ``info``), if known.
    """

    def __init__(self, message: str, *, solver: str | None = None, status: object = None):
        super().__init__(message)
        self.solver, self.status = solver, status


class ArmError(QpavoidError):
    """The arm cannot be driven: unreachable, refusing the connection, its state stalled,
    a command it rejected, or a fault it reports.

    Attributes
    ----------
    arm
        Which arm (e.g. ``"franka:127.0.0.1"``), if known.
    reason
        A short machine-readable cause (``"unreachable"``, ``"stalled"``, ``"rejected"``,
        ``"fault"``, ``"limit"``; ``"model"``: not the arm the description is), if known.
    value
        The offending value (a command, a state's age), if any.
    """

    def __init__(
        self,
        message: str,
        *,
        arm: str | None = None,
        reason: str | None = None,
        value: object = None,
    ):
        super().__init__(message)
        self.arm, self.reason, self.value = arm, reason, value


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the program is (the command line's handler, or a library
    that turned its own into this), so that it ends as on Ctrl-C: workers stopped,
    staging folders removed, nothing written. Not a :class:`QpavoidError`: an interrupt."""
