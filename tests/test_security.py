"""Only the cell's own sensors are believed (issue 24): keys, signed datagrams, the replay
window, the receiver's order of checks, the caps on people and the flags on phantoms."""

from __future__ import annotations

import dataclasses
import json
import os
import random
import socket
import struct
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import PYTHON, write_calibration

from qpavoid.cli.commands import main as cli_main
from qpavoid.core.checks import is_loopback
from qpavoid.core.errors import CalibrationError, InputError
from qpavoid.fusion.association import torso_centre
from qpavoid.fusion.fuser import Fuser, FusionConfig
from qpavoid.human.posture import Operator
from qpavoid.loop.live_input import Listener, LiveSource
from qpavoid.sensing.calibration import Calibration, SensorCalibration
from qpavoid.sensing.calibration_file import load_calibration
from qpavoid.sensing.keys import MAX_KEY_FILE_BYTES, SensorKeys, load_key_file, new_key_file
from qpavoid.sensing.per_sensor import BodyFrame
from qpavoid.sensing.replay_window import REPLAY_WINDOW, ReplayWindow
from qpavoid.sensing.signing import Signer, Verifier, fields
from qpavoid.sensing.synthetic_pair import KINECT_V2_FIELD_OF_VIEW_DEG, KINECT_V2_RANGE_M, look_at
from qpavoid.sensing.wire import WireError, encode

POSES = {
    "a": look_at(np.array([1.0, 2.5, 1.3]), np.zeros(3)),
    "b": look_at(np.array([-1.0, 2.5, 1.3]), np.zeros(3)),
}


def cell(name: str = "cell-1", view: bool = False) -> Calibration:
    extra = {"field_of_view_deg": KINECT_V2_FIELD_OF_VIEW_DEG, "range_m": KINECT_V2_RANGE_M}
    sensors = {n: SensorCalibration(n, T, **(extra if view else {})) for n, T in POSES.items()}
    return Calibration(sensors, cell=name, keys={n: SensorKeys.generate(n) for n in POSES})


def body(sensor: str = "a", t: float = 10.0, body_id: int = 0, shift=(0.0, 0.0, 0.0)):
    """The seated operator at rest (moved by ``shift``, base frame, m) as ``sensor`` sees it."""
    T = np.linalg.inv(POSES[sensor])
    joints = (Operator().rest() + shift) @ T[:3, :3].T + T[:3, 3]
    return BodyFrame(sensor, body_id, t, joints, np.full(25, 2, dtype=np.int8))


# --- keys and key files ------------------------------------------------------------------


def test_a_key_file_round_trips_rotates_and_never_shows_its_secret(tmp_path):
    path = tmp_path / "a.key"
    first = new_key_file(path, "a")
    assert oct(path.stat().st_mode & 0o777) == "0o600"
    assert load_key_file(path, "a") == first and first.ids == (1,)
    with pytest.raises(CalibrationError, match="exists"):
        new_key_file(path, "a")
    second = new_key_file(path, "a", rotate=True)
    assert second.ids == (2, 1) and second.keys[1] == first.keys[0]  # the old one kept
    third = new_key_file(path, "a", rotate=True)
    assert third.ids == (3, 2)  # the oldest dropped
    for text in (repr(third), str(third)):
        assert all(secret.hex() not in text for _, secret in third.keys)
    assert not list(tmp_path.glob(".*"))  # no temporary file left


@pytest.mark.parametrize(
    ("content", "mode", "words"),
    [
        ("ok", 0o640, "lets its group or others"),
        ("ok", 0o604, "lets its group or others"),
        ('sensor = "b"\n', 0o600, "the key of sensor 'b'"),
        (
            'sensor = "a"\n[[key]]\nid = 1\nsecret = "00"\n',
            0o600,
            r"key\[0\]\.secret must be 64 hex",
        ),
        ('sensor = "a"\n', 0o600, "1 or 2"),
        ("x" * (MAX_KEY_FILE_BYTES + 1), 0o600, "more than the 4096"),
        ("ok3", 0o600, "1 or 2"),
        ("dup", 0o600, "same id"),
        ("{", 0o600, "key file"),
    ],
)
def test_a_bad_key_file_is_refused_naming_why(tmp_path, content, mode, words):
    keys = SensorKeys.generate("a")
    text = {
        "ok": keys.to_toml(),
        "ok3": keys.to_toml() + "\n[[key]]\nid = 7\nsecret = '" + "ab" * 32 + "'\n" * 2,
        "dup": keys.to_toml() + f"\n[[key]]\nid = 1\nsecret = '{'ab' * 32}'\n",
    }.get(content, content)
    if content == "ok3":
        text = keys.to_toml() + "".join(
            f"\n[[key]]\nid = {i}\nsecret = '{'ab' * 32}'\n" for i in (7, 8)
        )
    path = tmp_path / "a.key"
    path.write_text(text)
    path.chmod(mode)
    with pytest.raises(CalibrationError, match=words):
        load_key_file(path, "a")


