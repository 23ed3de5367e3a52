"""What every published figure states besides itself: the command, the machine, its load, the source.

``python -m bench`` runs every benchmark module in one process and sets :data:`COMMAND_ENV` to its own
command line, so each section of RESULTS.md names the command that actually produced it; a module run
on its own (``python bench/bench_efficiency.py``) names itself.
"""

from __future__ import annotations

import os
import shlex
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import _results

__all__ = ["COMMAND_ENV", "command_line", "load_average", "meta", "source_state"]

REPO = Path(__file__).resolve().parent.parent
COMMAND_ENV = "SERVOBUS_BENCH_COMMAND"


def command_line(script: str, arguments: Sequence[str]) -> str:
    """The command as run: ``python -m bench ...`` when the runner set it, else this script's own."""
    outer = os.environ.get(COMMAND_ENV)
    if outer:
        return outer
    command = shlex.join([Path(sys.executable).name, script, *arguments])
    pythonpath = os.environ.get("PYTHONPATH")
    return f"PYTHONPATH={shlex.quote(pythonpath)} {command}" if pythonpath else command


def load_average() -> list[float]:
    """The 1, 5 and 15 minute load averages (others' work on this shared machine skews a run)."""
    return [round(x, 2) for x in os.getloadavg()]


def source_state() -> dict[str, Any]:
    """The commit measured, and which files under src/ differed from it (others edit the tree too)."""

    def git(*args: str) -> str:
        try:
            done = subprocess.run(["git", *args], cwd=REPO, capture_output=True, text=True, timeout=10)
        except (OSError, subprocess.TimeoutExpired):
            return ""
        return done.stdout.strip() if done.returncode == 0 else ""

    status = git("status", "--porcelain", "--", "src")
    return {
        "commit": git("rev-parse", "--short", "HEAD"),
        "src_changes": [s.strip() for s in status.splitlines()],
    }


def meta(script: str, arguments: Sequence[str], **extra: Any) -> dict[str, Any]:
    """The ``meta`` entry of a results.json key: command, machine, load now, source, and ``extra``."""
    import servobus

    return {
        "command": command_line(script, arguments),
        "machine": _results.machine_info(),
        "servobus": servobus.__version__,
        "servobus_path": str(Path(servobus.__file__).resolve().parent),
        "source": source_state(),
        **extra,
    }


def header_lines(title: str, info: dict[str, Any]) -> list[str]:
    """The lines that open a RESULTS.md section: command, date, machine, Python, load."""
    machine = info["machine"]
    source = info["source"]
    changed = (
        f"; uncommitted changes under src/ at run time: {', '.join(source['src_changes'])}"
        if source["src_changes"]
        else "; src/ clean"
    )
    load = info.get("load_average_at_start")
    lines = [
        title,
        "",
        f"- Command: `{info['command']}` (from the repository root"
        + (f"; this part {info['runtime_s']:.0f} s)" if "runtime_s" in info else ")"),
        f"- Date: {machine['date_utc']}; servobus {info['servobus']}, commit {source['commit']}{changed}",
        f"- Machine: {machine['platform']}; CPU {machine['cpu_model']}, {machine['cpu_count']} cores "
        "(shared with other work)",
        f"- Python: {machine['python']}"
        + (
            "; load average (1, 5, 15 min) at start: " + ", ".join(f"{x:.2f}" for x in load)
            if load is not None
            else ""
        ),
    ]
    return lines
