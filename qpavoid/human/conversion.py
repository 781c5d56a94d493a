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
from dataclasses import dataclass
from typing import NoReturn

import msgspec
import numpy as np

from qpavoid.core.errors import SkeletonFormatError
from qpavoid.core.schema import convert
from qpavoid.human.format_schema import (
    CONFIDENCE_KINDS,
    MAX_RULE_UNCERTAINTY_M,
    ConfidenceTable,
    Rule,
    RuleTable,
)

__all__ = [
    "CONFIDENCE_KINDS",
    "MAX_RULE_UNCERTAINTY_M",
    "Confidence",
    "LandmarkRule",
    "is_number",
    "parse_rule",
    "refused",
    "rule_of",
]

#: The library's tracking states (not tracked, inferred, tracked).
_STATES = (0, 1, 2)


def _fail(message: str, name: str, value: object) -> NoReturn:
    raise SkeletonFormatError(message, name=name, value=value)


def is_number(value: object) -> bool:
    """A finite int or float (not a bool): a number a format file may hold."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


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
        """The ``[confidence]`` table of a format file (its shape: the schema's)."""
        return cls.from_table(convert(data, ConfidenceTable, refused, prefix="confidence"))

    @classmethod
    def from_table(cls, table: ConfidenceTable) -> Confidence:
        """The confidence of a ``[confidence]`` table its schema read."""
        return cls(
            kind=table.kind,
            levels=tuple(table.levels),
            level_names=tuple(table.level_names),
            range=table.range,
            inferred_at=table.inferred_at,
            tracked_at=table.tracked_at,
        )

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
    """The rule of a ``[landmarks]`` or ``[simulate]`` entry (module docstring): its shape
    the schema's (:data:`~qpavoid.human.format_schema.Rule`), its form checked here."""
    return rule_of(convert(value, Rule, refused, prefix=key), key)


def rule_of(rule: str | RuleTable, key: str) -> LandmarkRule:
    """The rule of an entry its schema read: one form, weights summing to 1, a ``lerp``'s
    two joints and its ``t``, the joints of a mean each once."""
    if isinstance(rule, str):
        return LandmarkRule((rule,), (1.0,))
    forms = [k for k in ("joint", "mean", "lerp", "weights") if getattr(rule, k) is not None]
    if len(forms) != 1:
        _fail(
            f"{key} must have one of joint, mean, lerp or weights (and t, uncertainty_m), "
            f"got {msgspec.structs.asdict(rule)!r}",
            key,
            rule,
        )
    uncertainty = rule.uncertainty_m
    form = forms[0]
    if rule.weights is not None:
        table = rule.weights
        if (
            not table
            or abs(sum(table.values()) - 1.0) > 1e-9
            or not all(-1.0 <= w <= 2.0 for w in table.values())
        ):
            _fail(
                f"{key}.weights must be joint = weight pairs in [-1, 2] (as lerp's t: no "
                f"point far off its joints) summing to 1, got {table!r}",
                f"{key}.weights",
                table,
            )
        return LandmarkRule(tuple(table), tuple(table.values()), uncertainty)
    joints = [rule.joint] if rule.joint is not None else (rule.mean or rule.lerp or [])
    if not joints:
        _fail(f"{key}.{form} must name joints, got {joints!r}", f"{key}.{form}", joints)
    if rule.lerp is not None:
        t = rule.t
        if len(joints) != 2 or t is None:
            _fail(
                f"{key}: lerp takes two joints and t in [-1, 2], got {joints!r}, t={t!r}",
                key,
                rule,
            )
        return LandmarkRule(tuple(joints), (1.0 - t, t), uncertainty)
    if rule.t is not None:
        _fail(f"{key}: t goes with lerp only", f"{key}.t", rule.t)
    if len(set(joints)) != len(joints):
        _fail(f"{key}.{form} names a joint twice: {joints!r}", f"{key}.{form}", joints)
    n = len(joints)
    return LandmarkRule(tuple(joints), (1.0 / n,) * n, uncertainty)


def refused(name: str, message: str, value: object) -> SkeletonFormatError:
    """A schema's refusal as a :class:`SkeletonFormatError` (the file added by its reader)."""
    return SkeletonFormatError(message, name=name, value=value)
