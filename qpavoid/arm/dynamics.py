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

:func:`read_arm` reads the table; every value is bounded (a value beyond the bounds below is
a unit error or a typo) and every refusal is a one-line :class:`RobotDescriptionError`
naming the file, the key and the fix.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from qpavoid.arm.fields import number as _number
from qpavoid.arm.fields import table as _table
from qpavoid.arm.fields import unknown_keys as _unknown_keys
from qpavoid.core.errors import RobotDescriptionError

#: Plausible bounds of the ``[arm]`` facts (a value outside is a unit error or a typo, and
#: would make speed and separation never move or never stop the arm in time): a reaction
#: slower than 0.1 s (arms react within one period of their real-time interface, 1-8 ms
#: for the arms here: 1 meant as 1 ms is refused); a joint braking below 0.1 rad/s² (10 s
#: to stop from 1 rad/s) or above 100 rad/s² (arms brake at 5-50: the iiwa 8.6-15.7, the
#: Panda 7.5-20, the UR5's elbow 19.5; in degrees, 5 rad/s² would read 286 and is
#: refused); a point faster than 10 m/s (cobots move their tool at up to 1-5 m/s).
MAX_REACTION_S = 0.1
MIN_ACCEL_RADPS2, MAX_ACCEL_RADPS2 = 0.1, 100.0
MAX_SPEED_MPS = 10.0
#: A joint's jerk: at least 1 rad/s³ (10 s to reach 10 rad/s²: a typo) and at most 10⁶ rad/s³
#: (1000 rad/s² within 1 ms: indistinguishable from no limit; Franka's are 3750-10000).
MIN_JERK_RADPS3, MAX_JERK_RADPS3 = 1.0, 1.0e6
#: A joint's velocity limit: above 0 and at most 20 rad/s (cobot joints turn at 1.3-6.3 rad/s;
#: 85 °/s written as 85 would pass unnoticed above it).
MAX_VELOCITY_RADPS = 20.0
#: A joint's position limit: within ±4π rad (two turns either way; UR joints turn ±2π; an
#: angle in degrees, 170 for 170°, lies beyond).
MAX_POSITION_RAD = 4.0 * math.pi
#: A maker's stop: within 5 s (KUKA's heavy industrial arms stop in 0.2-0.5 s; 244 written
#: for 244 ms lies beyond) and one turn (30° written as 30 lies beyond); the payload at most
#: 1000 kg (a stop's, and an arm's rated payload: above 0 and at most this).
MAX_STOP_TIME_S = 5.0
MAX_STOP_DISTANCE_RAD = 2.0 * math.pi
MAX_PAYLOAD_KG = 1000.0
#: The stop categories of IEC 60204-1 a maker's stopping data may be given for (ISO 10218-1
#: asks for both): 0, power removed at once; 1, a controlled stop, then power removed.
STOP_CATEGORIES = (0, 1)
#: Keys of the ``[arm]`` table that must be given, and those that may be (each of these
#: then needs its source in ``[arm.sources]``).
ARM_KEYS = ("reaction_time_s", "max_acceleration_radps2", "max_point_speed_mps")
OPTIONAL_KEYS = (
    "max_velocity_radps",
    "max_jerk_radps3",
    "position_limits_rad",
    "stopping",
    "rated_payload_kg",
)
#: Keys of a ``[[arm.stopping]]`` entry (all needed).
STOPPING_KEYS = (
    "joints",
    "category",
    "speed_radps",
    "distance_rad",
    "time_s",
    "extension",
    "payload_kg",
)
#: The table's shape, shown when it is missing.
EXAMPLE = (
    "reaction_time_s = 0.005, max_acceleration_radps2 = { <joint> = 10.0, ... }, "
    "max_point_speed_mps = 3.0"
)

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
        the module's constants), or gives an optional fact without its source.
    """
    table = _table(cfg, "arm", path, EXAMPLE)
    _unknown_keys(table, (*ARM_KEYS, *OPTIONAL_KEYS, "sources"), "[arm]", path, "arm")
    missing = [k for k in ARM_KEYS if k not in table]
    if missing:
        raise RobotDescriptionError(
            f"{path}: [arm] is missing key(s) {', '.join(missing)} (docs/robot.md: Arm)",
            path=path,
            name="arm",
            value=missing,
        )
    accel = table["max_acceleration_radps2"]
    if not isinstance(accel, dict) or sorted(accel) != sorted(joints):
        given = sorted(accel) if isinstance(accel, dict) else accel
        raise RobotDescriptionError(
            f"{path}: [arm] max_acceleration_radps2 must give one limit (rad/s²) for each "
            f"joint of the URDF, {list(joints)}; it gives {given!r}",
            path=path,
            name="arm.max_acceleration_radps2",
            value=given,
        )
    sources = _sources(table, path)
    where = "arm.max_acceleration_radps2"
    return ArmDynamics(
        reaction_time_s=_number(
            table["reaction_time_s"], "arm.reaction_time_s", path, 0.0, False, MAX_REACTION_S
        ),
        max_acceleration_radps2=tuple(
            (n, _number(accel[n], f"{where}.{n}", path, MIN_ACCEL_RADPS2, False, MAX_ACCEL_RADPS2))
            for n in joints
        ),
        max_point_speed_mps=_number(
            table["max_point_speed_mps"], "arm.max_point_speed_mps", path, 0.0, True, MAX_SPEED_MPS
        ),
        sources=sources,
        max_velocity_radps=_per_joint(
            table, "max_velocity_radps", path, joints, (0.0, True, MAX_VELOCITY_RADPS)
        ),
        max_jerk_radps3=_per_joint(
            table, "max_jerk_radps3", path, joints, (MIN_JERK_RADPS3, False, MAX_JERK_RADPS3)
        ),
        position_limits_rad=_position_limits(table, path, joints),
        stopping=_stopping(table, path, joints),
        rated_payload_kg=(
            _number(
                table["rated_payload_kg"], "arm.rated_payload_kg", path, 0.0, True, MAX_PAYLOAD_KG
            )
            if "rated_payload_kg" in table
            else None
        ),
    )


def _sources(table: Mapping[str, Any], path: Path) -> tuple[tuple[str, str], ...]:
    """``[arm.sources]``: a text per fact, one for each optional fact given."""
    sources = table.get("sources", {})
    if not isinstance(sources, dict) or not all(isinstance(v, str) for v in sources.values()):
        raise RobotDescriptionError(
            f"{path}: [arm.sources] must map each fact to the text of its source",
            path=path,
            name="arm.sources",
            value=sources,
        )
    _unknown_keys(sources, (*ARM_KEYS, *OPTIONAL_KEYS), "[arm.sources]", path, "arm.sources")
    for key in OPTIONAL_KEYS:
        if key in table and not sources.get(key, "").strip():
            raise RobotDescriptionError(
                f"{path}: [arm] {key} needs its source: add {key} = "
                '"<the maker\'s document, table, page or URL>" to [arm.sources]',
                path=path,
                name=f"arm.sources.{key}",
                value=None,
            )
    return tuple((str(k), v) for k, v in sources.items())


def _per_joint(
    table: Mapping[str, Any],
    key: str,
    path: Path,
    joints: Sequence[str],
    bounds: tuple[float, bool, float],
) -> Pairs:
    """An optional ``{ <joint> = number }`` table, in URDF order (empty if not given)."""
    if key not in table:
        return ()
    value = _joint_table(table[key], f"arm.{key}", path, joints, "{ <joint> = number, ... }")
    low, strict, high = bounds
    return tuple(
        (n, _number(value[n], f"arm.{key}.{n}", path, low, strict, high))
        for n in joints
        if n in value
    )


def _position_limits(
    table: Mapping[str, Any], path: Path, joints: Sequence[str]
) -> tuple[tuple[str, tuple[float, float]], ...]:
    """The optional ``position_limits_rad = { <joint> = [lower, upper] }``, in URDF order."""
    key = "position_limits_rad"
    if key not in table:
        return ()
    shape = "{ <joint> = [lower, upper], ... }"
    value = _joint_table(table[key], f"arm.{key}", path, joints, shape)
    out = []
    for n in joints:
        if n not in value:
            continue
        pair, where = value[n], f"arm.{key}.{n}"
        if not isinstance(pair, list) or len(pair) != 2:
            raise RobotDescriptionError(
                f"{path}: {where} must be [lower, upper] in rad, got {pair!r}",
                path=path,
                name=where,
                value=pair,
            )
        low, high = (
            _number(x, where, path, -MAX_POSITION_RAD, False, MAX_POSITION_RAD) for x in pair
        )
        if not low < high:
            raise RobotDescriptionError(
                f"{path}: {where} must be [lower, upper] with lower below upper, got {pair!r}",
                path=path,
                name=where,
                value=pair,
            )
        out.append((n, (low, high)))
    return tuple(out)


def _stopping(
    table: Mapping[str, Any], path: Path, joints: Sequence[str]
) -> tuple[StoppingData, ...]:
    """The optional ``[[arm.stopping]]`` entries."""
    if "stopping" not in table:
        return ()
    entries = table["stopping"]
    if (
        not isinstance(entries, list)
        or not entries
        or not all(isinstance(e, dict) for e in entries)
    ):
        raise RobotDescriptionError(
            f"{path}: arm.stopping must be one or more [[arm.stopping]] tables, each with "
            f"{', '.join(STOPPING_KEYS)} (docs/robot.md: Arm)",
            path=path,
            name="arm.stopping",
            value=entries,
        )
    out = []
    for k, entry in enumerate(entries):
        where = f"arm.stopping[{k}]"
        _unknown_keys(entry, STOPPING_KEYS, f"[[arm.stopping]] entry {k}", path, where)
        missing = [key for key in STOPPING_KEYS if key not in entry]
        if missing:
            raise RobotDescriptionError(
                f"{path}: [[arm.stopping]] entry {k} is missing key(s) {', '.join(missing)} "
                "(docs/robot.md: Arm)",
                path=path,
                name=where,
                value=missing,
            )
        names = entry["joints"]
        if (
            not isinstance(names, list)
            or not names
            or not all(isinstance(n, str) for n in names)
            or len(set(names)) != len(names)
        ):
            raise RobotDescriptionError(
                f"{path}: {where}.joints must be a list of distinct joint names, got {names!r}",
                path=path,
                name=f"{where}.joints",
                value=names,
            )
        _check_joints(names, f"{where}.joints", path, joints)
        category = entry["category"]
        if isinstance(category, bool) or category not in STOP_CATEGORIES:
            raise RobotDescriptionError(
                f"{path}: {where}.category must be the stop category 0 or 1 of IEC 60204-1, "
                f"got {category!r}",
                path=path,
                name=f"{where}.category",
                value=category,
            )
        out.append(
            StoppingData(
                joints=tuple(names),
                category=int(category),
                speed_radps=_number(
                    entry["speed_radps"],
                    f"{where}.speed_radps",
                    path,
                    0.0,
                    True,
                    MAX_VELOCITY_RADPS,
                ),
                distance_rad=_number(
                    entry["distance_rad"],
                    f"{where}.distance_rad",
                    path,
                    0.0,
                    True,
                    MAX_STOP_DISTANCE_RAD,
                ),
                time_s=_number(
                    entry["time_s"], f"{where}.time_s", path, 0.0, True, MAX_STOP_TIME_S
                ),
                extension=_number(entry["extension"], f"{where}.extension", path, 0.0, True, 1.0),
                payload_kg=_number(
                    entry["payload_kg"], f"{where}.payload_kg", path, 0.0, False, MAX_PAYLOAD_KG
                ),
            )
        )
    return tuple(out)


def _joint_table(
    value: object, where: str, path: Path, joints: Sequence[str], shape: str
) -> dict[str, Any]:
    """``value`` as a non-empty table keyed by joints of the URDF."""
    if not isinstance(value, dict) or not value:
        raise RobotDescriptionError(
            f"{path}: {where} must be a table {shape}, got {value!r}",
            path=path,
            name=where,
            value=value,
        )
    _check_joints(list(value), where, path, joints)
    return value


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
