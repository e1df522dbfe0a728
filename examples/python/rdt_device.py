"""An ATI RDT device on UDP, fed one sample per simulation step (docs/sensor.md, the
protocol; `shared/src/rdt` is afs's side of it).

A request is 8 bytes, `>HHI`: header 0x1234, command, sample count (0: no end). A record is 36
bytes, `>III6i`: rdt_sequence (1 for a stream's first record), ft_sequence (the device's
free-running sample count), status (0: healthy), then Fx Fy Fz Tx Ty Tz in counts. Like a Net
F/T, the device streams to one client; another client's start is ignored until that stream
stops. "Set bias" (0x0042) takes the present reading as the zero of the following ones. ft_sequence
follows the device's real-time clock at 1 kHz (see `sample`).
"""

import socket
import struct
import time

HEADER = 0x1234
STOP, REAL_TIME, BUFFERED, SET_BIAS = 0x0000, 0x0002, 0x0003, 0x0042
RECORD = struct.Struct(">III6i")
REQUEST = struct.Struct(">HHI")


class RdtDevice:
    def __init__(self, host, port, counts_per_force=1_000_000.0, counts_per_torque=1_000_000.0):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, port))
        self.sock.setblocking(False)
        self.scale = [counts_per_force] * 3 + [counts_per_torque] * 3
        self.client = None
        self.remaining = 0
        self.rdt_sequence = 0
        self.ft_sequence = 0
        self.zero = [0.0] * 6
        self.last = [0.0] * 6
        self.bad_requests = 0
        self.rate_hz = 1000.0
        self.t0 = time.monotonic()

    def poll(self):
        """Takes every request waiting on the socket."""
        while True:
            try:
                data, addr = self.sock.recvfrom(64)
            except (BlockingIOError, InterruptedError):
                return
            except ConnectionRefusedError:
                # The client's port closed (a killed sensor board): stop streaming to it.
                self.client = None
                continue
            if len(data) != REQUEST.size:
                self.bad_requests += 1
                continue
            header, command, count = REQUEST.unpack(data)
            if header != HEADER:
                self.bad_requests += 1
            elif command in (REAL_TIME, BUFFERED):
                if self.client is None or self.client == addr:
                    self.client, self.remaining, self.rdt_sequence = addr, count, 0
            elif command == STOP:
                if self.client == addr:
                    self.client = None
            elif command == SET_BIAS:
                self.zero = list(self.last)
            else:
                self.bad_requests += 1

    def sample(self, six):
        """One device sample: streamed to the client, if one asked."""
        self.poll()
        # A device samples on its own clock, in real time: ft_sequence counts its periods since
        # it started, so a simulation that runs slower than real time skips numbers (which a
        # receiver does not count as lost: loss is judged by rdt_sequence) rather than
        # falling behind the receiver's clock.
        tick = int((time.monotonic() - self.t0) * self.rate_hz)
        self.ft_sequence = max(tick, self.ft_sequence + 1) & 0xFFFFFFFF
        self.last = list(six)
        if self.client is None:
            return
        self.rdt_sequence = (self.rdt_sequence + 1) & 0xFFFFFFFF
        counts = [
            max(-(2**31), min(2**31 - 1, round((v - z) * s))) for v, z, s in zip(six, self.zero, self.scale)
        ]
        try:
            self.sock.sendto(RECORD.pack(self.rdt_sequence, self.ft_sequence, 0, *counts), self.client)
        except (BlockingIOError, ConnectionRefusedError):
            pass
        if self.remaining:
            self.remaining -= 1
            if self.remaining == 0:
                self.client = None
