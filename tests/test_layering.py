"""Sans-IO below the Bus: these modules never await, sleep or read a clock (design.md, "Layers").

Checked on the source, so a violation fails here before it can hide in a timing-dependent test.
Later layers add their sans-IO modules (protocols/, scheduler.py, sim device models) to SANS_IO.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "servobus"
SANS_IO = ["codec", "frame.py", "errors.py", "protocols", "scheduler.py"]
FORBIDDEN_MODULES = {"asyncio", "anyio", "time", "threading", "socket", "selectors", "serial", "can"}
FORBIDDEN_CALLS = {("datetime", "now"), ("datetime", "utcnow")}


def _sans_io_files() -> list[Path]:
    files: list[Path] = []
    for entry in SANS_IO:
        path = SRC / entry
        files += sorted(path.rglob("*.py")) if path.is_dir() else [path] if path.exists() else []
    return files


@pytest.mark.parametrize("path", _sans_io_files(), ids=lambda p: str(p.relative_to(SRC)))
def test_sans_io_module_imports_no_io_or_clock(path: Path) -> None:
    tree = ast.parse(path.read_text(), filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module]
        elif isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
            clock = (node.value.id, node.attr) in FORBIDDEN_CALLS
            assert not clock, f"{path.name}:{node.lineno} reads a clock"
            continue
        else:
            continue
        for name in names:
            assert name.split(".")[0] not in FORBIDDEN_MODULES, f"{path.name}:{node.lineno} imports {name}"
