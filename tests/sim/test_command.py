"""One click command for the simulator: ``servobus sim`` and ``python -m servobus.sim`` are the same."""

from __future__ import annotations

import pytest

from servobus.cli import main as servobus
from servobus.cli.sim import sim as cli_sim
from servobus.sim import command


def test_servobus_sim_is_the_simulators_own_command() -> None:
    assert cli_sim is command.sim


@pytest.mark.parametrize(
    ("args", "line"),
    [
        (["--family", "lk", "--slcan", "--rs485"], "servobus.sim: error: --rs485: not allowed with --slcan"),
        (["--family", "lk", "--motors", "0"], "servobus.sim: error: --motors 0: need at least 1 motor"),
        (["--motors", "2"], "servobus.sim: error: Missing option '--family'."),
    ],
)
def test_a_bad_argument_is_one_line_and_status_2_under_both_names(
    capsys: pytest.CaptureFixture[str], args: list[str], line: str
) -> None:
    assert command.main(args) == 2
    assert capsys.readouterr() == ("", line + "\n")
    assert servobus(["sim", *args]) == 2
    assert capsys.readouterr() == ("", line + "\n")


def test_help_under_both_names_lists_the_same_options(capsys: pytest.CaptureFixture[str]) -> None:
    assert command.main(["-h"]) == 0
    direct = capsys.readouterr().out
    assert servobus(["sim", "--help"]) == 0
    nested = capsys.readouterr().out
    assert direct.startswith("Usage: python -m servobus.sim [OPTIONS]")
    assert nested.startswith("Usage: servobus sim [OPTIONS]")
    for option in (
        "--family",
        "--motors",
        "--first-id",
        "--slcan",
        "--rs485",
        "--baud",
        "--revision",
        "--fd",
        "--modbus",
        "--link",
    ):
        assert option in direct and option in nested
    assert direct.split("\n", 1)[1] == nested.split("\n", 1)[1]
