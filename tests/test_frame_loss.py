"""Loss on the path (issue 40): a sensor's frame counts only when every body its signed
manifest lists came, and a frame missing or incomplete makes that sensor's older frames
stale at once. The live attack is ``test_attacks.py`` (slow); these are its rules, one by
one, none of them timed (the last goes through the receiver process, on loopback)."""

from __future__ import annotations

import dataclasses
import json
import math
import socket
import time

import numpy as np
import pytest
from test_security import body, cell

from qpavoid.core.errors import InputError
from qpavoid.fusion.fuser import Fuser
from qpavoid.loop.live_input import Listener, LiveSource
from qpavoid.sensing.assembly import LossConfig, LossWatch, SensorFrames, Step, assemble
from qpavoid.sensing.keys import SensorKeys
from qpavoid.sensing.receiver import SensorLoss
from qpavoid.sensing.signing import Signer, Verifier, fields
from qpavoid.sensing.streamer import camera_frames
from qpavoid.sensing.wire import WireError, payload

NEAR, FAR = (0.0, 0.0, 0.0), (0.0, 1.9, 0.0)  #: the operator's seat, and 1.9 m behind it


def frame_of(signer: Signer, t: float) -> list[bytes]:
    """One camera frame of sensor "a" at ``t``: the operator (body 0) and a bystander
    (body 3), signed."""
    return signer.encode_frame([body("a", t, 0, NEAR), body("a", t, 3, FAR)])


def feed(datagrams: list[bytes], verifier: Verifier) -> list[Step]:
    """Each datagram verified and assembled in turn (sensor "a"'s frames)."""
    state, steps = SensorFrames(), []
    for data in datagrams:
        step = assemble(state, *verifier.read(data))
        state = step.state
        steps.append(step)
    return steps


def delivered(steps: list[Step]) -> list[tuple[float, int]]:
    return [(f.t, f.body) for step in steps for f in step.complete]


# --- the assembly: whole frames, every loss seen ------------------------------------------


def test_a_frame_is_delivered_whole_once_all_its_bodies_came_in_any_order():
    cal = cell()
    signer = Signer(cal.cell, cal.keys["a"], first_sequence=100)
    first, second = frame_of(signer, 1.0), frame_of(signer, 1.033)
    steps = feed([first[1], first[0], *second], Verifier(cal))  # reordered within a frame
    assert [len(s.complete) for s in steps] == [0, 2, 0, 2]
    assert delivered(steps) == [(1.0, 0), (1.0, 3), (1.033, 0), (1.033, 3)]
    assert not any(s.lost for s in steps)


def test_a_body_dropped_on_the_path_holds_its_frame_back_and_the_next_shows_the_loss():
    """The selective drop of issue 40: the operator's datagram dropped, the bystander's
    forwarded. Before, the bystander's body was taken and the input stayed fresh."""
    cal = cell()
    signer = Signer(cal.cell, cal.keys["a"], first_sequence=100)
    frames = [frame_of(signer, 1.0 + k / 30) for k in range(4)]
    path = [*frames[0], frames[1][1], frames[2][1], *frames[3]]  # body 0 of two dropped
    steps = feed(path, Verifier(cal))
    assert delivered(steps) == [(1.0, 0), (1.0, 3), (1.1, 0), (1.1, 3)]  # first and last
    lost = [s for s in steps if s.lost]
    assert [s.stale_before_s for s in lost] == [1.0 + 2 / 30, 1.1]  # seen at the next frame
    assert [s.discarded for s in lost] == [1, 1]  # the bystanders held back, never delivered


def test_a_gap_in_the_frame_numbers_is_a_loss_at_once():
    cal = cell()
    signer = Signer(cal.cell, cal.keys["a"], first_sequence=100)
    frames = [frame_of(signer, 1.0 + k / 30) for k in range(3)]
    steps = feed([*frames[0], *frames[2]], Verifier(cal))  # a whole frame missing
    assert [s.lost for s in steps] == [False, False, True, False]
    assert steps[2].stale_before_s == 1.0 + 2 / 30 and steps[2].discarded == 0
    assert delivered(steps)[-2:] == [(1.0 + 2 / 30, 0), (1.0 + 2 / 30, 3)]  # the new one whole


def test_a_datagram_of_a_frame_already_closed_is_dropped():
    cal = cell()
    signer = Signer(cal.cell, cal.keys["a"], first_sequence=100)
    first, second = frame_of(signer, 1.0), frame_of(signer, 1.033)
    steps = feed([first[0], *second, first[1]], Verifier(cal))  # reordered across frames
    assert [s.lost for s in steps] == [False, True, False, False]
    assert steps[-1].closed and not steps[-1].complete
    assert delivered(steps) == [(1.033, 0), (1.033, 3)]


def test_a_sender_before_manifests_still_shows_its_losses_by_the_sequence_numbers():
    cal = cell()
    verifier = Verifier(cal)
    signer = Signer(cal.cell, cal.keys["a"], first_sequence=100)

    def legacy(frame) -> bytes:
        """A datagram as a sender before issue 40 signed it: no manifest."""
        return signer.seal(frame.t, json.dumps(payload(frame)).encode())

    sent = [legacy(body("a", 1.0 + k / 30, k % 2)) for k in range(4)]
    steps = feed([sent[0], sent[1], sent[3]], verifier)  # the third dropped
    assert [len(s.complete) for s in steps] == [1, 1, 1]  # each a frame of its one body
    assert [s.lost for s in steps] == [False, False, True]


