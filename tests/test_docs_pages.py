"""Every fenced block of every page under docs/ runs as written (docs/api/families.md: its own test),
one test per block (``page.md:line``): python blocks as scripts, console blocks command by command
with their output checked, toml blocks parsed; and no block is of a kind nothing runs. The convention
(how outputs are matched, which devices are simulated, the shims) is tests/_docs_blocks.py's
docstring."""

from __future__ import annotations

import contextlib
import os
import re
import signal
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from _adapters import HARDWARE, simulated
from _docs_blocks import (
    DEVICES,
    NEEDS_BRIDGE,
    UNTIL_CTRL_C,
    Block,
    Command,
    Session,
    adapters,
    blocks,
    commands,
    devices_for,
    environment,
    files,
    line_matches,
    output_matches,
    pages,
    unrunnable,
)

ALL = [block for page in pages() for block in blocks(page)]
RUN = [block for block in ALL if block.kind in ("python", "console", "toml")]


def _folder(block: Block, tmp_path: Path) -> Path:
    """A fresh folder for ``block``, holding the files its page names (``<!-- file: NAME -->``)."""
    folder = tmp_path / "block"
    folder.mkdir()
    for name, content in files(block.page).items():
        (folder / name).write_text(content, encoding="utf-8")
    return folder


def _python(block: Block, folder: Path) -> None:
    first = block.code.splitlines()[0]
    hardware = first.startswith(HARDWARE)
    if not hardware:
        assert not any(device in block.code for device in DEVICES), f"{block.id}: a device, not {HARDWARE!r}"
    said = re.search(r"(\d+) motors", first)
    bridge = NEEDS_BRIDGE.match(first)
    adapters = simulated(block.code, folder, motors=int(said.group(1)) if said else 1) if hardware else None
    env = environment(folder)
    with adapters or contextlib.nullcontext(block.code) as code, Session(folder, env) as session:
        if bridge:  # served while the script runs, as in another terminal
            session.run(Command(f"{bridge.group(1).strip()}  {UNTIL_CTRL_C}", []))
        (folder / "block.py").write_text(code, encoding="utf-8")
        done = subprocess.run(
            [sys.executable, "block.py"],
            cwd=folder,
            env=env,
            capture_output=True,
            text=True,
            timeout=120,
        )
    assert done.returncode == 0, f"{block.id}\n{done.stderr}"
    if block.prints is not None:
        assert done.stdout == block.prints, f"{block.id}: printed\n{done.stdout}"


def _console(block: Block, folder: Path) -> None:
    env = environment(folder)
    with devices_for(block.code, folder) as code, Session(folder, env) as session:
        env["SERVOBUS_DOCS_PTYS"] = os.pathsep.join(
            str(folder / Path(d).name) for _, d in adapters(block.code)
        )
        for command in commands(code):
            status, output = session.run(command)
            said = "\n".join(output)
            expected = command.exit_code
            if expected is None:
                assert status != 0, (
                    f"{block.id}: {command.line!r} exited 0, its output shows an error\n{said}"
                )
            else:
                assert status == expected, f"{block.id}: {command.line!r} exited {status}\n{said}"
            if command.output:
                assert output_matches(command.output, output), (
                    f"{block.id}: {command.line!r} printed\n{said}\n--- the page shows\n"
                    + "\n".join(command.output)
                )


def _toml(block: Block) -> None:
    tomllib.loads(block.code)  # (raises on a file that is not TOML)
    if block.page == "limits.md" or (block.file or "").startswith("limits"):
        from servobus.limits import parse

        parse(block.code)


@pytest.mark.parametrize("block", RUN, ids=[block.id for block in RUN])
def test_every_block_runs_as_written(block: Block, tmp_path: Path) -> None:
    if block.kind == "toml":
        _toml(block)
    elif block.kind == "python":
        _python(block, _folder(block, tmp_path))
    else:
        _console(block, _folder(block, tmp_path))


def test_every_block_on_the_site_is_of_a_kind_that_runs() -> None:
    wrong = [f"{block.id}: {why}" for block in ALL if (why := unrunnable(block))]
    assert not wrong, "\n".join(wrong)


