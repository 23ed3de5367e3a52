"""``python -m servobus.sim``: simulated motors on a pseudo-terminal, for any tool to talk to.

Prints the device path a host should open on its first line of output, then serves until
interrupted (Ctrl-C)::

    python -m servobus.sim --family myactuator --motors 4 --slcan
    python -m servobus.sim --family myactuator --motors 4 --rs485 --baud 1000000
    python -m servobus.sim --family hollow --motors 4 --slcan
    python -m servobus.sim --family hollow --motors 4 --rs485          # converter, transparent, 1 Mbaud
    python -m servobus.sim --family hollow --motors 4 --rs485 --modbus # converter, Modbus RTU, 19200
    python -m servobus.sim --family lk --motors 8 --revision V2_35

``--slcan`` presents a USB-CAN adapter speaking SLCAN (python-can: ``interface="slcan"``);
``--rs485`` presents the family's RS485 line. ``--link PATH`` also creates a stable symlink.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from servobus.sim.attach import serve_rs485, serve_slcan
from servobus.sim.device import Device, SerialDevice
from servobus.sim.network import SimCanNetwork
from servobus.sim.pty import PtyPort


@dataclass(frozen=True, slots=True)
class Setup:
    """What to serve: CAN devices (behind SLCAN) or serial devices (on an RS485 line at ``baud``)."""

    can_devices: Sequence[Device] = ()
    serial_devices: Sequence[SerialDevice] = ()
    baud: int = 0


def _hollow(args: argparse.Namespace) -> Setup:
    from servobus.sim.devices.hollow import HollowMotor
    from servobus.sim.devices.hollow_converter import ConverterMode, HollowConverter

    ids = range(args.first_id, args.first_id + args.motors)
    if not args.rs485:
        return Setup(can_devices=[HollowMotor(i, fd_enabled=args.fd) for i in ids])
    mode = ConverterMode.MODBUS if args.modbus else ConverterMode.TRANSPARENT
    converter = HollowConverter([HollowMotor(i, fd_enabled=True) for i in ids], mode=mode)
    return Setup(serial_devices=[converter], baud=converter.baud)


def _lk(args: argparse.Namespace) -> Setup:
    from servobus.protocols.lk import LkModel, Revision
    from servobus.sim.devices.lk import LkMotor

    if args.rs485:
        raise SystemExit("lk: neither LK manual defines an RS485 framing (lk-v2.md §1.3); use --slcan")
    model = LkModel(revision=Revision[args.revision or "V2_36"])
    return Setup(
        can_devices=[LkMotor(i, model=model) for i in range(args.first_id, args.first_id + args.motors)]
    )


def _myactuator(args: argparse.Namespace) -> Setup:
    from servobus.protocols.myactuator import Revision
    from servobus.sim.devices.myactuator import MyActuatorMotor
    from servobus.sim.devices.myactuator_rs485 import MyActuatorRs485Motor

    revision = Revision[args.revision or "V4_4"]
    motors = [
        MyActuatorMotor(i, revision=revision) for i in range(args.first_id, args.first_id + args.motors)
    ]
    if args.rs485:
        # the manuals list 115200 .. 2.5 Mbit/s and name no default (spec §1.2): 1 Mbit/s here
        return Setup(serial_devices=[MyActuatorRs485Motor(m) for m in motors], baud=1_000_000)
    return Setup(can_devices=motors)


FAMILIES: dict[str, Callable[[argparse.Namespace], Setup]] = {
    "hollow": _hollow,
    "lk": _lk,
    "myactuator": _myactuator,
}


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m servobus.sim", description=__doc__.split("\n\n")[0])
    parser.add_argument("--family", choices=sorted(FAMILIES), required=True)
    parser.add_argument("--motors", type=int, default=1, help="how many motors (default 1)")
    parser.add_argument("--first-id", type=int, default=1, help="id of the first motor (default 1)")
    medium = parser.add_mutually_exclusive_group()
    medium.add_argument("--slcan", action="store_true", help="a simulated SLCAN USB-CAN adapter (default)")
    medium.add_argument("--rs485", action="store_true", help="the family's RS485 line")
    parser.add_argument("--baud", type=int, help="RS485 baud rate (default: the family's)")
    parser.add_argument("--revision", help="protocol revision, e.g. V2_35 (default: the family's newest)")
    parser.add_argument("--fd", action="store_true", help="CAN FD motors (hollow)")
    parser.add_argument("--modbus", action="store_true", help="hollow converter in Modbus RTU mode")
    parser.add_argument("--link", help="also create this symlink to the pty")
    args = parser.parse_args(argv)
    if not 1 <= args.motors <= 32:
        parser.error(f"--motors {args.motors} is outside 1..32")
    return args


async def serve(args: argparse.Namespace, ready: Callable[[str], None]) -> None:
    """Build the devices, open the pty, report its path through ``ready`` and serve until cancelled."""
    setup = FAMILIES[args.family](args)
    port = PtyPort(args.link)
    try:
        ready(port.name)
        if setup.serial_devices:
            await serve_rs485(setup.serial_devices, port, baud=args.baud or setup.baud)
        else:
            await serve_slcan(SimCanNetwork(setup.can_devices), port)
    finally:
        port.close()


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)

    def ready(path: str) -> None:
        print(path, flush=True)
        kind = "RS485 line" if args.rs485 else "SLCAN adapter"
        print(
            f"{args.motors} simulated {args.family} motor(s) behind a {kind}; Ctrl-C stops", file=sys.stderr
        )

    with contextlib.suppress(KeyboardInterrupt):
        asyncio.run(serve(args, ready))
    return 0


if __name__ == "__main__":
    sys.exit(main())
