"""The arm's dynamics as its maker publishes them: the ``[arm]`` table of a control-point file.

How the real arm follows a velocity command and how fast it can stop is a fact of each arm,
so it lives in its description (``docs/robot.md``, "Arm"), each value with its source:

* ``reaction_time_s``: from a command to the arm starting to follow it (one period of the
  arm's real-time interface), s;
* ``max_acceleration_radps2``: every joint's acceleration (and deceleration) limit, rad/s²
  (m/s² for a prismatic joint), one for **each** joint of the URDF: an arm whose joints
  were renamed cannot silently run with another arm's limits;
* ``max_point_speed_mps``: no point of the arm moves faster, m/s;
* optional, ``rated_payload_kg``: the maker's rated payload, kg (the heaviest payload the arm
  is rated to carry at its flange; power and force limiting refuses a heavier one,
  :class:`qpavoid.arm.inertia.EffectiveMass`);
* optional, where the maker publishes them: ``max_velocity_radps`` (a joint's velocity limit
  where the maker's is lower than the URDF's), ``max_jerk_radps3`` (the rate of change of a
  joint's acceleration), ``position_limits_rad`` (a joint's ``[lower, upper]`` where the
  maker's range is narrower than the URDF's), and ``[[arm.stopping]]``, the maker's stopping
  distances and times (ISO 10218-1 Annex B), each entry for a joint or a group of joints:

  .. code-block:: toml

      [[arm.stopping]]
      joints = ["shoulder_pan_joint"]   # the joint, or the group of joints, it holds for
      category = 0                      # IEC 60204-1 stop category: 0 or 1
      speed_radps = 3.194               # the joint speed the stop started from
      distance_rad = 0.31               # how far the joint turned until it stood
      time_s = 0.244                    # how long that took
      extension = 1.0                   # the arm's extension, a fraction of its reach
      payload_kg = 5.0                  # the payload at the flange

* ``[arm.sources]``: each fact's source, as text; required for every optional fact (a
  maker's number without its document cannot be checked), optional for the three above.

A maker's stop from speed v₀ that takes T₀ and travels D₀ brakes, read as a constant
deceleration, at ``v₀ / T₀`` (the stop lasts T₀) and at ``v₀² / (2 D₀)`` (it travels D₀);
the smaller of the two, :attr:`StoppingData.deceleration_radps2`, is a ramp that from v₀
lasts at least T₀ **and** travels at least D₀. Speed and separation monitoring brakes each
joint at the slower of that and the joint's acceleration limit
(:meth:`ArmDynamics.braking_deceleration_radps2`).

:func:`read_arm` reads the table: its shape (types, bounds, keys) is a schema,
:mod:`qpavoid.arm.dynamics_schema` (every value is bounded: a value beyond a bound is a
unit error or a typo); the joints it names are checked against the URDF's here. Every
refusal is a one-line :class:`RobotDescriptionError` naming the file, the key's path and
the fix.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgspec
import numpy as np

from qpavoid.arm.dynamics_schema import (
    MAX_PAYLOAD_KG,
    OPTIONAL_KEYS,
    ArmOf,
    ArmTable,
)
from qpavoid.arm.fields import refused
from qpavoid.core.errors import RobotDescriptionError
from qpavoid.core.schema import convert

__all__ = [
    "MAX_PAYLOAD_KG",
    "ArmDynamics",
    "StoppingData",
    "arm_dynamics",
    "read_arm",
    "tighter_limits",
]


Pairs = tuple[tuple[str, float], ...]


@dataclass(frozen=True)
class StoppingData:
    """One stop the maker measured (``[[arm.stopping]]``, ISO 10218-1 Annex B).

    Attributes
    ----------
    joints
        The joint, or the group of joints, the data holds for.
    category
        IEC 60204-1 stop category: 0 (power removed at once) or 1 (a controlled stop, then
        power removed).
    speed_radps
        v₀: the joint speed the stop started from, rad/s.
    distance_rad
        D₀: how far the joint turned from the stop signal until it stood, rad.
    time_s
        T₀: how long that took, s.
    extension
        The arm's extension during the measurement, a fraction of its reach (1.0: stretched).
    payload_kg
        The payload at the flange during the measurement, kg.
    """

    joints: tuple[str, ...]
    category: int
    speed_radps: float
    distance_rad: float
    time_s: float
    extension: float
    payload_kg: float

    @property
    def deceleration_radps2(self) -> float:
        """The constant deceleration that is no faster than this stop in time or distance:

            a = min(v₀ / T₀, v₀² / (2 D₀))

        From v₀ a ramp at a lasts ``v₀ / a ≥ T₀`` and travels ``v₀² / (2a) ≥ D₀``. It reads
        the maker's whole stop (its detection, the brakes' engaging and the braking) as
        braking; from other speeds it scales as a constant deceleration does (a stop from
        v takes ``v / a``), which the data, measured at one speed, cannot refine.
        """
        v = self.speed_radps
        return min(v / self.time_s, v * v / (2.0 * self.distance_rad))


@dataclass(frozen=True)
class ArmDynamics:
    """How the real arm follows a velocity command and how fast it can move (``[arm]``).

    Used by the simulated arm (:class:`~qpavoid.arm.braking.ArmResponse`) and by speed and
    separation monitoring (:mod:`qpavoid.laws.ssm`) unless their settings say otherwise.

    Attributes
    ----------
    reaction_time_s
        From a command to the arm starting to follow it, s.
    max_acceleration_radps2
        ``(joint name, limit)`` pairs: each joint's acceleration (and deceleration)
        limit, rad/s², every joint of the URDF.
    max_point_speed_mps
        No point of the arm moves faster than this, m/s: a speed and separation bound
        above it cannot bind, so its row is left out.
    sources
        ``(fact, source)`` pairs: where each value comes from (the file's ``[arm.sources]``).
    max_velocity_radps
        ``(joint name, limit)`` pairs: the maker's velocity limits, rad/s, for the joints
        it gives (the tighter of these and the URDF's hold: :func:`tighter_limits`).
    max_jerk_radps3
        ``(joint name, limit)`` pairs: the maker's jerk limits, rad/s³, for the joints it
        gives; a joint without one changes its acceleration at once.
    position_limits_rad
        ``(joint name, (lower, upper))`` pairs: the maker's position limits, rad, for the
        joints it gives (intersected with the URDF's: :func:`tighter_limits`).
    stopping
        The maker's stopping distances and times.
    rated_payload_kg
        The maker's rated payload, kg (the heaviest it may carry at its flange), or None
        where the description gives none.
    """

    reaction_time_s: float
    max_acceleration_radps2: Pairs
    max_point_speed_mps: float
    sources: tuple[tuple[str, str], ...] = ()
    max_velocity_radps: Pairs = ()
    max_jerk_radps3: Pairs = ()
    position_limits_rad: tuple[tuple[str, tuple[float, float]], ...] = ()
    stopping: tuple[StoppingData, ...] = ()
    rated_payload_kg: float | None = None

    def stopping_deceleration_radps2(self) -> Pairs:
        """``(joint, a)`` for each joint the maker's stopping data cover: the smallest
        :attr:`StoppingData.deceleration_radps2` of the entries naming it (the slowest of
        the stops measured, whatever its category, extension or payload), in URDF order."""
        slowest: dict[str, float] = {}
        for entry in self.stopping:
            for name in entry.joints:
                a = entry.deceleration_radps2
                slowest[name] = min(a, slowest.get(name, math.inf))
        return tuple((n, slowest[n]) for n, _ in self.max_acceleration_radps2 if n in slowest)

    def braking_deceleration_radps2(self) -> Pairs:
        """``(joint, a_j)`` for every joint: the deceleration a stop can count on, the slower
        of the joint's acceleration limit and the maker's stopping data,

            a_j = min(max_acceleration_j, min over its stops of min(v₀/T₀, v₀²/(2 D₀)))

        (:attr:`max_acceleration_radps2` itself, unchanged, without stopping data)."""
        maker = dict(self.stopping_deceleration_radps2())
        if not maker:
            return self.max_acceleration_radps2
        return tuple((n, min(a, maker.get(n, math.inf))) for n, a in self.max_acceleration_radps2)


def tighter_limits(
    arm: ArmDynamics,
    path: Path,
    joint_names: Sequence[str],
    lower_rad: np.ndarray,
    upper_rad: np.ndarray,
    velocity_radps: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The joints' limits that hold: the tighter of the URDF's and the maker's.

    ``lower = max(urdf, maker)``, ``upper = min(urdf, maker)``, ``velocity = min(urdf,
    maker)`` for the joints the maker gives; the others keep the URDF's.

    Parameters
    ----------
    arm
        The description's ``[arm]``.
    path
        The control-point file (for the error).
    joint_names
        The joints, in the order of the arrays.
    lower_rad, upper_rad, velocity_radps
        The URDF's limits of those joints.

    Raises
    ------
    RobotDescriptionError
        If a maker's position range does not overlap the URDF's (the description holds
        two different arms).
    """
    lo, hi = np.array(lower_rad, dtype=float), np.array(upper_rad, dtype=float)
    vel = np.array(velocity_radps, dtype=float)
    index = {n: i for i, n in enumerate(joint_names)}
    for name, limit in arm.max_velocity_radps:
        if name in index:
            vel[index[name]] = min(vel[index[name]], limit)
    for name, (low, high) in arm.position_limits_rad:
        if name not in index:
            continue
        i = index[name]
        new_lo, new_hi = max(lo[i], low), min(hi[i], high)
        if not new_lo < new_hi:
            raise RobotDescriptionError(
                f"{path}: arm.position_limits_rad.{name} = [{low:g}, {high:g}] does not "
                f"overlap the URDF's [{lo[i]:g}, {hi[i]:g}]; give the maker's limits of "
                "this URDF's joint",
                path=path,
                name=f"arm.position_limits_rad.{name}",
                value=(low, high),
            )
        lo[i], hi[i] = new_lo, new_hi
    return lo, hi, vel


def read_arm(cfg: Mapping[str, Any], path: Path, joints: Sequence[str]) -> ArmDynamics:
    """The ``[arm]`` table of the control-point file ``path`` (its parsed TOML ``cfg``).

    Parameters
    ----------
    cfg
        The whole file, parsed.
    path
        The file (for the errors).
    joints
        Every joint of the URDF, locked or not (an acceleration is needed for each).

    Raises
    ------
    RobotDescriptionError
        If the table is missing, has an unknown key, lacks a needed key or a joint's
        acceleration, names a joint the URDF lacks, holds a value out of its bounds (see
        :mod:`qpavoid.arm.dynamics_schema`), or gives an optional fact without its source.
    """
    return arm_dynamics(convert(cfg, ArmOf, refused(path)).arm, path, joints)


def arm_dynamics(table: ArmTable, path: Path, joints: Sequence[str]) -> ArmDynamics:
    """The :class:`ArmDynamics` of an ``[arm]`` table of the shape its schema checked:
    each joint it names one of the URDF's ``joints``, an acceleration for each of them,
    a source for each optional fact given."""
    accel = table.max_acceleration_radps2
    if sorted(accel) != sorted(joints):
        raise RobotDescriptionError(
            f"{path}: [arm] max_acceleration_radps2 must give one limit (rad/s²) for each "
            f"joint of the URDF, {list(joints)}; it gives {sorted(accel)!r}",
            path=path,
            name="arm.max_acceleration_radps2",
            value=sorted(accel),
        )
    for key in OPTIONAL_KEYS:
        if getattr(table, key) is not None and not getattr(table.sources, key).strip():
            raise RobotDescriptionError(
                f"{path}: [arm] {key} needs its source: add {key} = "
                '"<the maker\'s document, table, page or URL>" to [arm.sources]',
                path=path,
                name=f"arm.sources.{key}",
                value=None,
            )
    stopping = table.stopping or []
    for k, entry in enumerate(stopping):
        where = f"arm.stopping[{k}].joints"
        if len(set(entry.joints)) != len(entry.joints):
            raise RobotDescriptionError(
                f"{path}: {where} must be a list of distinct joint names, got {entry.joints!r}",
                path=path,
                name=where,
                value=entry.joints,
            )
        _check_joints(entry.joints, where, path, joints)
    tables = {key: getattr(table, key) or {} for key in OPTIONAL_KEYS[:3]}
    for key, value in tables.items():
        _check_joints(list(value), f"arm.{key}", path, joints)
    for name, (low, high) in tables["position_limits_rad"].items():
        if not low < high:
            where = f"arm.position_limits_rad.{name}"
            raise RobotDescriptionError(
                f"{path}: {where} must be [lower, upper] with lower below upper, "
                f"got {[low, high]!r}",
                path=path,
                name=where,
                value=[low, high],
            )
    sources = msgspec.structs.asdict(table.sources)

    def in_order(values: Mapping[str, Any]) -> tuple[tuple[str, Any], ...]:
        return tuple((n, values[n]) for n in joints if n in values)

    return ArmDynamics(
        reaction_time_s=table.reaction_time_s,
        max_acceleration_radps2=tuple((n, float(accel[n])) for n in joints),
        max_point_speed_mps=table.max_point_speed_mps,
        sources=tuple((k, v) for k, v in sources.items() if v),
        max_velocity_radps=in_order(tables["max_velocity_radps"]),
        max_jerk_radps3=in_order(tables["max_jerk_radps3"]),
        position_limits_rad=in_order(tables["position_limits_rad"]),
        stopping=tuple(
            StoppingData(
                joints=tuple(e.joints),
                category=e.category,
                speed_radps=e.speed_radps,
                distance_rad=e.distance_rad,
                time_s=e.time_s,
                extension=e.extension,
                payload_kg=e.payload_kg,
            )
            for e in stopping
        ),
        rated_payload_kg=table.rated_payload_kg,
    )


def _check_joints(names: Sequence[str], where: str, path: Path, joints: Sequence[str]) -> None:
    """Refuse names that are not joints of the URDF."""
    unknown = [n for n in names if n not in joints]
    if unknown:
        raise RobotDescriptionError(
            f"{path}: {where}: {unknown} are not joints of the URDF; its joints are {list(joints)}",
            path=path,
            name=where,
            value=unknown,
        )
