"""The ``servobus`` command as a whole, for the bus commands: every one has --help with examples, bad
usage is one line and exit 2 (a traceback only with --debug), the exit code of a delegated server
comes through, and click's shell completion works (``_SERVOBUS_COMPLETE``)."""

from __future__ import annotations

import signal
import subprocess
import time

import pytest
from click.testing import CliRunner

from cli._bus_cli import SERVOBUS, one_line, run
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


def _interrupted(args: list[str], after_s: float) -> tuple[int, list[str]]:
    """``servobus ARGS`` in its own process, Ctrl-C after ``after_s``: (exit code, stderr lines)."""
    process = subprocess.Popen(
        [*SERVOBUS, *args],
        stdin=subprocess.PIPE,  # held open: decode - waits on it
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),  # (not ignored in a background job)
    )
    time.sleep(after_s)
    process.send_signal(signal.SIGINT)
    _, err = process.communicate(timeout=20)
    return process.returncode, err.strip().splitlines()


@pytest.mark.parametrize(
    "args", [["monitor", "--sim", "1", "--json"], ["decode", "-"]], ids=["reads only", "no bus"]
)
def test_ctrl_c_claims_no_stop_where_no_motor_was_commanded(args: list[str]) -> None:
    code, err = _interrupted(args, after_s=3.0)
    assert code == 130 and err[-1] == "servobus: interrupted", err


def test_the_interrupted_line_names_the_motors_the_stop_did_not_reach_or_that_did_not_answer_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import servobus.cli

    monkeypatch.setattr(
        servobus.cli,
        "SAFE_EXITS",
        [("can0", "lk", "stop", (1, 5, 6), (7, 8), (2, 3)), ("sim", "lk", "off", (4,), (), ())],
    )
    assert servobus.cli._interrupted() == (
        "servobus: interrupted; stop sent to lk motors 1, 5, 6 on can0"
        "; stop sent to lk motors 7, 8 on can0, NOT acknowledged"
        "; stop NOT sent to lk motors 2, 3 on can0; off sent to lk motor 4 on sim"
    )
