"""``servobus dbc``: the DBC it writes loads in cantools and decodes the frames of a simulator recording
to the values servobus decodes; families without field tables and bad arguments are one line, exit 2;
without cantools, one line telling how to install it (exit 1)."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import cantools
import pytest

from _cli_run import invoke, moving_sim, one_line_error
from servobus.dbc import MUX, layouts, signal_names
from servobus.logs import FrameDecoder, read_log


def test_the_dbc_decodes_a_recording_as_servobus_does(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    moving_sim(monkeypatch)
    dbc = tmp_path / "myactuator.dbc"
    result = invoke(["dbc", "--family", "myactuator", "--ids", "1-4", "-o", str(dbc)])
    assert result.stderr.startswith("dbc: 9 messages -> ") and "motion (MIT)" in result.stderr
    logs = [tmp_path / "status2.log", tmp_path / "status1.log"]
    for poll, log in zip(["read_status2", "read_status1"], logs, strict=True):
        invoke(["record", "--sim", "4", "--duration", "0.08", "--poll", poll, "--log", str(log)])
    database = cantools.database.load_file(dbc)
    requests, replies, _ = layouts("myactuator")
    tables = {"request": (requests, signal_names(requests)), "reply": (replies, signal_names(replies))}
    decoder = FrameDecoder("myactuator")
    seen = set()
    for frame in (frame for log in logs for frame in read_log(log)):
        ours = decoder.decode(frame)
        theirs = database.decode_message(frame.arbitration_id, frame.data)
        table, names = tables[ours.direction or ""]
        layout = next(t for t in table if t.code == frame.data[0])
        assert str(theirs[MUX]) == layout.name == ours.type
        values = ours.values()
        for spec in layout.signals:
            value = theirs[names[spec][0]]
            if spec.choices:
                assert str(value) == str(values[spec.field])
            else:
                assert math.isclose(value, values[spec.field], rel_tol=1e-12, abs_tol=1e-12)
        seen.add((ours.direction, ours.type, ours.motor_id))
    assert {(d, t) for d, t, _ in seen} == {
        ("request", "ReadStatus2"),
        ("reply", "StatusReply"),
        ("request", "ReadStatus1"),
        ("reply", "Status1Reply"),
    }
    assert {m for _, _, m in seen} == {1, 2, 3, 4}


def test_stdout_and_a_json_summary(tmp_path: Path) -> None:
    text = invoke(["dbc", "--revision", "V4_3"]).stdout
    database = cantools.database.load_string(text, "dbc")
    assert [m.frame_id for m in database.messages] == [0x141, 0x241, 0x280]
    result = invoke(["dbc", "--ids", "1-2", "--json", "-o", str(tmp_path / "ma.dbc")])
    summary = json.loads(result.stdout)
    assert summary["messages"] == [
        "myactuator_request_1",
        "myactuator_reply_1",
        "myactuator_request_2",
        "myactuator_reply_2",
        "myactuator_broadcast",
    ]
    assert any("0xB5" in reason for reason in summary["left_out"])


def test_without_cantools_one_line_says_how_to_install(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setitem(sys.modules, "cantools", None)
    err = one_line_error(capsys, ["dbc", "-o", str(tmp_path / "x.dbc")], code=1)
    assert "pip install 'servobus[dbc]'" in err
    assert not (tmp_path / "x.dbc").exists()


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["--family", "lk"], "lk has none"),
        (["--family", "hollow"], "hollow has none"),
        (["--family", "bogus"], "bogus"),
        (["--revision", "V9"], "no revision"),
        (["--ids", "0-2"], "motor_id"),
        (["--ids", "x"], "--ids"),
        (["--json"], "give -o"),
        (["-o", "exists.dbc"], "exists"),
    ],
)
def test_bad_arguments_are_one_line_and_exit_2(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    args: list[str],
    says: str,
) -> None:
    monkeypatch.chdir(tmp_path)
    Path("exists.dbc").write_text("mine")
    assert says in one_line_error(capsys, ["dbc", *args])
    assert Path("exists.dbc").read_text() == "mine"
