"""``record --watch-setpoints``: the set-points another controller sends our motors, seen on the bus.

CAN is broadcast: a controller's request to one of our motors reaches us too (the Bus counts it in
``foreign_requests``). The recording's :class:`~servobus.tools.recording.TapLink` shows each frame
received to :meth:`SeenSetpoints.on_frame`, which decodes the ones on our motors' request
identifiers with the family's own codec (:class:`~servobus.tools.logs.FrameDecoder`) and keeps, per
motor, the last value of each kind of set-point: the commands the family's ``move``, ``speed`` and
``torque`` build (its ``cli`` part), the value read back in the CLI's units by the builder's own
scale. A command class two of them share (hollow's one set-point frame, whose meaning is the mode
selected before) says no kind by itself, and is not recorded.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from servobus.cli._drive import moved_fields
from servobus.cli._families import cli_part
from servobus.frame import Frame
from servobus.protocols import Command
from servobus.tools.logs import FrameDecoder, Scalar

__all__ = ["SEEN", "SeenSetpoints"]

#: CLI command -> (the column its set-points fill, its value's name), in the columns' order
SEEN: Mapping[str, tuple[str, str]] = {
    "move": ("setpoint_angle_deg", "angle_deg"),
    "speed": ("setpoint_speed_dps", "speed_dps"),
    "torque": ("setpoint_current_a", "current_a"),
}
#: what the builders are given beside the value (an absolute move without limits of its own)
_OTHERS: Mapping[str, Any] = {"max_speed_dps": None, "relative": False, "max_current_a": None}


class SeenSetpoints:
    """The last set-point of each kind another controller sent each of our motors.

    Args:
        family: the motors' family.
        codecs: our motors' bound codecs.
        bind_options: the options they were bound with (``revision``, ``link``).
    """

    def __init__(self, family: str, codecs: Sequence[Any], bind_options: Mapping[str, Any]) -> None:
        options = {k: v for k, v in bind_options.items() if k != "link"}  # (the decoder binds each link)
        self._decoder = FrameDecoder(family, ids=[c.motor_id for c in codecs], **options)
        self._ids = {i & 0x1FFFFFFF for c in codecs for i in c.request_ids}
        self.kinds = _kinds(family, codecs[0])
        self.columns = [
            column for column, _ in SEEN.values() if column in {k[0] for k in self.kinds.values()}
        ]
        self.last: dict[int, dict[str, float]] = {}
        # motor id -> (timestamp, column, value) seen but not yet in ``last``: a batch the tap shows
        # before the Bus handles it may hold a reply and, after it, a set-point the reply predates
        self._pending: dict[int, list[tuple[float, str, float]]] = {}
        self.count = 0

    def on_frame(self, frame: Frame, received: bool, timestamp: float) -> None:
        """A :class:`~servobus.tools.recording.TapLink` callback: note a set-point in ``frame``."""
        if not received or frame.arbitration_id not in self._ids:
            return
        decoded = self._decoder.decode(frame)
        if decoded.direction != "request" or decoded.motor_id is None:
            return  # (a reply on a shared identifier: LK V2.35 answers on its request's)
        kind = self.kinds.get(type(decoded.message))  # type: ignore[arg-type]
        if kind is None:
            return
        column, field, scale = kind
        value = round(getattr(decoded.message, field) / scale, 6)
        self._pending.setdefault(decoded.motor_id, []).append((timestamp, column, value))
        self.count += 1

    def row(self, motor_id: int, at: float) -> dict[str, Scalar]:
        """The columns of ``motor_id``'s row for a reply received at ``at`` (the tap's clock): each
        kind's last value seen at or before then (None: none yet)."""
        mine = self.last.setdefault(motor_id, {})
        pending = self._pending.get(motor_id)
        if pending:
            later = []
            for entry in pending:
                if entry[0] <= at:
                    mine[entry[1]] = entry[2]
                else:
                    later.append(entry)
            pending[:] = later
        return {column: mine.get(column) for column in self.columns}


def _kinds(family: str, codec: Any) -> dict[type[Command], tuple[str, str, float]]:
    """Set-point command class -> (its column, the field holding the value, the field's value per
    unit of the CLI's), from what the family's move, speed and torque build; a class two of them
    share says no kind by itself and is left out."""
    part = cli_part(family)
    found: dict[type[Command], tuple[str, str, float]] = {}
    shared: set[type[Command]] = set()
    for name, (column, key) in SEEN.items():
        entry = part.op(name)
        if entry is None:
            continue
        for cls, (field, scale) in moved_fields(entry, codec, key, _OTHERS).items():
            if cls in found and found[cls][0] != column:
                shared.add(cls)
            found[cls] = (column, field, scale)
    return {cls: kind for cls, kind in found.items() if cls not in shared}
