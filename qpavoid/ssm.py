"""Speed and separation monitoring (ISO/TS 15066 §5.5.4, ISO 10218-2): each term one function.

The protective separation distance at time t₀ (ISO/TS 15066, eq. 1):

    S_p(t₀) = S_h + S_r + S_s + C + Z_d + Z_r

* S_h: how far the person moves while the robot reacts and stops, v_h · (T_r + T_s);
* S_r: how far the robot moves during its reaction time, v_r · T_r;
* S_s: the robot's stopping distance from v_r (constant deceleration a: v_r² / 2a);
* C: the intrusion distance, how far a body part can reach past what the sensor sees;
* Z_d: the sensing uncertainty of the person's position;
* Z_r: the uncertainty of the robot's position.

With the stopping time T_s = v_r / a, ``S_p ≤ d`` is a quadratic inequality in the robot's
approach speed v_r, whose positive root :func:`max_approach_speed` is the fastest the robot
may approach a person at separation d and still be stationary before contact. The human
speed is ISO 13855's: 2.0 m/s within 0.5 m, 1.6 m/s beyond (:func:`human_speed`).

Every function is pure and works element-wise on arrays (every set × part pair at once).
Units: m, s, m/s, m/s².
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike


@dataclass(frozen=True)
class SSMConfig:
    """Constants of speed and separation monitoring.

    Attributes
    ----------
    human_speed_near_mps, human_speed_far_mps, human_speed_zone_m
        ISO 13855 §6.2.3 approach speed of the body: 2.0 m/s when the separation is at most
        0.5 m, 1.6 m/s beyond.
    reaction_time_s
        T_r: from a change in the scene to the robot starting to brake: the sensor's
        latency, one frame period and the controller's period (see docs/safety.md).
    deceleration_mps2
        a: the braking deceleration of the robot's closest point, m/s².
    intrusion_m
        C: how far a hand reaches past the tracked skeleton (fingers beyond HandTip, the
        hand's width beyond its capsule).
    sensing_uncertainty_m
        Z_d: the skeleton's position error for a tracked joint.
    robot_uncertainty_m
        Z_r: the robot's position error (repeatability and model error).
    """

    human_speed_near_mps: float = 2.0
    human_speed_far_mps: float = 1.6
    human_speed_zone_m: float = 0.5
    reaction_time_s: float = 0.15
    deceleration_mps2: float = 2.0
    intrusion_m: float = 0.02
    sensing_uncertainty_m: float = 0.05
    robot_uncertainty_m: float = 0.005


def human_speed(separation_m: ArrayLike, cfg: SSMConfig) -> np.ndarray:
    """ISO 13855 approach speed of the person: 2.0 m/s within 0.5 m, 1.6 m/s beyond (v_h)."""
    d = np.asarray(separation_m, dtype=float)
    return np.where(d <= cfg.human_speed_zone_m, cfg.human_speed_near_mps, cfg.human_speed_far_mps)


def stopping_time(robot_speed_mps: ArrayLike, cfg: SSMConfig) -> np.ndarray:
    """T_s: the time to brake from v_r at constant deceleration a, v_r / a."""
    return np.maximum(np.asarray(robot_speed_mps, dtype=float), 0.0) / cfg.deceleration_mps2


def human_distance(
    human_speed_mps: ArrayLike, robot_speed_mps: ArrayLike, cfg: SSMConfig
) -> np.ndarray:
    """S_h = v_h (T_r + T_s): the person's travel while the robot reacts and stops."""
    return np.asarray(human_speed_mps, dtype=float) * (
        cfg.reaction_time_s + stopping_time(robot_speed_mps, cfg)
    )


def reaction_distance(robot_speed_mps: ArrayLike, cfg: SSMConfig) -> np.ndarray:
    """S_r = v_r T_r: the robot's travel during its reaction time."""
    return np.maximum(np.asarray(robot_speed_mps, dtype=float), 0.0) * cfg.reaction_time_s


def stopping_distance(robot_speed_mps: ArrayLike, cfg: SSMConfig) -> np.ndarray:
    """S_s = v_r² / 2a: the robot's travel while braking at constant deceleration."""
    v = np.maximum(np.asarray(robot_speed_mps, dtype=float), 0.0)
    return v * v / (2.0 * cfg.deceleration_mps2)


def protective_distance(
    robot_speed_mps: ArrayLike,
    separation_m: ArrayLike,
    cfg: SSMConfig,
    extra_uncertainty_m: ArrayLike = 0.0,
) -> np.ndarray:
    """S_p = S_h + S_r + S_s + C + Z_d + Z_r (ISO/TS 15066 eq. 1), m.

    Parameters
    ----------
    robot_speed_mps
        v_r: the robot point's speed towards the person (negative: moving away, counted 0).
    separation_m
        The current separation (it selects the human speed's zone).
    cfg
        The constants.
    extra_uncertainty_m
        Added to Z_d: the growth of a lost or inferred joint's uncertainty.
    """
    v_h = human_speed(separation_m, cfg)
    return (
        human_distance(v_h, robot_speed_mps, cfg)
        + reaction_distance(robot_speed_mps, cfg)
        + stopping_distance(robot_speed_mps, cfg)
        + cfg.intrusion_m
        + cfg.sensing_uncertainty_m
        + np.asarray(extra_uncertainty_m, dtype=float)
        + cfg.robot_uncertainty_m
    )


def max_approach_speed(
    separation_m: ArrayLike, cfg: SSMConfig, extra_uncertainty_m: ArrayLike = 0.0
) -> np.ndarray:
    """The largest v_r ≥ 0 with ``S_p(v_r) ≤ d``, or a negative speed where none exists.

    ``S_p ≤ d`` reads ``v_r²/2a + v_r (T_r + v_h/a) + (v_h T_r + C + Z_d + Z_r − d) ≤ 0``: a
    quadratic with positive leading coefficient, so v_r may be anything up to its larger
    root. Where the constant term is positive (the person is already closer than the
    robot can stop from rest) the root is negative: the robot must move *away* at least
    that fast, which is how the QP reads the bound (and infeasibility means stop).
    """
    d = np.asarray(separation_m, dtype=float)
    v_h = human_speed(d, cfg)
    a, T_r = cfg.deceleration_mps2, cfg.reaction_time_s
    A = 1.0 / (2.0 * a)
    B = T_r + v_h / a
    C0 = (
        v_h * T_r
        + cfg.intrusion_m
        + cfg.sensing_uncertainty_m
        + np.asarray(extra_uncertainty_m, dtype=float)
        + cfg.robot_uncertainty_m
        - d
    )
    disc = np.maximum(B * B - 4.0 * A * C0, 0.0)
    return (-B + np.sqrt(disc)) / (2.0 * A)
