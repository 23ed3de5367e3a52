"""How tests/test_docs_pages.py reads and runs the fenced blocks of the pages under docs/.

The convention (what a page writes, what is checked):

- ```python: a complete script, run as ``python block.py`` in a fresh folder, exit 0 within 120 s.
  Followed by the paragraph ``It prints:`` and a ```text block, its stdout must equal that block.
  A first line ``# needs hardware: an SLCAN adapter on /dev/ttyACM0`` (or ``RS485 adapter on ...``)
  gets simulated MyActuator motors behind a pty in its place (``N motors`` in that line: N of them).
- ```console: each ``$ `` line is a command (a trailing ``\\`` continues it), run by bash in the
  block's folder; each must exit 0, or the code its comment says (``# ... (exit 1)``), or non-zero
  where its output shows an ``error:`` line. The lines up to the next command are its output
  (stdout and stderr, as a terminal shows them), none shown: not checked. A line ``...`` skips any
  lines (none included); the others match in order, each EXACTLY or, failing that, with its NUMBERS
  free: every run of digits (with a decimal point) may be another number, but the words, the
  punctuation and the count of numbers must be the same (a latency, a reply count, a stamp vary from
  run to run); runs of spaces and of one box-drawing character count as one (a rich table's columns
  widen with their numbers).
- A command naming ``/dev/ttyACM0`` (SLCAN) or ``/dev/ttyUSB0`` (RS485) runs on simulated motors
  behind a pty in their place (the highest id of the block's ``--ids``, 1 without); ``-i socketcan
  -c can0`` on python-can's ``virtual`` interface with the simulated motors of ``--family`` served on
  it. A ``servobus`` command on such a pty gets ``--timeout-ms 200`` unless it gives one (a
  simulator behind a pty on a loaded computer answers slower than a motor). ``sudo``, ``ip``,
  ``slcand`` and ``pip`` are shims that check their arguments the way the real ones would (``ip link
  set can0 up type can bitrate 1000000``) and change nothing on this computer.
- A command ending ``# until Ctrl-C`` serves until stopped: it is started, its first line awaited
  (and matched with the first line shown), it must still be alive, and SIGINT ends it.
- Such a command keeps serving while the block's next commands run ("in another terminal": a
  ``servobus status --remote`` of the bridge it started), until the end of the block (two servers
  of one port: two blocks). A python block whose first line is ``# needs a bridge: servobus bridge
  ...`` runs while that command serves.
- A block after ``<!-- file: NAME -->`` is also written as NAME into the folder of every block of
  its page (the ``limits.toml`` a command names).
- ```toml: parsed by tomllib; a limits file (on limits.md, or a file named ``limits*.toml``) also by
  ``servobus.limits.parse``. ```text: only as an output (``It prints:``), a file, or a block
  another test checks (DELEGATED). Any other kind fails test_every_block_on_the_site_is_of_a_kind_that_runs.
"""

from __future__ import annotations

import contextlib
import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cache
from pathlib import Path

from _adapters import simulated

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
TESTS = Path(__file__).resolve().parent
#: pages whose blocks another test runs
SKIPPED = {"api/families.md": "tests/test_docs_families.py"}
#: ```text blocks another test compares (page, the section they are in): by whom
DELEGATED = {("recording.md", "Logging both directions of a link with TapLink"): "tests/test_taplink_doc.py"}
RUNS = ("python", "console", "toml")
FENCE = re.compile(r"^([ \t]*)```([\w+-]*)[^\n]*\n(.*?)^\1```[ \t]*$", re.S | re.M)
FILE = re.compile(r"<!-- file: (\S+) -->\s*$")
UNTIL_CTRL_C = "# until Ctrl-C"
#: a python block's first line naming the bridge it talks to
NEEDS_BRIDGE = re.compile(r"^# needs a bridge: (servobus bridge [^#\n]*)")
DEVICES = {"/dev/ttyACM0": "SLCAN", "/dev/ttyUSB0": "RS485"}


