"""Clearance against where the person really is (qpavoid.loop.truth)."""

from __future__ import annotations

import numpy as np

from qpavoid.experiments.runs import RunSpec, simulate_one
from qpavoid.loop.truth import true_frame
from qpavoid.sensing.recording import Recording


def test_a_recording_is_interpolated_between_its_frames():
    joints = np.zeros((2, 25, 3))
    joints[1] = 1.0
    joints[1, 3] = np.nan  # Head lost in the second frame
    rec = Recording(np.array([0.0, 0.1]), joints, np.full((2, 25), 2))
    mid = true_frame(rec, 0.025)
    np.testing.assert_allclose(mid.joints[0], 0.25)  # a quarter of the way
    np.testing.assert_allclose(mid.joints[3], 0.0)  # held where it was last seen
    np.testing.assert_allclose(true_frame(rec, 5.0).joints[0], 1.0)  # held after the end


def test_truth_equals_the_seen_frame_at_capture_instants():
    """A generated motion is seen exactly when captured: there truth = the seen capsules."""
    run = simulate_one(
        RunSpec(scenario="test1", distance="spheres", bench="ideal", rate_hz=90.0, max_time_s=12.0)
    )
    log, m = run.sim.log, run.metrics
    fresh = log["frame_age_s"] < 1e-9  # ticks at a capture instant
    assert fresh.sum() > 100
    np.testing.assert_allclose(
        log["true_distance"][fresh], log["distance_other"][fresh], atol=1e-9
    )  # spheres run: other = capsules
    moving = np.any(log["dq"] != 0, axis=1)
    assert m["min_true_clearance_moving_m"] == np.min(log["true_distance"][moving])
    assert m["ticks_moving_in_true_contact"] == 0
    assert m["ticks_moving_below_stop_distance"] == 0


def test_stop_events_say_how_fast_the_robot_was():
    run = simulate_one(RunSpec(scenario="test2", rate_hz=100.0, max_time_s=6.0))
    (event,) = run.metrics["stop_events"]
    assert 0.0 < event["robot_speed_mps"] < 1.0
