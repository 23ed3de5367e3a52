"""A command line that helps (issue 41): "did you mean" for a mistyped command or option, ``--help``
in groups (the command's own options, then Connection, then Remote), ``--debug`` on every command,
durations in ms, and one rule for ``--sim N`` and ``--ids``."""

from __future__ import annotations

import re
import shlex
import subprocess
import uuid
from pathlib import Path

import click
import pytest

from cli._bus_cli import SERVOBUS, keep_devices, one_line, run, run_json
from servobus.cli import COMMANDS, cli
from servobus.cli._connect import SIM_RULE

# ---- did you mean ----


def _commands() -> list[list[str]]:
    """Every command and subcommand, as the words that name it."""
    ctx = click.Context(cli)
    named: list[list[str]] = []
    for name in sorted(COMMANDS):
        command = cli.get_command(ctx, name)
        named.append([name])
        if isinstance(command, click.Group):
            named += [[name, sub] for sub in command.commands]
    return named


def _with_ids() -> list[list[str]]:
    """The commands that take ``--ids``."""
    ctx = click.Context(cli)
    found = []
    for words in _commands():
        command: click.Command | None = cli.get_command(ctx, words[0])
        for sub in words[1:]:
            assert isinstance(command, click.Group)
            command = command.commands[sub]
        assert command is not None
        if any("--ids" in param.opts for param in command.params):
            found.append(words)
    return found


@pytest.mark.parametrize(
    ("args", "said"),
    [
        (["scna"], "servobus: error: No such command 'scna'. Did you mean 'scan'?"),
        (["statsu"], "servobus: error: No such command 'statsu'. Did you mean 'status'?"),
        (["config", "lsit"], "servobus config: error: No such command 'lsit'. Did you mean 'list'?"),
        (["--verson"], "servobus: error: No such option '--verson'. Did you mean '--version'?"),
        (
            ["move", "--sim", "1", "--angle", "3"],
            "servobus move: error: No such option '--angle'. Did you mean '--angle-deg'?",
        ),
        (  # (a tie with --bitrate: the name the word begins wins)
            ["move", "--sim", "1", "--rate", "3", "--angle-deg", "3"],
            "servobus move: error: No such option '--rate'. Did you mean '--rate-hz'?",
        ),
        (["frobnicate"], "servobus: error: No such command 'frobnicate'."),
        (["scan", "--xyzzy"], "servobus scan: error: No such option '--xyzzy'."),
    ],
)
def test_a_mistyped_name_is_one_line_with_the_closest_name(
    capsys: pytest.CaptureFixture[str], args: list[str], said: str
) -> None:
    assert one_line(capsys, args) == said + "\n"


@pytest.mark.parametrize("command", _with_ids(), ids=" ".join)
def test_every_command_taking_ids_suggests_it(capsys: pytest.CaptureFixture[str], command: list[str]) -> None:
    said = one_line(capsys, [*command, "--idz", "3"])
    assert said == f"servobus {' '.join(command)}: error: No such option '--idz'. Did you mean '--ids'?\n"


def test_the_commands_taking_ids_are_the_bus_commands() -> None:
    # (the parametrisation above is not empty by accident: a subcommand of a group is there too)
    assert {"scan", "status", "move", "dashboard", "record"} <= {w[0] for w in _with_ids()}
    assert ["config", "get"] in _with_ids()


def test_the_suggestion_comes_from_the_console_script_too() -> None:
    done = subprocess.run([*SERVOBUS, "scna"], capture_output=True, text=True, timeout=60, check=False)
    assert (done.returncode, done.stdout, done.stderr) == (
        2,
        "",
        "servobus: error: No such command 'scna'. Did you mean 'scan'?\n",
    )


# ---- --help in groups ----


def _headings(text: str) -> list[str]:
    return [line[:-1] for line in text.splitlines() if line and not line[0].isspace() and line.endswith(":")]


def _rows(text: str, heading: str) -> list[str]:
    """The first word of each row under ``heading`` (its options' longest names)."""
    section = text.split(f"\n{heading}:\n", 1)[1].split("\n\n", 1)[0]
    names = [re.findall(r"--[\w-]+", line) for line in section.splitlines() if line.startswith("  -")]
    return [found[-1] if len(found) > 1 else found[0] for found in names if found]


