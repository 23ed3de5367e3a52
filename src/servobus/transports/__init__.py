"""Transports: frames to and from real devices, on anyio (asyncio or trio), with counters and recovery.

Every transport is a :class:`~servobus.transports.contract.FrameLink` (``rules``, ``stats()``,
``send(frame, handle)`` with reports that echo the handle, open and close in one task), on one
base class (:class:`Transport`: ``open``/``close``, ``send``, ``drain``, ``receive``, ``async for``,
``events``, ``stats``, ``rules``), over these lines:

* ``"can"``: :class:`CanTransport`, any python-can interface, CAN and CAN FD, carrying
  :class:`~servobus.frame.Frame`.
* ``"slcan"``: :class:`SlcanTransport`, an SLCAN (LAWICEL) USB-CAN adapter spoken natively
  (pyserial and the C line de-framer, no python-can), carrying
  :class:`~servobus.frame.Frame`.
* ``"rs485"``: :class:`SerialTransport`, an RS485 port through pyserial, carrying
  serial :class:`~servobus.frame.Frame` messages in the framing its family supplies (the family's
  declared serial lines, ``Family.serial``, give the framing by name, its baud rates and parity).
* ``"sim"``: :class:`SimTransport`, the in-process bus onto a simulated CAN network
  (:class:`~servobus.sim.network.SimCanNetwork`), on the event loop's clock (virtual time under
  ``looptime``, :func:`servobus.sim.virtual.run` or trio's ``MockClock``), carrying
  :class:`~servobus.frame.Frame`.

:func:`create_transport` builds one by name; third-party transports register under the
``servobus.transports`` entry-point group. The heavy modules load on first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from servobus import _plugins
from servobus.transports.base import BusOffError, SendQueueFull, Transport
from servobus.transports.contract import FrameLink, LineRules
from servobus.transports.events import (
    BusOff,
    BusRestarted,
    CanErrorClass,
    ErrorFrame,
    FramesDropped,
    StateChanged,
    TransportEvent,
    TransportState,
)
from servobus.transports.stats import TransportStats

if TYPE_CHECKING:
    from servobus.transports.can import CanTransport
    from servobus.transports.rs485 import SerialTransport
    from servobus.transports.sim import SimTransport
    from servobus.transports.slcan import SlcanTransport

__all__ = [
    "TRANSPORTS",
    "BusOff",
    "BusOffError",
    "BusRestarted",
    "CanErrorClass",
    "CanTransport",
    "ErrorFrame",
    "FrameLink",
    "FramesDropped",
    "LineRules",
    "SendQueueFull",
    "SerialTransport",
    "SimTransport",
    "SlcanTransport",
    "StateChanged",
    "Transport",
    "TransportEvent",
    "TransportState",
    "TransportStats",
    "available_transports",
    "create_transport",
]

TRANSPORTS: dict[str, str] = {
    "can": "servobus.transports.can:CanTransport",
    "rs485": "servobus.transports.rs485:SerialTransport",
    "sim": "servobus.transports.sim:SimTransport",
    "slcan": "servobus.transports.slcan:SlcanTransport",
}

ENTRY_POINT_GROUP = "servobus.transports"

_LAZY = {
    "CanTransport": "servobus.transports.can",
    "SerialTransport": "servobus.transports.rs485",
    "SimTransport": "servobus.transports.sim",
    "SlcanTransport": "servobus.transports.slcan",
}


def available_transports() -> dict[str, str]:
    """Built-in transports plus those registered by installed plug-ins (built-ins win on a clash)."""
    return _plugins.available(ENTRY_POINT_GROUP, TRANSPORTS)


def create_transport(name: str, *args: Any, **options: Any) -> Transport[Any, Any]:
    """Build (not open) the transport registered as ``name`` with these arguments.

    ``async with create_transport("can", "virtual", "bus0", fd=True) as bus: ...``

    Raises:
        ValueError: no transport has that name, or its target is not a Transport class.
    """
    cls = _plugins.load(ENTRY_POINT_GROUP, TRANSPORTS, name, "transport")
    if not (isinstance(cls, type) and issubclass(cls, Transport)):
        raise ValueError(f"{available_transports()[name]} is not a servobus Transport class")
    transport: Transport[Any, Any] = cls(*args, **options)
    return transport


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