@dataclass(frozen=True)
class Block:
    page: str  # relative to docs/
    line: int  # of the opening fence
    kind: str
    code: str
    section: str  # the ## heading it is under
    before: str  # the paragraph before it
    file: str | None  # the name it is written under (``<!-- file: NAME -->``)
    prints: str | None = None  # a python block's expected stdout

    @property
    def id(self) -> str:
        return f"{self.page}:{self.line}"


def pages() -> list[str]:
    return sorted(
        str(p.relative_to(DOCS)) for p in DOCS.rglob("*.md") if str(p.relative_to(DOCS)) not in SKIPPED
    )


@cache
def blocks(page: str) -> list[Block]:
    text = (DOCS / page).read_text(encoding="utf-8")
    found: list[Block] = []
    for match in FENCE.finditer(text):
        indent, kind, body = match.groups()
        code = "".join(
            line[len(indent) :] if line.startswith(indent) else line for line in body.splitlines(True)
        )
        head = text[: match.start()]
        sections = re.findall(r"^## (.*)$", head, re.M)
        paragraph = head.rstrip().rsplit("\n\n", 1)[-1].strip()
        named = FILE.search(head.rstrip().rsplit("\n", 1)[-1])
        found.append(
            Block(
                page,
                head.count("\n") + 1,
                kind,
                code,
                sections[-1] if sections else "",
                paragraph,
                named.group(1) if named else None,
            )
        )
    # a python block's "It prints:" output
    for i, block in enumerate(found[:-1]):
        after = found[i + 1]
        if block.kind == "python" and after.kind == "text" and after.before == "It prints:":
            found[i] = Block(**{**block.__dict__, "prints": after.code})
    return found


def unrunnable(block: Block) -> str | None:
    """Why ``block`` is of a kind no test runs, or None."""
    if block.kind in RUNS:
        return None
    if block.kind == "text":
        previous = [b for b in blocks(block.page) if b.line < block.line]
        if block.before == "It prints:" and previous and previous[-1].kind == "python":
            return None
        if block.file or (block.page, block.section) in DELEGATED:
            return None
        return "a ```text block that is no script's output (It prints:), no file and no other test's"
    return f"a ```{block.kind or '(no language)'} block: write python, console or toml"


def files(page: str) -> dict[str, str]:
    """The blocks of ``page`` written as files into each of its blocks' folders."""
    return {b.file: b.code for b in blocks(page) if b.file}


# ---- console blocks -------------------------------------------------------------------------------


@dataclass(frozen=True)
class Command:
    line: str
    output: list[str]

    @property
    def until_ctrl_c(self) -> bool:
        return self.line.rstrip().endswith(UNTIL_CTRL_C)

    @property
    def exit_code(self) -> int | None:
        """The exit code the command must end with; None: any non-zero (its output shows an error)."""
        said = re.search(r"#.*\(exit (\d+)\)", self.line)
        if said:
            return int(said.group(1))
        if any(re.search(r"\berror:", line) for line in self.output):
            return None
        return 0


def commands(code: str) -> list[Command]:
    found: list[Command] = []
    lines = code.splitlines()
    i = 0
    while i < len(lines):
        line = lines[i]
        assert line.startswith("$ "), f"a console block's line {line!r} is neither a command nor its output"
        command = line[2:]
        while command.endswith("\\") and i + 1 < len(lines):
            i += 1
            command = command[:-1].rstrip() + " " + lines[i].strip()
        output = []
        while i + 1 < len(lines) and not lines[i + 1].startswith("$ "):
            i += 1
            output.append(lines[i])
        found.append(Command(command, output))
        i += 1
    return found


#: the box-drawing characters (rich's tables)
BOX = "".join(chr(c) for c in range(0x2500, 0x2580))


def _loose(line: str) -> str:
    line = re.sub(r"\d+(?:\.\d+)?", "0", line)
    line = re.sub(rf"([{BOX}])\1+", r"\1", line)
    return re.sub(r"\s+", " ", line).strip()


def line_matches(expected: str, actual: str) -> bool:
    return expected == actual or _loose(expected) == _loose(actual)


