"""The summary of a simulated run: the keys of ``metrics.json``.

:func:`run_metrics` condenses a run's log (path error, distances, stops, limits, tick
times); :func:`describe` puts them in a few lines of words; :func:`end_of_run` says why the
run ended: the goal was reached, a person held the
robot off its goal (``held_by_person``), the robot was stopped for another reason, or the
time cap came first.
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np

from qpavoid.arm.model import Robot
from qpavoid.control.tick import Command
from qpavoid.distance.methods import geometry
from qpavoid.laws.avoidance import AvoidanceConfig, set_stop_distances, stop_rule_prefixes
from qpavoid.loop.truth import TrueContact


def end_of_run(
    reached: bool,
    last: Command,
    robot: Robot,
    avoidance: AvoidanceConfig,
    log: dict[str, np.ndarray],
    goal: np.ndarray,
) -> dict[str, Any]:
    """Why the run ended: ``end_reason`` and, if a person kept the robot off its goal,
    ``held_by_person``.

    A run that did not reach its goal was held by a person when, at its last tick, the
    robot was stopped by one of the paper's rules or a robot set was within the repulsion's
    reach of a body part (``rho_rep_m``): then ``held_by_person`` names the closest set and
    part, their distance (m) and the remaining end-effector error (m). Otherwise it is None.
    """
    remaining = float(np.linalg.norm(log["ee_pos"][-1] - goal[:3, 3]))
    if reached:
        return {"end_reason": "goal reached", "held_by_person": None}
    table = last.table
    s, k = np.unravel_index(int(np.argmin(table.distance)), table.distance.shape)
    closest = float(table.distance[s, k])
    by_rule = last.stopped and last.reason.startswith(
        (*stop_rule_prefixes(robot.role_names), "speed and separation")
    )
    if by_rule or closest < avoidance.rho_rep_m:
        held = {
            "set": robot.set_names[s],
            "part": table.part_names[k],
            "distance_m": closest,
            "remaining_error_m": remaining,
            "stopped": bool(last.stopped),
        }
        return {"end_reason": "held by person", "held_by_person": held}
    reason = f"stopped: {last.reason}" if last.stopped else "time cap"
    return {"end_reason": reason, "held_by_person": None}


#: A measured arm moves when a control point moves faster than this between two ticks, m/s:
#: above franky-sim's creep of a stopped wrist (1.5 mm/s: its velocity loop holds no
#: position) and the noise of its joint angles; a person at 5 mm/s is not struck.
MOVING_MPS = 0.005
#: Over this long, s (ten of franky's 1 ms states, five 500 Hz ticks).
MOVING_WINDOW_S = 0.01


def measured_motion(robot: Robot, q: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(T,) the ticks in which a measured arm moved: some control point's displacement over
    the next :data:`MOVING_WINDOW_S` (the last ticks: the window before them), over the
    time it took, above :data:`MOVING_MPS`. A window, not one tick: an arm's states come
    with its own timing (franky's at 1 ms), so one tick's step may hold two of them."""
    n = len(t)
    if n < 2:
        return np.zeros(n, dtype=bool)
    points = np.array([robot.control_points(qk) for qk in q])  # (T, P, 3)
    end = np.minimum(np.searchsorted(t, t + MOVING_WINDOW_S), n - 1)
    start = np.where(end > np.arange(n), np.arange(n), np.searchsorted(t, t - MOVING_WINDOW_S))
    end = np.where(end > np.arange(n), end, np.arange(n))
    span = np.maximum(t[end] - t[start], 1e-9)
    speed = np.linalg.norm(points[end] - points[start], axis=2).max(axis=1) / span
    return speed > MOVING_MPS