def test_a_new_key_counts_afresh_and_its_first_frame_is_used():
    cal = cell()
    rotated = SensorKeys("a", (cal.keys["a"].keys[0], (2, bytes(32))))
    new_cal = dataclasses.replace(cal, keys={**cal.keys, "a": rotated})
    verifier = Verifier(new_cal)
    old = Signer(cal.cell, cal.keys["a"], first_sequence=5000)
    new = Signer(cal.cell, SensorKeys("a", (rotated.keys[1],)), first_sequence=100)
    steps = feed([*frame_of(old, 1.0), *frame_of(new, 1.033)], verifier)  # lower numbers
    assert [s.lost for s in steps] == [False, False, True, False]
    assert delivered(steps) == [(1.0, 0), (1.0, 3), (1.033, 0), (1.033, 3)]


# --- the manifest is signed, checked, and its datagrams taken once -----------------------


def test_a_forged_manifest_or_a_replayed_datagram_is_refused():
    cal = cell()
    verifier = Verifier(cal)
    signer = Signer(cal.cell, cal.keys["a"], first_sequence=100)
    whole = frame_of(signer, 1.0)
    bystander = whole[1]
    _, _, sequence, _, signed = fields(bystander)
    msg = json.loads(signed)
    assert (msg["bodies"], sequence) == ([0, 3], 101)  # the second of frame 100
    # the device on the path makes the bystander's datagram a whole frame of its own
    msg.update(bodies=[3])
    new = json.dumps(msg, separators=(",", ":")).encode()
    forged = bystander[: len(bystander) - len(signed) - 32] + new + bystander[-32:]
    for data, reason in ((forged, "bad_tag"), (bystander, None), (bystander, "replayed")):
        if reason is None:
            assert verifier.read(data).manifest.bodies == (0, 3)
            continue
        with pytest.raises(WireError) as err:
            verifier.read(data)
        assert err.value.reason == reason


@pytest.mark.parametrize(
    ("bodies", "sequence", "words"),
    [
        ([0], 101, "body 3, sequence number 101"),  # its own body not listed
        ([0, 0], 101, "bodies"),  # one body twice
        (list(range(7)), 101, "bodies"),  # more than a Kinect tracks
        ([], 101, "bodies"),
        ([0, True], 101, "bodies"),
        ("03", 101, "bodies"),
        ([0, 3], 0, "body 3, sequence number 0"),  # its frame would start at -1
    ],
)
def test_a_key_holders_malformed_manifest_is_refused_after_the_tag(bodies, sequence, words):
    cal = cell()
    signer = Signer(cal.cell, cal.keys["a"], first_sequence=100)
    msg = json.loads(fields(frame_of(signer, 1.0)[1])[4])
    msg.update(bodies=bodies)
    data = signer.seal(1.0, json.dumps(msg).encode(), sequence)  # the sensor's own fault
    with pytest.raises(WireError, match=words) as err:
        Verifier(cal).read(data)
    assert err.value.reason == "bad_manifest"


def test_a_frame_whose_datagrams_disagree_is_refused():
    cal = cell()
    verifier = Verifier(cal)
    signer = Signer(cal.cell, cal.keys["a"], first_sequence=100)
    state = assemble(SensorFrames(), *verifier.read(frame_of(signer, 1.0)[0])).state
    other = Signer(cal.cell, cal.keys["a"], first_sequence=100).encode_frame(
        [body("a", 1.0, 0), body("a", 1.0, 3), body("a", 1.0, 4)]
    )
    with pytest.raises(WireError, match="before as") as err:
        assemble(state, *Verifier(cal).read(other[1]))
    assert err.value.reason == "bad_manifest"


@pytest.mark.parametrize(
    ("bodies", "words"),
    [
        ([], "no body"),
        ([body("a", 1.0, 0), body("a", 1.1, 3)], "share its capture time"),
        ([body("a", 1.0, 0), body("a", 1.0, 0)], "distinct"),
        ([body("b", 1.0, 0)], "signed as 'a'"),
    ],
)
def test_a_sender_refuses_a_frame_that_is_not_one(bodies, words):
    cal = cell()
    with pytest.raises(InputError, match=words):
        Signer(cal.cell, cal.keys["a"]).encode_frame(bodies)


def test_the_streamer_sends_a_sensors_bodies_of_one_time_as_one_frame():
    frames = [body("a", 1.0, 0), body("a", 1.0, 3), body("b", 1.0, 0), body("a", 1.0, 3)]
    frames += [body("a", 1.1, 3)]
    groups = [[(f.sensor, f.t, f.body) for f in g] for g in camera_frames(frames)]
    assert groups == [
        [("a", 1.0, 0), ("a", 1.0, 3)],
        [("b", 1.0, 0)],
        [("a", 1.0, 3)],
        [("a", 1.1, 3)],
    ]


