#!/usr/bin/env python3
"""afs's simulated FR3 cell: franky-sim's MuJoCo FR3 served over FCI on a loopback address,
with the simulator's wire brought to the real robot's (docs/franka.md, *Where franky-sim
deviates*).

franky-sim 1.0.4 answers Connect with a u16 status (`<HH4x`); an FR3, and Franka's own client,
use a u8 status and a u16 version (`<BH`). The cell packs the same 8 bytes as `<BH5x`, so a
client that reads the official layout (franka-rs) connects, and one that reads franky-sim's
reads the same status and version (pylibfranka reads the version only on a failed status).

    python3 examples/python/fr3_cell.py --hostname 127.0.0.21 [--seconds S]

Prints `ready <hostname>` once the server listens, and runs until killed (SIGTERM, SIGINT) or
for --seconds. Needs franky-sim 1.0.4 and mujoco 3.17.0 (examples/python/requirements.txt).
"""

import argparse
import logging
import select
import signal
import struct
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))


def official_connect_reply(franka_server):
    """Replaces franky-sim's Connect handler by one that packs the official layout."""
    command = franka_server.ConnectCommand

    def handle(self, server, command_type_struct="I"):
        if server.udp_connected:
            logging.warning("Received connect command but already connected.")
            return
        header = franka_server.MessageHeader(self.command_type, self.command_id, 8)
        body = struct.pack("<BH5x", franka_server.ConnectStatus.kSuccess.value, server.library_version)
        try:
            self.client_socket.sendall(header.to_bytes(command_type_struct=command_type_struct) + body)
        except BlockingIOError:
            pass
        server._setup_udp_connection(self.network_udp_port)

    command.handle = handle


def run_cycles(server, seconds_per_cycle=0.001):
    """franky-sim's loop (commands, step, state), with the real robot's cycle: after sending a
    state, wait for the client's command for it (up to one cycle) before the next step, then
    keep the cycle's pace. franky-sim's own `run_forever` sleeps only what is left of the
    cycle after stepping; on a machine where a step takes longer than that it goes straight on
    to the next step, so every command arrived a step late and the robot acted on the state
    before last (docs/franka-cell.md, *The cell*)."""
    server.running = True
    while server.running:
        start = time.monotonic()
        server.run_once(realtime=False)
        sent = time.monotonic()
        sockets = [s for s in (rs._FrankaServer__udp_socket for rs in server.robot_servers) if s is not None]
        if sockets:
            select.select(sockets, [], [], seconds_per_cycle)
        left = seconds_per_cycle - (time.monotonic() - start)
        if left > 0 and time.monotonic() - sent < seconds_per_cycle:
            time.sleep(left)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--hostname", required=True, help="loopback address to serve the FR3 on")
    parser.add_argument("--seconds", type=float, default=0.0, help="stop after this long (0: until killed)")
    parser.add_argument("--rdt-port", type=int, default=0, help="serve the wrist sensor over RDT on this UDP port of --hostname (0: no sensor, no scene)")
    parser.add_argument("--tool-length-m", type=float, default=0.16, help="flange to the tool tip's centre (m)")
    parser.add_argument("--tip-radius-m", type=float, default=0.005, help="the tool tip's radius (m)")
    parser.add_argument("--wall-at", type=float, nargs=2, default=[0.554, 0.007], metavar=("X", "Y"), help="a point of the wall's face (base frame, m)")
    parser.add_argument("--wall-normal", type=float, nargs=2, default=[0.0, -1.0], metavar=("NX", "NY"), help="the wall's outward normal (towards the tool)")
    parser.add_argument("--stiffness-n-per-m", type=float, default=1e4, help="the contact's stiffness (N/m; the thesis's 10 kN/m)")
    parser.add_argument("--damping-n-s-per-m", type=float, default=50.0, help="the contact's damping (N·s/m)")
    parser.add_argument("--mu", type=float, default=0.3, help="Coulomb friction between the tip and the part")
    parser.add_argument("--friction-damping-n-s-per-m", type=float, default=5.0, help="how hard sticking holds the tip (N·s/m, docs/mujoco.md)")
    parser.add_argument("--cell-config", default=None, help="the part to build instead of the wall (`afs run` writes it: cell.toml)")
    # Given to every supervised process by `afs run`: the stack's prefix, scenario, seed, CPU
    # and priority. The cell uses the seed (the sensor's noise and bias); it runs at normal
    # priority, its pace set by franky-sim's real-time loop.
    parser.add_argument("--seed", type=int, default=1)
    for name in ("--prefix", "--scenario", "--sim-config", "--cpu", "--priority"):
        parser.add_argument(name, default=None)
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING, format="fr3_cell: %(levelname)s %(message)s")
    try:
        import franky_sim
        import mujoco
        from franky_sim import franka_server
        from franky_sim.mujoco_simulator import MujocoSimulator
    except ImportError as e:
        print(f"fr3_cell: franky-sim is not installed ({e}); pip install -r examples/python/requirements-franka.txt", file=sys.stderr)
        return 2
    official_connect_reply(franka_server)
    with MujocoSimulator(enable_visualization=False) as sim:
        sim.add_robot()
        device = None
        if args.rdt_port:
            import fr3_scene
            from rdt_device import RdtDevice

            # The start pose puts the flange 0.625 m up, pointing down: the tip's centre is
            # tool_length below it, and the wall stands 4 cm above the tip, below the fingers.
            if args.cell_config:
                import tomllib

                with open(args.cell_config, "rb") as f:
                    spec = tomllib.load(f)
                tool_length = spec["tool_length_m"]
                part = fr3_scene.Part(spec["surface_m"], spec["plane_normal"], args.tip_radius_m)
            else:
                tool_length = args.tool_length_m
                part = fr3_scene.Part.wall(args.wall_at, args.wall_normal, 0.625 - tool_length, args.tip_radius_m)
            fr3_scene.add_tool(sim, tool_length, args.tip_radius_m)
            part.build(sim)
            part.add_contact(sim, mujoco, args.stiffness_n_per_m, args.damping_n_s_per_m, args.mu, args.friction_damping_n_s_per_m)
            sim.register_pre_step_callback(lambda s: part.update(s, mujoco))
            sensor = fr3_scene.WristSensor(args.seed)
            try:
                device = RdtDevice(args.hostname, args.rdt_port)
            except OSError as e:
                print(f"fr3_cell: cannot serve RDT on {args.hostname}:{args.rdt_port}: {e}", file=sys.stderr)
                return 2

            def serve(s):
                if sensor.site is None:
                    sensor.attach(s.model, mujoco)
                device.sample(sensor.reading(s.model, s.data, mujoco))

            sim.register_post_step_callback(serve)
        with franky_sim.SimulationServer(sim, hostname_candidates=[args.hostname]) as server:

            def stop(*_):
                server.running = False

            signal.signal(signal.SIGTERM, stop)
            signal.signal(signal.SIGINT, stop)
            if args.seconds > 0:
                signal.signal(signal.SIGALRM, stop)
                signal.setitimer(signal.ITIMER_REAL, args.seconds)
            print(f"ready {args.hostname}", flush=True)
            run_cycles(server)
    return 0


if __name__ == "__main__":
    sys.exit(main())
