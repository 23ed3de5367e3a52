"""Connection mistakes on the command line: each is one line naming what is wrong and what to give,
exit 2, and no bus opened (not python-can's traceback, nor its ``Unknown interface type "None"``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import can
import pytest

import servobus.cli._connect as connect
from _cli_run import one_line_error


@pytest.fixture(autouse=True)
def no_python_can_configuration(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """No ``CAN_*`` variables and no configuration file but ``tmp_path/.canrc`` (returned; absent)."""
    for name in ("CAN_INTERFACE", "CAN_CHANNEL", "CAN_BITRATE", "CAN_CONFIG"):
        monkeypatch.delenv(name, raising=False)
    canrc = tmp_path / ".canrc"
    monkeypatch.setattr(can.util, "CONFIG_FILES", [str(canrc)])

    def opened(*args: Any, **kwargs: Any) -> Any:
        raise AssertionError("a bus was opened for a connection mistake")

    monkeypatch.setattr(connect.Connection, "transport", opened)
    return canrc


COMMANDS = [["status"], ["scan"], ["monitor"], ["stop"], ["record", "--log", "x.log"]]


@pytest.mark.parametrize(("args", "says"), [
    (["-i", "slcan"], "-i slcan needs -c: the adapter's channel (-c /dev/ttyACM0)"),
    ([], "no bus: give --sim N, --interface/--channel"),
    (["-c", "/dev/pts/0"], "-c /dev/pts/0 needs -i: the python-can interface"),
    (["-i", "bogus", "-c", "x"], "-i bogus: python-can has no such interface; one of"),
    (["-i", "servobus-slcan"], "-i servobus-slcan needs the adapter's serial port: -c"),
    (["-i", "virtual", "-c", "x", "--data-bitrate", "2000000"], "--data-bitrate"),
    (["--port", "/dev/ttyUSB0", "--bitrate", "1000000"], "a serial --port takes --baud"),
    (["--sim", "1", "--fd"], "--fd: the simulated myactuator motors speak classic CAN"),
    (["--sim", "1", "-i", "slcan"], "name different buses"),
])  # fmt: skip
@pytest.mark.parametrize("command", COMMANDS, ids=lambda c: c[0])
def test_a_connection_mistake_is_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str], command: list[str], args: list[str], says: str
) -> None:
    err = one_line_error(capsys, [*command, *args])
    assert says in err, err


def test_an_interface_python_can_lacks_in_its_configuration_is_named(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, no_python_can_configuration: Path
) -> None:
    monkeypatch.setenv("CAN_INTERFACE", "bogus")
    assert "names interface 'bogus'" in one_line_error(capsys, ["status"])
    monkeypatch.delenv("CAN_INTERFACE")
    no_python_can_configuration.write_text("[default]\ninterface = bogus\n")
    assert "names interface 'bogus'" in one_line_error(capsys, ["status"])


def test_a_configured_interface_that_needs_a_channel_asks_for_it(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, no_python_can_configuration: Path
) -> None:
    no_python_can_configuration.write_text("[default]\ninterface = slcan\n")
    assert "-i slcan needs -c" in one_line_error(capsys, ["status"])


def test_a_configured_python_can_bus_is_opened(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, no_python_can_configuration: Path
) -> None:
    """Not a mistake: python-can's configuration names the bus (the check lets it through)."""
    no_python_can_configuration.write_text("[default]\ninterface = virtual\nchannel = servobus-test\n")
    with pytest.raises(AssertionError, match="a bus was opened"):
        _main(["status"])


def _main(args: list[str]) -> int:
    from servobus.cli import main

    return main(args)
