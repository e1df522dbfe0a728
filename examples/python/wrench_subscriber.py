"""Subscribes to a running afs stack's force-sensor stream from Python.

The payload is decoded with the byte layout of docs/messages.md (``WrenchSample``, 104 bytes),
through iceoryx2's Python binding: zero-copy, the same shared memory the servo reads.

Terminal 1::

    cargo build --release && ./target/release/afs run --prefix demo --duration 60

Terminal 2::

    pip install -r examples/python/requirements.txt
    python3 examples/python/wrench_subscriber.py --prefix demo --count 200

With ``--json`` it prints one JSON object summarising what it received (used by the tests).
"""

import argparse
import ctypes
import json
import math
import sys
import time

from afs_client import subscribe


class WrenchSample(ctypes.Structure):
    """``afs::WrenchSample``: one force-sensor sample (docs/messages.md)."""

    _fields_ = [
        ("version", ctypes.c_uint32),
        ("flags", ctypes.c_uint32),
        ("seq", ctypes.c_uint64),
        ("epoch_ns", ctypes.c_uint64),
        ("plant_seq", ctypes.c_uint64),
        ("plant_tick_ns", ctypes.c_uint64),
        ("sample_ns", ctypes.c_uint64),
        ("publish_ns", ctypes.c_uint64),
        ("force_n", ctypes.c_double * 2),
        ("torque_nm", ctypes.c_double),
        ("tare_force_n", ctypes.c_double * 2),
        ("tare_torque_nm", ctypes.c_double),
    ]

    @staticmethod
    def type_name() -> str:
        """The iceoryx2 type name the Rust side registers."""
        return "afs::WrenchSample"


assert ctypes.sizeof(WrenchSample) == 104, "layout differs from docs/messages.md"

LAYOUT_VERSION = 1


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--prefix", default="afs", help="the stack's prefix")
    parser.add_argument("--count", type=int, default=100, help="samples to receive")
    parser.add_argument("--timeout", type=float, default=20.0, help="seconds to wait")
    parser.add_argument("--json", action="store_true", help="print a JSON summary")
    args = parser.parse_args()

    deadline = time.monotonic() + args.timeout
    opened = subscribe(
        args.prefix, "afs/sensor/wrench", WrenchSample, deadline, node_name="wrench_subscriber.py"
    )
    if opened is None:
        return 2
    _node, subscriber = opened

    received = []
    while len(received) < args.count and time.monotonic() < deadline:
        sample = subscriber.receive()
        if sample is None:
            time.sleep(0.001)
            continue
        w = sample.payload().contents
        received.append(
            {
                "version": w.version,
                "seq": w.seq,
                "sample_ns": w.sample_ns,
                "publish_ns": w.publish_ns,
                "force_n": [w.force_n[0], w.force_n[1]],
                "torque_nm": w.torque_nm,
                "tare_force_n": [w.tare_force_n[0], w.tare_force_n[1]],
            }
        )
        if not args.json:
            f = [w.force_n[0] - w.tare_force_n[0], w.force_n[1] - w.tare_force_n[1]]
            print(
                f"seq {w.seq:8d}  force {f[0]:+8.3f} {f[1]:+8.3f} N  "
                f"torque {w.torque_nm - w.tare_torque_nm:+7.4f} N·m"
            )

    seqs = [r["seq"] for r in received]
    summary = {
        "received": len(received),
        "versions_ok": all(r["version"] == LAYOUT_VERSION for r in received),
        "seq_increasing": all(b > a for a, b in zip(seqs, seqs[1:])),
        "timestamps_ordered": all(r["publish_ns"] >= r["sample_ns"] for r in received),
        "finite": all(
            math.isfinite(x) for r in received for x in r["force_n"] + [r["torque_nm"]]
        ),
        "mean_force_magnitude_n": (
            sum(
                math.hypot(r["force_n"][0] - r["tare_force_n"][0], r["force_n"][1] - r["tare_force_n"][1])
                for r in received
            )
            / len(received)
            if received
            else None
        ),
        "first": received[0] if received else None,
    }
    if args.json:
        print(json.dumps(summary))
    return 0 if len(received) >= args.count else 1


if __name__ == "__main__":
    sys.exit(main())