def truth_metrics(
    log: dict[str, np.ndarray],
    robot: Robot,
    avoidance: AvoidanceConfig,
    stop_events: list[dict[str, Any]],
    dt: float,
    moving: np.ndarray | None = None,
) -> dict[str, Any]:
    """Safety judged against where the person really is (``log["true_distance"]``).

    ``moving`` (T,) says which ticks the arm moved in; by default those with a non-zero
    velocity ``log["dq"]`` (the simulated arm's, exact); a real arm's measured velocity is
    never exactly zero (:func:`measured_motion`).

    Returns ``min_true_clearance_moving_m`` (smallest true capsule distance over the ticks
    with a non-zero command, m; None if never measured or never moving),
    ``ticks_moving_in_true_contact`` (moving while a true distance is <= 0),
    ``ticks_moving_below_stop_distance`` (moving while a set is closer than its stop
    distance, :func:`~qpavoid.laws.avoidance.set_stop_distances`), and adds to each stop event the
    robot's speed when it began (``robot_speed_mps``: the fastest control point over the
    tick before it).
    """
    true = log["true_distance"]
    if moving is None:
        moving = np.any(log["dq"] != 0.0, axis=1)
    for event in stop_events:
        # (event times are rounded to 1 µs: a real-time tick's may round past its own)
        k = min(int(np.searchsorted(log["t"], event["t"] - 1e-6)), len(log["t"]) - 1)
        if k > 0:
            step = robot.control_points(log["q"][k]) - robot.control_points(log["q"][k - 1])
            elapsed = float(log["t"][k] - log["t"][k - 1]) or dt  # a late tick's real gap
            event["robot_speed_mps"] = float(np.linalg.norm(step, axis=1).max() / elapsed)
        else:
            event["robot_speed_mps"] = 0.0
    if np.isnan(true).all():
        return {
            "min_true_clearance_moving_m": None,
            "ticks_moving_in_true_contact": None,
            "ticks_moving_below_stop_distance": None,
        }
    below = np.any(true < set_stop_distances(avoidance, robot.roles, len(robot.sets)), axis=1)
    closest = true.min(axis=1)
    return {
        "min_true_clearance_moving_m": float(closest[moving].min()) if moving.any() else None,
        "ticks_moving_in_true_contact": int((moving & (closest <= 0.0)).sum()),
        "ticks_moving_below_stop_distance": int((moving & below).sum()),
    }


def contact_metrics(
    contacts: dict[int, list[TrueContact]], moving: np.ndarray, t: np.ndarray
) -> dict[str, Any]:
    """Power and force limiting judged against the truth: the ``true_contacts`` metric.

    ``contacts`` maps each tick in true contact to its pairs
    (:meth:`~qpavoid.loop.truth.TrueClearance.contacts`); ``moving`` (T,) says which ticks
    the arm moved in, ``t`` (T,) when they were (s). A pair's contact lasts while it is in
    contact tick after tick; over it the robot's own advance into the part is summed, its
    approach speed times each tick's duration (never below 0: backing off undoes it), from
    the tick before the first (the motion that crossed the surface, at the first tick's
    approach: the faster of the velocities before and after it).
    Returns tick counts (a tick counts once, by its worst pair):

    * ``ticks_moving_protected``: the arm moving while touching a region that permits no
      contact (head, face, neck, trunk), at that tick or the one before (the motion that
      made the contact: a robot that stops on the touch moved into it); must be zero in
      every mode;
    * ``ticks_above_limit``: a permitted region (arm, hand) touched faster than its
      transient limit (or with no limit known), or a clamped one approached or advanced
      into (quasi-static: no approach at all); must be zero;
    * ``ticks_within_limit``: every pair touched within its region's limits (allowed with
      ``safety="pfl"``);
    * ``ticks_clamped``: a permitted region touched where it could be pinned against the
      fixed surface;
    * ``ticks_pushed``: the robot advanced into a free part further than its allowance
      δ = F_T / k over one contact: it pushed the part along (a free part recoils, so Annex
      A counts the contact as transient; were it pinned, the spring's force ``k x`` would
      pass F_T): reported, not a limit;

    and over the contacts with permitted regions: ``max_speed_mps``, ``max_speed_ratio``
    (speed / limit, over the parts not clamped), ``max_advance_m`` (the robot's deepest
    advance into a part over one contact), ``max_force_n`` (the impact's, ``v √(μk)``;
    None without any), and ``by_region`` (ticks per region).
    """
    protected = above = within = clamped = pushed = 0
    speeds, ratios, forces, advances = [], [], [], []
    by_region: dict[str, int] = {}
    advance: dict[tuple[int, str, str], float] = {}
    last: dict[tuple[int, str, str], TrueContact] = {}
    previous = -2
    for k in sorted(contacts):
        pairs = contacts[k]
        dt = float(t[k] - t[k - 1]) if k > 0 else 0.0
        now: dict[tuple[int, str, str], float] = {}
        for c in pairs:  # each pair's advance since its contact began
            key = (c.person, c.set_name, c.part)
            before = last.get(key) if previous == k - 1 else None
            now[key] = max(
                0.0,
                advance[key] + before.approach_mps * dt if before is not None else c.speed_mps * dt,
            )
        advance, last, previous = now, {(c.person, c.set_name, c.part): c for c in pairs}, k
        if bool(moving[k] or (k > 0 and moving[k - 1])) and any(not c.permitted for c in pairs):
            protected += 1
        touched = [c for c in pairs if c.permitted]
        clamped += any(c.clamped for c in touched)
        pushed += any(c.pushed(advance[(c.person, c.set_name, c.part)]) for c in touched)
        if touched:
            if all(c.within_limit(advance[(c.person, c.set_name, c.part)]) for c in touched):
                within += 1
            else:
                above += 1
        for region in {c.region or "none" for c in pairs}:
            by_region[region] = by_region.get(region, 0) + 1
        for c in touched:
            x = advance[(c.person, c.set_name, c.part)]
            speeds.append(c.speed_mps)
            advances.append(x)
            if c.limit_mps > 0.0:  # (a clamped part's limit is 0: counted on its own)
                ratios.append(c.speed_mps / c.limit_mps)
            forces.append(c.force_n)

    def top(x: list[float]) -> float | None:
        return round(float(np.max(x)), 6) if x else None

    return {
        "ticks_moving_protected": protected,
        "ticks_above_limit": above,
        "ticks_within_limit": within,
        "ticks_clamped": clamped,
        "ticks_pushed": pushed,
        "max_speed_mps": top(speeds),
        "max_speed_ratio": top(ratios),
        "max_advance_m": top(advances),
        "max_force_n": top(forces),
        "by_region": dict(sorted(by_region.items())),
    }


