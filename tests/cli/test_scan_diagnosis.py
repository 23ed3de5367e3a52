"""[field] case 7: ``servobus scan`` of a bus where nobody answers as the family asked says what it saw
instead, and a wrong family costs about a second, not a timeout per id (32 s before): every id is
probed at once with a short first timeout, the silent ones once more."""

from __future__ import annotations

import re
import time
from typing import Any

import pytest

import servobus.cli._connect as connect
from cli._bus_cli import one_line, pty_simulators, run, run_json
from servobus.bus import Motor
from servobus.cli import scan as scan_cli
from servobus.protocols.lk.sim.device import LkMotor
from servobus.protocols.myactuator.sim.device import MyActuatorMotor

#: what a wrong family may cost at most (the issue's Done-when)
BUDGET_S = 3.0


def _simulate(monkeypatch: pytest.MonkeyPatch, *devices: Any) -> None:
    """``--sim`` builds these devices, whatever the family asked."""
    monkeypatch.setattr(connect, "sim_devices", lambda family, ids, revision=None: list(devices))


def test_an_lk_bus_scanned_as_myactuator_takes_under_3_s_and_names_lk(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    _simulate(monkeypatch, LkMotor(1), LkMotor(2))
    began = time.monotonic()
    err = one_line(capsys, ["scan", "--sim", "2"], code=1)  # ids 1-32, the default family
    took_s = time.monotonic() - began
    assert took_s <= BUDGET_S, took_s
    assert "no myactuator motor answered on ids 1-32" in err
    assert "on 0x181-0x182 answered as lk motors 1-2 (V2_36) would: --family lk?" in err, err


def test_a_silent_bus_says_no_frame_at_all(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    _simulate(monkeypatch)
    began = time.monotonic()
    err = one_line(capsys, ["scan", "--sim", "1"], code=1)
    assert time.monotonic() - began <= BUDGET_S
    assert err.strip().endswith(
        "no myactuator motor answered on ids 1-32; no frame at all: check bitrate, wiring and "
        "termination, or another program on the port"
    ), err


def test_motors_found_are_listed_and_what_else_answered_is_one_line_on_stderr(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    _simulate(monkeypatch, MyActuatorMotor(1), MyActuatorMotor(2), LkMotor(5))
    out, err = run(capsys, ["scan", "--sim", "2", "--ids", "1-8"])
    assert "myactuator" in out
    said = r"also seen: \d+ frames? on 0x185 answered as lk motor 5 \(V2_36\) would: --family lk\?"
    assert re.fullmatch(said, err.strip()), err


def _spy_probes(monkeypatch: pytest.MonkeyPatch) -> list[tuple[int, float | None]]:
    """Every request scan makes, as (motor id, its timeout_s), in order."""
    probes: list[tuple[int, float | None]] = []
    request = Motor.request

    async def spied(self: Motor, command: Any, *, timeout_s: float | None = None, **kwargs: Any) -> Any:
        probes.append((self.motor_id, timeout_s))
        return await request(self, command, timeout_s=timeout_s, **kwargs)

    monkeypatch.setattr(Motor, "request", spied)
    return probes


def test_the_probes_are_short_first_and_the_silent_ids_are_probed_again(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Without --timeout-ms: every id at FIRST_TIMEOUT_S, the silent ones at SECOND_TIMEOUT_S (the
    line answers), then the motors found are asked with the library's timeouts."""
    _simulate(monkeypatch, MyActuatorMotor(1))
    probes = _spy_probes(monkeypatch)
    rows = run_json(capsys, ["scan", "--sim", "1", "--ids", "1-3"])
    assert [r["id"] for r in rows] == [1]
    first, second = scan_cli.FIRST_TIMEOUT_S, scan_cli.SECOND_TIMEOUT_S
    assert probes[:5] == [(1, first), (2, first), (3, first), (2, second), (3, second)]
    assert all(t is None for _, t in probes[5:])


def test_on_a_silent_line_one_id_gets_the_librarys_timeout_before_the_others_their_second_probe(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A fresh adapter's first exchange can be slow: one probe waits the library's timeout (the
    others do not each wait it, as a half-duplex line would have them in turn)."""
    _simulate(monkeypatch)
    probes = _spy_probes(monkeypatch)
    one_line(capsys, ["scan", "--sim", "1", "--ids", "1-3"], code=1)
    first, second = scan_cli.FIRST_TIMEOUT_S, scan_cli.SECOND_TIMEOUT_S
    assert probes == [(1, first), (2, first), (3, first), (1, None), (2, second), (3, second)]


def test_a_motor_slower_than_the_first_probe_is_found_by_the_second(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    _simulate(monkeypatch, MyActuatorMotor(2, turnaround_s=0.15))
    rows = run_json(capsys, ["scan", "--sim", "1", "--ids", "1-3"])
    assert [r["id"] for r in rows] == [2]


def test_through_a_real_pty_an_lk_bus_is_named_within_3_s(capsys: pytest.CaptureFixture[str]) -> None:
    with pty_simulators() as start:
        path = start("--family", "lk", "--motors", "2")
        began = time.monotonic()
        err = one_line(capsys, ["scan", "-i", "servobus-slcan", "-c", path], code=1)
        took_s = time.monotonic() - began
    assert took_s <= BUDGET_S, took_s
    assert "answered as lk motors 1-2 (V2_36) would: --family lk?" in err, err


@pytest.mark.parametrize(
    ("args", "naming"),
    [
        (["scan", "--sim", "1", "--ids", "0-x"], "--ids"),
        (["scan", "--sim", "1", "--timeout-ms", "soon"], "soon"),
    ],
)
def test_bad_arguments_are_still_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str], args: list[str], naming: str
) -> None:
    assert naming in one_line(capsys, args)
