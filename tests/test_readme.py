"""The README is the front door and runs as written; the content it sent into the site still does.

The README: under 250 lines, its two commands (which .ci/run runs) its first two blocks, every link
resolving to a file of the repository and its #anchor to a heading there, its quick start running on
asyncio and trio. The pages it moved into docs/guides and docs/explanation: the Bus guide's service
and signal examples do what they say, the C core and codec screens print what the page says, every
command of the CLI is on the command-line guide and every runtime dependency on the development guide,
and their own links resolve. (tests/test_docs_pages.py runs every block of every page as well.)"""

from __future__ import annotations

import contextlib
import os
import re
import signal
import subprocess
import sys
import threading
import time
import tomllib
import unicodedata
from pathlib import Path
from typing import Any

import anyio
import click
import pytest

from _adapters import HARDWARE
from _adapters import simulated as _simulated
from _backends import BACKENDS
from servobus.cli import cli
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim.plant import PositionControl, SpeedControl
from servobus.transports.sim import SimTransport

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
TEXT = README.read_text(encoding="utf-8")
DOCS = ROOT / "docs"
#: the pages the README's long sections moved to (the guides' hardware and metrics pages are the tutorial's)
MOVED = sorted(
    page
    for page in [*DOCS.glob("guides/*.md"), *DOCS.glob("explanation/*.md")]
    if page.name not in {"hardware.md", "metrics.md"}
)
BUS_GUIDE = DOCS / "guides" / "bus.md"
#: the README's two commands, byte for byte: .ci/run runs them as "the README's" commands
COMMANDS = (
    "python3 -m venv .venv && . .venv/bin/activate && pip install . && servobus demo --duration 5\n",
    "python3 -m venv .venv && . .venv/bin/activate && pip install '.[test]' && pytest\n",
)


def _fenced(text: str, language: str = r"\w*") -> list[tuple[int, str, str]]:
    """Every fenced block of ``text`` in ``language``: (the line its code starts on, language, code)."""
    return [
        (text.count("\n", 0, match.start(2)) + 1, match.group(1), match.group(2))
        for match in re.finditer(rf"^```({language})\n(.*?)^```$", text, re.S | re.M)
    ]


PYTHON = [(line, code) for line, _, code in _fenced(TEXT, "python")]


def _block(marker: str, text: str = TEXT) -> str:
    """The ```python block that follows the ``<!-- marker: ... -->`` comment."""
    match = re.search(rf"<!-- {marker}:[^\n]*-->\n```python\n(.*?)```", text, re.S)
    assert match, f"no python block after a <!-- {marker}: ... --> comment"
    return match.group(1)


def _section(text: str, title: str) -> str:
    """The ``## TITLE`` section of ``text``, up to the next ``## ``."""
    match = re.search(rf"^## {re.escape(title)}\n(.*?)(?=^## |\Z)", text, re.S | re.M)
    assert match, f"no '## {title}' section"
    return match.group(1)


def _page(path: Path) -> str:
    return path.read_text(encoding="utf-8")


# -- the front door -------------------------------------------------------------------------------


def test_the_readme_is_under_250_lines() -> None:
    assert len(TEXT.splitlines()) < 250, len(TEXT.splitlines())


def test_its_two_commands_are_its_first_two_blocks_word_for_word() -> None:
    blocks = _fenced(TEXT)
    assert [(language, code) for _, language, code in blocks[:2]] == [("sh", c) for c in COMMANDS]
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")  # what CI runs of them
    assert "pip install '.[test]'\npytest\n" in ci and "servobus demo --duration" in ci


def test_it_shows_a_picture_the_quick_start_and_links_into_the_site() -> None:
    targets = {target.split("#")[0] for _, target in _links(TEXT)}
    assert any(target.endswith(".png") for target in targets), targets
    for page in ("docs/tutorial.md", "docs/reference/cli.md", "docs/guides/bus.md", "docs/api/servobus.md"):
        assert page in targets, page
    assert len(PYTHON) == 1 and _block("quickstart") == PYTHON[0][1]


def test_a_block_that_names_a_device_says_it_needs_hardware_in_its_first_line() -> None:
    for path in [README, *MOVED]:
        for line, _, code in _fenced(_page(path), "python"):
            if "/dev/" in code:
                assert code.startswith(HARDWARE), f"{path.name}:{line} names a device but not '{HARDWARE}'"


