"""How a camera's numbers become the library's: its confidence as tracking states, its
joints as the body's landmarks, as data read from its format file.

Two small frozen tables a format file may hold beside its joints
(:class:`~qpavoid.human.skeleton.SkeletonFormat` parses them, checks their joint names and
keeps them):

* :class:`Confidence`: what a joint's confidence value is (``[confidence]``): the
  library's own states (``kind = "states"``: the Kinect v2), a level that a table turns
  into a state (``kind = "levels"``: the Azure Kinect Body Tracking SDK's NONE, LOW,
  MEDIUM, HIGH), or a score in a range with two thresholds (``kind = "score"``: the ZED's
  0-100 keypoint confidence, MediaPipe's 0-1 visibility).
* :class:`LandmarkRule`: one landmark as a weighted mean of joints,
  ``p = sum_i w_i x_i`` with ``sum_i w_i = 1`` (a joint as it is, the mid-point of two, a
  point along a bone), and the position uncertainty the rule adds, m. The
  ``[landmarks]`` table of a camera's format maps the body's landmarks onto its joints;
  its ``[simulate]`` table maps the other way, for the simulated camera of the format.

In a file a rule is a joint's name (``SpineBase = "PELVIS"``), a mean of joints
(``{ mean = ["HIP_LEFT", "HIP_RIGHT"] }``), or a point along a segment
(``{ lerp = ["NECK", "HEAD"], t = 0.5 }``: ``a + t (b - a)``, ``t`` outside [0, 1]
extrapolates), or any weights summing to 1 (``{ weights = { HEAD = 1.0, SHOULDER_LEFT =
0.4, SPINE_CHEST = -0.4 } }``: a point offset from one joint along a body direction); a
table form takes ``uncertainty_m``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, NoReturn

import numpy as np

from qpavoid.core.errors import SkeletonFormatError

__all__ = ["CONFIDENCE_KINDS", "Confidence", "LandmarkRule", "is_number", "only_keys", "parse_rule"]

#: The kinds of a joint's confidence value a format may declare.
CONFIDENCE_KINDS = ("states", "levels", "score")
#: The library's tracking states (not tracked, inferred, tracked).
_STATES = (0, 1, 2)
#: Largest uncertainty a rule may add, m: a derived landmark further off than this is no
#: landmark (the longest bone of the body is 0.40 m).
MAX_RULE_UNCERTAINTY_M = 0.5


def _fail(message: str, name: str, value: object) -> NoReturn:
    raise SkeletonFormatError(message, name=name, value=value)


def is_number(value: object) -> bool:
    """A finite int or float (not a bool): a number a format file may hold."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def only_keys(data: Mapping[str, object], known: tuple[str, ...], prefix: str) -> None:
    """Refuse a key of ``data`` not in ``known`` (a misspelt key would be ignored)."""
    unknown = [k for k in data if k not in known]
    if unknown:
        _fail(
            f"unknown key {prefix}{unknown[0]}; the keys are {', '.join(known)}",
            f"{prefix}{unknown[0]}",
            data[unknown[0]],
        )


@dataclass(frozen=True)
class Confidence:
    """What a joint's confidence value is, and the tracking state it gives.

    Attributes
    ----------
    kind
        ``"states"``: the value is the library's state (0 not tracked, 1 inferred,
        2 tracked). ``"levels"``: a whole number ``k`` in ``[0, len(levels))`` whose state
        is ``levels[k]``. ``"score"``: a number in ``range`` that is tracked at or above
        ``tracked_at``, inferred at or above ``inferred_at``, not tracked below.
    levels
        The state of each level (``"levels"`` only).
    level_names
        The SDK's name of each level, for messages (``"levels"`` only).
    range
        (low, high) of a score (``"score"`` only).
    inferred_at, tracked_at
        A score's thresholds (``"score"`` only), ``low <= inferred_at <= tracked_at <=
        high``; the format file gives their reason.
    """

    kind: str = "states"
    levels: tuple[int, ...] = ()
    level_names: tuple[str, ...] = ()
    range: tuple[float, float] = (0.0, 0.0)
    inferred_at: float = 0.0
    tracked_at: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in CONFIDENCE_KINDS:
            _fail(
                f"confidence.kind must be one of {CONFIDENCE_KINDS}, got {self.kind!r}",
                "confidence.kind",
                self.kind,
            )
        if self.kind == "levels":
            if not self.levels or not all(
                isinstance(s, int) and not isinstance(s, bool) and s in _STATES for s in self.levels
            ):
                _fail(
                    f"confidence.levels must be states (0, 1 or 2), one per level, got "
                    f"{self.levels!r}",
                    "confidence.levels",
                    self.levels,
                )
            if self.level_names and len(self.level_names) != len(self.levels):
                _fail(
                    "confidence.level_names must name each level",
                    "confidence.level_names",
                    self.level_names,
                )
        if self.kind == "score":
            low, high = self.range if len(self.range) == 2 else (math.nan, math.nan)
            values = (low, self.inferred_at, self.tracked_at, high)
            if not all(is_number(v) for v in values) or not (
                low <= self.inferred_at <= self.tracked_at <= high and low < high
            ):
                _fail(
                    "confidence needs range = [low, high] and low <= inferred_at <= "
                    f"tracked_at <= high, got range {self.range!r}, inferred_at "
                    f"{self.inferred_at!r}, tracked_at {self.tracked_at!r}",
                    "confidence",
                    values,
                )

    @classmethod
    def from_mapping(cls, data: object) -> Confidence:
        """The ``[confidence]`` table of a format file."""
        if not isinstance(data, dict):
            _fail(f"confidence must be a table, got {data!r}", "confidence", data)
        only_keys(
            data,
            ("kind", "levels", "level_names", "range", "inferred_at", "tracked_at"),
            "confidence.",
        )
        args: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in data.items()}
        return cls(**args)

    def states(self, value: np.ndarray) -> np.ndarray:
        """The tracking states (int8) of confidence values ``value`` (any shape).

        Raises
        ------
        ValueError
            For a value this confidence cannot have (a level out of the table, a score out
            of range, NaN); the caller names the frame and the joint.
        """
        v = np.asarray(value, dtype=np.float64)
        if not np.all(np.isfinite(v)):
            raise ValueError("a confidence is not a finite number")
        if self.kind == "score":
            low, high = self.range
            if np.any((v < low) | (v > high)):
                raise ValueError(f"a confidence is outside [{low:g}, {high:g}]")
            return np.where(v >= self.tracked_at, 2, np.where(v >= self.inferred_at, 1, 0)).astype(
                np.int8
            )
        table = _STATES if self.kind == "states" else self.levels
        if np.any((v != np.round(v)) | (v < 0) | (v >= len(table))):
            what = "0, 1 or 2" if self.kind == "states" else f"a level 0 to {len(table) - 1}"
            raise ValueError(f"a confidence is not {what}")
        return np.asarray(table, dtype=np.int8)[v.astype(np.int64)]

    def describe(self) -> str:
        """The accepted values, for messages."""
        if self.kind == "score":
            return f"a score in [{self.range[0]:g}, {self.range[1]:g}]"
        if self.kind == "levels":
            names = self.level_names or tuple(str(k) for k in range(len(self.levels)))
            return "a level " + ", ".join(f"{k} ({n})" for k, n in enumerate(names))
        return "0 (not tracked), 1 (inferred) or 2 (tracked)"


