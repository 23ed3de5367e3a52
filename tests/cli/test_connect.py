"""Connection mistakes on the command line: each is one line naming what is wrong and what to give,
exit 2, and no bus opened (not python-can's traceback, nor its ``Unknown interface type "None"``)."""

from __future__ import annotations

import dataclasses
from importlib.metadata import EntryPoint
from pathlib import Path
from typing import Any

import can
import pytest

import servobus.cli._connect as connect
from _cli_run import one_line_error
from servobus import _plugins
from servobus.protocols import ENTRY_POINT_GROUP, get_family


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
    found = [EntryPoint("bare", f"{__name__}:BARE", ENTRY_POINT_GROUP)]  # a plug-in family, by entry point
    monkeypatch.setattr(_plugins, "entry_points", lambda group: found if group == ENTRY_POINT_GROUP else [])
    return canrc


#: a family a plug-in registers, without a simulator part (its codec is LK's under another name)
BARE = dataclasses.replace(get_family("lk"), name="bare", parts={}, package=None)


COMMANDS = [["status"], ["scan"], ["monitor"], ["stop"], ["record", "--log", "x.log"]]


@pytest.mark.parametrize(("args", "says"), [
    (["-i", "slcan"], "-i slcan needs -c: the adapter's channel (-c /dev/ttyACM0)"),
    ([], "no bus: give --sim N, --interface/--channel"),
    (["-c", "/dev/pts/0"], "-c /dev/pts/0 needs -i: the python-can interface"),
    (["-i", "bogus", "-c", "x"], "-i bogus: python-can has no such interface; one of"),
    (["-i", "servobus-slcan"], "-i servobus-slcan needs the adapter's serial port: -c"),
    (["-i", "virtual", "-c", "x", "--data-bitrate", "2000000"], "--data-bitrate"),
    (["--port", "/dev/ttyUSB0", "--bitrate", "1000000"], "a serial --port takes --baud"),
    (["--sim", "1", "--fd"], "myactuator motors speak classic CAN only (CAN FD: --family hollow)"),
    (["--sim", "1", "--family", "lk", "--fd"], "--fd: the simulated lk motors speak classic CAN only"),
    (["--sim", "1", "--family", "bare"], "--sim: the bare family has no sim part"),
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


def test_the_family_choices_are_the_registry_s_read_when_asked() -> None:
    """The built-ins in registry order, then the plug-ins' (here ``bare``, by entry point)."""
    assert connect.FamilyChoice().choices == ("myactuator", "lk", "hollow", "bare")


def test_the_in_process_simulator_builds_the_family_s_devices() -> None:
    motors = connect.sim_devices("lk", (3, 4), "v2.35")
    assert [(m.motor_id, m.model.revision.name) for m in motors] == [(3, "V2_35"), (4, "V2_35")]
    assert [m.fd_enabled for m in connect.sim_devices("hollow", (1,), fd=True)] == [True]
    with pytest.raises(ValueError, match="--sim: the bare family has no sim part"):
        connect.sim_devices("bare", (1,))