def test_a_device_or_a_huge_calibration_is_refused_before_it_is_read(tmp_path):
    with pytest.raises(CalibrationError, match="not a regular file"):
        load_calibration("/dev/zero")
    big = tmp_path / "big.toml"
    with big.open("wb") as f:
        f.truncate((1 << 20) + 1)  # sparse: no time to write it
    with pytest.raises(CalibrationError, match="more than"):
        load_calibration(big)


def test_a_calibration_gives_keys_to_every_sensor_or_none(tmp_path):
    path = Path(write_calibration(tmp_path, cell()))
    loaded = load_calibration(path)
    assert loaded.cell == "cell-1" and set(loaded.keys) == {"a", "b"}
    text = path.read_text()
    one = text.replace('key_file = "b.key"\n', "")
    path.write_text(one)
    with pytest.raises(CalibrationError, match="names a key for a only"):
        load_calibration(path)
    path.write_text(text.replace('key_file = "b.key"', 'key_file = "b.key"\nkey_ids = [1, 4]'))
    with pytest.raises(CalibrationError, match="unknown key id 4"):
        load_calibration(path)
    path.write_text(text.replace('key_file = "b.key"', 'key_file = "nosuch.key"'))
    with pytest.raises(CalibrationError, match="missing"):
        load_calibration(path)
    path.write_text(text.replace('cell = "cell-1"', 'cell = ""'))
    with pytest.raises(CalibrationError, match="cell must be"):
        load_calibration(path)


def test_key_errors_on_the_command_line_are_one_line_with_status_2_and_write_nothing(
    tmp_path, capsys
):
    calib = Path(write_calibration(tmp_path, cell()))
    text = calib.read_text()
    cases = {
        "loose": lambda: (tmp_path / "a.key").chmod(0o644),
        "missing": lambda: calib.write_text(text.replace('"a.key"', '"gone.key"')),
        "unknown id": lambda: calib.write_text(text.replace('"a.key"', '"a.key"\nkey_ids = [9]')),
        "one sensor": lambda: calib.write_text(text.replace('key_file = "a.key"\n', "")),
    }
    for name, spoil in cases.items():
        calib.write_text(text)
        (tmp_path / "a.key").chmod(0o600)
        spoil()
        out = tmp_path / f"out-{name.replace(' ', '-')}"
        argv = ["run", "--listen", "127.0.0.1:9", "--sensors", str(calib), "--out", str(out)]
        assert cli_main([*argv, "--max-time", "1"]) == 2, name
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("qpavoid: error:"), (name, lines)
        assert not out.exists(), name


def test_keygen_writes_a_private_key_file_and_refuses_to_overwrite(tmp_path, capsys):
    path = tmp_path / "left.key"
    argv = ["keygen", "kinect_left", "--out", str(path)]
    assert cli_main(argv) == 0
    assert "key 1 of sensor 'kinect_left' signs" in capsys.readouterr().out
    assert path.stat().st_mode & 0o077 == 0
    before = path.read_bytes()
    assert cli_main(argv) == 2 and "exists" in capsys.readouterr().err
    assert path.read_bytes() == before
    assert cli_main([*argv, "--rotate"]) == 0
    assert "key 1 still accepted" in capsys.readouterr().out
    assert load_key_file(path, "kinect_left").ids == (2, 1)
    for k, odd in enumerate(("a\\b", 'a"b', "ü x.y]")):  # TOML that reads back as itself
        other = tmp_path / f"odd{k}.key"
        assert cli_main(["keygen", odd, "--out", str(other)]) == 0
        assert load_key_file(other, odd).sensor == odd
    capsys.readouterr()
    assert cli_main(["keygen", "x" * 256, "--out", str(tmp_path / "long.key")]) == 2
    assert "at most 255 bytes" in capsys.readouterr().err
    link = tmp_path / "link.key"
    link.symlink_to(path)
    assert cli_main(["keygen", "kinect_left", "--out", str(link), "--rotate"]) == 0
    assert link.is_symlink() and load_key_file(path, "kinect_left").ids == (3, 2)


