"""``servobus scan`` against the simulator: the motors that answer, with revision, model (0xB5),
firmware date (0xB2), state and errors; a V4.3 motor is recognised by its firmware date."""

from __future__ import annotations

from typing import Any

import pytest

import servobus.cli._connect as connect
from cli._bus_cli import one_line, pty_simulators, run, run_json
from servobus.protocols.myactuator import Revision
from servobus.protocols.myactuator.sim.device import MyActuatorMotor


def test_scan_lists_the_motors_that_answer(capsys: pytest.CaptureFixture[str]) -> None:
    rows = run_json(capsys, ["scan", "--sim", "3"])  # probes 1-32; the simulator has 1-3
    assert [r["id"] for r in rows] == [1, 2, 3]
    for row in rows:
        assert row["family"] == "myactuator" and row["revision"] == "V4_4"
        assert row["model"] and row["firmware"].isdigit() and row["state"] and row["errors"] == []
    out, _ = run(capsys, ["scan", "--sim", "2", "--ids", "1-4"])
    assert "firmware" in out and "model" in out


def test_a_v43_motor_is_told_by_its_firmware_date(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    def v43(family: str, ids: tuple[int, ...], revision: str | None = None) -> list[Any]:
        return [MyActuatorMotor(i, revision=Revision.V4_3) for i in ids]

    monkeypatch.setattr(connect, "sim_devices", v43)
    rows = run_json(capsys, ["scan", "--sim", "2", "--ids", "1-2"])
    assert [r["revision"] for r in rows] == ["V4_3", "V4_3"] and all(r["model"] for r in rows)


def test_lk_motors_report_state_and_errors(capsys: pytest.CaptureFixture[str]) -> None:
    rows = run_json(capsys, ["scan", "--family", "lk", "--sim", "2", "--ids", "1-3"])
    assert [(r["id"], r["revision"], r["state"], r["errors"]) for r in rows] == [
        (1, "V2_36", "ON", []),
        (2, "V2_36", "ON", []),
    ]


def test_scan_through_a_real_pty(capsys: pytest.CaptureFixture[str]) -> None:
    with pty_simulators() as start:
        path = start("--family", "myactuator", "--motors", "2", "--first-id", "5")
        rows = run_json(capsys, ["scan", "-i", "servobus-slcan", "-c", path, "--ids", "4-6"])
    assert [r["id"] for r in rows] == [5, 6]


def test_nobody_answering_is_one_line_and_exit_1(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(connect, "sim_devices", lambda family, ids, revision=None: [])
    assert "no myactuator motor answered on ids 1-3" in one_line(
        capsys, ["scan", "--sim", "1", "--ids", "1-3"], 1
    )


@pytest.mark.parametrize(
    ("args", "naming"),
    [
        (["scan", "--family", "hollow", "--sim", "1"], "hollow motors have no status"),
        (["scan", "--sim", "1", "--ids", "x"], "--ids"),
        (["scan", "--family", "nope"], "--family"),
    ],
)
def test_bad_arguments_are_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str], args: list[str], naming: str
) -> None:
    assert naming in one_line(capsys, args)
