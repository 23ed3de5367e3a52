"""``servobus dbc``: the DBC it writes loads in cantools and decodes a simulator recording (MyActuator,
LK) to the values servobus decodes, every field compared (``_dbc_check.check_frame``); bad arguments are
one line, exit 2; without cantools, one line telling how to install it (exit 1)."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import cantools
import pytest

from _cli_run import invoke, moving_sim, one_line_error
from _dbc_check import check_frame
from servobus.dbc import MessageSpec, Plan, plan
from servobus.frame import Frame
from servobus.logs import FrameDecoder, read_log


def _spec(p: Plan, frame: Frame) -> MessageSpec:
    return next(
        m for m in p.messages if m.frame_id == frame.arbitration_id and m.extended == frame.is_extended_id
    )


def _check_log(
    p: Plan, database: Any, family: str, logs: list[Path]
) -> set[tuple[str | None, str | None, int | None]]:
    decoder = FrameDecoder(family)
    seen = set()
    for frame in (frame for log in logs for frame in read_log(log)):
        ours = decoder.decode(frame)
        assert ours.message is not None, ours.error
        check_frame(_spec(p, frame), database, frame.data, ours.message)
        seen.add((ours.direction, ours.type, ours.motor_id))
    return seen


def test_the_myactuator_dbc_decodes_a_recording_as_servobus_does(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    moving_sim(monkeypatch)
    dbc = tmp_path / "myactuator.dbc"
    result = invoke(["dbc", "--family", "myactuator", "--ids", "1-4", "-o", str(dbc)])
    assert result.stderr.startswith("dbc: 17 messages -> ") and "0xB5" in result.stderr
    logs = [tmp_path / "status2.log", tmp_path / "status1.log"]
    for poll, log in zip(["read_status2", "read_status1"], logs, strict=True):
        invoke(["record", "--sim", "4", "--duration", "0.08", "--poll", poll, "--log", str(log)])
    database = cantools.database.load_file(dbc)
    seen = _check_log(plan("myactuator", range(1, 5)), database, "myactuator", logs)
    assert {(d, t) for d, t, _ in seen} == {
        ("request", "ReadStatus2"),
        ("reply", "StatusReply"),
        ("request", "ReadStatus1"),
        ("reply", "Status1Reply"),
    }
    assert {m for _, _, m in seen} == {1, 2, 3, 4}
    motion = database.get_message_by_name("myactuator_motion_command_3")
    assert motion.frame_id == 0x403 and motion.get_signal_by_name("kd").scale == 50 / 4095


def test_the_lk_dbc_decodes_a_recording_as_servobus_does(tmp_path: Path) -> None:
    dbc = tmp_path / "lk.dbc"
    result = invoke(["dbc", "--family", "lk", "--ids", "1-4", "-o", str(dbc)])
    assert result.stderr.startswith("dbc: 8 messages -> ")
    log = tmp_path / "lk.log"
    invoke(["record", "--family", "lk", "--sim", "4", "--duration", "0.08", "--log", str(log)])
    database = cantools.database.load_file(dbc)
    seen = _check_log(plan("lk", range(1, 5)), database, "lk", [log])
    assert {(d, t) for d, t, _ in seen} == {("request", "ReadStatus2"), ("reply", "Status2Reply")}
    assert {m for _, _, m in seen} == {1, 2, 3, 4}


def test_stdout_and_a_json_summary(tmp_path: Path) -> None:
    text = invoke(["dbc", "--revision", "V4_3"]).stdout
    database = cantools.database.load_string(text, "dbc")
    assert [m.frame_id for m in database.messages] == [0x141, 0x241, 0x401, 0x501, 0x280]
    result = invoke(["dbc", "--ids", "1-2", "--json", "-o", str(tmp_path / "ma.dbc")])
    summary = json.loads(result.stdout)
    assert summary["messages"] == [
        "myactuator_request_1",
        "myactuator_reply_1",
        "myactuator_motion_command_1",
        "myactuator_motion_reply_1",
        "myactuator_request_2",
        "myactuator_reply_2",
        "myactuator_motion_command_2",
        "myactuator_motion_reply_2",
        "myactuator_broadcast",
    ]
    assert any("0xB5" in reason for reason in summary["left_out"])
    assert not any("motion" in reason for reason in summary["left_out"])


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
        (["--family", "bogus"], "bogus"),
        (["--revision", "V9"], "no revision"),
        (["--family", "lk", "--revision", "V4_4"], "no revision"),
        (["--ids", "0-2"], "motor_id"),
        (["--family", "lk", "--ids", "33"], "motor_id"),
        (["--family", "hollow", "--ids", "99-101"], "motor_id"),
        (["--family", "hollow", "--ids", "1-4,100"], "host id"),
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
