#!/usr/bin/env python3
"""Checks a layout of the Franka Control Interface (FCI v10) against Franka's own client.

A stub robot, built from the layout given with --layout (JSON: the message sizes and the
RobotState's field offsets, as franka-rs declares them; tests/fci_wire.rs writes it), serves pylibfranka
(Franka's bindings of libfranka) on a loopback address. The stub fills every state field with
its own distinct values and records what the client sends. The client connects, reads the
state, sets the collision thresholds and the load, runs a torque-control motion for a few cycles, finishes
it and asks for an automatic error recovery. The report (JSON on stdout) says, message by message, whether the official
client read and wrote what the layout says:

- connect: the request's payload size and version; the client accepts the reply as
  (u8 status, u16 version), and names the version the reply carries when the status is 1;
- state: every RobotState field pylibfranka exposes, read back against what was written;
- move: the request's size and its controller / motion-generator modes;
- command: the datagrams' size, message_id, tau_J_d and the finished flag;
- error_recovery: the request is answered and the client returns;
- collision, load: SetCollisionBehavior's and SetLoad's command numbers, sizes and each
  field's place.

Exit 0 when every check agrees, 1 when one does not, 2 when pylibfranka is missing or the
stub cannot bind (the report says which).

python3 examples/python/fci_wire_check.py --layout LAYOUT.json [--address 127.0.0.N]
python3 examples/python/fci_wire_check.py --layout LAYOUT.json --model-at Q1 .. Q7 DQ1 .. DQ7
    (libfranka's model at that state, from the URDF the stub serves: mass, coriolis, gravity and
    the end effector's zero Jacobian, column-major, as JSON)
"""

import argparse
import json
import multiprocessing as mp
import socket
import struct
import sys
import threading
import time

COMMAND_PORT = 1337
HEADER = struct.Struct("<III")  # command, command_id, size (header included)
CONNECT, MOVE, STOP_MOVE, ERROR_RECOVERY, GET_ROBOT_MODEL = 0, 1, 2, 10, 11
MOTION_STARTED, SUCCESS = 1, 0
# RobotState enums (franka-rs rbk_types): motion generator None = 5, controller
# ExternalController = 2, robot mode Idle = 1, Move = 2.
STATE_MG_NONE, STATE_CTRL_EXTERNAL, ROBOT_IDLE, ROBOT_MOVE = 5, 2, 1, 2
TORQUES = [0.5 * (i + 1) for i in range(7)]
# What the client sets, each value distinct, by the request's field names. SetCollisionBehavior
# in pylibfranka's four-array form: libfranka sends each array as both the acceleration and the
# nominal threshold.
COLLISION = {"lower_torque": [10.0 + i for i in range(7)], "upper_torque": [30.0 + i for i in range(7)],
             "lower_force": [50.0 + i for i in range(6)], "upper_force": [70.0 + i for i in range(6)]}
SETTERS = {
    "collision": {f"{k}_thresholds_{when}": v for k, v in COLLISION.items()
                  for when in ("acceleration", "nominal")},
    "load": {"m_load": [1.25], "F_x_Cload": [0.01, 0.02, 0.03],
             "I_load": [0.001 * (i + 1) for i in range(9)]},
}


def field_values(index, count):
    """Distinct values, exact in f32: field k's j-th element is 100 k + j + 0.25."""
    return [100.0 * index + j + 0.25 for j in range(count)]


IDENTITY = [1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0]


def build_state(layout, message_id, moving, at=None):
    """The state datagram: distinct values in every field, or, with `at` (q and dq), an arm at
    rest there with no load and identity tool frames (for the model's check)."""
    buf = bytearray(layout["state_size"])
    for k, f in enumerate(layout["state"]):
        off, n = f["offset"], f["count"]
        if f["kind"] == "f32":
            values = field_values(k, n)
            if at is not None:
                values = at.get(f["name"], IDENTITY if n == 16 else [0.0] * n)
            struct.pack_into(f"<{n}f", buf, off, *values)
        elif f["kind"] == "u64":
            struct.pack_into("<Q", buf, off, message_id)
    offsets = {f["name"]: f["offset"] for f in layout["state"]}
    buf[offsets["motion_generator_mode"]] = STATE_MG_NONE if moving else 0
    buf[offsets["controller_mode"]] = STATE_CTRL_EXTERNAL if moving else 0
    buf[offsets["robot_mode"]] = ROBOT_MOVE if moving else ROBOT_IDLE
    return bytes(buf)