# --- the replay window and the signed datagram ------------------------------------------


def test_the_replay_window_accepts_each_number_once_as_a_set_would():
    rng = random.Random(3)
    for _ in range(50):
        window, seen, top = ReplayWindow(), set(), -1
        for _ in range(300):
            n = max(0, top + rng.randint(-2 * REPLAY_WINDOW, 8))
            expected = n not in seen and n > top - REPLAY_WINDOW
            assert window.accept(n) == expected, n
            if expected:
                seen.add(n)
                top = max(top, n)


def test_a_jump_of_the_sequence_numbers_costs_nothing():
    """An adversarial tester's case: a week-old datagram set the window's top, and the
    next real one shifted its bits by 10^11 places (gigabytes, then a MemoryError that
    dropped every later datagram of that sensor)."""
    window = ReplayWindow()
    assert window.accept(5) and window.accept(2**63) and window.accept(2**63 + 10**15)
    assert window._bits < 2**REPLAY_WINDOW
    assert not window.accept(2**63) and not window.accept(5)


def test_an_old_or_future_genuine_datagram_moves_no_window():
    """An adversarial tester's cases: a genuine datagram from an earlier run (higher
    sequence numbers) or a week-old one was dropped as late, but only after it moved its
    sensor's window: every real datagram after it was dropped as replayed."""
    cal = cell()
    now = [1000.0]
    verifier = Verifier(cal, max_age_s=0.1, clock=lambda: now[0])
    live = Signer(cal.cell, cal.keys["a"], first_sequence=999_000_000)  # started at 999 s
    later = Signer(cal.cell, cal.keys["a"], first_sequence=999_500_000)  # higher numbers
    top = Signer(cal.cell, cal.keys["a"], first_sequence=2**64 - 1)
    for old, reason in (
        (later.encode(body("a", t=999.0)), "late"),  # a second old
        (later.encode(body("a", t=1000.5)), "from_the_future"),  # half a second ahead
        (top.encode(body("a", t=999.99)), "replayed"),  # numbers ahead of the clock
    ):
        with pytest.raises(WireError) as err:
            verifier.decode(old)
        assert err.value.reason == reason
    for _ in range(100):
        now[0] += 1 / 30
        assert verifier.decode(live.encode(body("a", t=now[0] - 0.03))).t == now[0] - 0.03


def test_a_new_key_counts_afresh_whatever_the_old_keys_holder_did():
    """An adversarial tester's case: the holder of a sensor's key set its window's top far
    ahead, and a rotated key did not help, for the window was the sensor's, not the key's."""
    cal = cell()
    verifier = Verifier(cal)
    old = Signer(cal.cell, cal.keys["a"], first_sequence=10**15)
    assert verifier.decode(old.encode(body("a"))).sensor == "a"
    new_keys = SensorKeys("a", ((2, os.urandom(32)), cal.keys["a"].keys[0]))
    verifier.rekey(dataclasses.replace(cal, keys={"a": new_keys, "b": cal.keys["b"]}))
    new = Signer(cal.cell, new_keys, first_sequence=1000)  # far below the old key's top
    assert verifier.decode(new.encode(body("a"))).sensor == "a"
    with pytest.raises(WireError, match="seen"):  # the old key's window is kept
        verifier.decode(Signer(cal.cell, cal.keys["a"], first_sequence=5).encode(body("a")))