def test_the_pages_have_blocks_of_every_kind() -> None:
    assert {block.kind for block in RUN} == {"python", "console", "toml"}
    assert len(RUN) >= 30, len(RUN)


# ---- the runner's own rules ------------------------------------------------------------------------


def test_a_line_matches_with_other_numbers_but_not_other_words() -> None:
    assert line_matches("latency p50 0.57 ms", "latency p50 1.25 ms")
    assert line_matches("1176 replies (1: 294)", "1180 replies (1: 295)")
    assert not line_matches("1176 replies", "1176 requests")
    assert not line_matches("moved 1 motor", "moved 1 motor 2")
    assert line_matches("┏━━━┳━━┓", "┏━━━━━┳━┓") and line_matches("│  1 │ a  │", "│ 10 │ a    │")


def test_an_output_matches_in_order_with_dots_skipping_lines() -> None:
    assert output_matches(["a", "...", "d"], ["a", "b", "c", "d"])
    assert output_matches(["a", "...", "b"], ["a", "b"])
    assert not output_matches(["a", "d"], ["a", "b", "d"])
    assert not output_matches(["d", "...", "a"], ["a", "b", "d"])
    assert not output_matches(["a"], ["a", "b"])


def test_a_command_s_exit_code_is_zero_unless_it_says_or_shows_an_error() -> None:
    block = "$ servobus scan --sim 1\n$ servobus status --sim 1 --ids 1-2  # (exit 1)\n$ servobus scna\n"
    one, two, three = commands(block + "servobus: error: No such command 'scna'.")
    assert (one.exit_code, two.exit_code, three.exit_code) == (0, 1, None)
    (long,) = commands("$ servobus bridge \\\n    --sim 2  # until Ctrl-C")
    assert long.line == "servobus bridge --sim 2  # until Ctrl-C" and long.until_ctrl_c


@pytest.mark.parametrize(
    ("line", "ok"),
    [
        ("sudo ip link set can0 up type can bitrate 1000000", True),
        ("sudo ip link set can0 up type can bitrate 1000000 dbitrate 5000000 fd on", True),
        ("sudo ip link set can0 down", True),
        ("ip link set can0 up type can bitrate 1000000", False),  # not as root
        ("sudo ip link set can0 up type can bitrate 1000001", False),
        ("sudo ip link set can0 up bitrate 1000000", False),  # no type can
        ("sudo ip link set can0 up type can bitrate 1000000 dbitrate 5000000", False),  # no fd on
        ("sudo slcand -o -c -s8 ttyACM0 can0", True),
        ("sudo slcand -o -c -s9 ttyACM0 can0", False),
        ("slcand -o -c -s8 ttyACM0 can0", False),
        ("sudo slcand -o -c -S 3000000 -s8 ttyACM0 can0", True),  # (a value after its option)
        ("sudo slcand -o -c -s8 ttyACM0 can0 extra", False),
        ("sudo ip link set can0 up type can", False),  # no bit timing
        ("sudo touch ran-as-root", False),  # the shim runs only the shims
        ("pip install 'servobus[dashboard]'", True),
        ("pip install 'servobus[dashbord]'", False),
    ],
)
def test_the_shims_check_their_arguments(line: str, ok: bool, tmp_path: Path) -> None:
    folder = tmp_path / "shims"
    folder.mkdir()
    (folder / "ttyACM0").touch()
    done = subprocess.run(
        ["bash", "-c", line], cwd=folder, env=environment(folder), capture_output=True, text=True
    )
    assert (done.returncode == 0) == ok, done.stderr


def test_a_served_command_must_serve_until_stopped_and_is_stopped_at_the_block_s_end(tmp_path: Path) -> None:
    folder = tmp_path / "served"
    folder.mkdir()
    env = environment(folder)
    with Session(folder, env) as session:
        with pytest.raises(AssertionError, match="ended by itself"):
            session.run(Command("echo up  # until Ctrl-C", []))
        session.servers.clear()  # it ended: nothing to stop
        status, first = session.run(
            Command("python -c 'import time; print(\"up\", flush=True); time.sleep(60)'  # until Ctrl-C", [])
        )
        assert (status, first) == (0, ["up"])
        (_, server, _) = session.servers[0]
    assert server.returncode == -signal.SIGINT  # stopped at the block's end, as by Ctrl-C