def test_move_help_lists_its_own_options_then_the_connection_then_the_remote(
    capsys: pytest.CaptureFixture[str],
) -> None:
    out, _ = run(capsys, ["move", "--help"])
    assert _headings(out) == ["Options", "Connection", "Remote (a bridge's bus)"]
    own = _rows(out, "Options")
    assert own[0] == "--angle-deg" and own[-2:] == ["--debug", "--help"]
    assert "--ids" not in own and "--password" not in own
    assert _rows(out, "Connection") == [
        "--family",
        "--revision",
        "--ids",
        "--sim",
        "--interface",
        "--channel",
        "--bitrate",
        "--fd",
        "--data-bitrate",
        "--port",
        "--baud",
        "--timeout-ms",
        "--limits",
    ]
    assert _rows(out, "Remote (a bridge's bus)") == [
        "--remote",
        "--endpoint",
        "--user",
        "--password",
        "--read-only",
    ]
    assert out.index("--angle-deg") < out.index("--family") < out.index("--password") < out.index("Examples:")


@pytest.mark.parametrize(
    "command", [["status"], ["zero"], ["config", "get"], ["record"], ["dashboard"]], ids=" ".join
)
def test_every_command_groups_its_connection_options(
    capsys: pytest.CaptureFixture[str], command: list[str]
) -> None:
    out, _ = run(capsys, [*command, "--help"])
    assert "--ids" in _rows(out, "Connection") and "--ids" not in _rows(out, "Options")
    assert _rows(out, "Options")[-2:] == ["--debug", "--help"]
    remote = "--remote" in out
    assert _headings(out) == ["Options", "Connection", *(["Remote (a bridge's bus)"] if remote else [])]


@pytest.mark.parametrize("command", _commands(), ids=" ".join)
def test_every_help_page_aligns_its_help_texts_in_one_column(
    capsys: pytest.CaptureFixture[str], command: list[str]
) -> None:
    out, _ = run(capsys, [*command, "--help"])
    assert not [line for line in out.splitlines() if line.endswith(" ")]  # (a padded name, alone)
    page = out.split("Examples:")[0]
    columns = {
        len(line) - len(line.split("  ", 2)[-1].lstrip())
        for line in page.splitlines()
        if re.match(r"  -[^ ].*?\S  +\S", line) and "  " in line.strip()
    }
    assert len(columns) <= 1, (columns, out)


def test_a_group_keeps_its_commands_after_its_options(capsys: pytest.CaptureFixture[str]) -> None:
    out, _ = run(capsys, ["config", "--help"])
    assert _headings(out) == ["Options", "Commands"]


def test_debug_is_taken_after_the_command_too(capsys: pytest.CaptureFixture[str]) -> None:
    assert [r["id"] for r in run_json(capsys, ["scan", "--sim", "1", "--ids", "1", "--debug"])] == [1]
    with pytest.raises(click.UsageError, match="--sim 2 simulates"):  # the error as it is, not a line
        run(capsys, ["status", "--sim", "2", "--ids", "5", "--debug"])


# ---- durations in ms ----


def test_a_motor_that_does_not_answer_is_said_in_ms(capsys: pytest.CaptureFixture[str]) -> None:
    rows = run_json(capsys, ["status", "--sim", "1", "--ids", "1-2", "--timeout-ms", "5"], 1)
    assert rows[0]["error"] is None and rows[0]["angle_deg"] is not None
    assert rows[1]["id"] == 2 and "ReadStatus1: no reply within 5 ms;" in rows[1]["error"]
    said = one_line(capsys, ["status", "--sim", "1", "--ids", "1-2", "--timeout-ms", "2.5"], 1)
    assert "motor 2 ReadStatus1: no reply within 2.5 ms;" in said


def test_a_timeout_on_python_can_virtual_is_said_in_ms(capsys: pytest.CaptureFixture[str]) -> None:
    channel = f"servobus-help-{uuid.uuid4().hex[:8]}"  # (a bus of its own: nobody answers)
    said = one_line(
        capsys, ["status", "-i", "virtual", "-c", channel, "--ids", "3", "--timeout-ms", "7.5"], 1
    )
    assert "myactuator motor 3 ReadStatus1: no reply within 7.5 ms;" in said


# ---- --sim N and --ids ----


def test_the_rule_is_said_in_the_connection_options(capsys: pytest.CaptureFixture[str]) -> None:
    for command in (["status"], ["scan"], ["move"], ["config", "get"]):
        out, _ = run(capsys, [*command, "--help"])
        assert SIM_RULE in " ".join(out.split())


