"""``servobus decode``: logs (python-can's readers) and frames on the command line, requests and replies
of every family, decoded byte-exactly as the family decoders do; undecodable frames are printed and
counted; bad arguments give one line and exit 2."""

from __future__ import annotations

import json
from pathlib import Path

import can
import pytest
from click.testing import CliRunner

from _cli_run import invoke, one_line_error
from _log_samples import SAMPLES, Sample
from servobus.cli import cli
from servobus.tools.logs import message_values
from servobus.transports.can import message_from_frame

FAMILIES = ("myactuator", "lk", "hollow")


def _records(stdout: str) -> list[dict]:
    return [json.loads(line) for line in stdout.splitlines()]


def _check(record: dict, sample: Sample) -> None:
    assert record["direction"] == sample.direction
    assert record["motor_id"] == sample.motor_id
    assert record["type"] == type(sample.expected).__name__
    assert record["fields"] == message_values(sample.expected)
    assert bytes.fromhex(record["data"]) == sample.frame.data


def _candump(frame: object) -> str:
    ident = f"{frame.arbitration_id:03X}"  # type: ignore[attr-defined]
    data = frame.data.hex().upper()  # type: ignore[attr-defined]
    return f"{ident}##1{data}" if frame.is_fd else f"{ident}#{data}"  # type: ignore[attr-defined]


@pytest.mark.parametrize("family", FAMILIES)
def test_frames_on_the_command_line_decode_both_directions(family: str) -> None:
    samples = [s for s in SAMPLES if s.family == family]
    result = invoke(["decode", "--family", family, "--json", *(_candump(s.frame) for s in samples)])
    records = _records(result.stdout)
    assert len(records) == len(samples)
    for record, sample in zip(records, samples, strict=True):
        _check(record, sample)
    assert result.stderr == f"decode: {len(samples)} frames, {len(samples)} decoded, 0 not decoded\n"


def test_hex_bytes_and_text_output() -> None:
    result = invoke(["decode", "--hex", "241 9C 32 64 00 F4 01 2D 00", "141#9C00000000000000"])
    assert result.stdout.splitlines() == [
        "141#9C00000000000000  request to motor 1: ReadStatus2",
        "241#9C326400F4012D00  reply from motor 1: StatusReply temperature_c=50 current_a=1.0 "
        "speed_dps=500.0 angle_deg=45.0 command=READ_STATUS_2",
    ]


def test_frames_that_do_not_decode_are_printed_and_counted() -> None:
    result = invoke(["decode", "123#0102", "241#9C", "241#9C326400F4012D00"])
    lines = result.stdout.splitlines()
    assert lines[0] == "123#0102  not decoded: 0x123 is no identifier of the myactuator motors"
    assert lines[1].startswith("241#9C  not decoded: StatusReply: expected 8 data bytes, got 1")
    assert "reply from motor 1" in lines[2]
    assert result.stderr == "decode: 3 frames, 1 decoded, 2 not decoded\n"
    result = CliRunner().invoke(cli, ["decode", "--json", "123#0102"])
    records = _records(result.stdout)
    assert records[0]["error"] and "fields" not in records[0]
    assert result.exit_code == 1  # nothing decoded
    assert result.stderr.endswith("1 not decoded: nothing decoded (another --family or --revision?)\n")


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf", ".csv"])
def test_logs_of_every_format_decode(tmp_path: Path, suffix: str) -> None:
    for family in FAMILIES:
        samples = [s for s in SAMPLES if s.family == family and not (s.frame.is_fd and suffix == ".csv")]
        path = tmp_path / f"{family}{suffix}"
        with can.Logger(path) as logger:
            for i, sample in enumerate(samples):
                message = message_from_frame(sample.frame)
                message.timestamp = 1700000000.0 + i / 1000
                message.is_rx = sample.frame.is_rx
                logger.on_message_received(message)
        result = invoke(["decode", "--family", family, "--json", str(path)])
        records = _records(result.stdout)
        assert len(records) == len(samples)
        for record, sample in zip(records, samples, strict=True):
            _check(record, sample)
        assert records[1]["time"] - records[0]["time"] == pytest.approx(0.001, abs=1e-5)  # ASC: relative