def run_metrics(
    log: dict[str, np.ndarray],
    robot: Robot,
    goal: np.ndarray,
    reached: bool,
    stop_events: list[dict[str, Any]],
    vel_violations: int,
    pos_violations: int,
    controller: str,
    method: str,
    control_rate_hz: float,
) -> dict[str, Any]:
    """The summary of a run (the keys of ``metrics.json``).

    ``controller`` and ``method`` name the controller and its distance method;
    ``control_rate_hz`` is the simulation's control rate.
    """
    dt = 1.0 / control_rate_hz
    path_err = np.linalg.norm(log["ee_pos"] - log["ee_ref"], axis=1)
    used = geometry(method)  # "capsules-coal" measures capsules too
    other = "capsules" if used == "spheres" else "spheres"
    dmin = {used: float(np.min(log["distance"])), other: float(np.min(log["distance_other"]))}
    tick = log["tick_us"]
    final_err = float(np.linalg.norm(log["ee_pos"][-1] - goal[:3, 3]))
    return {
        "reached_goal": bool(reached),
        "final_position_error_m": final_err,
        "rms_path_error_m": float(np.sqrt(np.mean(path_err**2))),
        "max_path_error_m": float(np.max(path_err)),
        "duration_s": float(log["t"][-1]),
        "stopped_s": float(np.count_nonzero(log["stopped"]) * dt),
        "stopped_s_by_cause": stopped_by_cause(log["stop_reason"], dt),
        "stop_events": stop_events,
        "max_f": float(np.max(log["f"])),
        "min_distance_m": {"spheres": dmin["spheres"], "capsules": dmin["capsules"]},
        "min_distance_per_set_m": {
            method: dict(
                zip(robot.set_names, np.min(log["distance"], axis=0).tolist(), strict=True)
            ),
            other: dict(
                zip(robot.set_names, np.min(log["distance_other"], axis=0).tolist(), strict=True)
            ),
        },
        "joint_velocity_limit_violations": int(vel_violations),
        "joint_position_limit_violations": int(pos_violations),
        "tick_us": {"median": float(np.median(tick)), "p99": float(np.percentile(tick, 99))},
        "controller": controller,
        "distance_method": method,
        "control_rate_hz": control_rate_hz,
        "ticks": len(tick),
    }


def stop_cause(reason: str) -> str:
    """What kind of stop a reason is: its words before the first ':', '(', ' = ', '<', '>'
    or number ("speed and separation", "human frame is stale", "d_L2" of "d_L2 = 0.121 m
    <= 0.15 m", "f" of "f = 0.987 > 0.95", "QP solution breaks a hard constraint by")."""
    return _CAUSE_END.split(reason, 1)[0].strip() or reason