def test_a_signed_datagram_round_trips_and_each_forgery_is_refused_by_its_reason():
    cal = cell()
    verifier = Verifier(cal)
    sign_a = Signer(cal.cell, cal.keys["a"], first_sequence=100)
    good = sign_a.encode(body("a", t=5.0, body_id=2))
    frame = verifier.decode(good)
    assert (frame.sensor, frame.body, frame.t) == ("a", 2, 5.0)
    sensor, key_id, sequence, t, payload = fields(good)
    assert (sensor, key_id, sequence, t) == ("a", 1, 100, 5.0)

    def forged(payload_change=None, t_change: float = 0.0) -> bytes:
        """``good`` with its payload or capture time changed, its tag kept (no key)."""
        msg = json.loads(payload)
        if payload_change:
            payload_change(msg)
        new = json.dumps(msg, separators=(",", ":")).encode()
        head = good[: len(good) - len(payload) - 32 - 8] + struct.pack("!d", t + t_change)
        return head + new + good[-32:]

    attacker = SensorKeys("a", ((1, os.urandom(32)),))  # a key of the attacker's own
    other_cell = Signer("cell-2", cal.keys["a"], first_sequence=200)
    as_b_with_a_key = Signer(cal.cell, SensorKeys("b", cal.keys["a"].keys), 300)
    cases = {
        "replayed": good,  # taken once already
        "bad_tag": forged(t_change=0.004),  # re-stamped
        "bad_tag ": forged(lambda m: m.__setitem__("body", 5)),  # re-slotted
        "bad_tag  ": Signer(cal.cell, attacker, 400).encode(body("a")),  # forged
        "bad_tag   ": as_b_with_a_key.encode(body("b")),  # impersonating b with a's key
        "bad_tag    ": other_cell.encode(body("a")),  # another cell's datagram
        "bad_tag     ": good[:-1] + bytes([good[-1] ^ 1]),  # a bit flipped
        "unknown_key": Signer(cal.cell, SensorKeys("a", ((9, os.urandom(32)),)), 9).encode(
            body("a")
        ),
        "unknown_sensor": Signer(cal.cell, SensorKeys("z", attacker.keys), 1).seal(0.0, b"{}"),
        "unauthenticated": encode(body("a")),  # version 1
        "bad_header": b"QPAV\x03" + good[5:],
        "too_long": good + b" " * 8192,
    }
    for reason, data in cases.items():
        with pytest.raises(WireError) as err:
            verifier.decode(data)
        assert err.value.reason == reason.strip(), reason
    # a sensor's own broken payload is checked after its tag
    for payload_bytes, reason in ((b"{]", "bad_json"), (b'{"body":7}', "bad_field")):
        with pytest.raises(WireError) as err:
            verifier.decode(sign_a.seal(5.05, payload_bytes))
        assert err.value.reason == reason
    # the bodies of one frame may come in any order within the window; once each
    late_in_window = sign_a.encode(body("a", t=5.1))
    newer = sign_a.encode(body("a", t=5.2))
    assert verifier.decode(newer).t == 5.2 and verifier.decode(late_in_window).t == 5.1
    with pytest.raises(WireError, match="unsigned"):  # never unsigned for a sensor with keys
        Verifier(cal, accept_v1=True).decode(encode(body("a")))
    plain = Calibration({"a": SensorCalibration("a", POSES["a"])})
    assert Verifier(plain, accept_v1=True).decode(encode(body("a"))).sensor == "a"


def test_a_forged_datagram_is_refused_before_its_json_is_read(monkeypatch):
    cal = cell()
    verifier = Verifier(cal)
    good = Signer(cal.cell, cal.keys["a"]).encode(body("a"))
    monkeypatch.setattr(
        "qpavoid.sensing.signing.json_object", lambda data: pytest.fail("JSON parsed")
    )
    with pytest.raises(WireError, match="tag"):
        verifier.decode(good[:-1] + bytes([good[-1] ^ 1]))


def test_a_listener_takes_unsigned_datagrams_only_by_opt_in_and_on_loopback():
    plain = Calibration({"a": SensorCalibration("a", POSES["a"])})
    with pytest.raises(InputError, match="no keys"):
        Listener(("127.0.0.1", 0), plain)
    with pytest.raises(InputError, match="loopback only"):
        Listener(("0.0.0.0", 0), plain, accept_unauthenticated=True)
    assert is_loopback("localhost") and is_loopback("::1") and not is_loopback("0.0.0.0")
    assert not is_loopback("no.such.host.invalid")


# --- one sender cannot hold the cell -----------------------------------------------------


def far_body(k: int, t: float) -> BodyFrame:
    """Body k of a scatter flood: anywhere in a 6 m square whose nearest point is 3 m
    from the robot's base (the operator's seat moved 2.1 to 8.1 m away)."""
    rng = np.random.default_rng(k)
    return body("a", t, k % 6, (rng.uniform(-3.0, 3.0), rng.uniform(2.1, 8.1), 0.0))


