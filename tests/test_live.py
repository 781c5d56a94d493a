"""Live input over UDP: the wire format, the listener under faults and floods, end to end."""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import time
from pathlib import Path
from urllib.request import urlopen

import numpy as np
import pytest
from conftest import PYTHON, write_calibration

from qpavoid.cli.commands import main as cli_main
from qpavoid.control.journal import KINDS, Journal, reproduce
from qpavoid.control.qp import QPController
from qpavoid.control.tick import ControllerConfig
from qpavoid.fusion.fuser import FusionConfig
from qpavoid.human.frames import HumanFrame
from qpavoid.human.posture import Operator
from qpavoid.loop.live_input import Listener, LiveSource, parse_address
from qpavoid.loop.simulation import SimConfig, simulate
from qpavoid.scenarios.generated import make_scenario
from qpavoid.sensing.calibration import Calibration, SensorCalibration
from qpavoid.sensing.keys import SensorKeys
from qpavoid.sensing.per_sensor import BodyFrame, save_sensor_npz
from qpavoid.sensing.signing import Signer, Verifier, fields
from qpavoid.sensing.streamer import stream
from qpavoid.sensing.synthetic_pair import TwoSensorConfig, look_at, two_sensor_data
from qpavoid.sensing.wire import WireError, Workspace, decode, encode

CAL = Calibration(
    {"a": SensorCalibration("a", look_at(np.array([1.0, 2.5, 1.3]), np.zeros(3)))},
    cell="test-cell",
    keys={"a": SensorKeys.generate("a")},
)


def signer() -> Signer:
    """Sensor "a"'s sender (a new one counts on from now, in microseconds)."""
    return Signer(CAL.cell, CAL.keys["a"])


def frame(t: float = 10.0, sensor: str = "a") -> BodyFrame:
    T = np.linalg.inv(CAL["a"].base_from_camera)
    joints = Operator().rest() @ T[:3, :3].T + T[:3, 3]
    state = np.full(25, 2, dtype=np.int8)
    state[3] = 0  # the head not tracked: sent as state 0
    return BodyFrame(sensor, 1, t, joints, state)


def test_a_datagram_round_trips_and_a_joint_not_tracked_comes_back_missing():
    f = frame()
    back = decode(encode(f), CAL, Workspace())
    assert (back.sensor, back.body, back.t) == ("a", 1, 10.0)
    ok = f.state > 0
    np.testing.assert_allclose(back.joints[ok], f.joints[ok], atol=5e-7, rtol=0)
    assert np.isnan(back.joints[3]).all() and back.state[3] == 0
    assert len(encode(f)) < 1400  # one Ethernet frame


def mutate(**changes) -> bytes:
    msg = json.loads(encode(frame()))
    msg.update(changes)
    return json.dumps(msg).encode()


@pytest.mark.parametrize(
    ("data", "reason"),
    [
        (b"x" * 9000, "too_long"),
        (b"{not json", "bad_json"),
        (b"\xff\xfe", "bad_json"),
        (b"[1, 2]", "bad_json"),
        (mutate(v=2), "bad_version"),
        (mutate(v=True), "bad_version"),
        (mutate(sensor=""), "bad_field"),
        (mutate(body=6), "bad_field"),
        (mutate(body="0"), "bad_field"),
        (mutate(t="now"), "bad_field"),
        (mutate(joints=[[0, 0, 0, 2]] * 24), "bad_field"),
        (mutate(joints=[[0, 0, "0", 2]] * 25), "bad_field"),
        (mutate(joints=[[0, 0, 0, 3]] * 25), "bad_field"),
        (encode(frame()).replace(b'"t":10.0', b'"t":NaN'), "non_finite"),
        (mutate(joints=[[1e400, 0, 0, 2]] * 25), "non_finite"),
        (mutate(sensor="kinect_9"), "unknown_sensor"),
        (mutate(t=10**309), "non_finite"),  # an integer too large for a float
        (mutate(joints=[[10**309, 0, 0, 2]] * 25), "non_finite"),
        (mutate(joints=[[0, 0, 0, 10**309]] * 25), "non_finite"),
        (mutate(joints=[[0.0, 0.0, 40.0, 2]] * 25), "outside_workspace"),
    ],
)
def test_every_malformed_datagram_is_refused_with_its_reason(data, reason):
    with pytest.raises(WireError) as err:
        decode(data, CAL, Workspace())
    assert err.value.reason == reason