def recv_exact(conn, n):
    data = b""
    while len(data) < n:
        chunk = conn.recv(n - len(data))
        if not chunk:
            raise ConnectionError("client closed the connection")
        data += chunk
    return data


def serve(address, layout, connect_status, out, at=None):
    """The stub robot: one client, its requests and datagrams recorded in `out`."""
    report = {"requests": [], "commands": []}
    try:
        tcp = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        tcp.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        tcp.bind((address, COMMAND_PORT))
        tcp.listen(1)
        udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        udp.bind((address, 0))
    except OSError as e:
        out.put({"error": f"the stub cannot bind {address}:{COMMAND_PORT}: {e}"})
        return
    out.put({"ready": True})
    tcp.settimeout(20.0)
    conn, peer = tcp.accept()
    conn.settimeout(20.0)
    setters = {s["command"]: s for s in layout["setters"].values()}
    moving = threading.Event()
    stop = threading.Event()
    client = {}
    move_id = {}

    def stream_states():
        message_id = 1
        while not stop.is_set():
            if "udp" in client:
                udp.sendto(build_state(layout, message_id, moving.is_set(), at), client["udp"])
                message_id += 1
            time.sleep(0.001)

    def read_commands():
        udp.settimeout(0.05)
        while not stop.is_set():
            try:
                data, _ = udp.recvfrom(4096)
            except socket.timeout:
                continue
            tau = None
            finished = None
            try:
                tau = list(struct.unpack_from("<7d", data, layout["tau_offset"]))
                finished = data[layout["finished_offset"]]
            except (struct.error, IndexError):
                pass  # a datagram shorter than the layout: recorded by its size
            report["commands"].append(
                {"size": len(data), "message_id": struct.unpack_from("<Q", data, 0)[0],
                 "tau": tau, "finished": finished})
            if finished and "id" in move_id:
                moving.clear()
                reply(MOVE, move_id.pop("id"), struct.pack("<B", SUCCESS))

    def reply(command, command_id, payload):
        conn.sendall(HEADER.pack(command, command_id, HEADER.size + len(payload)) + payload)

    threading.Thread(target=stream_states, daemon=True).start()
    threading.Thread(target=read_commands, daemon=True).start()
    try:
        while True:
            command, command_id, size = HEADER.unpack(recv_exact(conn, HEADER.size))
            payload = recv_exact(conn, size - HEADER.size)
            entry = {"command": command, "payload_size": len(payload)}
            if command == CONNECT:
                version, udp_port = struct.unpack("<HH", payload)
                entry.update(version=version)
                reply(CONNECT, command_id, struct.pack("<BH", connect_status, 10))
                client["udp"] = (peer[0], udp_port)
            elif command == MOVE:
                controller, generator = struct.unpack_from("<II", payload, 0)
                entry.update(controller_mode=controller, motion_generator_mode=generator)
                move_id["id"] = command_id
                reply(MOVE, command_id, struct.pack("<B", MOTION_STARTED))
                moving.set()
            elif command == GET_ROBOT_MODEL:
                # The FR3 serves its URDF: a u8 status, then the text.
                reply(command, command_id, struct.pack("<B", SUCCESS) + layout["urdf"].encode())
            elif command in setters:
                entry["fields"] = {
                    f["name"]: list(struct.unpack_from(f"<{f['count']}d", payload, f["offset"]))
                    for f in setters[command]["fields"]
                    if f["offset"] + 8 * f["count"] <= len(payload)}
                reply(command, command_id, struct.pack("<B", SUCCESS))
            elif command in (STOP_MOVE, ERROR_RECOVERY):
                reply(command, command_id, struct.pack("<B", SUCCESS))
            report["requests"].append(entry)
    except (ConnectionError, socket.timeout, OSError):
        pass
    stop.set()
    out.put(report)