def stopped_by_cause(reasons: np.ndarray, dt: float) -> dict[str, float]:
    """How long (s) the robot was stopped by each kind of stop (:func:`stop_cause`), the
    longest first: a run held by a person for most of it and whose camera stopped at the end
    ends on a stale frame, and this says both."""
    kinds, counts = np.unique([stop_cause(str(r)) for r in reasons if r], return_counts=True)
    order = np.argsort(-counts, kind="stable")
    return {str(kinds[i]): round(float(counts[i]) * dt, 3) for i in order}


#: Where a stop reason's kind ends: its details begin (:func:`stop_cause`).
_CAUSE_END = re.compile(r":|\(| = |<|>|\s[-+]?\d")

#: A hold by speed and separation longer than this share of the run gets a hint in the
#: summary: what the protective distance counts and what to change.
HOLD_HINT_SHARE = 0.25


def _ending(m: dict[str, Any]) -> str:
    """How a run ended, in words: why it ended early (Ctrl-C, an arm's error) before who
    held it."""
    reason = str(m.get("end_reason", "goal reached" if m["reached_goal"] else "time cap"))
    held = m.get("held_by_person")
    if reason not in ("goal reached", "time cap") and not reason.startswith("held"):
        return reason
    if held:
        return (
            f"held by person: {held['part']} {held['distance_m']:.3f} m from {held['set']}, "
            f"{held['remaining_error_m'] * 1e3:.1f} mm from the goal"
        )
    return reason


#: More late ticks than this share of a real-time run's gets a line in the summary.
OVERRUN_HINT_SHARE = 0.1

#: Stop events :func:`describe` lists (the rest are counted).
STOPS_SHOWN = 4


def describe(m: dict[str, Any]) -> str:
    """A run's metrics as a few readable lines."""
    events = m["stop_events"]
    stops = "; ".join(f"{e['t']:.2f} s: {e['reason']}" for e in events[:STOPS_SHOWN]) or "none"
    if len(events) > STOPS_SHOWN:
        stops += f"; and {len(events) - STOPS_SHOWN} more (metrics.json: stop_events)"
    md = m["min_distance_m"]
    sphere_note = (
        "\n  (spheres below 0: the conservative spheres of eq. 1, larger than the links, "
        "overlap the person; not contact)"
        if md["spheres"] < 0
        else ""
    )
    return (
        (
            f"{m['scenario']}: controller {m['controller']}, distances {m['distance_method']}\n"
            f"  reached goal {m['reached_goal']} in {m['duration_s']:.2f} s: {_ending(m)} "
            f"(final error {m['final_position_error_m'] * 1e3:.3f} mm)\n"
            f"  path error rms {m['rms_path_error_m'] * 1e3:.3f} mm, "
            f"max {m['max_path_error_m'] * 1e3:.3f} mm\n"
            f"  min distance spheres {md['spheres']:.4f} m, capsules {md['capsules']:.4f} m, "
            f"max f {m['max_f']:.3f}{sphere_note}\n"
            f"  stopped {m['stopped_s']:.2f} s{_causes(m)}, stops: {stops}\n"
            f"  tick {m['tick_us']['median']:.0f} us median, {m['tick_us']['p99']:.0f} us p99; "
            f"limit violations: velocity {m['joint_velocity_limit_violations']}, "
            f"position {m['joint_position_limit_violations']}"
        )
        + (_input_line(m["input"], m.get("input_unit", "datagrams")) if "input" in m else "")
        + _contact_line(m)
        + _loop_line(m)
        + _hold_hint(m)
    )


def _causes(m: dict[str, Any]) -> str:
    """ " (speed and separation 20.0 s, human frame is stale 10.0 s)": what stopped it."""
    causes = m.get("stopped_s_by_cause") or {}
    if not causes:
        return ""
    return " (" + ", ".join(f"{k} {v:.1f} s" for k, v in list(causes.items())[:3]) + ")"


def _hold_hint(m: dict[str, Any]) -> str:
    """What to change when speed and separation held the robot for much of the run."""
    held = (m.get("stopped_s_by_cause") or {}).get("speed and separation", 0.0)
    if held <= HOLD_HINT_SHARE * max(m["duration_s"], 1e-9):
        return ""
    latency = m.get("latency_s")
    counted = f" ({latency:.3f} s here)" if isinstance(latency, float) and latency else ""
    return (
        f"\n  speed and separation held the robot {held:.1f} s: its protective distance "
        f"counts the camera's latency{counted} at ISO 13855's body speeds. Measure the "
        "latency (qpavoid latency) and give it, or seat the operator further from the "
        "path (a task file's [operator], docs/tasks.md)"
    )