def test_addresses():
    assert parse_address("127.0.0.1:5005") == ("127.0.0.1", 5005)
    assert parse_address("[::1]:7") == ("::1", 7)
    for bad in ("5005", "host:", ":80", "h:99999", "h:x", "h:0", "127.0.0.1:５００６"):
        with pytest.raises(Exception, match="HOST:PORT"):
            parse_address(bad)


def test_a_flood_keeps_each_bodys_newest_frame_and_counts_the_rest():
    def stamp(k: int) -> float:  # frame k's capture time: when it is sent, increasing
        while len(stamps) <= k:
            stamps.append(max(time.time(), stamps[-1] + 1e-6 if stamps else 0.0))
        return stamps[k]

    sign, stamps = signer(), []
    # the flood's bookkeeping, not lateness: on a loaded machine the receiver (nice +10)
    # may reach a datagram after the fusion's max_age_s and rightly drop it as late
    with Listener(("127.0.0.1", 0), CAL, max_age_s=60.0) as listener:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            for k in range(400):
                sock.sendto(sign.encode(frame(t=stamp(k))._replace(body=k % 2)), listener.address)
                if k % 50 == 0:
                    sock.sendto(b"junk", listener.address)
            old = sign.encode(frame(t=stamp(3)))  # older than body 1's last
            sock.sendto(old, listener.address)
        deadline, last = time.time() + 5.0, -1
        while last < listener.counters["received"] < 409 and time.time() < deadline:
            last = listener.counters["received"]  # until all came, or no more comes
            time.sleep(1.0)
        frames = listener.drain()
        again = listener.drain()
    counts = listener.counters
    received = counts["received"]
    assert 16 < received <= 409  # the kernel may shed some too; we count what came
    index = [stamps.index(f.t) for f in frames]
    assert sorted(f.body for f in frames) == [0, 1]  # one frame per body ...
    assert all(k % 2 == f.body for k, f in zip(index, frames, strict=True))
    assert frames[0].t < frames[1].t  # ... in order
    assert all(g.t > f.t for g in again for f in frames if f.body == g.body)  # taken once
    assert counts["dropped_bad_header"] >= 1  # the junk, checked on the receiver's side
    drops = sum(v for k, v in counts.items() if k.startswith("dropped_"))
    drops += counts["out_of_order_or_duplicate"] + counts["late"] + counts["from_the_future"]
    assert received == counts["accepted"] + drops  # every datagram accounted for
    assert counts["superseded"] == counts["accepted"] - 2  # all but the two taken
    if received == 409:  # nothing shed by the kernel: exactly the newest of each body
        assert index == [398, 399]
        assert counts["dropped_bad_header"] == 8
        assert counts["late"] == 0
        assert counts["out_of_order_or_duplicate"] == 1  # the old frame


def test_a_busy_port_is_a_clear_error():
    with Listener(("127.0.0.1", 0), CAL) as first, pytest.raises(Exception, match="cannot listen"):
        Listener(first.address, CAL)