def run_client(address, out):
    """Franka's own client against the stub; what it read and what failed."""
    import pylibfranka as franka

    result = {}
    try:
        robot = franka.Robot(address, franka.RealtimeConfig.kIgnore)
        state = robot.read_once()
        result["state"] = {name: list(getattr(state, name)) if hasattr(getattr(state, name), "__len__")
                           else getattr(state, name) for name in dir(state) if not name.startswith("_")
                           and isinstance(getattr(state, name), (float, int, list, tuple))}
        robot.set_collision_behavior(COLLISION["lower_torque"], COLLISION["upper_torque"],
                                     COLLISION["lower_force"], COLLISION["upper_force"])
        load = SETTERS["load"]
        robot.set_load(load["m_load"][0], load["F_x_Cload"], load["I_load"])
        result["setters_returned"] = True
        control = robot.start_torque_control()
        for _ in range(20):
            control.readOnce()
            control.writeOnce(franka.Torques(TORQUES))
        last = franka.Torques(TORQUES)
        last.motion_finished = True
        control.readOnce()
        control.writeOnce(last)
        time.sleep(0.05)
        robot.automatic_error_recovery()
        result["returned"] = True
        del robot
    except Exception as e:  # the official client's own words are the evidence
        result["exception"] = f"{type(e).__name__}: {e}"
    out.put(result)


def run_model_client(address, out):
    """Franka's own model (libfranka's, from the URDF the stub serves) at the stub's state."""
    import pylibfranka as franka

    try:
        robot = franka.Robot(address, franka.RealtimeConfig.kIgnore)
        model = robot.load_model()
        state = robot.read_once()
        out.put({"q": list(state.q), "dq": list(state.dq), "mass": list(model.mass(state)),
                 "coriolis": list(model.coriolis(state)), "gravity": list(model.gravity(state)),
                 "zero_jacobian_ee": list(model.zero_jacobian(state))})
        del robot
    except Exception as e:
        out.put({"exception": f"{type(e).__name__}: {e}"})


def stub_and_client(address, layout, status, at, client_target):
    """Starts the stub (Connect answered with `status`, its state at `at` or distinct values)
    and `client_target` against it; returns the client's result once both have ended, or
    {"skipped": why} when the stub cannot bind."""
    out = mp.Queue()
    server = mp.Process(target=serve, args=(address, layout, status, out, at))
    server.start()
    ready = out.get(timeout=10)
    if "error" in ready:
        server.join()
        return {"skipped": ready["error"]}
    client_out = mp.Queue()
    client = mp.Process(target=client_target, args=(address, client_out))
    client.start()
    result = client_out.get(timeout=60)
    client.join()
    server.terminate()
    server.join()
    return result


def model_at(address, layout, q, dq):
    """The official model's mass, Coriolis, gravity and Jacobian at (q, dq)."""
    # O_ddP_O is the gravity vector the robot reports, which libfranka's gravity() takes.
    at = {"q": q, "dq": dq, "O_ddP_O": [0.0, 0.0, -9.81]}
    return stub_and_client(address, layout, 0, at, run_model_client)


def check_connect_refusal(address, layout):
    """Status 1 in the (u8, u16) layout: the client names the version the reply carries."""
    result = stub_and_client(address, layout, 1, None, run_client)
    return None if "skipped" in result else result.get("exception", "")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--layout", required=True, help="the layout JSON (tests/fci_wire.rs writes it: AFS_FCI_LAYOUT_OUT)")
    parser.add_argument("--address", default="127.0.0.9", help="loopback address for the stub")
    parser.add_argument("--model-at", nargs=14, type=float, metavar="X",
                        help="instead of the wire check: libfranka's model at q (7 rad) and "
                        "dq (7 rad/s), as JSON")
    args = parser.parse_args()
    with open(args.layout) as f:
        layout = json.load(f)
    try:
        import pylibfranka  # noqa: F401
    except ImportError as e:
        print(json.dumps({"skipped": f"pylibfranka is not installed ({e}); "
                          "pip install -r examples/python/requirements.txt"}))
        return 2
    mp.set_start_method("spawn")
    if args.model_at:
        result = model_at(args.address, layout, args.model_at[:7], args.model_at[7:])
        print(json.dumps(result))
        return 2 if "skipped" in result else (1 if "exception" in result else 0)
    out = mp.Queue()
    server = mp.Process(target=serve, args=(args.address, layout, 0, out))
    server.start()
    ready = out.get(timeout=10)
    if "error" in ready:
        server.join()
        print(json.dumps({"skipped": ready["error"]}))
        return 2
    client_out = mp.Queue()
    client = mp.Process(target=run_client, args=(args.address, client_out))
    client.start()
    client_result = client_out.get(timeout=60)
    client.join()
    stub = out.get(timeout=30)
    server.join()
    report = compare(layout, stub, client_result)
    report["connect"]["refusal"] = check_connect_refusal(args.address, layout)
    report["connect"]["refusal_names_version_10"] = "server version: 10" in (
        report["connect"]["refusal"] or "")
    checks = [report["connect"]["agrees"], report["connect"]["refusal_names_version_10"],
              report["state"]["agrees"], report["move"]["agrees"], report["command"]["agrees"],
              report["error_recovery"]["agrees"]] + [report[name]["agrees"] for name in SETTERS]
    report["agrees"] = all(checks)
    print(json.dumps(report, indent=1))
    return 0 if report["agrees"] else 1


