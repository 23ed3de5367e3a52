"""Helpers for the bus commands' tests: ``servobus`` through ``main`` (exit codes, one-line errors),
simulated motors the test keeps hold of, and the simulator's pty server in a subprocess."""

from __future__ import annotations

import contextlib
import json
import subprocess
import sys
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import pytest

import servobus.cli._connect as connect
from servobus.cli import main

#: ``servobus`` as a subprocess (the console script's own entry point)
SERVOBUS = [sys.executable, "-c", "import sys; from servobus.cli import main; sys.exit(main())"]


def run(capsys: pytest.CaptureFixture[str], args: Sequence[str], code: int = 0) -> tuple[str, str]:
    """``servobus ARGS`` through ``main``; the exit code checked; (stdout, stderr)."""
    capsys.readouterr()
    got = main(list(args))
    out, err = capsys.readouterr()
    assert got == code, (got, out, err)
    return out, err


def run_json(capsys: pytest.CaptureFixture[str], args: Sequence[str], code: int = 0) -> Any:
    out, _ = run(capsys, [*args, "--json"], code)
    return json.loads(out)


def one_line(capsys: pytest.CaptureFixture[str], args: Sequence[str], code: int = 2) -> str:
    """``servobus ARGS`` fails with ``code`` and exactly one line on stderr, no traceback (returned)."""
    _, err = run(capsys, args, code)
    assert len(err.splitlines()) == 1, err
    assert "Traceback" not in err
    return err


class Devices:
    """The simulated motors ``--sim`` builds, kept for the test to inspect (one list per bus opened)."""

    def __init__(self) -> None:
        self.made: list[list[Any]] = []

    @property
    def last(self) -> list[Any]:
        assert self.made, "no simulated bus was opened"
        return self.made[-1]


def keep_devices(monkeypatch: pytest.MonkeyPatch) -> Devices:
    """Have ``--sim`` hand the test every simulated motor it builds."""
    kept = Devices()
    build = connect.sim_devices

    def sim_devices(family: str, ids: tuple[int, ...], revision: str | None = None) -> list[Any]:
        made = build(family, ids, revision)
        kept.made.append(made)
        return made

    monkeypatch.setattr(connect, "sim_devices", sim_devices)
    return kept


@contextlib.contextmanager
def pty_simulators() -> Iterator[Callable[..., str]]:
    """``start(*args)`` runs ``servobus sim ARGS`` (a real pty server in its own process) and returns
    its pty path; every server is stopped (SIGTERM, exit 0) at the end."""
    processes: list[subprocess.Popen[str]] = []

    def start(*args: str) -> str:
        process = subprocess.Popen(
            [*SERVOBUS, "sim", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
        processes.append(process)
        assert process.stdout is not None
        path = process.stdout.readline().strip()
        assert path.startswith("/"), f"first line {path!r}"
        return path

    try:
        yield start
    finally:
        for process in processes:  # (all told first: one slow to go leaves none of the others running)
            process.terminate()
        codes = [process.wait(timeout=5) for process in processes]
        assert codes == [0] * len(processes), codes
