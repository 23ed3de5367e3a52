"""The loop:// read test_slcan relies on takes every waiting byte whatever the wall clock does.

python-can opens pyserial's loop:// port with a 1 ms timeout that the port checks on the wall
clock after each byte: a descheduled thread used to come back with part of a line (the race of
test_python_can_sends_what_the_adapter_parses). Here the clock jumps 10 ms at every reading.
"""

from __future__ import annotations

import itertools

import can
import pytest
import serial.urlhandler.protocol_loop as protocol_loop

from sim.test_slcan import _python_can_slcan, _read_all


def test_a_descheduled_read_still_takes_the_whole_line(monkeypatch: pytest.MonkeyPatch) -> None:
    bus = _python_can_slcan()
    clock = itertools.count(0.0, 0.01)
    monkeypatch.setattr(protocol_loop.time, "time", lambda: next(clock))
    bus.send(can.Message(arbitration_id=0x123, data=bytes(range(8)), is_extended_id=False))
    written = _read_all(bus.serialPortOrig)  # type: ignore[attr-defined]
    monkeypatch.undo()
    bus.shutdown()
    assert written == b"t12380001020304050607\r"
