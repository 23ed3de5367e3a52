"""Sans-IO below the Bus: these modules never await, sleep or read a clock (design.md, "Layers").

Checked on the source, so a violation fails here before it can hide in a timing-dependent test.
Later layers add their sans-IO modules (protocols/, scheduler.py, sim device models) to SANS_IO.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "servobus"
SANS_IO = [
    "core",
    "frame.py",
    "errors.py",
    "protocols",
    "scheduler.py",
    "timing.py",
    "sim/canbus.py",
    "sim/plant.py",
    "sim/slcan.py",
    "sim/faults.py",
    "sim/device.py",
    "sim/network.py",
    "sim/corenet.py",
    "sim/coreplant.py",
    "sim/family.py",
]
FORBIDDEN_MODULES = {"asyncio", "anyio", "time", "threading", "socket", "selectors", "serial", "can"}
FORBIDDEN_CALLS = {("datetime", "now"), ("datetime", "utcnow")}


def violations(source: str) -> list[str]:
    """Line-numbered imports of I/O or clock modules, and clock reads, in ``source``."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module]
        elif isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
            if (node.value.id, node.attr) in FORBIDDEN_CALLS:
                found.append(f"{node.lineno}: reads a clock ({node.value.id}.{node.attr})")
            continue
        else:
            continue
        found += [f"{node.lineno}: imports {n}" for n in names if n.split(".")[0] in FORBIDDEN_MODULES]
    return found


def _sans_io_files() -> list[Path]:
    files: list[Path] = []
    for entry in SANS_IO:
        path = SRC / entry
        files += sorted(path.rglob("*.py")) if path.is_dir() else [path] if path.exists() else []
    return files


@pytest.mark.parametrize("path", _sans_io_files(), ids=lambda p: str(p.relative_to(SRC)))
def test_sans_io_module_imports_no_io_or_clock(path: Path) -> None:
    assert violations(path.read_text()) == []


def test_the_check_catches_violations() -> None:
    source = "\n".join(
        [
            "import asyncio",
            "from time import monotonic",
            "import can.interfaces",
            "x = datetime.now()",
            "import math",
        ]
    )
    assert sorted(violations(source)) == [
        "1: imports asyncio",
        "2: imports time",
        "3: imports can.interfaces",
        "4: reads a clock (datetime.now)",
    ]
