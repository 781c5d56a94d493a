"""A run reproduced from the bag qpavoid wrote of it (``qpavoid run --human RUN.mcap``).

The bag carries the run's settings and what its controller was handed, call by call
(:mod:`qpavoid.control.journal`); a controller built from the same settings, handed the same,
gives the run's commands again. That is how a live run (a ROS 2 cell's, an arm's) is
checked, explained or debugged after the fact, without the cell: each command against
the one the bag recorded.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from qpavoid.control.journal import reproduce
from qpavoid.core.errors import RecordingError
from qpavoid.experiments.run_spec import RunSpec
from qpavoid.experiments.runs import build_controller, spec_robot
from qpavoid.sensing.bags import read_run

__all__ = ["REPRODUCED_RADPS", "Reproduction", "reproduce_bag"]

#: The largest difference, rad/s, at which a command counts as the recorded one (the same
#: machine reproduces them to the bit; another CPU's floating point may differ in the
#: last bits, which the QP's iterations can grow).
REPRODUCED_RADPS = 1e-9


@dataclass(frozen=True)
class Reproduction:
    """The commands of a bag's run given again.

    Attributes
    ----------
    spec
        The run's settings, as recorded.
    commands
        (T, nv) the commands given again, rad/s.
    recorded
        (T, nv) the bag's, rad/s.
    """

    spec: RunSpec
    commands: np.ndarray
    recorded: np.ndarray

    @property
    def largest_difference_radps(self) -> float:
        if self.commands.shape != self.recorded.shape:
            return float("inf")
        return float(np.abs(self.commands - self.recorded).max(initial=0.0))

    def line(self, path: str) -> str:
        """What it says: how many commands, of which run, and the largest difference."""
        return (
            f"reproduced the {len(self.recorded)} commands of {path} ({self.spec.label}, "
            f"{self.spec.controller} controller on {self.spec.robot}): largest difference "
            f"{self.largest_difference_radps:.3g} rad/s"
        )


def reproduce_bag(path: str | Path) -> Reproduction:
    """The run in the bag at ``path`` (one qpavoid wrote with ``--bag``), given again.

    Raises
    ------
    RecordingError
        For a bag that is not such a run, whose settings no longer build (a file they
        name is gone), or whose commands are not reproduced within
        :data:`REPRODUCED_RADPS` (one line: the first tick that differs, and by how much).
    """
    record = read_run(path)
    names = {f.name for f in fields(RunSpec)}
    try:
        settings = json.loads(record.spec_json)
        spec = RunSpec(**{k: v for k, v in settings.items() if k in names})
    except (ValueError, TypeError) as exc:
        raise RecordingError(
            f"{path}: the run's settings on /qpavoid/run do not read: {exc}", path=str(path)
        ) from None
    robot = spec_robot(spec)
    got = reproduce(build_controller(spec, robot), record.entries)
    result = Reproduction(spec, got, record.commands)
    if result.largest_difference_radps > REPRODUCED_RADPS:
        if got.shape != record.commands.shape:
            why = f"{len(got)} commands given again, the bag has {len(record.commands)}"
        else:
            diff = np.abs(got - record.commands).max(axis=1)
            k = int(np.argmax(diff > REPRODUCED_RADPS))
            why = f"tick {k} differs first, by {diff[k]:.3g} rad/s"
        raise RecordingError(
            f"{path}: the run's commands are not reproduced ({why}; the largest "
            f"difference {result.largest_difference_radps:.3g} rad/s): another version of "
            "qpavoid, of the robot description or of a file the settings name?",
            path=str(path),
        )
    return result