@dataclass(frozen=True)
class LandmarkRule:
    """A point as a weighted mean of joints: ``p = sum_i weights[i] x[sources[i]]``.

    Attributes
    ----------
    sources
        The joints' names (of the format the rule reads).
    weights
        Their weights, summing to 1 (a point of the joints' affine hull).
    uncertainty_m
        How far the true landmark may be from the point, m (0 for a joint the camera
        measures as the landmark); added to the landmark's uncertainty radius.
    """

    sources: tuple[str, ...]
    weights: tuple[float, ...]
    uncertainty_m: float = 0.0


def parse_rule(value: object, key: str) -> LandmarkRule:
    """The rule of a ``[landmarks]`` or ``[simulate]`` entry (module docstring)."""
    if isinstance(value, str):
        return LandmarkRule((value,), (1.0,))
    if not isinstance(value, dict):
        _fail(f"{key} must be a joint name or a table, got {value!r}", key, value)
    forms = [k for k in ("joint", "mean", "lerp", "weights") if k in value]
    known = ("joint", "mean", "lerp", "weights", "t", "uncertainty_m")
    unknown = [k for k in value if k not in known]
    if unknown or len(forms) != 1:
        _fail(
            f"{key} must have one of joint, mean, lerp or weights (and t, uncertainty_m), "
            f"got {value!r}",
            key,
            value,
        )
    uncertainty = value.get("uncertainty_m", 0.0)
    if not is_number(uncertainty) or not 0.0 <= uncertainty <= MAX_RULE_UNCERTAINTY_M:
        _fail(
            f"{key}.uncertainty_m must be in [0, {MAX_RULE_UNCERTAINTY_M}] m, got {uncertainty!r}",
            f"{key}.uncertainty_m",
            uncertainty,
        )
    form = forms[0]
    joints = value[form]
    if form == "weights":
        table = joints
        if (
            not isinstance(table, dict)
            or not table
            or not all(is_number(w) for w in table.values())
            or abs(sum(table.values()) - 1.0) > 1e-9
            or not all(-1.0 <= w <= 2.0 for w in table.values())
        ):
            _fail(
                f"{key}.weights must be joint = weight pairs in [-1, 2] (as lerp's t: no "
                f"point far off its joints) summing to 1, got {table!r}",
                f"{key}.weights",
                table,
            )
        return LandmarkRule(
            tuple(table), tuple(float(w) for w in table.values()), float(uncertainty)
        )
    if form == "joint":
        joints = [joints]
    if not isinstance(joints, list) or not joints or not all(isinstance(j, str) for j in joints):
        _fail(f"{key}.{form} must name joints, got {joints!r}", f"{key}.{form}", joints)
    if form == "lerp":
        t: Any = value.get("t")
        if len(joints) != 2 or not is_number(t) or not -1.0 <= t <= 2.0:
            _fail(
                f"{key}: lerp takes two joints and t in [-1, 2], got {joints!r}, t={t!r}",
                key,
                value,
            )
        return LandmarkRule(tuple(joints), (1.0 - float(t), float(t)), float(uncertainty))
    if "t" in value:
        _fail(f"{key}: t goes with lerp only", f"{key}.t", value["t"])
    if len(set(joints)) != len(joints):
        _fail(f"{key}.{form} names a joint twice: {joints!r}", f"{key}.{form}", joints)
    n = len(joints)
    return LandmarkRule(tuple(joints), (1.0 / n,) * n, float(uncertainty))
