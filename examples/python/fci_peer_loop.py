#!/usr/bin/env python3
"""The peer figure of `afs bench robot` (docs/franka.md, *The FCI loop*): Franka's own client,
pylibfranka, holding the robot at `--address` by a joint impedance through its torque loop
(`start_torque_control`, `readOnce`, `writeOnce`), timed as afs's loop is: from a state
received (`readOnce` returned) to its command sent (`writeOnce` returned).

    python3 examples/python/fci_peer_loop.py --address 127.0.0.21 --seconds 5

Prints one JSON object: cycles, the robot's time and the cycles it ran without a command,
the command success rate, the state-to-command percentiles (µs) and the joints' largest drift
(rad); or {"skipped": why} without pylibfranka. The joint impedance is the one measured in
../shared/franka-notes.md: K = (600, 600, 600, 600, 250, 150, 50) N·m/rad, D = 2√K.
"""

import argparse
import json
import math
import sys
import time


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--address", required=True)
    parser.add_argument("--seconds", type=float, default=5.0)
    args = parser.parse_args()
    try:
        import pylibfranka as franka
    except ImportError as e:
        print(json.dumps({"skipped": f"pylibfranka is not installed ({e})"}))
        return 0
    robot = franka.Robot(args.address, franka.RealtimeConfig.kIgnore)
    k = [600.0, 600.0, 600.0, 600.0, 250.0, 150.0, 50.0]
    d = [2.0 * math.sqrt(x) for x in k]
    control = robot.start_torque_control()
    q0 = None
    robot_time = 0.0
    cycles = missed = 0
    spans = []
    drift = 0.0
    success = 0.0
    while True:
        state, period = control.readOnce()
        received = time.perf_counter_ns()
        dt = period.to_sec()
        robot_time += dt
        missed += max(0, round(dt / 1e-3) - 1)
        if q0 is None:
            q0 = list(state.q)
        tau = [-k[i] * (state.q[i] - q0[i]) - d[i] * state.dq[i] for i in range(7)]
        command = franka.Torques(tau)
        last = robot_time >= args.seconds
        if last:
            command.motion_finished = True
        control.writeOnce(command)
        spans.append(time.perf_counter_ns() - received)
        cycles += 1
        success = state.control_command_success_rate
        drift = max(drift, max(abs(state.q[i] - q0[i]) for i in range(7)))
        if last:
            break
    spans.sort()
    at = lambda p: spans[min(len(spans) - 1, int(p * len(spans)))] / 1e3
    print(json.dumps({
        "cycles": cycles,
        "robot_time_s": robot_time,
        "missed_cycles": missed,
        "command_success_rate": success,
        "state_to_command_us": {"p50": at(0.5), "p90": at(0.9), "p99": at(0.99), "max": spans[-1] / 1e3},
        "joint_drift_rad": drift,
    }))
    return 0


if __name__ == "__main__":
    sys.exit(main())