def compare(layout, stub, client):
    requests = stub.get("requests", [])
    by = {}
    for r in requests:
        by.setdefault(r["command"], []).append(r)
    connect = by.get(CONNECT, [{}])[0]
    report = {"client": {k: v for k, v in client.items() if k != "state"}}
    report["connect"] = {"payload_size": connect.get("payload_size"),
                         "version": connect.get("version")}
    report["connect"]["agrees"] = connect.get("payload_size") == 4 and connect.get("version") == 10
    # Every exposed field that the layout names, element by element.
    fields = {f["name"]: (k, f) for k, f in enumerate(layout["state"])}
    read = client.get("state", {})
    mismatched, compared = [], 0
    for name, value in read.items():
        if name not in fields or fields[name][1]["kind"] != "f32":
            continue
        k, f = fields[name]
        want = field_values(k, f["count"])
        got = list(value) if isinstance(value, (list, tuple)) else [value]
        compared += 1
        if [float(x) for x in got] != want:
            mismatched.append(name)
    report["state"] = {"size": layout["state_size"], "fields_compared": compared,
                       "mismatched": mismatched,
                       "agrees": compared > 0 and not mismatched and "exception" not in client}
    move = by.get(MOVE, [{}])[0]
    report["move"] = {"payload_size": move.get("payload_size"),
                      "controller_mode": move.get("controller_mode"),
                      "motion_generator_mode": move.get("motion_generator_mode")}
    report["move"]["agrees"] = (move.get("payload_size") == layout["move_size"]
                                and move.get("controller_mode") == 2
                                and move.get("motion_generator_mode") == 4)
    commands = stub.get("commands", [])
    sizes = sorted({c["size"] for c in commands})
    taus = [c["tau"] for c in commands if c["tau"] is not None]
    report["command"] = {"datagrams": len(commands), "sizes": sizes,
                         "tau_as_written": sum(1 for t in taus if t == TORQUES),
                         "finished_seen": any(c["finished"] for c in commands)}
    report["command"]["agrees"] = (sizes == [layout["command_size"]]
                                   and report["command"]["tau_as_written"] >= 20
                                   and report["command"]["finished_seen"])
    report["error_recovery"] = {"requests": len(by.get(ERROR_RECOVERY, [])),
                                "client_returned": client.get("returned", False)}
    report["error_recovery"]["agrees"] = (report["error_recovery"]["requests"] == 1
                                          and report["error_recovery"]["client_returned"])
    # Each setter: its command's number and size, and each field where the layout puts it.
    for name, sent in SETTERS.items():
        setter = layout["setters"][name]
        requests = by.get(setter["command"], [])
        got = requests[0].get("fields", {}) if requests else {}
        mismatched = [f["name"] for f in setter["fields"] if got.get(f["name"]) != sent[f["name"]]]
        part = {"requests": len(requests),
                "payload_size": requests[0]["payload_size"] if requests else None,
                "fields_compared": len(got), "mismatched": mismatched,
                "client_returned": client.get("setters_returned", False)}
        part["agrees"] = (len(requests) == 1 and part["payload_size"] == setter["size"]
                          and len(got) == len(setter["fields"]) and not mismatched
                          and part["client_returned"])
        report[name] = part
    return report


if __name__ == "__main__":
    sys.exit(main())
