"""servobus: asyncio orchestrator for buses of servo actuators, with a small C core.

Layers (the docs' "How servobus is built"): ``servobus.core`` wraps the C core (CRCs, bit packing,
de-framers); protocol families, the scheduler, transports, the simulator and the Bus build on it.
"""

import importlib
from typing import TYPE_CHECKING

from servobus._version import __version__
from servobus.errors import (
    MotorBusy,
    MotorFault,
    MotorNotExecuted,
    MotorOffline,
    MotorStreaming,
    MotorTimeout,
    ProtocolError,
    RequestStateError,
    ServobusError,
    TransportError,
)
from servobus.frame import Frame

if TYPE_CHECKING:
    from servobus.bus import Bus, FrameLink, Motor, MotorStatus
    from servobus.limits import LimitBook, LimitExceeded, Limits
    from servobus.loop import Loop

__all__ = [
    "Bus",
    "Frame",
    "FrameLink",
    "LimitBook",
    "LimitExceeded",
    "Limits",
    "Loop",
    "Motor",
    "MotorBusy",
    "MotorFault",
    "MotorNotExecuted",
    "MotorOffline",
    "MotorStatus",
    "MotorStreaming",
    "MotorTimeout",
    "ProtocolError",
    "RequestStateError",
    "ServobusError",
    "TransportError",
    "__version__",
]


def __getattr__(name: str) -> object:
    # The Bus pulls in asyncio and anyio: imported when first used, so the codecs stay light.
    if name in ("Bus", "FrameLink", "Motor", "MotorStatus"):
        from servobus import bus

        return getattr(bus, name)
    if name in ("LimitBook", "LimitExceeded", "Limits"):  # (they import the protocols' contract)
        return getattr(importlib.import_module("servobus.limits"), name)
    if name == "Loop":  # (the loop's layer is above this package's: imported by name, when used)
        return importlib.import_module("servobus.loop").Loop
    raise AttributeError(f"module 'servobus' has no attribute {name!r}")