def output_matches(expected: list[str], actual: list[str]) -> bool:
    """``actual`` as ``expected`` says: in order, ``...`` any lines, each other line by line_matches."""

    @cache
    def match(e: int, a: int) -> bool:
        if e == len(expected):
            return a == len(actual)
        if expected[e].strip() == "...":
            return any(match(e + 1, k) for k in range(a, len(actual) + 1))
        return a < len(actual) and line_matches(expected[e], actual[a]) and match(e + 1, a + 1)

    return match(0, 0)


def highest_id(code: str) -> int:
    """The highest id the block's ``--ids`` name (1 without)."""
    highest = 1
    for ids in re.findall(r"--ids[ =]([\d,\-]+)", code):
        highest = max([highest, *(int(n) for n in re.findall(r"\d+", ids))])
    return highest


def adapters(code: str) -> list[tuple[str, str]]:
    return [(kind, device) for device, kind in DEVICES.items() if device in code]


@contextlib.contextmanager
def devices_for(code: str, folder: Path) -> Iterator[str]:
    """``code`` with its adapters' devices swapped for ptys of simulated motors served meanwhile."""
    named = adapters(code)
    if not named:
        yield code
        return
    with simulated(code, folder, named, motors=highest_id(code)) as swapped:
        yield swapped


def environment(folder: Path) -> dict[str, str]:
    """The commands' environment: the checking shims first on PATH, this tree's servobus."""
    shims = folder.parent / f"{folder.name}-bin"
    shims.mkdir(exist_ok=True)
    for name, body in SHIMS.items():
        path = shims / name
        path.write_text(f"#!{sys.executable}\n{body}", encoding="utf-8")
        path.chmod(0o755)
    path = os.pathsep.join([str(shims), str(Path(sys.executable).parent), os.environ.get("PATH", "")])
    # (without tests/, which pytest puts on sys.path: a page's script sees what a user has)
    python_path = os.pathsep.join(p for p in sys.path if p and Path(p).resolve() != TESTS)
    return {**os.environ, "PATH": path, "PYTHONPATH": python_path, "COLUMNS": "100", "TERM": "dumb"}


class Session:
    """A block's commands, run in its folder one after the other; a command that serves until Ctrl-C
    keeps serving while the next ones run ("in another terminal"), until the end of the block, and is
    then stopped with SIGINT (the last started first)."""

    def __init__(self, folder: Path, env: dict[str, str]) -> None:
        self.folder, self.env = folder, env
        self.servers: list[tuple[str, subprocess.Popen[bytes], Path]] = []

    def run(self, command: Command) -> tuple[int, list[str]]:
        """Run ``command``: its exit code and its output lines (a server's: its first line)."""
        if not command.until_ctrl_c:
            done = subprocess.run(
                ["bash", "-c", command.line],
                cwd=self.folder,
                env=self.env,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                text=True,
                timeout=120,
            )
            return done.returncode, done.stdout.splitlines()
        log = self.folder.parent / f"server-{time.monotonic_ns()}.out"
        with log.open("wb") as out:
            server = subprocess.Popen(
                ["bash", "-c", f"exec {command.line}"],
                cwd=self.folder,
                env=self.env,
                stdout=out,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
        self.servers.append((command.line, server, log))
        deadline = time.monotonic() + 60
        while b"\n" not in log.read_bytes() and server.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        first = log.read_bytes().decode().split("\n", 1)[0]
        assert server.poll() is None, (
            f"{command.line!r} ended by itself: it should serve until Ctrl-C\n{log.read_text()}"
        )
        assert first, f"{command.line!r} printed no line within 60 s"
        return 0, [first]

    def stop(self) -> None:
        """Stop the commands serving with SIGINT, the last first: each must end within 30 s."""
        wrong = []
        while self.servers:
            line, server, log = self.servers.pop()
            server.send_signal(signal.SIGINT)
            try:
                server.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(server.pid, signal.SIGKILL)
                server.wait()
                wrong.append(f"{line!r} still ran 30 s after SIGINT\n{log.read_text()}")
            if server.returncode not in (0, 130, -signal.SIGINT, -signal.SIGKILL):  # as Ctrl-C ends it
                wrong.append(f"{line!r} ended with {server.returncode} on SIGINT\n{log.read_text()}")
        assert not wrong, "\n".join(wrong)

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc: object) -> None:
        if exc[0] is not None:
            with contextlib.suppress(AssertionError):
                self.stop()
        else:
            self.stop()


