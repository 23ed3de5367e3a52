"""Where the time goes: summaries of cProfile runs and py-spy recordings, for RESULTS.md and results.json.

* :func:`cprofile` runs a callable under :mod:`cProfile` and returns the functions with the most own
  time (``tottime``) and the most inclusive time (``cumtime``), as shares of the profiled total.
* :func:`pyspy_record` runs a command under ``py-spy record --format raw`` (collapsed stacks);
  :func:`collapsed` summarises such a file the same way: own time is the leaf frame's samples,
  inclusive time every sample a function is anywhere on the stack in, both as shares of all samples;
  ``by_area`` adds own time up by where the code lives (servobus's modules, asyncio, the selector, ...).
* :func:`markdown` renders either summary as a short table.
"""

from __future__ import annotations

import cProfile
import linecache
import math
import os
import pstats
import re
import shutil
import subprocess
from collections import Counter
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

__all__ = ["collapsed", "cprofile", "markdown", "pyspy_available", "pyspy_record"]

# Frames every run has at the bottom of its stack: left out of the inclusive lists (always ~100 %).
_WRAPPERS = (
    "asyncio/runners.py",
    "asyncio/base_events.py",
    "asyncio/events.py",
    "(~",
    "(<string>",
    "threading.py",
)


def _wrapper(name: str) -> bool:
    return any(w in name for w in _WRAPPERS) or name.startswith(
        ("<module>", "<lambda>", "main (", "spin (", "host_main (")
    )


_FRAME = re.compile(r"^(?P<func>.*?) \((?P<file>.*?)(?::(?P<line>\d+))?\)$")


def _short(path: str) -> str:
    for marker in ("/src/servobus/", "/site-packages/", "/lib/python3"):
        if marker in path:
            tail = path.split(marker, 1)[1]
            return ("servobus/" if marker == "/src/servobus/" else "") + (
                tail.split("/", 1)[1] if marker == "/lib/python3" and "/" in tail else tail
            )
    if "/bench/" in path:
        return "bench/" + path.split("/bench/", 1)[1]
    return path


def _syscall(file: str, line: str) -> str | None:
    """py-spy shows no C frames: a leaf frame on a line that calls select/epoll or os.read/os.write
    is time spent in that system call (waiting in the first case)."""
    if not line.isdigit():
        return None
    text = linecache.getline(file, int(line))
    if not text and not os.path.isabs(file):  # py-spy names a script by its file name alone
        text = linecache.getline(str(Path(__file__).resolve().parent / file), int(line))
    if "select(" in text or ".poll(" in text:
        return "waiting in select/epoll (idle, or the system call itself)"
    if "os.write(" in text or "os.read(" in text:
        return "os.write / os.read system calls (pty)"
    return None


def _area(file: str, func: str, line: str = "") -> str:
    """A coarse bucket for own time: which layer the code belongs to."""
    if (syscall := _syscall(file, line)) is not None:
        return syscall
    f = _short(file)
    if f.startswith("servobus/"):
        name = f.removeprefix("servobus/").removesuffix(".py")
        if name.startswith(("protocols/", "core/")):
            return "servobus codec (protocols, core)"
        if name.startswith("sim/"):
            return "servobus.sim (devices, bus model)"
        return f"servobus.{name.replace('/', '.')}"
    if "selectors" in f or func in ("select", "poll", "<built-in method select.epoll.poll>"):
        return "waiting in select/epoll (idle, or the system call itself)"
    if f.startswith("asyncio/"):
        return "asyncio (event loop, futures, tasks)"
    if f.startswith(("serial", "serial_asyncio_fast")):
        return "pyserial / pyserial-asyncio-fast"
    if f.startswith("bench/"):
        return "bench harness"
    return "builtins and other stdlib"


def cprofile(run: Callable[[], object], top: int = 12) -> dict[str, Any]:
    """Profile ``run()`` with cProfile; return the top functions by own and by inclusive time."""
    profiler = cProfile.Profile()
    profiler.enable()
    try:
        run()
    finally:
        profiler.disable()
    stats = pstats.Stats(profiler)
    raw: dict[Any, Any] = stats.stats  # type: ignore[attr-defined]
    total = max(float(stats.total_tt), 1e-12)  # type: ignore[attr-defined]
    rows = []
    areas: Counter[str] = Counter()
    for (file, line, func), (_cc, ncalls, tottime, cumtime, _callers) in raw.items():
        name = f"{func} ({_short(file)}:{line})"
        rows.append((name, ncalls, tottime, cumtime))
        areas[_area(file, func)] += tottime
    own = sorted(rows, key=lambda r: -r[2])[:top]
    inclusive = sorted((r for r in rows if not _wrapper(r[0])), key=lambda r: -r[3])[:top]
    return {
        "tool": "cProfile",
        "total_s": round(total, 4),
        "own": [{"function": n, "calls": c, "pct": round(100 * t / total, 1)} for n, c, t, _ in own],
        "inclusive": [
            {"function": n, "calls": c, "pct": round(100 * ct / total, 1)} for n, c, _, ct in inclusive
        ],
        "by_area": [{"area": a, "pct": round(100 * t / total, 1)} for a, t in areas.most_common()],
    }


def pyspy_available() -> bool:
    return shutil.which("py-spy") is not None


def pyspy_wrap(out: Path, rate: int = 250) -> list[str]:
    """The ``py-spy record`` prefix of :func:`pyspy_record`'s command, for a process started elsewhere."""
    return [
        "py-spy",
        "record",
        "--format",
        "raw",
        "--idle",
        "--nonblocking",
        "--rate",
        str(rate),
        "--output",
        str(out),
        "--",
    ]


