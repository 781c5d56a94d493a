"""Live skeletons from a ROS 2 graph: each calibrated camera's body-tracking topic, over
Cyclone DDS, as the UDP :class:`~qpavoid.loop.live_input.Listener` gives them.

:class:`DdsListener` has the Listener's interface (``drain``, ``losses``, ``counters``,
``format_mismatches``, ``calibration``, ``address``, ``close``), so the same
:class:`~qpavoid.loop.live_input.LiveSource` (fusion, freshness, age limits, loss
handling, the operator's lines) takes its frames unchanged.

A thread of its own waits on the readers (a DDS wait set: woken by a sample, not polled)
and, for each sample: its CDR bytes taken raw (:func:`~qpavoid.sensing.ros2_cell.take_raw`:
a malformed sample is one ``dropped_unreadable``), a MarkerArray longer than its cap
refused from its length field before any decoding (``dropped_too_many_markers``), then
decoded and read by the sensor's driver (:class:`~qpavoid.sensing.ros2_bodies.BodyTopic`:
every drop counted by reason, ``dropped_<reason>``). Each body's newest frame waits for the
loop (one replaced first is ``superseded``). An empty MarkerArray is a frame with nobody
seen, its receive time standing in for its missing stamp.

**Gaps**: a sensor's messages come at its format's frame rate. A gap of more than
:data:`GAP_FRAMES` frames between two messages' times is a dropout: the frames missing are
counted (``lost_frames``, and the sensor's :meth:`losses`), and every frame before the new
one is stale (as a UDP frame lost on the way: the fusion drops the sensor's old frames).

**Wrong types**: a publisher on a camera's topic whose type is not the driver's is never
matched by DDS (its samples are not delivered, a ``requested incompatible QoS``): said once
per topic, counted ``incompatible_publishers``.
"""

from __future__ import annotations

import math
import threading
import time
from collections import Counter
from collections.abc import Callable
from typing import Any

from qpavoid.core.errors import InputError
from qpavoid.sensing.calibration import Calibration
from qpavoid.sensing.per_sensor import BodyFrame
from qpavoid.sensing.receiver import SensorLoss
from qpavoid.sensing.ros2_bodies import BodyTopic
from qpavoid.sensing.ros2_cell import Cell, participant, reader, take_raw
from qpavoid.sensing.ros2_types import need

__all__ = ["GAP_FRAMES", "DdsListener", "check_trust"]

#: A gap between a sensor's messages of more than this many frame periods is a dropout.
GAP_FRAMES = 2.5
#: A sample of more bytes than this per body the format allows is refused undecoded (a
#: driver's MarkerArray is about 300 bytes a joint; a ZED Object about 3 kB).
BYTES_PER_BODY = 64 * 1024
#: Samples each camera reader keeps until the thread takes them (a burst is counted, not
#: overwritten unseen; the newest of each body is what the loop takes).
READER_DEPTH = 8
#: How long the reading thread waits for a sample before it looks at its stop flag, s.
WAIT_S = 0.05
#: How often each topic's unmatched publishers are looked at, s.
MATCH_CHECK_S = 0.5


def check_trust(trust_ros_graph: bool, domain_id: int) -> None:
    """A ROS 2 input takes skeletons from anyone on its DDS domain: only with the explicit
    opt-in (``--trust-ros-graph``), else :class:`InputError` (one line)."""
    if not trust_ros_graph:
        raise InputError(
            f"a ROS 2 input believes whatever anyone on DDS domain {domain_id} publishes "
            "(a forged skeleton can hide a person): fence the domain (docs/security.md) and "
            "give --trust-ros-graph",
            name="--trust-ros-graph",
            value=False,
        )