def test_a_scatter_flood_cannot_grow_the_people_tracked():
    fuser = Fuser(cell())
    cfg = fuser.cfg
    for tick in range(300):  # 10 s at 30 Hz, six new far bodies every frame
        t = tick / 30
        for k in range(6):
            fuser.add(far_body(6 * tick + k, t))
        fused = fuser.fuse(t)
        assert len(fused.people) <= cfg.max_people
    # at most the burst plus the rate's share were ever made
    assert fuser._next_id <= cfg.new_people_burst + cfg.max_new_people_per_s * 10 + 1
    refused = fuser.counters["too_many_people"] + fuser.counters["too_many_new_people"]
    assert refused > 300


def test_a_person_near_the_robot_joins_a_full_cell_and_displaces_nobody():
    fuser = Fuser(cell(), FusionConfig(max_people=2))
    for k in range(2):
        fuser.add(far_body(k, 0.0))
    assert len(fuser.fuse(0.0).people) == 2
    fuser.add(far_body(7, 0.02))  # a third far one: refused
    fuser.add(body("b", 0.02, 0, (0.0, 0.2, 0.0)))  # the operator's seat, near the robot
    people = fuser.fuse(0.02).people
    assert len(people) == 3 and fuser.counters["too_many_people"] == 1
    near = [p for p in people if np.linalg.norm(torso_centre(p.frame.joints)) < 1.5]
    assert len(near) == 1


def test_phantoms_from_one_sensor_cannot_push_out_the_person_the_other_sees():
    """An adversarial tester's case: with one sensor's key, six phantoms under the table
    from the start filled the cell (the nearest the base were kept) and the operator,
    whom the other sensor saw, was never tracked; the robot ran on, no flag raised."""
    fuser = Fuser(cell(view=True))
    under = [(x, y, -0.6) for x in (-0.45, 0.0, 0.45) for y in (-0.55, -0.2)]
    for k in range(60):
        t = k / 30
        for i, shift in enumerate(under):
            fuser.add(body("a", t, i, shift))
        fuser.add(body("b", t, 0))  # the operator, seen by the other sensor
        people = fuser.fuse(t).people
    seat = torso_centre(Operator().rest())
    seen = [p for p in people if np.linalg.norm(torso_centre(p.frame.joints) - seat) < 0.1]
    assert len(people) == 7 and len(seen) == 1 and not seen[0].flag


def test_a_flood_of_near_phantoms_keeps_the_fusion_bounded_and_those_seen_now():
    # every phantom is new: no gate, not even an unseen person's, reaches the next one
    fuser = Fuser(cell(), FusionConfig(association_gate_m=0.05, max_association_gate_m=0.05))
    for k in range(200):  # six new phantoms every frame, each at a new place near the base
        t = k / 30
        for i in range(6):
            rng = np.random.default_rng(6 * k + i)
            fuser.add(body("a", t, i, (rng.uniform(-1, 1), rng.uniform(-0.8, 0), -0.5)))
        fuser.add(body("b", t, 0))
        people = fuser.fuse(t).people
        assert len(fuser.tracks) <= fuser.cfg.max_tracks
    assert fuser.counters["forgotten_for_room"] > 100
    assert sum(bool(p.sensors) for p in people) >= 6  # everyone seen now is kept


def test_a_phantom_near_the_robot_is_flagged_still_stops_and_can_be_cleared():
    fuser = Fuser(cell(view=True))
    for k in range(60):  # the operator seen by both sensors from the start, 2 s
        for s in "ab":
            fuser.add(body(s, k / 30, 0))
        assert not any(p.flag for p in fuser.fuse(k / 30).people)
    # a body out of nowhere, 0.5 m from the base, from sensor "a" alone, for 0.1 s
    for k in range(3):
        t = 2.0 + k / 30
        fuser.add(body("a", t, 3, (0.4, -0.5, 0.0)))
        fuser.fuse(t)
    flagged = [p for p in fuser.fuse(2.1).people if p.flag]
    assert len(flagged) == 1 and "never seen approaching" in flagged[0].flag
    for k in range(120):  # it is never seen again: held (near the robot), still flagged
        t = 2.2 + k / 30
        fuser.fuse(t)
    assert [p.flag for p in fuser.fuse(6.2).people if p.id == flagged[0].id]
    assert fuser.clear_flagged() == (flagged[0].id,)
    assert all(p.id != flagged[0].id for p in fuser.fuse(6.3).people)


