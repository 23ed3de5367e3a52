"""Shared plumbing for the bench/ scripts: where results go and how they are written.

Every benchmark owns one top-level key of ``bench/results.json`` (``codec``, ``transport``, ``bus``, ...)
and one section of ``bench/RESULTS.md`` delimited by ``<!-- <key>:begin -->`` / ``<!-- <key>:end -->``.
A script replaces only its own key and its own section and leaves everything else byte for byte as it
was (design.md, "bench/results.json"). Both updates are read-modify-write under an exclusive lock on
the output directory, so two benchmarks finishing at the same time cannot drop each other's figures,
and the new file is moved into place atomically, so an interrupted run never leaves half a file.

Also here: a description of the machine (every published figure states where it was measured) and a
Markdown table formatter.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import fcntl
import json
import os
import platform
import re
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

__all__ = [
    "BENCH_DIR",
    "machine_info",
    "markdown_table",
    "replace_markdown_section",
    "update_results_json",
]

BENCH_DIR = Path(__file__).resolve().parent

_MD_TITLE = (
    "# servobus benchmark results\n\nEach section is written by the script it names; rerun it to refresh.\n"
)


def machine_info() -> dict[str, Any]:
    """Where and with what a benchmark ran: OS, CPU model, core count, Python, UTC date."""
    return {
        "platform": platform.platform(),
        "machine": platform.machine(),
        "cpu_model": _cpu_model(),
        "cpu_count": os.cpu_count() or 0,
        "python": f"{platform.python_implementation()} {platform.python_version()}",
        "date_utc": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M:%SZ"),
    }


def _cpu_model() -> str:
    try:
        text = Path("/proc/cpuinfo").read_text(errors="replace")
    except OSError:
        return platform.processor() or "unknown"
    for key in ("model name", "Hardware", "cpu model", "Processor"):
        match = re.search(rf"^{key}\s*:\s*(.+)$", text, re.MULTILINE)
        if match:
            return match.group(1).strip()
    return platform.processor() or "unknown"


def markdown_table(headers: Sequence[str], rows: Sequence[Sequence[object]], align: str = "") -> str:
    """A GitHub Markdown table. ``align`` holds one of ``l``/``r``/``c`` per column (default: left)."""
    align = align.ljust(len(headers), "l")
    marks = {"l": "---", "r": "---:", "c": ":---:"}
    lines = [
        "| " + " | ".join(headers) + " |",
        "|" + "|".join(marks[a] for a in align) + "|",
    ]
    lines += ["| " + " | ".join(str(cell) for cell in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


@contextlib.contextmanager
def _locked(directory: Path) -> Iterator[None]:
    # flock on the directory itself: no lock file left lying around in bench/.
    fd = os.open(directory, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # closing releases the lock


def _write_atomically(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def update_results_json(path: Path, key: str, value: Any) -> None:
    """Set ``path[key] = value`` in the shared JSON file, keeping every other key as it is.

    Raises:
        ValueError: the existing file is not a JSON object (it is left untouched rather than
            overwritten, since it holds other benchmarks' figures).
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    with _locked(path.parent):
        data: dict[str, Any] = {}
        if path.exists():
            text = path.read_text(encoding="utf-8")
            if text.strip():
                try:
                    loaded = json.loads(text)
                except json.JSONDecodeError as exc:
                    raise ValueError(f"{path} is not valid JSON ({exc}); fix or delete it") from exc
                if not isinstance(loaded, dict):
                    raise ValueError(f"{path} holds a JSON {type(loaded).__name__}, expected an object")
                data = loaded
        data[key] = value
        _write_atomically(path, json.dumps(data, sort_keys=True, indent=2) + "\n")


def replace_markdown_section(path: Path, key: str, body: str) -> None:
    """Put ``body`` between ``<!-- key:begin -->`` and ``<!-- key:end -->`` in ``path``.

    An existing section is replaced in place; otherwise the section is appended (a new file starts
    with a short title). Text outside the markers is not touched.

    Raises:
        ValueError: the file has a begin marker without its end marker, or the markers twice.
    """
    begin, end = f"<!-- {key}:begin -->", f"<!-- {key}:end -->"
    section = f"{begin}\n{body.rstrip()}\n{end}"
    path.parent.mkdir(parents=True, exist_ok=True)
    with _locked(path.parent):
        text = path.read_text(encoding="utf-8") if path.exists() else ""
        n_begin, n_end = text.count(begin), text.count(end)
        if (n_begin, n_end) == (0, 0):
            base = text.rstrip("\n") if text.strip() else _MD_TITLE.rstrip("\n")
            text = f"{base}\n\n{section}\n"
        elif (n_begin, n_end) == (1, 1) and text.index(begin) < text.index(end):
            head, rest = text.split(begin, 1)
            _, tail = rest.split(end, 1)
            text = f"{head}{section}{tail}"
        else:
            raise ValueError(f"{path}: markers {begin} / {end} are unbalanced; fix the file by hand")
        _write_atomically(path, text)


if __name__ == "__main__":  # pragma: no cover - a helper module, not a benchmark
    json.dump(machine_info(), sys.stdout, indent=2)
    print()
