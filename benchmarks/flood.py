"""A flood of datagrams against the live control loop (docs/sensors.md, "What is not covered").

    python benchmarks/flood.py [--seconds 6] [--flood-s 3] [--port 5222]

For each flood kind (none; garbage; unsigned skeletons, wire format version 1; forged
skeletons, signed with a key of the attacker's own): `qpavoid run --listen` at 100 Hz for
``--seconds``, fed by `qpavoid replay` of two simulated Kinects, while this process floods
the port as fast as Python sends for ``--flood-s`` from 1.5 s on. Prints the loop's
overruns, its control time per tick (p99), the longest interval between ticks, the time
stopped and the input counters from `metrics.json`.
"""

from __future__ import annotations

import argparse
import json
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from qpavoid.sensing.keys import SensorKeys
from qpavoid.sensing.signing import Signer

QPAVOID = [sys.executable, "-m", "qpavoid"]


def flood(port: int, seconds: float, kind: str) -> int:
    """Send ``kind`` datagrams to ``port`` for ``seconds``; how many were sent."""
    valid = {"v": 1, "sensor": "kinect_left", "body": 3, "t": 0.0, "joints": [[0, 0, 2, 2]] * 25}
    forger = Signer("two-sensors", SensorKeys.generate("kinect_left"))
    message = {
        "garbage": b"junk" * 50,
        "unsigned": json.dumps(valid).encode(),
        "forged": forger.seal(json.dumps({k: valid[k] for k in ("body", "t", "joints")}).encode()),
    }[kind]
    sent, end = 0, time.time() + seconds
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        while time.time() < end:
            for _ in range(100):
                sock.sendto(message, ("127.0.0.1", port))
            sent += 100
    return sent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=6.0)
    ap.add_argument("--flood-s", type=float, default=3.0)
    ap.add_argument("--port", type=int, default=5222)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp)
        example = Path(__file__).parents[1] / "examples" / "two_sensors.py"
        subprocess.run([sys.executable, str(example), str(data)], check=True, capture_output=True)
        sensors = ["--sensors", str(data / "calib.toml")]
        recordings = [str(data / "kinect_left.npz"), str(data / "kinect_right.npz")]
        print("flood     sent      overruns  tick p99  longest interval  stopped  input")
        for kind in ("none", "garbage", "unsigned", "forged"):
            out = data / f"out_{kind}"
            listen = ["--listen", f"127.0.0.1:{args.port}", *sensors, "--out", str(out)]
            limits = ["--max-time", str(args.seconds), "--rate", "100", "--no-plots", "-q"]
            run = subprocess.Popen([*QPAVOID, "run", *listen, *limits], stdout=subprocess.DEVNULL)
            time.sleep(1.2)
            replay = subprocess.Popen(
                [*QPAVOID, "replay", *recordings, "--to", f"127.0.0.1:{args.port}", *sensors],
                stdout=subprocess.DEVNULL,
            )
            time.sleep(1.5)
            sent = flood(args.port, args.flood_s, kind) if kind != "none" else 0
            run.wait()
            replay.kill()
            metrics = json.loads((out / "metrics.json").read_text())
            gap_ms = 1e3 * np.diff(np.load(out / "log.npz")["t"]).max()
            counts = {k: v for k, v in metrics["input"].items() if v}
            print(
                f"{kind:8s} {sent:8d} {metrics.get('realtime_overruns', 0):9d} "
                f"{metrics['tick_us']['p99'] / 1e3:6.1f} ms {gap_ms:10.1f} ms "
                f"{metrics['stopped_s']:8.2f} s  {counts}"
            )


if __name__ == "__main__":
    main()
