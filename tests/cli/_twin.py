"""``twin``: the toy plug-in family (tests/plugins/servobus_toy) with Damiao's two habits, for the tests
of what a family declares to the CLI and of fault codes.

* Its reply id of motor N is motor N + 16's request id (requests on 0x600 + N, replies on
  0x610 + N, as Damiao's feedback is N + 0x10): ids 1-32 cannot all share one bus.
* Its state reply carries one error CODE (:class:`DmState`, Damiao's 4-bit state: 0 disabled,
  1 enabled, 8.. faults) where the toy's carries flags: ``Reply.FAULT_CODE``.

Its ``cli`` part declares ``scan_ids`` 1-32. Import it only with the toy installed (the ``toy``
fixture), and drop it from ``sys.modules`` with it (:func:`installed`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import enum
import importlib
import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

from servobus_toy import FAMILY as TOY
from servobus_toy.cli import CLI as TOY_CLI
from servobus_toy.codec import ToyCodec
from servobus_toy.device import DEFAULT_TURNAROUND_S, ToyMotor
from servobus_toy.messages import ReadState, Revision, SpeedLimitEcho, StateReply, ToyFaults, ToyReply

from servobus.errors import ProtocolError
from servobus.frame import Frame
from servobus.protocols import Reply
from servobus.protocols.authoring import OpenEnumField, ScaledField
from servobus.sim.family import Setup, SimFamily, SimOptions

__all__ = [
    "CLI",
    "FAMILY",
    "SIM",
    "CodedState",
    "DmState",
    "ReadState",
    "SpeedLimitEcho",
    "StateReply",
    "ToyFaults",
    "TwinCodec",
    "TwinMotor",
    "installed",
]

MOTOR_IDS = range(1, 33)
REQUEST_BASE = 0x600
REPLY_BASE = 0x610  # motor N's reply id is motor N + 16's request id


class DmState(enum.IntEnum):
    """Damiao's state code (feedback DATA[0] high nibble): 0 and 1 are states, the others faults."""

    DISABLED = 0x0
    ENABLED = 0x1
    OVER_VOLTAGE = 0x8
    UNDER_VOLTAGE = 0x9
    OVER_CURRENT = 0xA
    MOS_OVER_TEMPERATURE = 0xB
    COIL_OVER_TEMPERATURE = 0xC
    COMMUNICATION_LOST = 0xD
    OVERLOAD = 0xE


@dataclass(frozen=True, slots=True, kw_only=True)
class CodedState(ToyReply):
    """0x81 as the twin reads it: DATA[7] is one state code, not flags."""

    CODE: ClassVar[int] = 0x81
    FAULT_CODE: ClassVar[str | None] = "state"
    NO_FAULT_CODES: ClassVar[frozenset[int]] = frozenset({DmState.DISABLED, DmState.ENABLED})
    FIELDS = (
        (1, ScaledField("position_deg", 4, counts_per_unit=100)),
        (5, ScaledField("speed_dps", 2, counts_per_unit=10)),
        (7, OpenEnumField("state", 1, DmState)),  # (an undefined code is kept as its int)
    )
    position_deg: float
    speed_dps: float
    state: DmState | int = DmState.DISABLED


def _check(motor_id: int) -> int:
    if isinstance(motor_id, bool) or not isinstance(motor_id, int) or motor_id not in MOTOR_IDS:
        raise ValueError(f"twin motor_id={motor_id!r} is outside 1..32")
    return motor_id


class TwinCodec(ToyCodec):
    """A toy motor whose reply id is 0x610 + N, its state read as :class:`CodedState`."""

    family = "twin"
    __slots__ = ()

    def __init__(self, motor_id: int, revision: Revision) -> None:
        super().__init__(1, revision)  # (the toy's own ids, replaced below)
        self.motor_id = _check(motor_id)
        self._request_id = REQUEST_BASE + motor_id
        self._reply_id = REPLY_BASE + motor_id
        self.request_ids = frozenset({self._request_id})
        self.reply_ids = frozenset({self._reply_id})

    def decode(self, frame: Frame) -> Reply:
        reply = super().decode(frame)
        return CodedState.decode(frame.data) if isinstance(reply, StateReply) else reply


def bind(motor_id: int, *, revision: Any = None, model: None = None, link: str = "can") -> TwinCodec:
    """Twin motor ``motor_id``'s codec (ValueError: outside 1..32, or what the toy's bind refuses)."""
    TOY.bind(1, revision=revision, model=model, link=link)  # (its checks of the options)
    return TwinCodec(motor_id, revision if isinstance(revision, Revision) else Revision.V1)


def decode_reply(can_id: int, data: bytes, **_: Any) -> ToyReply:
    if not REPLY_BASE + 1 <= can_id <= REPLY_BASE + MOTOR_IDS.stop - 1:
        raise ProtocolError(f"0x{can_id:03X} is no twin reply identifier", raw=data)
    reply = TOY.decode_reply(0x681, data)
    return CodedState.decode(data) if isinstance(reply, StateReply) else reply


class TwinMotor(ToyMotor):
    """A simulated toy motor answering on 0x610 + N; its faults byte is read as a state code
    (:meth:`report` sets it)."""

    def __init__(self, motor_id: int) -> None:
        super().__init__(motor_id, name=f"twin{motor_id}")
        self._reply_id = REPLY_BASE + motor_id

    def report(self, code: int) -> None:
        """Report state ``code`` in DATA[7] from now on (a code that is a fault latches as the
        toy's faults do: the output off until a restart)."""
        self.inject_fault(ToyFaults(code))


class TwinSim(SimFamily):
    def devices(self, ids: Sequence[int], revision: enum.Enum, options: SimOptions) -> Setup:
        return Setup(can_devices=[TwinMotor(i) for i in ids])


SIM = TwinSim(family="twin", media=("can",), turnaround_s=DEFAULT_TURNAROUND_S)
CLI = dataclasses.replace(TOY_CLI, scan_ids=range(1, 33))
FAMILY = dataclasses.replace(
    TOY,
    name="twin",
    description="the toy family with Damiao's ids (reply N + 16) and state codes",
    bind=bind,
    decode_reply=decode_reply,
    motor_ids=MOTOR_IDS,
    motor=None,
    parts={"cli": f"{__name__}:CLI", "sim": f"{__name__}:SIM"},
    package=None,
)


@contextlib.contextmanager
def installed() -> Iterator[Any]:
    """This module imported fresh (with the toy installed), registered as the family ``twin`` (an
    entry point of its own beside the installed ones), and forgotten afterwards."""
    import pytest

    from servobus import _plugins
    from servobus.protocols import ENTRY_POINT_GROUP

    sys.modules.pop(__name__, None)
    module = importlib.import_module(__name__)
    real = _plugins.entry_points
    ours = importlib.metadata.EntryPoint("twin", f"{__name__}:FAMILY", ENTRY_POINT_GROUP)

    def entry_points(group: str) -> Any:
        found = list(real(group=group))
        return [*found, ours] if group == ENTRY_POINT_GROUP else found

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(_plugins, "entry_points", entry_points)
        try:
            yield module
        finally:
            _plugins._LOADED.pop((ENTRY_POINT_GROUP, "twin"), None)
            sys.modules.pop(__name__, None)
