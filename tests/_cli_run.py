"""Running ``servobus`` subcommands in tests: through click's runner, and through ``main`` for the
one-line errors and exit codes."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import pytest
from click.testing import CliRunner, Result

import servobus.cli._connect as connect
from servobus.cli import cli, main
from servobus.protocols import myactuator as ma


def invoke(args: Sequence[str], **kwargs: Any) -> Result:
    """``servobus ARGS`` through click's runner; the exit code checked to be 0."""
    result = CliRunner().invoke(cli, list(args), **kwargs)
    assert result.exit_code == 0, (result.output, result.stderr, result.exception)
    return result


def one_line_error(capsys: pytest.CaptureFixture[str], args: Sequence[str], code: int = 2) -> str:
    """``servobus ARGS`` through ``main``: exit ``code`` and exactly one line on stderr (returned)."""
    capsys.readouterr()
    assert main(list(args)) == code
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1, err
    assert err.endswith("\n") and "Traceback" not in err
    return err


def moving_sim(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make ``--sim`` MyActuator motors turn (motor N at N x 90 dps) so recorded values are not all 0."""
    real = connect.sim_devices

    def devices(family: str, ids: tuple[int, ...], revision: str | None = None) -> list[Any]:
        made = real(family, ids, revision)
        if family == "myactuator":
            for device in made:
                device.handle(ma.SpeedControl(speed_dps=90.0 * device.motor_id), 0.0)
        return made

    monkeypatch.setattr(connect, "sim_devices", devices)
