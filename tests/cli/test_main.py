"""The ``servobus`` command as a whole, for the bus commands: every one has --help with examples, bad
usage is one line and exit 2 (a traceback only with --debug), the exit code of a delegated server
comes through, and click's shell completion works (``_SERVOBUS_COMPLETE``)."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from cli._bus_cli import one_line, run
from servobus.cli import cli, main

BUS_COMMANDS = [
    ["demo"],
    ["scan"],
    ["status"],
    ["monitor"],
    ["move"],
    ["speed"],
    ["torque"],
    ["mit"],
    ["stop"],
    ["off"],
    ["brake"],
    ["zero"],
    ["set-id"],
    ["clear-errors"],
    ["reset"],
    ["config"],
    ["config", "list"],
    ["config", "get"],
    ["config", "set"],
    ["sim"],
    ["bench"],
]


@pytest.mark.parametrize("command", BUS_COMMANDS, ids=" ".join)
def test_every_bus_command_has_help_with_examples(
    capsys: pytest.CaptureFixture[str], command: list[str]
) -> None:
    out, _ = run(capsys, [*command, "--help"])
    assert "Examples:" in out and f"servobus {command[0]}" in out.split("Examples:")[1]


@pytest.mark.parametrize(
    "command",
    [
        c
        for c in BUS_COMMANDS
        if c[0] not in ("demo", "sim", "bench", "config") or c[1:] in (["get"], ["set"])
    ],
)
def test_bus_commands_take_the_connection_options(
    capsys: pytest.CaptureFixture[str], command: list[str]
) -> None:
    out, _ = run(capsys, [*command, "--help"])
    for option in ("--sim", "--interface", "--channel", "--port", "--family", "--ids"):
        assert option in out, option


def test_usage_errors_are_one_line_and_a_traceback_only_with_debug(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert "No such command" in one_line(capsys, ["frobnicate"])
    assert "speed_dps" in one_line(capsys, ["speed", "--sim", "1", "--speed-dps", "1e9"])
    with pytest.raises(ValueError, match="speed_dps"):
        main(["--debug", "speed", "--sim", "1", "--speed-dps", "1e9"])


def test_shell_completion_offers_the_subcommands() -> None:
    result = CliRunner().invoke(
        cli,
        [],
        prog_name="servobus",
        env={"_SERVOBUS_COMPLETE": "bash_complete", "COMP_WORDS": "servobus st", "COMP_CWORD": "1"},
    )
    assert result.exit_code == 0
    assert {"plain,status", "plain,stop"} <= set(result.output.split())
    script = CliRunner().invoke(cli, [], prog_name="servobus", env={"_SERVOBUS_COMPLETE": "bash_source"})
    assert script.exit_code == 0 and "_servobus_completion" in script.output