def test_a_sensor_silent_where_the_other_sees_someone_raises_the_alert():
    """Issue 40's third network adversary silenced one camera whole: no frame is lost when
    a camera sends nothing (it may see nobody), so nothing was said. Silence where the
    other camera sees someone in the silent one's view is said; silence alone is not."""
    fuser = Fuser(cell(view=True))
    for k in range(60):  # the operator seen by both sensors, 2 s
        for s in "ab":
            fuser.add(body(s, k / 30, 0))
        fuser.fuse(k / 30)
        assert fuser.silent_sensors(k / 30) == ()
    quiet = []
    for k in range(60, 90):  # then "a" sends nothing for 1 s; "b" still sees the operator
        fuser.add(body("b", k / 30, 0))
        fuser.fuse(k / 30)
        quiet.append(fuser.silent_sensors(k / 30))
    assert all(q == () for q in quiet[:14])  # within 0.5 s: a dropout's business
    ((sensor, silent_s, person, other),) = quiet[-1]
    assert (sensor, person, other) == ("a", 0, "b") and silent_s == pytest.approx(89 / 30 - 59 / 30)
    empty = Fuser(cell(view=True))  # "a" never sends; "b" sees someone out of its view
    empty.add(body("b", 0.0, 0, shift=(0.0, 10.0, 0.0)))  # 10 m on: beyond its 4.5 m
    for k in range(60):
        empty.fuse(k / 30)
    assert empty.silent_sensors(59 / 30) == ()


def test_a_body_one_sensor_sees_where_the_other_looks_is_flagged():
    fuser = Fuser(cell(view=True))
    for k in range(60):
        for s in "ab":
            fuser.add(body(s, k / 30, 0))
        fuser.fuse(k / 30)
    # a second person 1.7 m away (beyond the reach: not flagged on appearing), seen by "a"
    # only for a second while "b", fresh, has that place in its view
    shift = (-0.6, 0.6, 0.0)
    where = torso_centre(Operator().rest() + shift)
    assert all(cell(view=True)[s].sees(where) for s in "ab") and np.linalg.norm(where) > 1.6
    for k in range(30):
        t = 2.0 + k / 30
        fuser.add(body("a", t, 4, shift))
        fuser.add(body("b", t, 0))
        fuser.add(body("a", t, 0))
        fuser.fuse(t)
    flags = [p.flag for p in fuser.fuse(3.0).people if p.flag]
    assert flags == ["seen by a only, in the view of b"]


def test_the_opt_in_listener_on_loopback_takes_unsigned_datagrams_of_sensors_without_keys():
    plain = Calibration({n: SensorCalibration(n, T) for n, T in POSES.items()})
    with pytest.raises(InputError, match="have keys"):  # keys and the opt-in: refused
        Listener(("127.0.0.1", 0), cell(), accept_unauthenticated=True)
    # fresh within 5 s (a loaded machine may take tenths of a second to deliver), late by 60
    with Listener(("127.0.0.1", 0), plain, max_age_s=5.0, accept_unauthenticated=True) as listener:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            now = time.time()
            sock.sendto(encode(body("a", now - 0.01, 1)), listener.address)
            sock.sendto(encode(body("b", now)), listener.address)
            sock.sendto(encode(body("b", now - 60.0, 2)), listener.address)  # late
        deadline = time.time() + 10.0
        while listener.counters["received"] < 3 and time.time() < deadline:
            time.sleep(0.02)
        frames = listener.drain()
    assert [(f.sensor, f.body) for f in frames] == [("a", 1), ("b", 0)]
    assert listener.counters["accepted"] == 2 and listener.counters["late"] == 1


