"""Simulated CAN buses behind SLCAN ptys, served by one lean process (the device side of bench_loop1k).

    python bench/_can_devices.py --family myactuator --motors 3,3,3,2    # one bus per number
    python bench/_can_devices.py --family hollow --fd --motors 8,8,8,8

Prints a JSON list of pty paths (one per bus, an SLCAN adapter each) on its first line of output, then
serves until stdin closes or SIGTERM. Motor ids run 1, 2, 3, ... across the buses (32 motors keep
distinct ids).

Each bus is the simulator's own sans-IO model: a :class:`~servobus.sim.corenet.CoreCanNetwork` with the
bit-exact :class:`~servobus.sim.canbus.CanBusModel` (1 Mbit/s; with ``--fd`` a 5 Mbit/s data phase) and
the simulator's device models (``MyActuatorMotor``, ``HollowMotor(fd_enabled=True)``, with their
turnaround), clocked by ``time.monotonic()``. What differs from ``python -m servobus.sim --slcan`` is only
the I/O around it: that one runs an asyncio task pair and a queue per frame per pty and costs 100-230 µs
of CPU per transaction (measured: a 1 kHz loop over 32 motors would need several cores for the devices
alone). Here one ``select()`` loop serves every pty: request lines are cut at CR and parsed once per
distinct line (a host polling the same command sends the same line every tick), frames go into the
network, and the network's next event (a frame's end on the wire, a reply becoming ready) sets the
select timeout, with microsecond resolution (``select`` takes a ``timeval``; the process's timer slack
is set to 1 µs so the kernel does not round wake-ups up by its default 50 µs). Replies are written as
LAWICEL lines the moment the network says their last bit crossed the wire. Command lines (``C``,
``S8``, ``Y5``, ``O``) are answered OK (``\\r``); the bit rates are this process's arguments.
"""

from __future__ import annotations

import argparse
import ctypes
import json
import math
import os
import select
import signal
import sys
import time
import tty
from collections.abc import Callable, Sequence

from servobus.frame import Frame
from servobus.sim.canbus import CanBusModel
from servobus.sim.corenet import CoreCanNetwork
from servobus.sim.device import Device
from servobus.sim.slcan import parse_frame
from servobus.transports.slcan import encode_line

_FRAME_PREFIXES = frozenset(b"tTdDbB")
_PR_SET_TIMERSLACK = 29


def _tight_timer_slack() -> None:
    """Ask the kernel for 1 µs timer slack (default 50 µs): select() wake-ups on time."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_TIMERSLACK, 1000, 0, 0, 0)
    except (OSError, AttributeError):
        pass


def devices_for(family: str, ids: Sequence[int]) -> list[Device]:
    if family == "myactuator":
        from servobus.protocols.myactuator.sim.device import MyActuatorMotor

        return [MyActuatorMotor(i) for i in ids]
    if family == "hollow":
        from servobus.protocols.hollow.sim.device import HollowMotor

        return [HollowMotor(i, fd_enabled=True) for i in ids]
    raise SystemExit(f"_can_devices: no family {family!r}")


class Port:
    """One pty (the adapter end) and the simulated bus behind it."""

    def __init__(self, network: CoreCanNetwork) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self.slave)
        self.network = network
        self.partial = b""
        self.frames_in = 0
        self.frames_out = 0
        self.next_s = 0.0  # when the network next has something for the host (run it then)


def serve(ports: list[Port], clock: Callable[[], float], stop_fd: int) -> None:
    parsed: dict[bytes, Frame | None] = {}
    by_fd = {port.master: port for port in ports}
    fds = [*by_fd, stop_fd]
    inf = math.inf
    while True:
        now = clock()
        wake = inf
        for port in ports:
            if port.next_s <= now:
                network = port.network
                received = network.advance(now)
                if received:
                    port.frames_out += len(received)
                    _write(port, b"".join(encode_line(frame) for _, frame in received))
                port.next_s = _next_visible(network, now)
            if port.next_s < wake:
                wake = port.next_s
        readable, _, _ = select.select(fds, [], [], None if wake == inf else max(0.0, wake - clock()))
        if not readable:
            continue
        now = clock()
        for fd in readable:
            if fd == stop_fd:
                if not os.read(stop_fd, 4096):
                    return
                continue
            port = by_fd[fd]
            try:
                data = os.read(fd, 65536)
            except BlockingIOError:
                continue
            except OSError:  # EIO: no host has the slave open right now
                continue
            lines = (port.partial + data).split(b"\r")
            port.partial = lines.pop()
            answers = 0
            network = port.network
            at = max(network.now_s, now)
            sent = False
            for line in lines:
                if not line or line[0] not in _FRAME_PREFIXES:
                    answers += bool(line.strip(b"\n"))
                    continue
                frame = parsed.get(line)
                if frame is None and line not in parsed:
                    frame = parsed[line] = _parse(line)
                if frame is not None:
                    network.send(frame, at)
                    port.frames_in += 1
                    sent = True
            if answers:
                _write(port, b"\r" * answers)
            if sent:
                port.next_s = _next_visible(network, at)


def _next_visible(network: CoreCanNetwork, now: float) -> float:
    """When ``network`` next has a frame for the host: it first runs over what the host can neither
    see nor change (its own requests ending, the motors' turnaround), so the process wakes once per
    reply instead of once per frame on the wire."""
    network.run_ahead(now)
    at = network.next_event_s()
    return math.inf if at is None else at


def _parse(line: bytes) -> Frame | None:
    try:
        frame, remote = parse_frame(line.decode("ascii"))
    except (ValueError, UnicodeDecodeError):
        return None
    return None if remote else frame


def _write(port: Port, data: bytes) -> None:
    view = memoryview(data)
    while view:
        try:
            view = view[os.write(port.master, view) :]
        except BlockingIOError:
            select.select([], [port.master], [], 0.01)
        except OSError:
            return


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--family", choices=("myactuator", "hollow"), required=True)
    parser.add_argument("--motors", required=True, help="motors per bus, comma-separated (one bus each)")
    parser.add_argument("--fd", action="store_true", help="CAN FD: 5 Mbit/s data phase")
    args = parser.parse_args(argv)
    _tight_timer_slack()
    counts = [int(n) for n in args.motors.split(",")]
    ports: list[Port] = []
    first = 1
    for n in counts:
        ids = range(first, first + n)
        first += n
        bus = CanBusModel(bitrate=1_000_000, data_bitrate=5_000_000 if args.fd else None)
        ports.append(Port(CoreCanNetwork(devices_for(args.family, ids), bus=bus)))
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    t0 = time.monotonic()
    print(json.dumps([port.path for port in ports]), flush=True)
    try:
        serve(ports, lambda: time.monotonic() - t0, sys.stdin.fileno())
    finally:
        stats = {"frames_in": sum(p.frames_in for p in ports), "frames_out": sum(p.frames_out for p in ports)}
        print(json.dumps(stats), file=sys.stderr, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
