"""What a datagram costs the receiver: verified or dropped (docs/performance.md, §4).

    python benchmarks/wire.py [--n 20000] [--json FILE]

The receiver's own per-datagram call (:meth:`qpavoid.sensing.signing.Verifier.decode`) on
one body of the seated operator (about 1 kB), median and p99 over ``--n`` calls each, after warm-up:

* ``v1 decode``: an unsigned datagram parsed and checked (:func:`qpavoid.sensing.wire.decode`:
  what every datagram cost before issue 24, forged or not);
* ``v2 valid``: a signed one verified, then parsed and checked;
* ``v2 forged``: a signed-looking one whose tag does not verify (a forger without the
  key): dropped before any JSON is read;
* ``v2 unknown key``, ``v2 replayed``, ``unsigned refused``, ``junk``: the other drops, in
  the order they are checked;
* ``v2 valid, assembled``: the receiver's whole per-datagram work since issue 40, a
  signed datagram of a frame of six bodies verified (:meth:`~qpavoid.sensing.signing.Verifier.read`)
  and put into its frame (:func:`qpavoid.sensing.assembly.assemble`).

It also prints the datagrams' sizes with their manifests: one body of the seated
operator alone and in a frame of six, and the widest a body can be, one of ten of the
ZED's 38 joints, every coordinate at its widest (``-4.123456``), against the 1472 bytes
of a UDP datagram in one Ethernet frame (IPv4).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import time
from collections.abc import Callable

import numpy as np

from qpavoid.human.posture import Operator
from qpavoid.sensing.assembly import SensorFrames, assemble
from qpavoid.sensing.calibration import Calibration, SensorCalibration, known_formats
from qpavoid.sensing.keys import SensorKeys
from qpavoid.sensing.per_sensor import BodyFrame
from qpavoid.sensing.signing import Signer, Verifier
from qpavoid.sensing.synthetic_pair import look_at
from qpavoid.sensing.wire import WireError, Workspace, decode, encode


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=20000, help="calls per case")
    parser.add_argument("--json", help="write the results here")
    args = parser.parse_args()

    pose = look_at(np.array([1.0, 2.5, 1.3]), np.zeros(3))
    cal = Calibration(
        {"kinect_left": SensorCalibration("kinect_left", pose)},
        cell="bench",
        keys={"kinect_left": SensorKeys.generate("kinect_left")},
    )
    T = np.linalg.inv(pose)
    joints = Operator().rest() @ T[:3, :3].T + T[:3, 3]
    frame = BodyFrame("kinect_left", 0, 1.0, joints, np.full(25, 2, dtype=np.int8))
    signer = Signer(cal.cell, cal.keys["kinect_left"], first_sequence=0)
    valid = [signer.encode(frame) for _ in range(args.n)]
    forged = [d[:-1] + bytes([d[-1] ^ 1]) for d in valid]
    stranger = Signer(cal.cell, SensorKeys("kinect_left", ((9, os.urandom(32)),)), 0)
    unknown = stranger.encode(frame)
    v1 = encode(frame)
    workspace = Workspace()

    def fresh() -> Callable[[bytes], object]:
        """A new receiver's check (its replay windows empty)."""
        return Verifier(cal, workspace).decode

    def having_seen_one() -> Callable[[bytes], object]:
        """A receiver that has taken ``valid[0]`` already."""
        call = fresh()
        call(valid[0])
        return call

    def timed(call, inputs) -> list[float]:
        times = []
        for data in inputs:
            t0 = time.perf_counter_ns()
            with contextlib.suppress(WireError):
                call(data)
            times.append((time.perf_counter_ns() - t0) / 1e3)
        return times

    six = []  # frames of six bodies
    for k in range(args.n // 6 + 1):
        six += signer.encode_frame([frame._replace(t=1.0 + k, body=b) for b in range(6)])
    six = six[: args.n]

    def assembling() -> Callable[[bytes], object]:
        """A new receiver's check and its frames' assembly."""
        read, state = Verifier(cal, workspace).read, [SensorFrames()]

        def call(data: bytes) -> object:
            step = assemble(state[0], *read(data))
            state[0] = step.state
            return step

        return call

    widest = widest_datagram_bytes()
    cases = {  # (a new receiver's check, its inputs)
        "v1 decode": (lambda: lambda d: decode(d, cal, workspace), [v1] * args.n),
        "v2 valid": (fresh, valid),
        "v2 forged": (fresh, forged),
        "v2 unknown key": (fresh, [unknown] * args.n),
        "v2 replayed": (having_seen_one, [valid[0]] * args.n),
        "unsigned refused": (fresh, [v1] * args.n),
        "junk": (fresh, [b"\x00garbage"] * args.n),
        "v2 valid, assembled": (assembling, six),
    }
    results = {
        "bytes": len(valid[0]),
        "bytes_of_six": len(six[0]),
        "bytes_widest": widest,
        "n": args.n,
        "machine": platform.processor() or "",
    }
    print(
        f"one body: {len(valid[0])} bytes signed ({len(six[0])} in a frame of six), "
        f"{len(v1)} unsigned; the widest: {widest} bytes (of 1472); {args.n} calls each"
    )
    print(f"{'case':<18} {'median us':>10} {'p99 us':>8}")
    for name, (receiver, inputs) in cases.items():
        timed(receiver(), inputs[:500])  # warm-up, on a receiver of its own
        times = np.array(timed(receiver(), inputs))
        median, p99 = float(np.median(times)), float(np.percentile(times, 99))
        results[name] = {"median_us": round(median, 2), "p99_us": round(p99, 2)}
        print(f"{name:<18} {median:10.2f} {p99:8.2f}")
    if args.json:
        with open(args.json, "w") as handle:
            json.dump(results, handle, indent=2)
        print(f"wrote {args.json}")


def widest_datagram_bytes() -> int:
    """The largest signed datagram of one body (sensor ``zed_left``): one of ten of a ZED's
    38 joints (the most joints and bodies of the formats), every coordinate
    ``-4.123456``."""
    name = "zed_body_38"
    fmt = known_formats()[name]
    keys = SensorKeys.generate("zed_left")
    signer = Signer("bench", keys, first_sequence=time.time_ns() // 1000)
    joints = np.full((fmt.n_joints, 3), -4.123456)
    bodies = [
        BodyFrame("zed_left", b, 1.0, joints, np.full(fmt.n_joints, 2, np.int8), name)
        for b in range(fmt.sensor.max_bodies)
    ]
    return max(len(d) for d in signer.encode_frame(bodies))


if __name__ == "__main__":
    main()