@pytest.mark.slow
def test_the_sender_example_signs_frames_a_listener_accepts(tmp_path):
    calib = write_calibration(tmp_path, cell())
    example = Path(__file__).parents[1] / "examples" / "sensor_sender.py"
    # frames 5 s old still fresh: a loaded machine may take tenths of a second to deliver
    with Listener(("127.0.0.1", 0), load_calibration(calib), max_age_s=5.0) as listener:
        to = f"127.0.0.1:{listener.address[1]}"
        cmd = [*PYTHON, str(example), calib, "b", to, "0.3"]
        result = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
        time.sleep(0.2)
        counts = listener.counters
        frames = listener.drain()
    assert result.returncode == 0, result.stderr
    sent = int(result.stdout.split()[1])
    assert sent >= 2 and counts["received"] == counts["accepted"] == sent, counts
    assert [(f.sensor, f.body) for f in frames] == [("b", 0)]


def test_a_key_is_rotated_without_stopping_the_listener(tmp_path):
    """An adversarial tester's case: the listener read its keys once, so a rotation needed
    a restart (a stop). It now reads them again when a file changes."""
    calib = write_calibration(tmp_path, cell())
    key_a = tmp_path / "a.key"

    def send(keys: SensorKeys, n: int = 5) -> None:
        signer = Signer("cell-1", keys)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            for _ in range(n):
                sock.sendto(signer.encode(body("a", time.time())), listener.address)
                time.sleep(0.005)

    def until(counter: str, value: int) -> dict:
        deadline = time.time() + 20.0
        while listener.counters[counter] < value and time.time() < deadline:
            time.sleep(0.05)
        return dict(listener.counters)

    # frames 5 s old still fresh: a loaded machine may take tenths of a second to deliver
    # (at the default 0.1 s a starved receiver dropped real datagrams as late)
    with Listener(
        ("127.0.0.1", 0), load_calibration(calib), key_check_s=0.1, max_age_s=5.0
    ) as listener:
        first = load_key_file(key_a, "a")
        send(first)
        assert until("accepted", 5)["accepted"] == 5
        new_key_file(key_a, "a", rotate=True)  # the listener's file first: ids 2, 1
        until("keys_reloaded", 1)
        send(first)  # the sender still on key 1: still taken
        assert until("accepted", 10)["accepted"] == 10
        second = load_key_file(key_a, "a")
        send(second)  # then the sender on key 2
        assert until("accepted", 15)["accepted"] == 15
        key_a.chmod(0o644)  # a bad reading keeps the keys in use
        until("keys_reload_failed", 1)
        send(second)
        assert until("accepted", 20)["accepted"] == 20
        key_a.chmod(0o600)
        until("keys_reloaded", 2)
        new_key_file(key_a, "a", rotate=True)  # ids 3, 2: key 1 is gone
        until("keys_reloaded", 3)
        send(first)
        until("dropped_unknown_key", 5)
        text = Path(calib).read_text()  # a new pose is not taken by a running listener
        Path(calib).write_text(text.replace("time_offset_s = 0.0", "time_offset_s = 0.5", 1))
        counts = until("keys_reload_failed", 2)
    assert counts["dropped_unknown_key"] == 5 and counts["accepted"] == 20, counts
    assert counts["keys_reloaded"] == 3 and counts["keys_reload_failed"] == 2, counts


def test_the_live_source_clears_the_flagged_people_when_the_view_asks():
    class Frames:
        """A listener's side: the frames sent so far, once each."""

        def __init__(self):
            self.calibration, self.counters = cell(view=True), {}
            self.pending: list[BodyFrame] = []

        def drain(self) -> list[BodyFrame]:
            out, self.pending = self.pending, []
            return out

        def losses(self) -> dict:  # none lost on the way
            return {}

        def format_mismatches(self) -> dict:  # every datagram of its sensor's format
            return {}

    listener, clear = Frames(), threading.Event()
    source = LiveSource(listener, clock=lambda: 100.0, clear=clear)  # run time 0 = 100 s
    for k in range(45):  # the operator from the start, then a phantom by the base at 1.2 s
        t = k / 30
        listener.pending = [body(s, 100.0 + t, 0) for s in "ab"]
        if k >= 36:
            listener.pending.append(body("a", 100.0 + t, 3, (0.4, -0.5, 0.0)))
        people, _ = source.frame_at(t)
    assert "never seen approaching" in source.alert and len(people.ids) == 2
    clear.set()
    listener.pending = [body(s, 101.69, 0) for s in "ab"]  # the phantom has gone
    people, _ = source.frame_at(1.7)
    assert source.alert == "" and len(people.ids) == 1 and not clear.is_set()