@pytest.mark.slow  # 4 s of real time on loopback (the default suite's cold time)
def test_loopback_replay_with_faults_never_moves_on_stale_or_invalid_data(robot):
    """stream → UDP → listener → fusion → controller, in real time, with bad datagrams."""
    motion = make_scenario("free", robot)
    data = two_sensor_data([motion], 3.0, TwoSensorConfig(seed=4))
    recordings = list(data.recordings.values())
    held: list[bytes] = []

    signers = {name: Signer(data.calibration.cell, k) for name, k in data.calibration.keys.items()}

    def changed(datagram: bytes, change, dt: float = 0.0) -> bytes:
        """The datagram with its payload and capture time changed, signed again by its own
        sensor under its own sequence number: a sensor's own fault, which the tag cannot
        catch."""
        sensor, _, sequence, t, payload = fields(datagram)
        msg = json.loads(payload)
        change(msg)
        return signers[sensor].seal(t + dt, json.dumps(msg).encode(), sequence)

    def late(msg: dict) -> None:
        msg["body"] = 5  # (as body 5, with no newer frame: as late, not out of order)

    def mangle(i: int, datagram: bytes) -> list[bytes]:
        k = i % 40
        if k == 5:
            return [datagram, datagram]  # a duplicate: a replay
        if k == 25:  # held back: it arrives after its sensor's next frame (out of order)
            held.append(datagram)
            return []
        if k == 29:
            return [datagram, held.pop()]
        if k == 9:
            return [b"\x00garbage"]
        if k == 13:
            return [datagram[:4] + b"\x07" + datagram[5:]]  # another version
        if k == 17:
            return [changed(datagram, late, -0.5)]  # half a second late: dropped as old
        if k == 21:  # garbage coordinates
            return [changed(datagram, lambda msg: msg["joints"][0].__setitem__(0, 1e9))]
        if k == 33:  # a bit flipped in transit
            return [datagram[:-40] + bytes([datagram[-40] ^ 1]) + datagram[-39:]]
        if 120 <= i < 160:  # a gap of about a third of a second: nothing at all
            return []
        return [datagram]

    controller = QPController(
        robot, config=ControllerConfig(control_period_s=0.01, safety="ssm", max_frame_age_s=0.1)
    )
    with Listener(("127.0.0.1", 0), data.calibration) as listener:
        source = LiveSource(listener, FusionConfig())
        pid = os.fork()
        if pid == 0:  # the sensors' side
            time.sleep(0.3)
            stream(recordings, listener.address, 30.0, data.calibration, mangle=mangle)
            os._exit(0)
        sim = simulate(
            controller,
            None,
            SimConfig(control_rate_hz=100.0, max_time_s=3.6, measure_truth=False),
            source=source,
            realtime=True,
        )
        os.waitpid(pid, 0)
        report = source.report()
    log = sim.log
    assert np.isfinite(log["dq"]).all()
    # driven, not braking: a stale frame's command is a braking ramp (stopped), which is
    # the stop itself (each person now counted at their oldest camera's age, a tick may
    # find the frame stale while the arm still moves: it brakes)
    moving = np.any(log["dq_command"] != 0.0, axis=1) & ~log["stopped"]
    assert moving.any()  # fresh frames: it works ...
    assert (log["frame_age_s"][moving] <= 0.1).all(), [  # ... and never on a stale frame
        (float(t), float(a), str(r))
        for t, a, r in zip(log["t"][moving], log["frame_age_s"][moving], log["stop_reason"][moving])
        if a > 0.1
    ]
    stopped_for_gap = [e for e in sim.metrics["stop_events"] if "stale" in e["reason"]]
    assert len(stopped_for_gap) >= 2  # at the start (no frame yet) and in the gap
    for reason in ("bad_header", "bad_tag", "replayed", "outside_workspace"):
        assert report[f"dropped_{reason}"] >= 2, report
    # the held-back frames (every 40th, twice each in 3 s, minus the gap)
    assert report["out_of_order_or_duplicate"] >= 2 and report["late"] >= 2, report
    # what the controller was handed, given to a fresh one, gives the same commands: a live
    # run's are reproducible after the fact (frames fused, held, stale; QP warm starts)
    entries = Journal.split(sim.journal["journal_data"], sim.journal["journal_offsets"])
    # a fused frame is kept when its content changes (the fusion's filter moves it between
    # captures too), not once a tick
    frames = sum(e[0] == KINDS["frame"] for e in entries)
    assert frames < sum(e[0] == KINDS["step"] for e in entries)
    again = reproduce(QPController(robot, config=controller.config), entries)
    assert again.shape == log["dq_command"].shape
    np.testing.assert_allclose(again, log["dq_command"], rtol=0, atol=1e-9)


