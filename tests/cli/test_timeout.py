"""``--timeout-ms`` on every bus command: each request the command makes waits that long for its reply
(``timeout_s`` of ``Motor.request`` and ``Bus.cycle``); without it the library picks. A value out of
range, or no number, is one line and exit 2 with nothing opened."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from cli._bus_cli import Devices, keep_devices, one_line, run
from servobus.bus import Bus, Motor


@pytest.fixture
def timeouts(monkeypatch: pytest.MonkeyPatch) -> list[float | None]:
    """The ``timeout_s`` of every ``Motor.request`` and ``Bus.cycle`` call the command makes."""
    seen: list[float | None] = []
    request: Callable[..., Any] = Motor.request
    cycle: Callable[..., Any] = Bus.cycle

    async def spied_request(self: Motor, *args: Any, **kwargs: Any) -> Any:
        seen.append(kwargs.get("timeout_s"))
        return await request(self, *args, **kwargs)

    async def spied_cycle(self: Bus, *args: Any, **kwargs: Any) -> Any:
        seen.append(kwargs.get("timeout_s"))
        return await cycle(self, *args, **kwargs)

    monkeypatch.setattr(Motor, "request", spied_request)
    monkeypatch.setattr(Bus, "cycle", spied_cycle)
    return seen


#: every command that talks to motors through a Bus, as a run against the simulator
BUS_RUNS = {
    "status": ["status", "--sim", "2"],
    "monitor": ["monitor", "--sim", "2", "--rate-hz", "50", "--duration", "0.1"],
    "scan": ["scan", "--sim", "2", "--ids", "1-2"],
    "speed": ["speed", "--sim", "2", "--speed-dps", "30", "--duration", "0.1"],
    "speed --keep": ["speed", "--sim", "1", "--speed-dps", "30", "--keep"],
    "move": ["move", "--sim", "1", "--angle-deg", "1", "--duration", "0.2"],
    "torque": ["torque", "--sim", "1", "--current-a", "0.1", "--duration", "0.1"],
    "mit": ["mit", "--sim", "1", "--position-rad", "0.1", "--kp", "5", "--kd", "1", "--duration", "0.1"],
    "stop": ["stop", "--sim", "2"],
    "off": ["off", "--sim", "1"],
    "brake": ["brake", "--sim", "1", "--release"],
    "zero": ["zero", "--sim", "1", "--yes"],
    "set-id": ["set-id", "--sim", "1", "--ids", "1", "5", "--yes"],
    "clear-errors": ["clear-errors", "--family", "lk", "--sim", "1"],
    "reset": ["reset", "--sim", "1"],
    "config get": ["config", "get", "--sim", "1", "pid.speed_kp"],
    "config set": ["config", "set", "--sim", "1", "pid.speed_kp", "0.25"],
    "record": ["record", "--sim", "1", "--duration", "0.1"],  # (+ --log in the test's folder)
    "demo": ["demo", "--motors", "2", "--hz", "100", "--duration", "0.1"],
}


def _args(name: str, tmp_path: Path) -> list[str]:
    return BUS_RUNS[name] + (["--log", str(tmp_path / "frames.log")] if name == "record" else [])


@pytest.mark.parametrize("name", list(BUS_RUNS))
def test_timeout_ms_reaches_every_request_of_every_bus_command(
    capsys: pytest.CaptureFixture[str], timeouts: list[float | None], tmp_path: Path, name: str
) -> None:
    run(capsys, [*_args(name, tmp_path), "--timeout-ms", "150"])
    assert timeouts and all(t == pytest.approx(0.15) for t in timeouts), timeouts


@pytest.mark.parametrize(
    "name", ["status", "speed", "record"]
)  # (scan's first probe is short: test_scan_diagnosis)
def test_without_timeout_ms_the_library_picks(
    capsys: pytest.CaptureFixture[str], timeouts: list[float | None], tmp_path: Path, name: str
) -> None:
    run(capsys, _args(name, tmp_path))
    assert timeouts and all(t is None for t in timeouts), timeouts


def test_a_timeout_shorter_than_the_reply_fails_the_request_and_says_so(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """End to end: the simulated motors answer after 0.2 ms, so 0.1 ms is too short, 100 ms is not."""
    err = one_line(capsys, ["status", "--sim", "2", "--timeout-ms", "0.1"], code=1)
    assert "2 of 2 motors failed" in err and "no reply within 100 µs" in err
    run(capsys, ["status", "--sim", "2", "--timeout-ms", "100"])


@pytest.mark.parametrize("value", ["0", "-5", "0.01", "10001", "1e9", "inf", "nan", "soon"])
def test_a_bad_timeout_is_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, value: str
) -> None:
    devices: Devices = keep_devices(monkeypatch)
    assert "--timeout-ms" in one_line(capsys, ["status", "--sim", "1", "--timeout-ms", value], code=2)
    assert not devices.made  # refused before a bus was opened


@pytest.mark.parametrize("name", list(BUS_RUNS))
def test_every_bus_command_refuses_a_zero_timeout(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path, name: str
) -> None:
    devices: Devices = keep_devices(monkeypatch)
    err = one_line(capsys, [*_args(name, tmp_path), "--timeout-ms", "0"], code=2)
    assert "--timeout-ms" in err and "0.1<=x<=10000" in err
    assert not devices.made
