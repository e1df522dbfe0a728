"""Subscribes to a running afs stack's controller stream (the servo's state) from Python.

The payload is decoded with the byte layout of docs/messages.md (``ServoSample`` version 3,
232 bytes).
The stream crosses the link board (docs/link.md), so this works the same on the controller's
host and on a remote host that its link board reaches.

    python3 examples/python/servo_subscriber.py --prefix demo --count 2000 --json

It reports the samples' numbers as it got them: every missing number counted (a link cut, or
this client falling behind the 10-kHz stream), never hidden.
"""

import argparse
import ctypes
import json
import math
import sys
import time

from afs_client import subscribe


class ServoSample(ctypes.Structure):
    """``afs::ServoSample.v3``: the controller's state of one servo tick (docs/messages.md)."""

    _fields_ = [
        ("version", ctypes.c_uint32),
        ("mode", ctypes.c_uint32),
        ("flags", ctypes.c_uint32),
        ("safe_reason", ctypes.c_uint32),
        ("seq", ctypes.c_uint64),
        ("tick_ns", ctypes.c_uint64),
        ("wrench_seq", ctypes.c_uint64),
        ("wrench_sample_ns", ctypes.c_uint64),
        ("force_age_ns", ctypes.c_uint64),
        ("publish_ns", ctypes.c_uint64),
        ("time_s", ctypes.c_double),
        ("normal_force_n", ctypes.c_double),
        ("tangential_force_n", ctypes.c_double),
        ("friction_normalized_n", ctypes.c_double),
        ("a_omega_m_per_s", ctypes.c_double),
        ("dither_amplitude_m", ctypes.c_double),
        ("dither_phase_rad", ctypes.c_double),
        ("nominal_velocity_m_per_s", ctypes.c_double),
        ("velocity_target_m_per_s", ctypes.c_double),
        ("tangent_velocity_m_per_s", ctypes.c_double),
        ("tangent_angle_rad", ctypes.c_double),
        ("set_point_m", ctypes.c_double * 2),
        ("torque_nm", ctypes.c_double * 2),
        ("estimations_started", ctypes.c_uint32),
        ("estimates", ctypes.c_uint32),
        ("reprobes", ctypes.c_uint32),
        ("failures", ctypes.c_uint32),
        ("aborted", ctypes.c_uint32),
        ("safe_entries", ctypes.c_uint32),
        ("estimations_requested", ctypes.c_uint32),
        ("force_triggers", ctypes.c_uint32),
        ("slope_triggers", ctypes.c_uint32),
        ("contact_losses", ctypes.c_uint32),
        ("reserved", ctypes.c_uint32 * 2),
    ]

    @staticmethod
    def type_name() -> str:
        """The iceoryx2 type name the Rust side registers."""
        return "afs::ServoSample.v3"


assert ctypes.sizeof(ServoSample) == 232, "layout differs from docs/messages.md"

LAYOUT_VERSION = 3


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--prefix", default="afs", help="the stack's prefix")
    parser.add_argument("--count", type=int, default=1000, help="samples to receive")
    parser.add_argument("--timeout", type=float, default=20.0, help="seconds to wait")
    parser.add_argument("--json", action="store_true", help="print a JSON summary")
    args = parser.parse_args()

    deadline = time.monotonic() + args.timeout
    # One second of ticks: the stream comes in bursts of 50 across a link, and Python is slow.
    opened = subscribe(
        args.prefix,
        "afs/servo/state",
        ServoSample,
        deadline,
        buffer_size=10_000,
        node_name="servo_subscriber.py",
    )
    if opened is None:
        return 2
    _node, subscriber = opened

    seqs, normal, versions_ok, finite = [], [], True, True
    while len(seqs) < args.count and time.monotonic() < deadline:
        sample = subscriber.receive()
        if sample is None:
            time.sleep(0.0005)
            continue
        s = sample.payload().contents
        seqs.append(s.seq)
        normal.append(s.normal_force_n)
        versions_ok = versions_ok and s.version == LAYOUT_VERSION
        finite = finite and math.isfinite(s.normal_force_n) and math.isfinite(s.time_s)
        if not args.json and len(seqs) % 100 == 0:
            print(f"tick {s.seq:8d}  t {s.time_s:7.3f} s  mode {s.mode}  "
                  f"normal force {s.normal_force_n:+8.3f} N  estimates {s.estimates}")

    steps = [b - a for a, b in zip(seqs, seqs[1:])]
    summary = {
        "received": len(seqs),
        "versions_ok": versions_ok,
        "finite": finite,
        "seq_increasing": all(d > 0 for d in steps),
        "first": seqs[0] if seqs else None,
        "last": seqs[-1] if seqs else None,
        "missing": sum(d - 1 for d in steps if d > 1),
        "gaps": sum(1 for d in steps if d > 1),
        "mean_normal_force_n": sum(normal) / len(normal) if normal else None,
    }
    if args.json:
        print(json.dumps(summary))
    return 0 if len(seqs) >= args.count else 1


if __name__ == "__main__":
    sys.exit(main())