# --- a loss makes the sensor's older frames stale, as a camera dropout ---------------------


def test_a_lost_frame_makes_its_sensors_older_frames_stale_at_once():
    fuser = Fuser(cell())
    for k in range(3):  # the operator, seen by "a" only
        fuser.add(body("a", k / 30, 0))
    seen = fuser.fuse(2 / 30)
    assert seen.captured_s == 2 / 30 and np.isfinite(seen.people[0].frame.joints).all()
    fuser.lose("a", 2.5 / 30)  # a frame of "a" lost on the way, seen at 2.5 / 30 s
    unseen = fuser.fuse(2.6 / 30)  # still within max_age_s of the last frame
    assert unseen.captured_s == -math.inf  # nothing fresh: the controller stops ...
    assert [p.id for p in unseen.people] == [seen.people[0].id]  # ... and holds the person
    assert np.isnan(unseen.people[0].frame.joints).all()
    fuser.add(body("a", 3 / 30, 0))  # the next whole frame
    again = fuser.fuse(3 / 30)
    assert again.captured_s == 3 / 30 and np.isfinite(again.people[0].frame.joints).all()


def test_the_live_source_applies_each_loss_and_raises_the_alert_while_frames_are_lost():
    class Frames:
        """A listener's side: the frames and losses of the sensors so far."""

        def __init__(self):
            self.calibration, self.counters = cell(), {}
            self.pending, self.lost = [], {"a": SensorLoss(0, -math.inf)}

        def drain(self):
            out, self.pending = self.pending, []
            return out

        def losses(self):
            return dict(self.lost)

        def format_mismatches(self):  # every datagram of its sensor's format
            return {}

    listener, dt = Frames(), 1 / 32  # a frame every 31 ms (exact in binary)
    source = LiveSource(listener, clock=lambda: 100.0)  # run time 0 = 100 s
    for k in range(30):  # 0.9 s: the operator and a bystander, whole frames
        listener.pending = [body("a", 100 + k * dt, 0, NEAR), body("a", 100 + k * dt, 3, FAR)]
        people, captured = source.frame_at(k * dt)
    assert captured == 29 * dt and len(people.ids) == 2 and source.alert == ""
    for k in range(30, 36):  # then the operator's datagrams dropped: each frame incomplete
        listener.lost = {"a": SensorLoss(k - 29, 100 + k * dt)}
        people, captured = source.frame_at(k * dt)
        assert captured == 29 * dt  # nothing fresh: the bystander's held back too
        assert all(np.isnan(f.joints).all() for f in people.frames)  # a dropout, at once
    assert "a lost 6 frames in the last 1 s" in source.alert
    for k in range(36, 80):  # whole frames again: fresh at once, the alert gone after 1 s
        listener.pending = [body("a", 100 + k * dt, 0, NEAR), body("a", 100 + k * dt, 3, FAR)]
        people, captured = source.frame_at(k * dt)
        assert captured == k * dt and len(people.ids) == 2
    assert source.alert == ""


def test_lost_frames_raise_the_alert_over_their_window_only():
    watch = LossWatch(LossConfig(window_s=1.0, alert_frames=3))
    assert watch.alert(0.0, {"a": 0, "b": 0}) == ""
    assert watch.alert(0.5, {"a": 2, "b": 0}) == ""
    assert watch.alert(0.9, {"a": 3, "b": 1}).startswith("a lost 3 frames")
    assert watch.alert(1.6, {"a": 3, "b": 1}) == ""  # one of them within the last second
    for bad in ({"window_s": 0.0}, {"window_s": math.inf}, {"alert_frames": 0}):
        with pytest.raises(InputError):
            LossConfig(**bad)


# --- on loopback, through the receiver process ----------------------------------------------


def test_the_listener_delivers_whole_frames_and_counts_each_loss():
    cal = cell()
    signer = Signer(cal.cell, cal.keys["a"])
    now = time.time() - 0.01
    frames = [frame_of(signer, now + k * 0.001) for k in range(4)]
    path = [*frames[0], frames[1][1], *frames[2][::-1], frames[3][1]]  # two operators dropped
    # frames 5 s old still fresh: a loaded machine may take tenths of a second to deliver
    with Listener(("127.0.0.1", 0), cal, max_age_s=5.0) as listener:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            for data in path:
                sock.sendto(data, listener.address)
        deadline = time.time() + 10.0
        while listener.counters["received"] < len(path) and time.time() < deadline:
            time.sleep(0.02)
        taken = listener.drain()
        losses = listener.losses()
    counts = listener.counters
    assert sorted((f.t, f.body) for f in taken) == [(now + 0.002, 0), (now + 0.002, 3)]
    assert losses == {"a": SensorLoss(1, now + 0.002), "b": SensorLoss(0, -math.inf)}
    assert counts["lost_frames"] == 1 and counts["incomplete_frame"] == 1, counts
    assert counts["accepted"] == 4 and counts["superseded"] == 2, counts  # frames 0 and 2
    assert counts["received"] == counts["accepted"] + counts["incomplete_frame"] + 1  # pending
