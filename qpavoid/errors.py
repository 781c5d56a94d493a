"""The library's own exceptions.

Every error names the bad value, so that a log line is enough to find the cause.
"""

from __future__ import annotations


class QpavoidError(Exception):
    """Base class of every error raised by qpavoid."""


class InputError(QpavoidError, ValueError):
    """An argument has the wrong shape, a non-finite value or an unknown name."""


class RobotDescriptionError(QpavoidError):
    """A robot description (URDF or control-point file) cannot be found or is inconsistent."""


class SolverError(QpavoidError):
    """A QP solver is unavailable or did not return a usable solution."""