def _contact_line(m: dict[str, Any]) -> str:
    """The true contacts as power and force limiting judges them (none: no line)."""
    c = m.get("true_contacts")
    if not c or not (
        c["ticks_within_limit"] or c["ticks_above_limit"] or c["ticks_moving_protected"]
    ):
        return ""
    fastest = (
        f" (fastest {c['max_speed_mps']:.3f} m/s, {c['max_speed_ratio']:.2f} of its limit; "
        f"{c['max_force_n']:.0f} N; deepest advance {c['max_advance_m'] * 1e3:.1f} mm)"
        if c["max_speed_mps"] is not None and c["max_speed_ratio"] is not None
        else ""
    )
    return (
        f"\n  true contacts: {c['ticks_within_limit']} ticks within the regions' limits"
        f"{fastest}, {c['ticks_above_limit']} above, {c['ticks_clamped']} clamped, "
        f"{c['ticks_moving_protected']} moving against the head or trunk, "
        f"{c['ticks_pushed']} pushing a part along"
    )


def _loop_line(m: dict[str, Any]) -> str:
    """A real-time run's loop (the arm it drove, its deadlines, its latency) and commands."""
    line = ""
    if "loop" in m:
        lp, lat = m["loop"], m["loop"]["frame_to_command_s"]
        line += (
            f"\n  loop on {m.get('arm', 'the simulated arm')}: {lp['commands_sent']} commands, "
            f"{lp['deadline_misses']} missed deadlines, longest gap "
            f"{lp['longest_gap_s'] * 1e3:.1f} ms; frame to command {lat['median'] * 1e3:.1f} ms "
            f"median, {lat['p99'] * 1e3:.1f} ms p99"
        )
        late, ticks = m.get("realtime_overruns", 0), max(m.get("ticks", 0), 1)
        if late > OVERRUN_HINT_SHARE * ticks:
            line += (
                f"\n  the loop fell behind: {late} of {ticks} ticks began more than a period "
                f"late (at {m['control_rate_hz']:g} Hz; the commands of the late ones counted "
                "at their true age): give the run a core of its own, or a lower --rate"
            )
    broken = {k: n for k, n in m.get("command_limit_violations", {}).items() if n}
    if broken:
        line += "\n  commands beyond the arm's limits: " + ", ".join(
            f"{k} {n}" for k, n in broken.items()
        )
    return line


#: What a live run's drops most likely mean: for the one that dominates the summary, and
#: said once during a live run (:class:`~qpavoid.loop.live_input.LiveSource`).
DROP_HINTS = {
    "dropped_bad_tag": "not signed by this cell's keys: check the key files and the cell name",
    "dropped_unknown_key": "signed with a key id this calibration does not hold",
    "dropped_unauthenticated": "unsigned: sign them (replay --sensors) or, without keys, "
    "--allow-unauthenticated on loopback",
    "dropped_unknown_sensor": "from a sensor the calibration does not name",
    "from_the_future": "stamped ahead of this clock: check the sensors' time_offset_s",
    "dropped_wrong_format": "of another skeleton format than the calibration's for their "
    "sensor: send that format, or correct the sensor's format key",
    "late_when_taken": "accepted on arrival, older than their sensor's age limit when the "
    "control loop took them: the loop fell behind, or the camera is at its limit",
    "late": "captured longer ago than their sensor's age limit, its latency + a frame + "
    "6.7 ms: if the camera's latency is longer, measure it (qpavoid latency) and set "
    "latency_s in the calibration or --latency; else check the clocks and the network",
}


def _input_line(counts: dict[str, int], unit: str) -> str:
    """A live run's ``unit`` (datagrams, DDS messages): how many came, how many were
    taken, the drops, and what the largest drop most likely means (docs/security.md)."""
    drops = sorted(
        ((n, k) for k, n in counts.items() if k.startswith("dropped_") or k in DROP_HINTS),
        reverse=True,
    )
    line = f"\n  input: {counts.get('received', 0)} {unit}, {counts.get('accepted', 0)} taken"
    if drops:
        line += "; " + ", ".join(f"{k} {n}" for n, k in drops[:4])
        if drops[0][1] in DROP_HINTS and drops[0][0] > counts.get("accepted", 0):
            line += f" ({DROP_HINTS[drops[0][1]]})"
    return line
