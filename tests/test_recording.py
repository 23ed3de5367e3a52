"""servobus.recording: output files that never overwrite or remove what they did not create, CSV and
JSONL telemetry rows, candump frames with their direction, and a tap that leaves the Bus unchanged."""

from __future__ import annotations

import asyncio
import io
import json
from pathlib import Path

import pytest

from servobus.bus import Bus
from servobus.frame import Frame
from servobus.logs import read_log
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.recording import CandumpWriter, NewFiles, TapLink, TelemetryWriter, telemetry_row
from servobus.transports.sim import SimTransport


def test_new_files_refuse_existing_ones_and_remove_only_their_own(tmp_path: Path) -> None:
    old, new = tmp_path / "old.csv", tmp_path / "new.csv"
    old.write_text("mine")
    files = NewFiles()
    with pytest.raises(FileExistsError, match="--force"):
        files.check([old])
    with pytest.raises(FileExistsError):
        files.open(old)
    files.open(new).write("x")
    files.discard()
    assert not new.exists() and old.read_text() == "mine"
    forced = NewFiles(force=True)
    forced.open(old).write("overwritten")
    forced.discard()
    assert old.read_text() == "mine"  # a run that failed leaves an existing file whole
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.csv"]
    kept = NewFiles(force=True)
    kept.open(old).write("overwritten")
    assert old.read_text() == "mine"  # not before the output is kept
    kept.close()
    assert old.read_text() == "overwritten"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.csv"]


def test_telemetry_rows_and_writers() -> None:
    reply = ma.decode_reply(0x241, bytes.fromhex("9C326400F4012D00"))
    row = telemetry_row(0.1234567, "myactuator", 1, reply)
    assert row == {
        "time_s": 0.123457,
        "motor_id": 1,
        "family": "myactuator",
        "reply": "StatusReply",
        "temperature_c": 50,
        "current_a": 1.0,
        "speed_dps": 500.0,
        "angle_deg": 45.0,
        "command": "READ_STATUS_2",
    }
    other = telemetry_row(0.2, "myactuator", 1, ma.decode_reply(0x241, bytes.fromhex("9A2D2C0102020600")))
    text = io.StringIO()
    writer = TelemetryWriter(text, "csv")
    for r in (row, other, row):
        writer.write(r)
    assert (writer.count, writer.skipped) == (2, 1)  # a CSV holds the first row's reply type
    assert text.getvalue().splitlines()[0] == ",".join(row)
    lines = io.StringIO()
    jsonl = TelemetryWriter(lines, "jsonl")
    jsonl.write(row)
    jsonl.write(other)
    assert [json.loads(line)["reply"] for line in lines.getvalue().splitlines()] == [
        "StatusReply",
        "Status1Reply",
    ]
    with pytest.raises(ValueError, match="xml"):
        TelemetryWriter(io.StringIO(), "xml")


def test_the_tap_sees_both_directions_and_the_bus_works_as_without_it(tmp_path: Path) -> None:
    path = tmp_path / "frames.log"

    async def run() -> object:
        loop = asyncio.get_running_loop()
        with path.open("w") as file:
            frames = CandumpWriter(file, epoch=1000.0, origin=loop.time())
            tap = TapLink(SimTransport(devices=[MyActuatorMotor(1)], name="sim"), frames.write, loop.time)
            async with Bus(tap) as bus:
                assert bus.name == "sim"
                reply = await bus.motor("myactuator", 1).read_status2()
            frames.close()
        return reply

    reply = asyncio.run(run())
    assert isinstance(reply, ma.StatusReply)
    read = list(read_log(path))
    assert [(f.arbitration_id, f.is_rx) for f in read] == [(0x141, False), (0x241, True)]
    assert read[1].data == reply.encode()
    assert 1000.0 <= read[0].timestamp <= read[1].timestamp < 1001.0
    assert read[0] == Frame(arbitration_id=0x141, data=ma.ReadStatus2().encode())