@pytest.mark.parametrize(("line", "code"), PYTHON, ids=[f"README.md:{line}" for line, _ in PYTHON])
def test_every_python_block_runs_as_written(line: int, code: str, tmp_path: Path) -> None:
    """As a user would: the block alone, as a script, in a fresh interpreter (in an empty folder)."""
    script = tmp_path / "block.py"
    hardware = code.startswith(HARDWARE)
    with _simulated(code, tmp_path) if hardware else contextlib.nullcontext(code) as runnable:
        script.write_text(runnable, encoding="utf-8")
        done = subprocess.run(
            [sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=120
        )
    assert done.returncode == 0, f"README.md:{line}\n{done.stderr}"


# -- links ----------------------------------------------------------------------------------------


def _links(text: str) -> list[tuple[int, str]]:
    """(line, target) of every markdown link and image of ``text`` that is not a URL, code aside."""
    prose = re.sub(r"^```.*?^```$", lambda m: "\n" * m.group(0).count("\n"), text, flags=re.S | re.M)
    prose = re.sub(r"`[^`\n]*`", lambda m: " " * len(m.group(0)), prose)
    return [
        (prose.count("\n", 0, match.start()) + 1, match.group(1))
        for match in re.finditer(r"!?\[[^\]]*\]\(([^)\s]+)\)", prose)
        if not re.match(r"[a-z]+:", match.group(1))
    ]


def _mkdocs_slug(title: str) -> str:
    """Python-Markdown's toc slugify, mkdocs's default."""
    text = unicodedata.normalize("NFKD", title).encode("ascii", "ignore").decode("ascii")
    return re.sub(r"[-\s]+", "-", re.sub(r"[^\w\s-]", "", text).strip().lower())


def _github_slug(title: str) -> str:
    """GitHub's heading anchors: lower case, punctuation dropped, each space a hyphen."""
    return re.sub(r"[^\w\- ]", "", title.lower()).replace(" ", "-")


def _anchors(text: str) -> set[str]:
    """The anchors of ``text``'s headings as both mkdocs and GitHub make them (repeats numbered)."""
    found: set[str] = set()
    for slug in (_mkdocs_slug, _github_slug):
        seen: dict[str, int] = {}
        for match in re.finditer(
            r"^#{1,6} +(.+?) *#*$", re.sub(r"^```.*?^```$", "", text, flags=re.S | re.M), re.M
        ):
            title = re.sub(r"[`*_]|\[([^\]]*)\]\([^)]*\)", r"\1", match.group(1))
            anchor = slug(title)
            found.add(f"{anchor}-{seen[anchor]}" if anchor in seen else anchor)
            seen[anchor] = seen.get(anchor, 0) + 1
    return found


def _check_links(path: Path, root: Path = ROOT) -> list[str]:
    """Each link of ``path`` whose file does not exist, or whose #anchor is no heading of it."""
    text = _page(path)
    broken = []
    for line, target in _links(text):
        file, _, anchor = target.partition("#")
        resolved = (path.parent / file).resolve() if file else path
        where = f"{path.relative_to(root)}:{line} -> {target}"
        if not resolved.is_file():
            broken.append(f"{where}: no such file")
        elif anchor and resolved.suffix == ".md":
            target_text = resolved.read_text(encoding="utf-8")
            if _mkdocs_slug(anchor) != anchor or anchor not in _anchors(target_text):
                broken.append(f"{where}: no heading with that anchor")
    return broken


def test_every_link_of_the_readme_resolves_to_a_file_and_a_heading() -> None:
    assert len(_links(TEXT)) >= 10
    assert _check_links(README) == []


@pytest.mark.parametrize("page", MOVED, ids=[str(p.relative_to(DOCS)) for p in MOVED])
def test_every_link_of_a_moved_page_resolves(page: Path) -> None:
    assert _check_links(page) == []


def test_the_link_check_finds_a_missing_file_and_a_missing_heading(tmp_path: Path) -> None:
    (tmp_path / "b.md").write_text("# Title\n\n## The 1 kHz loop: `cycle()`\n", encoding="utf-8")
    page = tmp_path / "a.md"
    page.write_text(
        "[ok](b.md#the-1-khz-loop-cycle) [gone](c.md) [no](b.md#nothing) `[code](c.md)` [web](https://x.org)\n",
        encoding="utf-8",
    )
    assert _check_links(page, tmp_path) == [
        "a.md:1 -> c.md: no such file",
        "a.md:1 -> b.md#nothing: no heading with that anchor",
    ]


# -- what the moved sections still show -----------------------------------------------------------


def test_the_bus_guide_s_quick_start_is_the_readme_s() -> None:
    assert _block("quickstart", _page(BUS_GUIDE)) == _block("quickstart")


def _on(backend: str, code: str) -> str:
    """``code`` with its ``anyio.run(main)`` line (at the start of a line) run on ``backend``."""
    run = re.compile(r"^anyio\.run\(main\)", re.M)
    assert len(run.findall(code)) == 1, "the block ends with one anyio.run(main)"
    return run.sub(f"anyio.run(main, backend={backend!r})", code)


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_quick_start_drives_simulated_motors_through_bus_and_motor(backend: str) -> None:
    code = _block("quickstart")
    assert not re.search(r"0x[0-9A-Fa-f]{3}\b", code), "the quick start names a raw CAN id"
    done = subprocess.run(
        [sys.executable, "-c", _on(backend, code)], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0].startswith("motor 1: ") and lines[1] == "cycle: 32/32 replies", done.stdout
    assert re.fullmatch(r"broadcast: 32 replies; latency p50 \d+\.\d\d ms", lines[2]), done.stdout
    # the Loop's last state: motor 1 turned back, the reply to a command of the last ticks
    assert re.fullmatch(r"loop: motor 1 at -90\.0 dps, the reply to tick 4[5-8] of 49", lines[3]), done.stdout


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_service_example_runs_in_a_task_group_and_stops_its_motors(backend: str) -> None:
    namespace: dict[str, Any] = {}
    exec(compile(_block("service", _page(BUS_GUIDE)), "bus.md service", "exec"), namespace)
    devices = [MyActuatorMotor(i) for i in (1, 2, 3)]

    async def main() -> None:
        with anyio.move_on_after(1.3):  # the service runs until its host cancels it
            await namespace["serve"](SimTransport(devices=devices))

    anyio.run(main, backend=backend)
    for device in devices:  # they ran at 30 dps; cancelled, the safe stop (0x81) made each hold
        assert isinstance(device.control, PositionControl), device.control


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_signal_example_stops_its_motor_and_exits_143_on_sigterm(backend: str) -> None:
    namespace: dict[str, Any] = {}
    exec(compile(_block("signals", _page(BUS_GUIDE)), "bus.md signals", "exec"), namespace)
    device = MyActuatorMotor(1)

    ended = threading.Event()

    def terminate_once_it_turns() -> None:  # (a thread: the signal comes once the block drives the motor)
        until = time.monotonic() + 30
        while not isinstance(device.control, SpeedControl) and time.monotonic() < until:
            if ended.wait(0.01):
                return  # the block ended on its own (an error): no signal for pytest itself
        time.sleep(0.2)
        if not ended.is_set():
            os.kill(os.getpid(), signal.SIGTERM)

    killer = threading.Thread(target=terminate_once_it_turns, daemon=True)
    killer.start()
    try:
        with pytest.raises(SystemExit) as stopped:
            anyio.run(namespace["main"], SimTransport(devices=[device]), backend=backend)
    finally:
        ended.set()
        killer.join()
    assert stopped.value.code == 143
    assert isinstance(device.control, PositionControl), device.control  # it turned; the stop made it hold


ARCHITECTURE = _page(DOCS / "explanation" / "architecture.md")
#: the C core's and the codecs' screens (once doctests in the README): each script and what it prints
SCREENS = re.findall(r"^```python\n(.*?)^```\n\nIt prints:\n\n```text\n(.*?)^```$", ARCHITECTURE, re.S | re.M)


def test_no_doctest_is_left_and_the_screens_say_what_they_print() -> None:
    assert not [p for p in [README, *MOVED] if "```pycon" in _page(p)]
    assert len(SCREENS) == 2 and "crc16_modbus" in SCREENS[0][0] and "check_bus" in SCREENS[1][0]


@pytest.mark.parametrize(("code", "prints"), SCREENS, ids=["c-core", "codecs"])
def test_the_c_core_and_codec_screens_print_what_the_page_says(
    code: str, prints: str, tmp_path: Path
) -> None:
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout == prints


def test_every_command_is_on_the_command_line_guide_and_the_readme_links_the_reference() -> None:
    commands = cli.list_commands(click.Context(cli))
    shown = set(re.findall(r"\bservobus ([\w-]+)", _page(DOCS / "guides" / "command-line.md")))
    assert len(commands) >= 22 and not set(commands) - shown, sorted(set(commands) - shown)
    assert "docs/reference/cli.md" in {target for _, target in _links(TEXT)}


def test_the_development_guide_names_every_runtime_dependency() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    names = [re.split(r"[\s<>=!~;\[]", spec)[0] for spec in project["dependencies"]]
    section = _section(_page(DOCS / "guides" / "development.md"), "Dependencies").lower()
    assert len(names) >= 6 and not [n for n in names if n.lower() not in section], names
    extras = project["optional-dependencies"]
    assert not [extra for extra in extras if not re.search(rf"[`\[]{extra}[`\]]", section)], sorted(extras)