def test_candump_lines_on_stdin() -> None:
    lines = "(1.000000) can0 141#9C00000000000000 T\n(1.000400) can0 241#9C326400F4012D00 R\n"
    result = invoke(["decode", "-"], input=lines)
    assert result.stdout.splitlines()[1].startswith("(1.000400) 241#9C326400F4012D00  reply from motor 1")


def test_a_log_recorded_from_the_simulator_decodes(tmp_path: Path) -> None:
    log = tmp_path / "lk.log"
    invoke(["record", "--family", "lk", "--sim", "2", "--duration", "0.1", "--log", str(log)])
    records = _records(invoke(["decode", "--family", "lk", "--json", str(log)]).stdout)
    assert {(r["direction"], r["type"]) for r in records} == {
        ("request", "ReadStatus2"),
        ("reply", "Status2Reply"),
    }
    assert {r["motor_id"] for r in records} == {1, 2}


def _candump_log(path: Path, frames: int) -> list[str]:
    """``frames`` candump lines, requests and replies of motor 1 in turn, written to ``path``."""
    lines = [
        f"({1.0 + i / 1000:.6f}) can0 "
        + ("141#9C00000000000000 T" if i % 2 == 0 else "241#9C326400F4012D00 R")
        for i in range(frames)
    ]
    path.write_text("\n".join(lines) + "\n")
    return lines


def test_a_damaged_line_is_reported_with_its_line_number_and_decoding_goes_on(tmp_path: Path) -> None:
    path = tmp_path / "candump.log"
    lines = _candump_log(path, 1203)
    lines.insert(100, "(1.1) can0 24#zz R")
    path.write_text("\n".join(lines) + "\n")
    result = invoke(["decode", str(path)])  # exit 0: it decoded what it could
    assert len(result.stdout.splitlines()) == 1203
    assert result.stderr.splitlines() == [
        f"decode: {path}:101: not a CAN log line (invalid literal for int() with base 16: 'zz'): "
        "'(1.1) can0 24#zz R'",
        "decode: 1203 frames, 1203 decoded, 0 not decoded, 1 bad line skipped",
    ]


@pytest.mark.parametrize("cut", ["(1.203000) can0 241#9C32640", "(1.203000) ca"])
def test_a_last_line_cut_short_is_reported_and_the_rest_decodes(tmp_path: Path, cut: str) -> None:
    """What a killed candump leaves: its last line cut short, without its newline."""
    path = tmp_path / "candump.log"
    lines = _candump_log(path, 1203)
    path.write_text("\n".join(lines) + "\n" + cut)
    result = invoke(["decode", "--json", str(path)])
    assert len(_records(result.stdout)) == 1203
    assert result.stderr.startswith(f"decode: {path}:1204: not a CAN log line (")
    assert result.stderr.endswith("decode: 1203 frames, 1203 decoded, 0 not decoded, 1 bad line skipped\n")


def test_bad_lines_on_stdin_are_named_stdin() -> None:
    lines = "(1.000000) can0 141#9C00000000000000 T\nnot candump\n(1.000400) can0 241#9C326400F4012D00 R\n"
    result = invoke(["decode", "-"], input=lines)
    assert len(result.stdout.splitlines()) == 2
    assert result.stderr.splitlines()[0].startswith("decode: <stdin>:2: not a CAN log line (")
    assert "TextIOWrapper" not in result.stderr