# ---- the shims: what a console command calls that must not touch this computer -----------------

_SUDO = """\
import os, sys
args = sys.argv[1:]
while args and args[0].startswith("-"):
    assert args[0] in ("-E", "--preserve-env"), f"sudo: this shim knows no option {args[0]}"
    args = args[1:]
assert args, "usage: sudo command"
# (only the shims: a page's sudo must never run a real command as this computer's root)
assert args[0] in ("ip", "slcand"), f"sudo (docs shim): runs only the ip and slcand shims, not {args[0]}"
os.environ["SERVOBUS_DOCS_ROOT"] = "1"
os.execvp(args[0], args)
"""

_IP = """\
import os, re, sys
BITRATES = {10000, 20000, 50000, 100000, 125000, 250000, 500000, 800000, 1000000}
DATA_BITRATES = {1000000, 2000000, 4000000, 5000000, 8000000}
args = sys.argv[1:]
def fail(why):
    sys.exit(f"ip (docs shim): {why}: {' '.join(sys.argv[1:])}")
details = False
while args and args[0].startswith("-"):
    if args[0] not in ("-details", "-d", "-statistics", "-s", "-detail"):
        fail(f"unknown option {args[0]}")
    args = args[1:]
if args[:2] == ["link", "show"] or args == ["link"]:
    dev = args[2] if len(args) > 2 else "can0"
    print(f"3: {dev}: <NOARP,UP,LOWER_UP,ECHO> mtu 16 qdisc pfifo_fast state UP mode DEFAULT group default "
          "qlen 10")
    print("    link/can ")
    sys.exit(0)
if args[:2] != ["link", "set"] or len(args) < 4:
    fail("this shim knows 'ip link set DEV ...' and 'ip link show DEV'")
if os.environ.get("SERVOBUS_DOCS_ROOT") != "1":
    sys.exit("RTNETLINK answers: Operation not permitted")
dev, rest = args[2], args[3:]
if not re.fullmatch(r"(v?can|slcan)\\d+", dev):
    fail(f"{dev} is not a CAN interface name")
opts = {}
i = 0
state = None
while i < len(rest):
    word = rest[i]
    if word in ("up", "down"):
        state = word; i += 1; continue
    if word == "type":
        if i + 1 >= len(rest) or rest[i + 1] != "can":
            fail("type must be can")
        opts["type"] = "can"; i += 2; continue
    if word in ("bitrate", "dbitrate", "sample-point", "dsample-point", "restart-ms", "txqueuelen", "fd",
                "berr-reporting", "loopback", "listen-only", "triple-sampling", "one-shot"):
        if i + 1 >= len(rest):
            fail(f"{word} needs a value")
        opts[word] = rest[i + 1]; i += 2; continue
    fail(f"unknown argument {word}")
can = {k for k in opts if k not in ("type", "txqueuelen")}
if can and opts.get("type") != "can":
    fail("bitrate and the other CAN settings come after 'type can'")
if "bitrate" in opts and int(opts["bitrate"]) not in BITRATES:
    fail(f"bitrate {opts['bitrate']} is not a standard CAN bit rate {sorted(BITRATES)}")
if ("dbitrate" in opts) != (opts.get("fd") == "on"):
    fail("dbitrate goes with fd on, and fd on needs dbitrate")
if "dbitrate" in opts and int(opts["dbitrate"]) not in DATA_BITRATES:
    fail(f"dbitrate {opts['dbitrate']} is not a CAN FD data bit rate {sorted(DATA_BITRATES)}")
for flag in ("fd", "berr-reporting", "loopback", "listen-only", "triple-sampling", "one-shot"):
    if flag in opts and opts[flag] not in ("on", "off"):
        fail(f"{flag} is on or off")
for number in ("restart-ms", "txqueuelen"):
    if number in opts and not opts[number].isdigit():
        fail(f"{number} is a number")
if "sample-point" in opts and not 0 < float(opts["sample-point"]) < 1:
    fail("sample-point is between 0 and 1 (0.875)")
if state is None and not opts:
    fail("nothing to set")
if state == "up" and opts.get("type") == "can" and "bitrate" not in opts:
    fail("a CAN interface goes up with its bit timing: bitrate N")
"""

