"""``servobus record`` against the simulator: telemetry rows and a candump log that ``decode`` reads back
to the same values; existing files are never overwritten without --force, and on an error only the
files record created are removed."""

from __future__ import annotations

import csv
import itertools
import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import servobus.cli._connect as connect
from _cli_run import invoke, moving_sim, one_line_error


def _replies_by_motor(records: list[dict]) -> dict[int, list[dict]]:
    out: dict[int, list[dict]] = {}
    for record in records:
        if record.get("direction") == "reply":
            out.setdefault(record["motor_id"], []).append(record)
    return out


def test_the_candump_log_decodes_to_the_telemetry_values(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    moving_sim(monkeypatch)
    telemetry, log = tmp_path / "run.jsonl", tmp_path / "run.log"
    result = invoke(["record", "--sim", "3", "--duration", "0.3", "-o", str(telemetry), "--log", str(log)])
    assert result.stderr.startswith("record: ") and "0 timeouts" in result.stderr
    rows = [json.loads(line) for line in telemetry.read_text().splitlines()]
    decoded = [json.loads(line) for line in invoke(["decode", "--json", str(log)]).stdout.splitlines()]
    assert {r["direction"] for r in decoded} == {"request", "reply"}  # the log keeps both (T/R)
    assert all(r["type"] == "ReadStatus2" for r in decoded if r["direction"] == "request")
    replies = _replies_by_motor(decoded)
    assert sorted(replies) == [1, 2, 3]
    for motor, records in replies.items():
        mine = [row for row in rows if row["motor_id"] == motor]
        assert len(mine) == len(records) >= 10  # ~100 Hz for 0.3 s
        for row, record in zip(mine, records, strict=True):
            assert row["family"] == "myactuator" and row["reply"] == record["type"] == "StatusReply"
            fields = {k: v for k, v in row.items() if k not in ("time_s", "motor_id", "family", "reply")}
            assert fields == record["fields"]
        # one clock: the rows' times and the log's stamps advance together
        row_steps = [b["time_s"] - a["time_s"] for a, b in itertools.pairwise(mine)]
        log_steps = [b["time"] - a["time"] for a, b in itertools.pairwise(records)]
        assert row_steps == pytest.approx(log_steps, abs=3e-6)
    speeds = {row["motor_id"]: row["speed_dps"] for row in rows[-3:]}
    assert speeds == {1: 90.0, 2: 180.0, 3: 270.0}  # the motors turn: the values are not all 0


def test_csv_telemetry_has_units_in_the_column_names(tmp_path: Path) -> None:
    path = tmp_path / "run.csv"
    invoke(["record", "--sim", "2", "--duration", "0.15", "-o", str(path), "--hz", "50"])
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == [
        "time_s",
        "motor_id",
        "family",
        "reply",
        "temperature_c",
        "current_a",
        "speed_dps",
        "angle_deg",
        "command",
    ]
    assert {row["motor_id"] for row in rows} == {"1", "2"}
    assert 8 <= len(rows) <= 20  # 50 Hz, 2 motors, 0.15 s


def test_another_poll_command(tmp_path: Path) -> None:
    path = tmp_path / "status1.jsonl"
    invoke(["record", "--sim", "1", "--duration", "0.1", "--poll", "read_status1", "-o", str(path)])
    row = json.loads(path.read_text().splitlines()[0])
    assert row["reply"] == "Status1Reply" and "voltage_v" in row and "errors" in row


def test_an_existing_file_is_kept_unless_force(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "run.csv"
    path.write_text("precious\n")
    args = ["record", "--sim", "1", "--duration", "0.05", "-o", str(path)]
    assert "exists" in one_line_error(capsys, args)
    assert path.read_text() == "precious\n"
    invoke([*args, "--force"])
    assert path.read_text().startswith("time_s,")


def test_on_an_error_only_the_files_record_created_are_removed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(connect, "sim_devices", lambda *args: [])  # nobody answers
    new, old = tmp_path / "new.csv", tmp_path / "old.log"
    old.write_text("(0.0) can0 141#00 T\n")
    args = ["record", "--sim", "1", "--duration", "0.1", "-o", str(new), "--log", str(old), "--force"]
    assert "no motor answered read_status2" in one_line_error(capsys, args, code=1)
    assert not new.exists()
    assert old.read_text() == "(0.0) can0 141#00 T\n"  # --force replaces it only with a kept recording
    assert "no motor answered" in one_line_error(
        capsys, ["record", "--sim", "1", "--duration", "0.05", "--log", str(tmp_path / "x.log")], code=1
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.log"]


def test_ctrl_c_ends_the_recording_with_whole_files(tmp_path: Path) -> None:
    """Without --duration Ctrl-C is how a recording ends (exit 0); with one it cuts it short (130).
    Either way the files are kept, whole, and the summary is printed."""
    script = "import sys; from servobus.cli import main; sys.exit(main())"
    runs = {}
    for name, extra in (("open", []), ("timed", ["--duration", "30"])):
        args = [
            "record",
            "--sim",
            "2",
            "-o",
            str(tmp_path / f"{name}.csv"),
            "--log",
            str(tmp_path / f"{name}.log"),
        ]
        runs[name] = subprocess.Popen(
            [sys.executable, "-c", script, *args, *extra],
            stderr=subprocess.PIPE,
            text=True,
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
        )
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline and not all(
        (tmp_path / f"{name}.csv").exists() and (tmp_path / f"{name}.csv").stat().st_size > 500
        for name in runs
    ):
        time.sleep(0.05)
    for process in runs.values():
        process.send_signal(signal.SIGINT)
    results = {name: (p.wait(timeout=20), p.stderr.read() if p.stderr else "") for name, p in runs.items()}
    assert results["open"][0] == 0 and results["timed"][0] == 130
    for name, (_, err) in results.items():
        assert "(interrupted)" in err.splitlines()[0]
        lines = (tmp_path / f"{name}.csv").read_text().splitlines()
        assert len(lines) > 5 and all(len(line.split(",")) == 9 for line in lines)
        decoded = invoke(["decode", str(tmp_path / f"{name}.log")])
        assert " 0 not decoded" in decoded.stderr


@pytest.mark.parametrize(
    ("args", "says"),
    [
        ([], "nothing to write"),
        (["-o", "x.txt"], ".csv or .jsonl"),
        (["--log", "x.asc"], "candump .log"),
        (["-o", "x.csv", "--hz", "0"], "--hz"),
        (["-o", "x.csv", "--duration", "-1"], "--duration"),
        (["-o", "x.csv", "--poll", "bogus"], "bogus is not a command"),
        (["-o", "x.csv", "--poll", "motor_stop"], "not a read"),
        (["-o", "x.csv", "--family", "hollow"], "no read to poll"),
        (["-o", "x.csv", "--sim", "40"], "between 1 and 32"),
        (["-o", "x.csv", "--ids", "3-1"], "empty"),
        (["-o", "x.csv", "--format", "xml"], "xml"),
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
    full = ["record", "--duration", "0.05", *args]
    if "--sim" not in args:
        full += ["--sim", "1"]
    assert says in one_line_error(capsys, full)
    assert list(tmp_path.iterdir()) == []  # nothing was created
