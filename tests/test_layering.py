"""Sans-IO below the Bus: these modules never await, sleep or read a clock (design.md, "Layers").

Checked on the source, so a violation fails here before it can hide in a timing-dependent test.
Later layers add their sans-IO modules (protocols/, scheduler.py, sim device models) to SANS_IO.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from servobus.protocols import FAMILIES

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


#: Modules that reach a family only through the registry and its parts (design.md: "a family is a
#: plug-in"): the serial transport asks ``Family.serial``, the simulator's command line, ``--sim N``
#: and the demo ask ``FAMILY.part("sim")``.
FAMILY_FREE = ["transports", "sim", "cli/_connect.py", "cli/sim.py", "cli/demo.py", "cli/_demo_report.py"]
FAMILY_NAME = re.compile(r"myactuator|\blk\b|hollow", re.IGNORECASE)
#: call keywords and constants whose strings are help texts (examples may name a family)
HELP_KEYWORDS = {"help", "epilog"}


def family_mentions(source: str) -> list[str]:
    """Line-numbered imports of a family's package, and family names in code: strings and names
    outside docstrings, comments and help texts (``help=``/``epilog=``, an ``EPILOG`` constant)."""
    tree = ast.parse(source)
    allowed: set[int] = set()  # ids of string nodes that are documentation
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if isinstance(body, list) and body and isinstance(body[0], ast.Expr):
            allowed.add(id(body[0].value))
        if isinstance(node, ast.keyword) and node.arg in HELP_KEYWORDS:
            allowed.update(id(n) for n in ast.walk(node.value))
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id.endswith("EPILOG") for t in node.targets
        ):
            allowed.update(id(n) for n in ast.walk(node.value))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module:
            modules = [node.module] + [f"{node.module}.{alias.name}" for alias in node.names]
        elif isinstance(node, ast.Import):
            modules = [alias.name for alias in node.names]
        else:
            modules = []
        for module in modules:
            parts = module.split(".")
            if parts[:2] == ["servobus", "protocols"] and len(parts) > 2 and parts[2] in FAMILIES:
                found.append(f"{node.lineno}: imports {module}")
                break
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in allowed:
            if FAMILY_NAME.search(node.value):
                found.append(f"{node.lineno}: names a family in {node.value!r}")
        elif isinstance(node, ast.Name) and FAMILY_NAME.search(node.id.replace("_", " ")):
            found.append(f"{node.lineno}: names a family in {node.id}")
        elif isinstance(node, ast.Attribute) and FAMILY_NAME.search(node.attr.replace("_", " ")):
            found.append(f"{node.lineno}: names a family in .{node.attr}")
    return sorted(set(found), key=lambda line: int(line.split(":")[0]))


def _family_free_files() -> list[Path]:
    files: list[Path] = []
    for entry in FAMILY_FREE:
        path = SRC / entry
        files += sorted(path.glob("*.py")) if path.is_dir() else [path]
    return files


@pytest.mark.parametrize("path", _family_free_files(), ids=lambda p: str(p.relative_to(SRC)))
def test_the_transports_and_the_simulator_name_no_family(path: Path) -> None:
    assert family_mentions(path.read_text()) == []


def test_the_family_check_catches_names_and_imports() -> None:
    source = "\n".join(
        [
            '"""The hollow converter (a docstring may name it)."""',
            "from servobus.protocols.hollow.sim import SIM",
            "from servobus.protocols import myactuator as ma",
            "import servobus.protocols.lk",
            "from servobus.protocols import get_family",
            "x = get_family('hollow')",
            "click.option('--fd', help='CAN FD (hollow)')",
            "EPILOG = 'servobus sim --family lk'",
            "if family == 'myactuator': pass",
            "lk_motor = 1",
        ]
    )
    assert family_mentions(source) == [
        "2: imports servobus.protocols.hollow.sim",
        "3: imports servobus.protocols.myactuator",
        "4: imports servobus.protocols.lk",
        "6: names a family in 'hollow'",
        "9: names a family in 'myactuator'",
        "10: names a family in lk_motor",
    ]
