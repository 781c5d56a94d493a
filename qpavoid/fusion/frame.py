"""What the fusion returns each time it fuses (:meth:`qpavoid.fusion.fuser.Fuser.fuse`): every
person known, their joints, confidence and the record of how they were merged."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from qpavoid.human.frames import HumanFrame

__all__ = ["FusedFrame", "FusedPerson", "OutlierChoice"]


class OutlierChoice(NamedTuple):
    """Sensors that disagreed on a joint: the one ``chosen`` and the ones dropped."""

    joint: int
    chosen: str
    rejected: tuple[str, ...]


class FusedPerson(NamedTuple):
    """One person at the fusion time.

    Attributes
    ----------
    id
        Stable id (:class:`~qpavoid.fusion.association.PersonTrack`).
    frame
        Joints in the robot base frame, m, and states (NaN and NotTracked where no
        sensor sees the joint).
    confidence
        (J,) per joint, in [0, 1].
    sensors
        Names of the sensors that contributed.
    outliers
        Joints on which sensors disagreed, and who was believed.
    mirrored
        Sensors whose body was relabelled left/right.
    flag
        Why this person is suspect ("" if not): appeared near the robot never seen
        approaching, or seen by one sensor only where another looks (a forged or phantom
        body). The controllers still treat them as a person.
    captured_s
        The capture time of the oldest sensor frame behind this person, s (controller
        clock; ``-inf``: no sensor sees them now): the person is as old as that frame.
    """

    id: int
    frame: HumanFrame
    confidence: np.ndarray
    sensors: tuple[str, ...]
    outliers: tuple[OutlierChoice, ...]
    mirrored: tuple[str, ...]
    flag: str = ""
    captured_s: float = float("-inf")


class FusedFrame(NamedTuple):
    """Every person known at fusion time ``t`` (s, controller clock); the capture time of
    the newest frame used (``captured_s``: which fusion is new) and of the oldest frame
    behind anybody seen (``oldest_s``: how old the people are, which speed and separation
    counts), both ``-inf`` if none: nobody seen by a fresh frame."""

    t: float
    people: tuple[FusedPerson, ...]
    captured_s: float = float("-inf")
    oldest_s: float = float("-inf")
