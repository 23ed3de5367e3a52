"""servobus.tools.logs: frames of either direction decoded byte-exactly as the family decoders do; logs read
through python-can's readers; frames typed on the command line."""

from __future__ import annotations

import io
from pathlib import Path

import can
import pytest

from _log_samples import SAMPLES, Sample
from servobus.frame import Frame
from servobus.protocols import hollow as ho
from servobus.protocols import lk
from servobus.protocols import myactuator as ma
from servobus.tools.logs import FrameDecoder, message_values, parse_frame, read_log
from servobus.transports.can import message_from_frame


@pytest.mark.parametrize(
    "sample", SAMPLES, ids=lambda s: f"{s.family}-{s.direction}-{type(s.expected).__name__}"
)
def test_a_frame_decodes_as_its_family_decoder_does(sample: Sample) -> None:
    decoded = FrameDecoder(sample.family).decode(sample.frame)
    assert decoded.error is None
    assert (decoded.direction, decoded.motor_id) == (sample.direction, sample.motor_id)
    assert decoded.message == sample.expected
    assert decoded.values() == message_values(sample.expected)
    assert decoded.as_dict()["fields"] == message_values(sample.expected)


def test_values_are_scalars_named_with_their_units() -> None:
    status = ma.decode_reply(0x241, bytes.fromhex("9A2D2C0102020600"))
    assert message_values(status) == {
        "temperature_c": 45,
        "mos_temperature_c": 44,
        "brake_released": True,
        "voltage_v": 51.4,
        "errors": 0x0006,  # flags as their int
    }
    echo = ma.decode_reply(0x241, bytes.fromhex("2003000001000000"))
    assert message_values(echo) == {
        "command": "FunctionControl",
        "command.index": "ERROR_REPORTING",  # enums by name
        "command.value": 1,
    }
    phases = lk.decode_reply(0x181, bytes.fromhex("9D1E4000C0FF0000"))
    assert message_values(phases)["currents_a[0]"] == pytest.approx(64 * 66 / 4096)
    assert message_values(phases)["currents_counts"] is None
    reply = ho.NormalReply(motor_id=3, position_deg=45, speed_rad_s=-2, current_a=0.5)
    assert "model" not in message_values(reply)  # configuration, not a value the frame carried


def test_direction_tells_a_v235_request_from_its_echo() -> None:
    decoder = FrameDecoder("lk", revision="V2_35")
    data = bytes.fromhex("8000000000000000")
    sent = decoder.decode(Frame(arbitration_id=0x141, data=data, is_rx=False))
    received = decoder.decode(Frame(arbitration_id=0x141, data=data))
    assert (sent.direction, sent.message) == ("request", lk.MotorOff())
    assert received.direction == "reply"
    assert received.message == lk.decode_reply(0x141, data, revision=lk.Revision.V2_35)


def test_a_v235_request_the_reply_decoder_refuses_decodes_as_a_request() -> None:
    decoder = FrameDecoder("lk", revision="V2_35")
    frame = Frame(arbitration_id=0x142, data=bytes.fromhex("9C00000000000000"))  # direction unknown
    decoded = decoder.decode(frame)
    assert decoded.ok


def test_shared_identifiers_name_no_motor() -> None:
    decoder = FrameDecoder("myactuator", revision="V4_3")
    broadcast = decoder.decode(Frame(arbitration_id=0x280, data=bytes.fromhex("9A00000000000000")))
    assert (broadcast.direction, broadcast.motor_id, broadcast.type) == ("request", None, "ReadStatus1")
    data = bytes.fromhex("7900010000004302")
    reply = decoder.decode(Frame(arbitration_id=0x300, data=data))
    assert (reply.direction, reply.motor_id) == ("reply", None)
    assert reply.message == ma.decode_reply(0x300, data, revision=ma.Revision.V4_3)


def test_frames_that_do_not_decode_say_why() -> None:
    decoder = FrameDecoder("myactuator")
    foreign = decoder.decode(parse_frame("123#00"))
    assert not foreign.ok and "0x123" in (foreign.error or "")
    short = decoder.decode(parse_frame("241#9C"))
    assert short.as_dict()["error"].startswith("StatusReply: expected 8 data bytes")
    assert FrameDecoder("myactuator", ids=[1]).decode(parse_frame("242#9C00000000000000")).error


def test_ids_the_family_refuses_are_an_error() -> None:
    with pytest.raises(ValueError, match="motor_id"):
        FrameDecoder("lk", ids=[40])


@pytest.mark.parametrize(
    ("text", "frame"),
    [
        ("141#9C00000000000000", Frame(arbitration_id=0x141, data=bytes.fromhex("9C00000000000000"))),
        ("00000064#0102", Frame(arbitration_id=0x64, data=b"\x01\x02", is_extended_id=True)),
        ("064##1" + "00" * 16, Frame(arbitration_id=0x64, data=bytes(16), is_fd=True, bitrate_switch=True)),
        ("241 9C 32 64 00 F4 01 2D 00", Frame(arbitration_id=0x241, data=bytes.fromhex("9C326400F4012D00"))),
        ("241", Frame(arbitration_id=0x241)),
    ],
)
def test_frames_on_the_command_line(text: str, frame: Frame) -> None:
    parsed = parse_frame(text)
    assert (parsed, parsed.is_extended_id, parsed.is_fd, parsed.bitrate_switch) == (
        frame,
        frame.is_extended_id,
        frame.is_fd,
        frame.bitrate_switch,
    )