@pytest.mark.parametrize(
    ("name", "text", "says"),
    [
        ("garbage.asc", "hello world\nthis is garbage\n", "garbage.asc: no CAN frames in it"),
        ("empty.log", "", "empty.log: no CAN frames in it"),
        ("bad.log", "this is not candump\nnor this\n", "bad.log:2: not a CAN log line"),
    ],
)
def test_a_log_with_nothing_to_decode_is_exit_1(tmp_path: Path, name: str, text: str, says: str) -> None:
    path = tmp_path / name
    path.write_text(text)
    result = CliRunner().invoke(cli, ["decode", str(path)])
    assert result.exit_code == 1 and not result.stdout
    assert says in result.stderr and "Traceback" not in result.stderr
    assert result.stderr.splitlines()[-1].endswith(": nothing decoded")


def test_a_log_of_another_family_is_exit_1_with_its_frames_printed(tmp_path: Path) -> None:
    path = tmp_path / "candump.log"
    _candump_log(path, 4)
    result = CliRunner().invoke(cli, ["decode", "--family", "hollow", str(path)])
    assert result.exit_code == 1 and len(result.stdout.splitlines()) == 4
    assert result.stderr == (
        "decode: 4 frames, 0 decoded, 4 not decoded: nothing decoded (another --family or --revision?)\n"
    )


def test_the_help_says_what_decode_does_with_bad_lines_and_its_exit_status() -> None:
    text = " ".join(invoke(["decode", "--help"]).stdout.split())
    assert "reported on stderr with its line number and skipped; decoding goes on" in text
    assert "0 when at least one frame decoded, 1 when none did" in text


def _blf(path: Path, *, damage: str) -> None:
    with can.BLFWriter(str(path)) as writer:
        for i in range(200):
            data = bytes([0x9C, 0, 0, 0, 0, 0, 0, i])
            writer.on_message_received(can.Message(arbitration_id=0x141, data=data, is_extended_id=False))
    raw = bytearray(path.read_bytes())
    if damage == "header":
        raw[:64] = bytes(range(64))
    else:  # the compressed objects after the file header
        raw[200:260] = bytes((7 * i) % 256 for i in range(60))
    path.write_bytes(bytes(raw))


def test_a_blf_with_a_damaged_header_is_one_line_and_exit_1(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """python-can's BLF reader raises its own errors (BLFParseError, zlib.error), not ValueError."""
    path = tmp_path / "trace.blf"
    _blf(path, damage="header")
    err = one_line_error(capsys, ["decode", str(path)], code=1)
    assert "does not parse" in err


def test_a_blf_with_damaged_objects_is_reported_and_decoding_goes_on(tmp_path: Path) -> None:
    """A binary log cannot go on past its damaged part: it ends there, the other sources decode."""
    path = tmp_path / "trace.blf"
    _blf(path, damage="objects")
    result = CliRunner().invoke(cli, ["decode", str(path), "141#9C00000000000000"])
    assert result.exit_code == 0, result.stderr
    first, summary = result.stderr.splitlines()
    assert first.startswith(f"decode: {path}: does not parse as a CAN log after 0 frames (error: Error -3")
    assert summary == "decode: 1 frames, 1 decoded, 0 not decoded, 1 log cut short by a damaged part"


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["decode"], "give a log file"),
        (["decode", "141#9C0"], "is not a frame"),
        (["decode", "--hex", "241 9C3"], "is not a frame"),
        (["decode", "nope.log"], "no such file"),
        (["decode", "--family", "bogus", "141#9C"], "bogus"),
        (["decode", "--ids", "5-1", "141#9C"], "empty"),
        (["decode", "--ids", "40", "--family", "lk", "141#9C"], "motor_id"),
        (["decode", "--revision", "V9", "141#9C"], "no revision"),
        (["decode", "--bogus"], "bogus"),
    ],
)
def test_bad_arguments_are_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str], args: list[str], says: str
) -> None:
    assert says in one_line_error(capsys, args)


def test_a_file_python_can_has_no_reader_for_is_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "trace.txt"
    path.write_text("141#9C00000000000000\n")
    assert str(path) in one_line_error(capsys, ["decode", str(path)])