_SLCAND = """\
import os, re, sys
if os.environ.get("SERVOBUS_DOCS_ROOT") != "1":
    sys.exit("slcand: failed to open the TTY: Permission denied (run it with sudo)")
args = sys.argv[1:]
positional = []
rest = iter(args)
for arg in rest:
    if arg in ("-S", "-t"):  # (their value as the next argument)
        next(rest, None)
    elif arg.startswith("-"):
        if not re.fullmatch(r"-(o|c|f|F|s[0-8]|S\\d+|t(hw|sw))", arg):
            sys.exit(f"slcand (docs shim): unknown option {arg} (-o -c -f -s0..-s8 -S baud)")
    else:
        positional.append(arg)
if len(positional) > 2:
    sys.exit(f"slcand (docs shim): one TTY and at most one interface name, not {positional}")
speeds = [a for a in args if re.fullmatch(r"-s[0-8]", a)]
if len(speeds) != 1:
    sys.exit("slcand (docs shim): give the CAN bit rate once: -s8 is 1 Mbit/s, -s6 500 kbit/s")
if not positional or not os.path.exists(positional[0]):
    sys.exit(f"slcand (docs shim): no such TTY {positional[:1]}")
if len(positional) == 2 and not re.fullmatch(r"(slcan|can)\\d+", positional[1]):
    sys.exit(f"slcand (docs shim): {positional[1]} is not an interface name")
"""

_PIP = """\
import re, sys, tomllib
from importlib import metadata
from pathlib import Path
args = sys.argv[1:]
assert args and args[0] == "install", "pip (docs shim): only 'pip install'"
extras = tomllib.loads(Path(%(pyproject)r).read_text())["project"]["optional-dependencies"]
for spec in args[1:]:
    if spec.startswith("-"):
        sys.exit(f"pip (docs shim): option {spec} not expected here")
    m = re.fullmatch(r"([A-Za-z0-9_.-]+)(?:\\[([\\w,-]+)\\])?(?:[<>=!~].*)?", spec)
    if not m:
        sys.exit(f"pip (docs shim): not a requirement: {spec}")
    name, wanted = m.group(1), m.group(2)
    if name == "servobus":
        for extra in (wanted or "").split(","):
            if extra and extra not in extras:
                sys.exit(f"WARNING: servobus does not provide the extra '{extra}'")
    else:
        metadata.version(name)  # a package the project's environment has
"""

_SERVOBUS = """\
import os, re, sys
sys.path.insert(0, %(tests)r)
args = sys.argv[1:]
from servobus.cli import main
line = " ".join(args)
# a simulator behind a pty on a loaded computer answers slower than a motor: a timeout of its pace
if os.environ.get("SERVOBUS_DOCS_PTYS") and "--timeout-ms" not in args:
    if any(pty in args for pty in os.environ["SERVOBUS_DOCS_PTYS"].split(os.pathsep)):
        args += ["--timeout-ms", "200"]
if not re.search(r"(-i|--interface)[ =]socketcan\\b", line):
    sys.exit(main(args))
from cli._virtual import served_on_virtual
from servobus.cli._connect import sim_devices
family = re.search(r"(?:-f|--family)[ =](\\S+)", line)
from _docs_blocks import highest_id
devices = sim_devices(family.group(1) if family else "myactuator", tuple(range(1, highest_id(line) + 1)))
# a virtual channel of this process named as the page's interface, so that what is printed is the same
with served_on_virtual(devices, channel="can0"):
    code = main(["virtual" if arg == "socketcan" else arg for arg in args])
sys.exit(code)
"""

SHIMS = {
    "sudo": _SUDO,
    "ip": _IP,
    "slcand": _SLCAND,
    "pip": _PIP % {"pyproject": str(ROOT / "pyproject.toml")},
    "servobus": _SERVOBUS % {"tests": str(TESTS)},
}
