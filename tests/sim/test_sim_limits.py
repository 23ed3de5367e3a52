"""``servobus sim --limits FILE``: the simulated drives keep the file's speed and current, whoever
commands them (here a Bus without limits of its own, through the SLCAN adapter on a pty); a bad file
is one line and exit 2."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import anyio
import pytest

from servobus import Bus
from servobus.limits import load
from servobus.protocols import myactuator as ma
from servobus.sim import command
from servobus.sim.attach import serve_slcan
from servobus.sim.corenet import CoreCanNetwork
from servobus.sim.family import SimOptions
from servobus.sim.pty import PtyPort
from servobus.transports import SlcanTransport

pytestmark = pytest.mark.anyio


@pytest.fixture
def anyio_backend() -> str:
    return "asyncio"


@pytest.mark.parametrize(
    ("text", "line"),
    [
        ("[all]\nspeed = 1\n", "unknown limit 'speed'"),
        ("[all\n", "not TOML"),
    ],
)
def test_a_bad_limits_file_is_one_line_and_status_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, line: str
) -> None:
    path = tmp_path / "limits.toml"
    path.write_text(text)
    assert command.main(["--family", "myactuator", "--limits", str(path)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.startswith(f"servobus.sim: error: --limits {path}: ") and line in err
    assert err.count("\n") == 1
    assert command.main(["--family", "myactuator", "--limits", str(tmp_path / "none.toml")]) == 2
    assert "No such file" in capsys.readouterr().err


async def test_the_served_drives_keep_the_file_s_envelope_over_a_pty(tmp_path: Path) -> None:
    path = tmp_path / "limits.toml"
    path.write_text("[all]\ncurrent_a = 2.0\n[motor.1]\nspeed_dps = 90\n")
    served = command.check("myactuator", SimOptions(), 1, 2, None, None)

    setup = command.build(dataclasses.replace(served, limits=load(path)))
    port = PtyPort()
    try:
        async with anyio.create_task_group() as group:
            group.start_soon(serve_slcan, CoreCanNetwork(setup.can_devices), port)
            async with Bus(SlcanTransport(port.path, bitrate=1_000_000)) as bus:
                one, two = bus.motor(ma.FAMILY, 1), bus.motor(ma.FAMILY, 2)
                await one.read_status2(timeout_s=0.5)
                for _ in range(60):
                    await bus.cycle(
                        [(m, ma.SpeedControl(speed_dps=400.0)) for m in (one, two)], timeout_s=0.2
                    )
                    await anyio.sleep(0.01)
                first, second = await one.read_status2(), await two.read_status2()
                assert first.speed_dps == pytest.approx(90.0, abs=4.0)
                assert second.speed_dps > 300.0
                await one.torque_control(current_a=10.0)
                await anyio.sleep(0.05)
                assert abs((await one.read_status2()).current_a) <= 2.0 + 0.02
            group.cancel_scope.cancel()
    finally:
        port.close()
