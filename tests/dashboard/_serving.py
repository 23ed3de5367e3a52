"""``servobus dashboard`` as a subprocess for tests: started on a free port, its URL read from its
first line, always killed on the way out."""

from __future__ import annotations

import contextlib
import os
import re
import selectors
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import IO

# (the package's own entry point, whether or not the ``servobus`` script is on PATH)
COMMAND = [sys.executable, "-c", "import sys; from servobus.cli import main; sys.exit(main())", "dashboard"]
URL = re.compile(r"^servobus dashboard: (https?://\S+/) \(")


@dataclass
class Served:
    """A running ``servobus dashboard``: its process, the URL of its first line and that line."""

    process: subprocess.Popen[bytes]
    url: str
    first_line: str
    _stderr: IO[bytes]

    def stderr(self) -> str:
        """What it wrote on stderr so far (for a failing test's message)."""
        self._stderr.flush()
        with open(self._stderr.name, "rb") as f:
            return f.read().decode(errors="replace")


def _first_line(process: subprocess.Popen[bytes], timeout_s: float) -> str:
    """The process's first stdout line, waited for at most ``timeout_s`` ("" if it exited first)."""
    assert process.stdout is not None
    deadline = time.monotonic() + timeout_s
    got = b""
    with selectors.DefaultSelector() as sel:
        sel.register(process.stdout, selectors.EVENT_READ)
        while b"\n" not in got:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError(f"no first line from servobus dashboard in {timeout_s} s: {got!r}")
            if sel.select(left):
                chunk = os.read(process.stdout.fileno(), 4096)
                if not chunk:
                    break
                got += chunk
    return got.decode(errors="replace").split("\n", 1)[0]


def stop(process: subprocess.Popen[bytes], timeout_s: float = 10.0) -> int:
    """End ``process``: SIGINT (Ctrl-C: its motors get their stop), SIGKILL if it is still there after
    ``timeout_s``. Its exit status."""
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
        try:
            return process.wait(timeout_s)
        except subprocess.TimeoutExpired:
            process.kill()
    return process.wait(timeout_s)


@contextlib.contextmanager
def dashboard(*args: str, timeout_s: float = 30.0) -> Iterator[Served]:
    """``servobus dashboard ARGS`` (give ``--listen 127.0.0.1:0``) running for the ``with`` block,
    once it printed its URL.

    Raises:
        AssertionError: it ended, or printed something else, before its URL (its stderr said).
        TimeoutError: no first line in ``timeout_s``.
    """
    with tempfile.NamedTemporaryFile(prefix="dashboard-stderr-") as err:
        process = subprocess.Popen(
            [*COMMAND, *args],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=err,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )
        try:
            line = _first_line(process, timeout_s)
            found = URL.match(line)
            served = Served(process, found.group(1) if found else "", line, err)
            assert found, f"servobus dashboard {' '.join(args)}: first line {line!r}; {served.stderr()}"
            yield served
        finally:
            stop(process)
            assert process.stdout is not None
            process.stdout.close()


def run(args: Sequence[str], timeout_s: float = 30.0) -> subprocess.CompletedProcess[str]:
    """``servobus dashboard ARGS`` to its end (for the ones that are refused), killed after
    ``timeout_s``."""
    return subprocess.run(
        [*COMMAND, *args], capture_output=True, text=True, timeout=timeout_s, stdin=subprocess.DEVNULL
    )