class DdsListener:
    """Each calibrated sensor's ROS 2 topic in, checked :class:`BodyFrame` s out (module
    docstring).

    Parameters
    ----------
    cell
        The distribution and DDS domain.
    calibration
        The sensors; each must name its ``topic``.
    trust_ros_graph
        The explicit opt-in (:func:`check_trust`).
    say
        Called (from the reading thread) with a line for the operator: a topic whose
        publishers match no type.

    Raises
    ------
    InputError
        Without the opt-in, a sensor without a topic, a format no driver publishes;
        :class:`~qpavoid.sensing.ros2_types.Ros2UnavailableError` without cyclonedds.
    """

    #: What its input arrives as (the summary's "input: N messages").
    unit = "messages"

    def __init__(
        self,
        cell: Cell,
        calibration: Calibration,
        trust_ros_graph: bool = False,
        say: Callable[[str], None] | None = None,
    ):
        check_trust(trust_ros_graph, cell.domain_id)
        need("cyclonedds.core")
        missing = [name for name, cal in calibration.sensors.items() if cal.topic is None]
        if missing:
            raise InputError(
                f"sensor {missing[0]} of {calibration.path or 'the calibration'} names no "
                'topic: give it its driver\'s body topic (topic = "/k4a/body_tracking_data")',
                name="topic",
                value=missing[0],
            )
        self.cell, self.calibration = cell, calibration
        self.address: tuple[str, int] = (f"ROS 2 domain {cell.domain_id}", cell.domain_id)
        self.say = say or (lambda line: None)
        self.topics = {
            name: BodyTopic(name, cal.format) for name, cal in calibration.sensors.items()
        }
        self._counts: Counter[str] = Counter()
        self._frames: dict[tuple[str, int], BodyFrame] = {}
        self._lost = {name: SensorLoss(0, -math.inf) for name in self.topics}
        self._last = {name: -math.inf for name in self.topics}  # each sensor's last time
        self._said: set[str] = set()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._dp = participant(cell.domain_id)
        core = need("cyclonedds.core")
        self._waitset = core.WaitSet(self._dp)
        self._readers: dict[str, Any] = {}
        for name, topic in self.topics.items():
            topic_name = calibration[name].topic
            assert topic_name is not None
            dds_reader = reader(
                self._dp, cell.distribution, topic_name, topic.message, depth=READER_DEPTH
            )
            self._readers[name] = dds_reader
            self._waitset.attach(core.ReadCondition(dds_reader, core.SampleState.Any))
        self._thread = threading.Thread(target=self._serve, name="qpavoid-dds", daemon=True)
        self._thread.start()

    # the Listener's interface -----------------------------------------------------------

    @property
    def counters(self) -> Counter[str]:
        """Samples received and dropped, by reason (zeros left out)."""
        with self._lock:
            return Counter({k: v for k, v in self._counts.items() if v})

    def drain(self) -> list[BodyFrame]:
        """Each body's newest valid frame received since the last call, oldest first."""
        with self._lock:
            frames, self._frames = list(self._frames.values()), {}
        return sorted(frames, key=lambda f: f.t)

    def losses(self) -> dict[str, SensorLoss]:
        """Each sensor's lost frames so far and the time before which its frames are stale."""
        with self._lock:
            return dict(self._lost)

    def format_mismatches(self) -> dict[str, tuple[str, str]]:
        """None here: a topic's type is its driver's (another type is never matched)."""
        return {}

    def ready_line(self) -> str:
        """What it listens for, in one line."""
        sensors = ", ".join(
            f"{name} on {cal.topic} ({self.topics[name].message.split('/')[-1]}, "
            f"{cal.format}, age limit {1e3 * cal.age_limit_s:.0f} ms)"
            for name, cal in self.calibration.sensors.items()
        )
        return (
            f"listening on ROS 2 ({self.cell.distribution}, DDS domain {self.cell.domain_id}) "
            f"for {sensors}: anyone on the domain is believed (--trust-ros-graph)"
        )

    def close(self) -> None:
        """Stop reading and leave the domain (idempotent)."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        dp, self._dp = self._dp, None
        if dp is not None:
            self._readers.clear()
            self._waitset = None
            del dp

    def __enter__(self) -> DdsListener:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # the reading thread -----------------------------------------------------------------

    def _serve(self) -> None:
        duration = need("cyclonedds.util").duration
        wait = duration(seconds=WAIT_S)
        next_check = 0.0
        while not self._stop.is_set():
            try:
                self._waitset.wait(wait)
                for name, dds_reader in self._readers.items():
                    for data in take_raw(dds_reader):
                        self._sample(name, data, time.time())
                if time.monotonic() >= next_check:
                    next_check = time.monotonic() + MATCH_CHECK_S
                    self._check_matches()
            except Exception as exc:  # never a thread's traceback: counted, said once
                with self._lock:
                    self._counts["reader_errors"] += 1
                if "error" not in self._said:
                    self._said.add("error")
                    self.say(f"ROS 2 input: {type(exc).__name__}: {str(exc)[:200]}")
                time.sleep(WAIT_S)

    def _sample(self, name: str, data: bytes, received_s: float) -> None:
        """One sample's bytes of sensor ``name``, received at ``received_s`` (epoch, s)."""
        topic = self.topics[name]
        counts = Counter({"received": 1})
        frame = None
        cap = topic.max_bodies * BYTES_PER_BODY
        if topic.driver.marker_id_stride and len(data) >= 8:  # a MarkerArray's length field
            little = bool(data[1] & 1)  # the encapsulation's CDR_LE
            if (
                int.from_bytes(data[4:8], "little" if little else "big")
                > topic.max_bodies * topic.skeleton.n_joints
            ):
                counts["dropped_too_many_markers"] += 1
                data = b""
        if data and len(data) > cap:
            counts["dropped_too_many_bodies"] += 1
        elif data:
            try:
                message = self._readers[name].topic.data_type.deserialize(data)
            except Exception:  # malformed CDR: this sample only
                counts["dropped_unreadable"] += 1
            else:
                before = Counter(topic.drops)
                frame = topic.read(message)
                for reason, n in (topic.drops - before).items():
                    key = reason if reason == "out_of_order_or_duplicate" else f"dropped_{reason}"
                    counts[key] += n
        with self._lock:
            self._counts.update(counts)
            if frame is None:
                return
            t = received_s if frame.t is None else frame.t
            self._gap(name, t)
            self._counts["accepted"] += 1
            for body in frame.bodies:
                if (name, body.body) in self._frames:
                    self._counts["superseded"] += 1
                self._frames[(name, body.body)] = body

    def _gap(self, name: str, t: float) -> None:
        """A gap in sensor ``name``'s times before ``t`` is a dropout (module docstring)."""
        rate = self.topics[name].skeleton.sensor.frame_rate_hz
        last, self._last[name] = self._last[name], max(self._last[name], t)
        gap = t - last
        if math.isfinite(gap) and gap > GAP_FRAMES / rate:
            missing = max(round(gap * rate) - 1, 1)
            old = self._lost[name]
            self._lost[name] = SensorLoss(old.frames + missing, max(old.stale_before_s, t))
            self._counts["lost_frames"] += missing

    def _check_matches(self) -> None:
        for name, dds_reader in self._readers.items():
            status = dds_reader.get_requested_incompatible_qos_status()
            if status.total_count and name not in self._said:
                self._said.add(name)
                with self._lock:
                    self._counts["incompatible_publishers"] += status.total_count
                topic, cal = self.topics[name], self.calibration[name]
                self.say(
                    f"{name}: a publisher on {cal.topic} matches no type qpavoid reads there "
                    f"({topic.message} of {self.cell.distribution}): its messages are not "
                    f"received; check its type (ros2 topic info -v {cal.topic}) and the cell's "
                    "distribution"
                )