def test_scan_finds_the_first_n_ids_of_ids(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    kept = keep_devices(monkeypatch)
    assert [r["id"] for r in run_json(capsys, ["scan", "--sim", "2", "--ids", "1-8"])] == [1, 2]
    assert [r["id"] for r in run_json(capsys, ["scan", "--sim", "2", "--ids", "5-8"])] == [5, 6]
    assert [d.motor_id for d in kept.last] == [5, 6]
    assert [r["id"] for r in run_json(capsys, ["scan", "--sim", "3"])] == [1, 2, 3]  # (probes 1-32)


def test_status_answers_from_n_motors_and_times_out_for_the_others(
    capsys: pytest.CaptureFixture[str],
) -> None:
    rows = run_json(capsys, ["status", "--sim", "2", "--ids", "1-4", "--timeout-ms", "20"], 1)
    assert [(r["id"], r["error"] is None) for r in rows] == [(1, True), (2, True), (3, False), (4, False)]
    assert all("no reply within 20 ms" in r["error"] for r in rows[2:])
    # (motors 1 and 2 answered just before: the line works, the silent motor is the one to check)
    assert rows[2]["error"].endswith("other frames came, none from motor 3: check its id, power and wiring")


@pytest.mark.parametrize(
    "args",
    [
        ["status", "--sim", "2", "--ids", "5"],
        ["scan", "--sim", "3", "--ids", "1,2"],
        ["speed", "--sim", "2", "--ids", "7", "--speed-dps", "10"],
        ["config", "get", "--sim", "2", "--ids", "1", "pid.speed_kp"],
    ],
    ids=lambda args: " ".join(args),
)
def test_fewer_ids_than_simulated_motors_is_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str], args: list[str]
) -> None:
    said = one_line(capsys, args)
    assert re.search(r"error: --sim (\d) simulates the first \1 ids of --ids, which names \d", said), said


def test_a_driving_command_drives_the_first_n_ids(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    kept = keep_devices(monkeypatch)
    args = ["speed", "--sim", "2", "--ids", "3,4", "--speed-dps", "20", "--duration", "0.1"]
    rows = run_json(capsys, args)
    assert [(r["id"], r["error"]) for r in rows] == [(3, None), (4, None)]
    assert [d.motor_id for d in kept.last] == [3, 4]
    args = [
        "speed",
        "--sim",
        "1",
        "--ids",
        "1-2",
        "--speed-dps",
        "20",
        "--duration",
        "0.1",
        "--timeout-ms",
        "20",
    ]
    rows = run_json(capsys, args, 1)  # (motor 2 is addressed, not simulated: it stays silent)
    assert rows[0]["error"] is None and "motor 2" in rows[1]["error"] and "within 20 ms" in rows[1]["error"]


def test_the_dashboard_says_how_many_of_its_motors_are_simulated(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    pytest.importorskip("servobus.dashboard")
    kept = keep_devices(monkeypatch)
    base = ["dashboard", "--listen", "127.0.0.1:0", "--still", "--duration", "0.3", "--timeout-ms", "20"]
    out, _ = run(capsys, [*base, "--sim", "1", "--ids", "4-5"])
    assert "(2 myactuator motor(s), 1 simulated; read-only;" in out.splitlines()[0]
    assert [d.motor_id for d in kept.last] == [4]
    out, _ = run(capsys, [*base, "--sim", "2"])
    assert "(2 simulated myactuator motor(s); read-only;" in out.splitlines()[0]


# ---- the page that says all this ----

PAGE = Path(__file__).resolve().parents[2] / "docs" / "cli.md"


def _said_errors() -> list[tuple[list[str], str]]:
    """Each ``$ servobus ...`` line of docs/cli.md's console blocks that its error line follows."""
    text = PAGE.read_text(encoding="utf-8")
    found = []
    for block in re.findall(r"^```console\n(.*?)^```$", text, re.S | re.M):
        lines = block.splitlines()
        for line, after in zip(lines, [*lines[1:], ""], strict=True):
            if line.startswith("$ servobus ") and after.startswith("servobus") and ": error: " in after:
                found.append((shlex.split(line.split("#")[0])[2:], after))
    return found


@pytest.mark.parametrize(
    ("args", "said"), _said_errors(), ids=lambda v: " ".join(v) if isinstance(v, list) else ""
)
def test_the_page_s_errors_are_what_the_command_says(
    capsys: pytest.CaptureFixture[str], args: list[str], said: str
) -> None:
    _, err = run(capsys, args, 2 if "No such" in said or "--sim 2 simulates" in said else 1)
    assert said in err.splitlines()


def test_the_page_shows_some_errors() -> None:
    assert len(_said_errors()) >= 4