@pytest.mark.parametrize("text", ["", "141#9C0", "xyz#00", "141#" + "00" * 9, "241 9C3 2", "800#00"])
def test_bad_frame_text_is_a_value_error(text: str) -> None:
    with pytest.raises(ValueError, match="is not a frame"):
        parse_frame(text)


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf", ".csv"])
def test_logs_are_read_through_python_can(tmp_path: Path, suffix: str) -> None:
    frames = [s.frame for s in SAMPLES if s.family == "myactuator" and not s.frame.is_fd]
    path = tmp_path / f"trace{suffix}"
    with can.Logger(path) as logger:
        for i, frame in enumerate(frames):
            message = message_from_frame(frame)
            message.timestamp = 1000.0 + i / 1000
            message.is_rx = frame.is_rx
            logger.on_message_received(message)
        logger.on_message_received(can.Message(timestamp=1001.0, is_error_frame=True))
    log = read_log(path)
    read = list(log)
    assert read == frames
    assert log.skipped == 1  # the error frame
    if suffix in (".log", ".asc", ".blf"):  # the direction survives (CSV has no column for it)
        assert [f.is_rx for f in read] == [f.is_rx for f in frames]


def test_a_damaged_blf_is_a_value_error_as_documented(tmp_path: Path) -> None:
    """python-can's BLF reader raises zlib.error on a damaged object; LogFrames says ValueError."""
    path = tmp_path / "trace.blf"
    with can.BLFWriter(str(path)) as writer:
        for i in range(200):
            data = bytes([0x9C, 0, 0, 0, 0, 0, 0, i])
            writer.on_message_received(can.Message(arbitration_id=0x141, data=data, is_extended_id=False))
    raw = bytearray(path.read_bytes())
    raw[200:260] = bytes((7 * i) % 256 for i in range(60))
    path.write_bytes(bytes(raw))
    with pytest.raises(ValueError, match=r"^error: Error -3 while decompressing"):
        list(read_log(path))


#: a frame line of each text format, and the same line damaged (a byte that is not hex, bad base64)
DAMAGE = {
    ".log": ("141#9C00000000000002", "141#9C000000000000ZZ"),
    ".asc": ("00 00 02\n", "00 00 ZZ\n"),
    ".csv": ("nAAAAAAAAAI=", "nAAA!AAAAAI"),
    ".trc": ("00 00 02\n", "00 00 ZZ\n"),
}


@pytest.mark.parametrize("suffix", DAMAGE)
def test_a_damaged_line_of_a_text_log_is_skipped_with_its_line_number(tmp_path: Path, suffix: str) -> None:
    """Reading goes on past it, with what the header said (ASC's and TRC's start time, CSV's columns)."""
    path = tmp_path / f"trace{suffix}"
    with can.Logger(path) as logger:
        for i in range(6):
            data = bytes([0x9C, 0, 0, 0, 0, 0, 0, i])
            logger.on_message_received(
                can.Message(timestamp=1000 + i / 1000, arbitration_id=0x141, data=data, is_extended_id=False)
            )
    good = list(read_log(path))
    text = path.read_text()
    line, damaged = DAMAGE[suffix]
    number = text[: text.index(line)].count("\n") + 1
    path.write_text(text.replace(line, damaged))
    met: list[tuple[int, str, str]] = []
    log = read_log(path, on_bad_line=lambda *bad: met.append(bad))
    assert list(log) == good[:2] + good[3:]
    assert log.bad_lines == met and len(met) == 1
    assert met[0][0] == number and damaged.strip() in met[0][1]


@pytest.mark.parametrize(
    ("cut", "why"),
    [("(1.003000) can0 241#9C32640", "odd number of data hex digits"), ("(1.003000) ca", "unpack")],
)
def test_a_candump_line_cut_short_is_a_bad_line(cut: str, why: str) -> None:
    """What a killed candump leaves as its last line (python-can would read ``9C3`` as 9C 03)."""
    lines = "(1.000000) can0 141#9C00000000000000 T\n(1.000400) can0 241#9C326400F4012D00 R\n" + cut
    log = read_log(io.StringIO(lines), name="<stdin>")
    assert len(list(log)) == 2
    assert [(n, text) for n, text, _ in log.bad_lines] == [(3, cut)]
    assert why in log.bad_lines[0][2]
    assert log.name == str(log) == "<stdin>"


def test_bad_lines_are_met_in_order_with_the_frames() -> None:
    lines = "(1.0) can0 141#9C00000000000000\nnot candump\n(2.0) can0 141#9C00000000000000\nx\n"
    events: list[object] = []
    for frame in read_log(io.StringIO(lines), on_bad_line=lambda n, *_: events.append(n)):
        events.append(frame.timestamp)
    assert events == [1.0, 2, 2.0, 4]


def test_a_log_is_named_by_its_path_or_stream(tmp_path: Path) -> None:
    stream = io.StringIO()
    stream.name = "<stdin>"
    assert read_log(stream).name == "<stdin>"
    assert read_log(io.StringIO()).name == "<stream>"
    assert read_log(tmp_path / "x.log").name == str(tmp_path / "x.log")