def test_a_frame_from_the_future_cannot_hide_the_real_ones():
    """An adversarial tester's case: a datagram stamped 10⁶ s ahead was dropped, but only
    after it became its body's newest, so every real frame after it was dropped too."""
    sign = signer()
    with Listener(("127.0.0.1", 0), CAL) as listener:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            sock.sendto(sign.encode(frame(t=time.time() + 1e6)), listener.address)
            sock.sendto(sign.encode(frame(t=time.time() - 10.0)), listener.address)
            time.sleep(0.2)
            now = time.time()
            sock.sendto(sign.encode(frame(t=now)), listener.address)
        deadline = time.time() + 5.0
        while listener.counters["received"] < 3 and time.time() < deadline:
            time.sleep(0.02)
        frames = listener.drain()
    counts = listener.counters
    assert [f.t for f in frames] == [now]
    assert counts["from_the_future"] == 1 and counts["late"] == 1
    assert counts["received"] == counts["accepted"] + 2 == 3


def listening(tmp_path: Path, *extra: str) -> tuple[subprocess.Popen, int, Path]:
    """``qpavoid run --listen`` on a free port, started; its process, port and output."""
    calib = write_calibration(tmp_path, CAL)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = tmp_path / "live"
    cmd = [*PYTHON, "-m", "qpavoid", "run", "--listen", f"127.0.0.1:{port}"]
    cmd += ["--sensors", str(calib), "--out", str(out), "--rate", "100", "--no-plots", "-q"]
    cmd += list(extra)
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    return proc, port, out


def wait_until_ticking(proc: subprocess.Popen, within_s: float = 60.0) -> None:
    """Wait until a run started with ``--view`` has logged its first tick (its live view
    then has a state to show)."""
    url = re.search(r"live view: (\S+)", proc.stdout.readline()).group(1)
    deadline = time.time() + within_s
    while urlopen(url + "state", timeout=10).read() == b"null":
        assert time.time() < deadline, "the run did not start ticking"
        time.sleep(0.1)


def wait_until_bound(port: int, within_s: float = 30.0) -> None:
    """Wait until some socket is bound to UDP ``port`` (read from /proc: probing by binding
    could steal the port from the receiver about to bind it)."""
    deadline = time.time() + within_s
    while time.time() < deadline:
        for table in ("/proc/net/udp", "/proc/net/udp6"):
            with open(table) as handle:
                if any(f":{port:04X} " in line.split()[1] + " " for line in handle.readlines()[1:]):
                    return
        time.sleep(0.1)
    raise AssertionError(f"nothing bound UDP port {port} in {within_s} s")


def port_is_free(port: int, within_s: float) -> bool:
    """True once ``port`` can be bound again, trying for ``within_s``."""
    deadline = time.time() + within_s
    while True:
        try:
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
                s.bind(("127.0.0.1", port))
            return True
        except OSError:
            if time.time() > deadline:
                return False
            time.sleep(0.1)


@pytest.mark.slow
def test_a_killed_run_leaves_no_receiver_holding_its_port(tmp_path):
    proc, port, _ = listening(tmp_path)
    wait_until_bound(port)
    assert not port_is_free(port, 0.0)  # the receiver has it
    proc.kill()
    proc.communicate(timeout=30)
    assert port_is_free(port, 3.0)  # the orphaned receiver saw its parent go, and left


@pytest.mark.parametrize(
    "signum", [signal.SIGINT, pytest.param(signal.SIGTERM, marks=pytest.mark.slow)]
)
def test_the_command_line_listens_and_ctrl_c_or_sigterm_writes_the_run(tmp_path, signum):
    proc, port, out = listening(tmp_path, "--view")
    wait_until_ticking(proc)  # a loaded CI may take seconds to start
    sign = signer()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        for _k in range(15):
            sock.sendto(sign.encode(frame(t=time.time())._replace(body=0)), ("127.0.0.1", port))
            sock.sendto(b"junk", ("127.0.0.1", port))
            time.sleep(1 / 30)
    proc.send_signal(signum)
    stdout, stderr = proc.communicate(timeout=30)
    assert proc.returncode == 0, stderr
    assert "Traceback" not in stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["end_reason"] == "interrupted"
    assert metrics["input"]["dropped_bad_header"] == 15
    assert metrics["input"]["accepted"] >= 1
    assert Path(out / "log.npz").exists() and "wrote metrics.json" in stdout
    assert port_is_free(port, 3.0)