def pyspy_record(
    command: Sequence[str],
    out: Path,
    *,
    rate: int = 250,
    env: dict[str, str] | None = None,
    timeout: float = 600,
) -> subprocess.CompletedProcess[str]:
    """Run ``command`` under ``py-spy record --format raw --idle --nonblocking``; stacks go to ``out``.

    ``--nonblocking``: py-spy reads the process's memory without pausing it, so the run keeps its
    timing (a stack may occasionally be torn; py-spy counts those as errors). ``--idle`` keeps the
    samples where the thread waits (in the selector), so the shares add up to the whole wall time.
    """
    return subprocess.run(
        [*pyspy_wrap(out, rate), *command],
        capture_output=True,
        text=True,
        env={**os.environ, **(env or {})},
        timeout=timeout,
        check=False,
    )


def collapsed(path: Path, top: int = 12, *, main_thread_only: bool = True) -> dict[str, Any]:
    """Summarise py-spy's raw output (``frame;frame;... count`` per line, outermost frame first).

    ``own``: the leaf frame's function (every line of it); ``own_lines``: the leaf line; ``inclusive``:
    every function on the stack, once per sample (the event loop's own frames left out).
    ``main_thread_only``: leave out stacks that start in ``threading.py`` (helper threads, e.g. an idle
    executor worker, which ``--idle`` samples too): the shares are then of the main thread's time.
    Stacks inside an import (start-up) are left out too.
    """
    own: Counter[str] = Counter()
    own_lines: Counter[str] = Counter()
    inclusive: Counter[str] = Counter()
    areas: Counter[str] = Counter()
    total = 0
    for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
        stack, _, count_text = line.rpartition(" ")
        if not stack or not count_text.isdigit():
            continue
        count = int(count_text)
        frames = []
        for part in stack.split(";"):
            match = _FRAME.match(part.strip())
            if match is None:
                continue  # the process/thread header py-spy may put first
            frames.append((match["func"], match["file"], match["line"] or ""))
        if not frames or (main_thread_only and frames[0][1].endswith("threading.py")):
            continue
        if any(f[1].startswith("<frozen importlib") for f in frames):
            continue  # start-up imports, not the measured work
        total += count
        func, file, lineno = frames[-1]
        own[f"{func} ({_short(file)})"] += count
        own_lines[f"{func} ({_short(file)}:{lineno})" if lineno else f"{func} ({_short(file)})"] += count
        areas[_area(file, func, lineno)] += count
        for name in {f"{f} ({_short(fl)})" for f, fl, _ in frames}:
            inclusive[name] += count
    total = max(total, 1)

    def shares(counter: Counter[str]) -> list[dict[str, Any]]:
        return [
            {"function": n, "pct": round(100 * c / total, 1)}
            for n, c in counter.most_common()
            if not _wrapper(n)
        ][:top]

    return {
        "tool": "py-spy",
        "samples": total,
        "own": shares(own),
        "own_lines": shares(own_lines),
        "inclusive": shares(inclusive),
        "by_area": [{"area": a, "pct": round(100 * c / total, 1)} for a, c in areas.most_common()],
    }


def markdown(
    summary: dict[str, Any], top: int = 10, *, unit_us: float | None = None, unit: str = ""
) -> list[str]:
    """A profile summary as Markdown lines: own time by area, then the top functions.

    ``unit_us``: the measured (unprofiled) cost of one ``unit`` (a transaction, a tick): each share is
    then also shown as µs of it.
    """
    if not summary:
        return ["(no profile)"]
    if summary["tool"] == "cProfile":
        basis = f"cProfile, {summary['total_s']:.2f} s profiled (cProfile's overhead inflates small calls)"
    else:
        basis = f"py-spy, {summary['samples']:,} samples"

    def cell(entry: dict[str, Any] | None) -> str:
        if entry is None:
            return " | "
        us = f" ({entry['pct'] / 100 * unit_us:.2f} µs)" if unit_us is not None else ""
        return f"{entry['pct']:.1f}{us} | `{entry['function']}`"

    per = f" (µs per {unit})" if unit_us is not None else ""
    lines = [
        f"Own time by area ({basis}): "
        + "; ".join(
            f"{a['area']} {a['pct']:.0f} %" + (f" ({a['pct'] / 100 * unit_us:.2f} µs)" if unit_us else "")
            for a in summary["by_area"]
            if a["pct"] >= 1.0
        )
        + ".",
        "",
        f"| own %{per} | function | | inclusive %{per} | function |",
        "|---:|---|---|---:|---|",
    ]
    own, inclusive = summary["own"][:top], summary["inclusive"][:top]
    for i in range(max(len(own), len(inclusive))):
        a = own[i] if i < len(own) else None
        b = inclusive[i] if i < len(inclusive) else None
        lines.append(f"| {cell(a)} | | {cell(b)} |")
    if summary.get("own_lines"):
        lines += [
            "",
            "Hottest lines (own time): "
            + "; ".join(
                f"`{e['function']}` {e['pct']:.1f} %"
                + (f" ({e['pct'] / 100 * unit_us:.2f} µs)" if unit_us is not None else "")
                for e in summary["own_lines"][: max(5, top // 2)]
            )
            + ".",
        ]
    return lines


def proc_cpu_s(pid: int) -> float:
    """User + system CPU seconds of process ``pid`` so far (Linux /proc)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return math.nan
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
