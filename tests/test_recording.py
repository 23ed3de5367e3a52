"""servobus.tools.recording: output files that never overwrite or remove what they did not create, CSV and
JSONL telemetry rows, candump frames with their direction, and a tap that leaves the Bus unchanged
(a FrameLink itself: the sender's handles echoed, the inner link's rules and stats, on asyncio and trio)."""

from __future__ import annotations

import asyncio
import dataclasses
import io
import json
from pathlib import Path

import anyio
import pytest

from _backends import BACKENDS, virtual
from servobus.bus import Bus
from servobus.frame import Frame
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.tools.logs import read_log
from servobus.tools.recording import CandumpWriter, NewFiles, TapLink, TelemetryWriter, telemetry_row
from servobus.transports.contract import FrameLink
from servobus.transports.sim import SimTransport


@pytest.fixture(params=BACKENDS)
def anyio_backend(request: pytest.FixtureRequest) -> tuple[str, dict[str, object]]:
    return virtual(request.param)


class CopyingSim(SimTransport):
    def send(self, frame: Frame, handle: object = None) -> None:
        super().send(dataclasses.replace(frame), frame if handle is None else handle)


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


@pytest.mark.anyio
@pytest.mark.parametrize("inner", [SimTransport, CopyingSim], ids=["sim", "copying-sim"])
async def test_the_tap_echoes_the_sender_s_handles_and_shows_the_frames_it_was_given(
    inner: type[SimTransport],
) -> None:
    seen: list[tuple[Frame, bool, float]] = []
    reports: list[tuple[object, float | None, str | None]] = []
    received: list[Frame] = []
    sim = inner(devices=[MyActuatorMotor(1)])
    tap = TapLink(sim, lambda frame, rx, at: seen.append((frame, rx, at)), anyio.current_time)
    assert isinstance(tap, FrameLink)
    assert tap.rules == sim.rules
    tap.set_send_reporter(lambda handle, at, why: reports.append((handle, at, why)))
    tap.set_consumer(received.extend)
    request = ma.FAMILY.bind(1).encode(ma.ReadStatus2())
    handle = object()
    async with tap:
        sent_at = anyio.current_time()
        tap.send(request, handle)
        tap.send(request)  # no handle: the frame is the handle
        with anyio.fail_after(1.0):
            while len(received) < 2:
                await anyio.sleep(0.0001)
        assert tap.stats().frames_out == 2
    assert reports == [(handle, sent_at, None), (request, sent_at, None)]
    assert reports[0][0] is handle and reports[1][0] is request
    assert [(frame is request, rx) for frame, rx, _ in seen[:2]] == [(True, False), (True, False)]
    assert [(frame, rx) for frame, rx, _ in seen[2:]] == [(frame, True) for frame in received]
    assert not tap.is_open