@pytest.mark.parametrize("signed", [True, False])
def test_per_sensor_files_replay_from_the_command_line(tmp_path, robot, signed, capsys):
    data = two_sensor_data([make_scenario("free", robot)], 0.3, TwoSensorConfig(seed=1))
    files = []
    for name, rec in data.recordings.items():
        save_sensor_npz(tmp_path / f"{name}.npz", rec)
        files.append(str(tmp_path / f"{name}.npz"))
    calib = write_calibration(tmp_path, data.calibration)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sink:
        sink.bind(("127.0.0.1", 0))
        sink.settimeout(5.0)
        port = sink.getsockname()[1]
        argv = ["replay", *files, "--to", f"127.0.0.1:{port}", "--rate", "300"]
        argv += ["--sensors", calib] if signed else ["--unsigned"]
        assert cli_main(argv) == 0, capsys.readouterr().err
        got = [sink.recv(65536) for _ in range(18)]
    kind = "signed" if signed else "unsigned"
    assert f"sent 18 datagrams to 127.0.0.1:{port} ({kind})" in capsys.readouterr().out
    if signed:
        verifier = Verifier(data.calibration)
        assert {verifier.decode(d).sensor for d in got} == set(data.recordings)
        with pytest.raises(WireError, match="seen"):  # each datagram is taken once
            verifier.decode(got[0])
    else:
        assert {decode(d, data.calibration).sensor for d in got} == set(data.recordings)


def test_a_late_control_loop_sees_its_frames_as_old_as_they_really_are(robot):
    """An adversarial tester's case: when the loop falls behind (a stall, a flood), ticks
    must be stamped with the wall time, or a frame 0.4 s old passes for a fresh one."""
    rest = Operator().rest()

    class Stalling:
        """Frames captured every 1/30 s of wall time, delivered at once; one 0.4 s stall
        of the loop at 0.5 s, after which delivery stops (frames only grow old)."""

        def __init__(self):
            self.stalled, self.start = False, None
            self.true_age = []  # the wall time of each tick minus its frame's capture

        def frame_at(self, t):
            if self.start is None:  # the run's time 0
                self.start = time.perf_counter() - t
            now = time.perf_counter() - self.start
            if now > 0.5 and not self.stalled:
                self.stalled = True
                time.sleep(0.4)
                now = time.perf_counter() - self.start
            k = min(int(now * 30), 15)  # frame k, captured at k / 30 s (none after 0.5 s)
            self.true_age.append(now - k / 30)
            return frames[k], k / 30

    noise = np.random.default_rng(0).normal(0.0, 0.002, (16, 25, 3))  # never bit-identical
    frames = [HumanFrame.check(rest + noise[k]) for k in range(16)]
    source = Stalling()
    controller = QPController(robot, config=ControllerConfig(control_period_s=0.01))
    sim = simulate(
        controller,
        None,
        SimConfig(control_rate_hz=100.0, max_time_s=1.2, measure_truth=False, braking=None),
        source=source,
        realtime=True,
    )
    log = sim.log
    moving = np.any(log["dq_command"] != 0.0, axis=1)
    true_age = np.array(source.true_age)[: len(moving)]
    assert moving.any()  # it moved on fresh frames ...
    assert (true_age[moving] <= 0.1).all()  # ... and never on a frame truly older than 0.1 s
    # The log tells the age as judged after the frame came: never younger than it truly was
    # (by how much older depends on the machine's load, so that is not asserted).
    assert np.all(log["frame_age_s"] >= true_age - 1e-9)
    assert sim.metrics["realtime_overruns"] >= 1
