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
import signal
import struct
import sys


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


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--hostname", required=True, help="loopback address to serve the FR3 on")
    parser.add_argument("--seconds", type=float, default=0.0, help="stop after this long (0: until killed)")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING, format="fr3_cell: %(levelname)s %(message)s")
    try:
        import franky_sim
        from franky_sim import franka_server
        from franky_sim.mujoco_simulator import MujocoSimulator
    except ImportError as e:
        print(f"fr3_cell: franky-sim is not installed ({e}); pip install -r examples/python/requirements.txt", file=sys.stderr)
        return 2
    official_connect_reply(franka_server)
    with MujocoSimulator(enable_visualization=False) as sim:
        sim.add_robot()
        with franky_sim.SimulationServer(sim, hostname_candidates=[args.hostname]) as server:

            def stop(*_):
                server.running = False

            signal.signal(signal.SIGTERM, stop)
            signal.signal(signal.SIGINT, stop)
            if args.seconds > 0:
                signal.signal(signal.SIGALRM, stop)
                signal.setitimer(signal.ITIMER_REAL, args.seconds)
            print(f"ready {args.hostname}", flush=True)
            server.run_forever(realtime=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
