"""The layers (design.md, "Layers"), checked on the source so a violation fails here before it can
hide in a timing-dependent test:

* sans-IO below the Bus: these modules never await, sleep or read a clock; later layers add their
  sans-IO modules (protocols/, scheduler.py, sim device models) to SANS_IO;
* the direction of imports: every module imports only from its own layer or the layers below it
  (the table and its rules are below, with the section's tests); no transport imports a family or
  the simulator's device models.
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
    "sim/corenodes.py",
    "sim/deadlines.py",
    "sim/coreplant.py",
    "sim/family.py",
    "sim/episodes.py",
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


#: sans-IO violations in modules this test does not own, reported to the coordinator: file -> reason
SANS_IO_KNOWN: dict[str, str] = {}  # a file here is a known violation (xfail, strict), with why


def _sans_io_params() -> list[object]:
    params: list[object] = []
    for path in _sans_io_files():
        name = str(path.relative_to(SRC))
        known = SANS_IO_KNOWN.get(name)
        marks = [pytest.mark.xfail(reason=known, strict=True)] if known else []
        params.append(pytest.param(path, id=name, marks=marks))
    return params


@pytest.mark.parametrize("path", _sans_io_params())
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


# ---- the direction of imports between layers ----
#
# Every module of servobus belongs to one layer (the longest prefix below that matches its dotted
# name; "<family>" stands for any built-in family), and imports only from the layers MAY_IMPORT
# gives it. Low to high:
#
#   base        the foundation every layer uses: errors, Frame, the C core, timing, the runtime lane,
#               metrics; sans-IO, imports nothing above itself
#   protocols   the family contract and its generic machinery (servobus.protocols, its _modules)
#   family      a family's codec (servobus.protocols.<family>): on the contract, never on what uses it
#   scheduler   the sans-IO request table: on the contract, never on a family, a link or the Bus
#   transports  the links: on the contract (a serial framing is looked up, never named) and, for the
#               in-process link, on the simulator's network and its device contract (TRANSPORT_SIM)
#               only, never on a family or a device model (the plant, a family's simulated motor)
#   sim         the simulator: networks, plant, device models (servobus.sim, a family's .sim)
#   sim-front   the simulator's I/O (real clock, ptys, python-can, its command line): on the sim
#               and the transports
#   bus         the Bus and what runs beside it (ticks, signals, sync, logs, recording): on the
#               scheduler and the transports, never on the simulator
#   tools       the DBC exporter, log decoding, recording: on the Bus and what is below it
#   testing     the family contract as a test suite (servobus.testing, issue 42): on the simulator's
#               family part and the DBC exporter it checks, imported by tests only
#   app         the command line: any layer
#
# A family's cli and dbc parts and its typed calls (_motor) are in the family layer: they implement
# the contracts of the protocols layer (servobus.protocols.cli, .dbc, ._calls.TypedCalls), which the
# command line, the DBC exporter and the Bus import from there.
#
# A module may also import any module of its own family's package (a family is one plug-in, whose
# parts the contract loads by name; test_family_layering.py checks that nothing else imports one).
# Checked statically: every `import` and `from ... import` anywhere in a module, inside functions
# and `if TYPE_CHECKING:` blocks too, since a lazy or type-only import still points a layer at
# another (the direction is what matters, not when the import runs). Only direct imports are
# checked: a generic registry (servobus.protocols) that loads a family by name at run time does
# not make its importer depend on that family.

PACKAGE = "servobus"
FAMILIES = sorted(
    p.name for p in (SRC / "protocols").iterdir() if p.is_dir() and (p / "__init__.py").exists()
)
LAYERS: dict[str, list[str]] = {
    "base": [
        "servobus._version",
        "servobus._core",
        "servobus._build_core",
        "servobus._plugins",
        "servobus.errors",
        "servobus.frame",
        "servobus.core",
        "servobus.timing",
        "servobus.metrics",
        "servobus.rtt",
        "servobus.runtime",
    ],
    "protocols": ["servobus.protocols", "servobus.limits"],
    "family": ["servobus.protocols.<family>"],
    # the scheduler's and the Bus's parts (issue 28) are named here before they land
    "scheduler": [
        "servobus.scheduler",  # (the package: its parts servobus.scheduler._table, _match, _keys, _hosts)
        "servobus.diagnosis",  # (what the bus saw instead of a reply: sans-IO, asks the registry)
    ],
    "transports": ["servobus.transports"],
    # (servobus.authoring: everything a plug-in family writes with, the simulator's contract too)
    "sim": ["servobus.sim", "servobus.protocols.<family>.sim", "servobus.authoring"],
    "sim-front": [
        "servobus.sim.attach",
        "servobus.sim.pty",
        "servobus.sim.virtual",
        "servobus.sim.__main__",
        "servobus.sim.command",
        "servobus.sim.canfaults",
    ],
    "bus": [
        "servobus",
        "servobus.bus",  # the package: Bus, Motor, engine, tick, delivery, safety, watchdog, ...
        "servobus.ticks",
        "servobus.signals",
        "servobus.sync",
    ],
    # the pipelined fixed-rate loop over many buses (issue 39): above the Bus
    "loop": ["servobus.loop"],
    # buses served to other computers (issue 29): above the Bus, below the command line; no family
    "remote": ["servobus.remote"],
    # what one does with a bus's traffic beside the control loop (issue 38): DBC, logs, recording
    "tools": ["servobus.tools"],
    # the live web page of buses, motors and a loop (issue 40): above all of them, below the CLI
    "dashboard": ["servobus.dashboard"],
    "testing": ["servobus.testing"],
    "app": [
        "servobus.cli",
        "servobus.dbc",  # (the deprecated alias of servobus.protocols.dbc and servobus.tools.dbc)
        "servobus.__main__",
    ],
}
MAY_IMPORT: dict[str, set[str]] = {
    "base": {"base"},
    "protocols": {"base", "protocols"},
    "family": {"base", "protocols"},
    "scheduler": {"base", "protocols", "scheduler"},
    "transports": {"base", "protocols", "transports"},
    "sim": {"base", "protocols", "family", "sim"},
    "sim-front": {"base", "protocols", "family", "sim", "sim-front", "transports"},
    "bus": {"base", "protocols", "family", "scheduler", "transports", "bus"},
    "loop": {"base", "protocols", "scheduler", "transports", "bus", "loop"},
    "remote": {"base", "protocols", "scheduler", "bus", "remote"},
    "tools": {"base", "protocols", "scheduler", "transports", "bus", "tools"},
    "dashboard": {
        "base",
        "protocols",
        "scheduler",
        "transports",
        "bus",
        "loop",
        "remote",
        "tools",
        "dashboard",
    },
    "testing": {"base", "protocols", "scheduler", "transports", "sim", "bus", "tools", "testing"},
    "app": set(LAYERS),
}
#: the simulator modules a transport may import: the networks the in-process link runs and the
#: device contract it passes devices through (not the plant, not a device model)
TRANSPORT_SIM = {
    "servobus.sim.network",
    "servobus.sim.corenet",
    "servobus.sim.canbus",
    "servobus.sim.faults",
    "servobus.sim.device",
    "servobus.sim.episodes",
}
#: violations in modules this test does not own, reported to the coordinator: module -> reason
KNOWN: dict[str, str] = {}
#: imports up the layers a type checker alone sees (inside ``if TYPE_CHECKING:``): module -> {module:
#: why}. Each is checked to stay type-only (test_type_only_imports_stay_type_only).
TYPE_ONLY: dict[str, dict[str, str]] = {
    "servobus.protocols._calls": {
        "servobus.bus": "the typed calls are a Motor to a type checker (user code passes them where a "
        "servobus.Motor is expected); at run time the Bus composes them with its Motor",
    },
    "servobus": {
        "servobus.loop": "servobus.Loop is the package's name for the loop above the Bus: a type "
        "checker sees the class, the run time imports it by name when first used (__getattr__)",
    },
}


def _prefixes() -> list[tuple[str, str]]:
    """(dotted prefix, layer), longest first, with <family> expanded."""
    out = [
        (prefix.replace("<family>", family), layer)
        for layer, prefixes in LAYERS.items()
        for prefix in prefixes
        for family in (FAMILIES if "<family>" in prefix else [""])
    ]
    return sorted(out, key=lambda item: -len(item[0]))


PREFIXES = _prefixes()


def layer_of(module: str) -> str | None:
    """The layer of a dotted servobus module name (None: not in any)."""
    for prefix, layer in PREFIXES:
        if module == prefix or module.startswith(prefix + "."):
            return layer
    return None


def family_of(module: str) -> str | None:
    parts = module.split(".")
    return (
        parts[2]
        if parts[:2] == ["servobus", "protocols"] and len(parts) > 2 and parts[2] in FAMILIES
        else None
    )


def _is_module(dotted: str) -> bool:
    path = SRC.parent.joinpath(*dotted.split("."))
    return path.with_suffix(".py").exists() or (path / "__init__.py").exists()


def imported_modules(source: str, module: str, *, package: bool = False) -> list[tuple[int, str]]:
    """(line, dotted module) of every servobus module ``source`` imports, wherever the import is.

    ``from X import Y`` names X.Y when that is a module (a submodule imported by name), else X.
    ``module`` (and whether it is a package) resolves relative imports.
    """
    found: list[tuple[int, str]] = []
    here = module.split(".") if package else module.split(".")[:-1]
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(here[: len(here) - node.level + 1] + ([base] if base else []))
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                found.append((node.lineno, sub if _is_module(sub) else base))
    return [(line, name) for line, name in found if name == PACKAGE or name.startswith(PACKAGE + ".")]


def type_checking_lines(source: str) -> set[int]:
    """The lines inside ``if TYPE_CHECKING:`` blocks (their ``else:`` aside) of ``source``."""
    lines: set[int] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING":
            for child in node.body:
                lines.update(range(child.lineno, (child.end_lineno or child.lineno) + 1))
    return lines


def import_violations(source: str, module: str, *, package: bool = False) -> list[str]:
    """Line-numbered imports in ``source`` (module ``module``) against the direction of the layers."""
    mine = layer_of(module)
    assert mine is not None, f"{module} is in no layer: add it to LAYERS"
    out = []
    for line, name in imported_modules(source, module, package=package):
        theirs = layer_of(name)
        if family_of(name) is not None and family_of(name) == family_of(module):
            continue  # a family's own parts
        if theirs in MAY_IMPORT[mine] or (mine == "transports" and name in TRANSPORT_SIM):
            continue
        if name in TYPE_ONLY.get(module, {}) and line in type_checking_lines(source):
            continue
        out.append(f"{line}: {mine} imports {name} ({theirs})")
    return out


def _modules() -> list[object]:
    params: list[object] = []
    for path in sorted(SRC.rglob("*.py")):
        parts = list(path.relative_to(SRC.parent).with_suffix("").parts)
        package = parts[-1] == "__init__"
        module = ".".join(parts[:-1] if package else parts)
        marks = [pytest.mark.xfail(reason=KNOWN[module], strict=True)] if module in KNOWN else []
        params.append(pytest.param(path, module, package, id=module, marks=marks))
    return params


@pytest.mark.parametrize(("path", "module", "package"), _modules())
def test_imports_go_down_the_layers(path: Path, module: str, package: bool) -> None:
    assert import_violations(path.read_text(), module, package=package) == []


def test_no_transport_imports_a_family_or_a_device_model() -> None:
    """The issue's rule, said on its own: what the transports import of the families and the sim."""
    found = []
    for path in sorted((SRC / "transports").rglob("*.py")):
        parts = list(path.relative_to(SRC.parent).with_suffix("").parts)
        package = parts[-1] == "__init__"
        module = ".".join(parts[:-1] if package else parts)
        for line, name in imported_modules(path.read_text(), module, package=package):
            if family_of(name) is not None or (layer_of(name) == "sim" and name not in TRANSPORT_SIM):
                found.append(f"{module}:{line}: {name}")
    assert found == []


def test_every_layer_can_be_named_and_the_table_is_a_partial_order() -> None:
    assert set(MAY_IMPORT) == set(LAYERS)
    for layer, allowed in MAY_IMPORT.items():
        assert allowed <= set(LAYERS), layer
        for other in allowed - {layer}:  # no two layers import each other
            assert layer not in MAY_IMPORT[other] or other == "app" or layer == "app", (layer, other)


def test_the_direction_check_catches_violations() -> None:
    source = "\n".join(
        [
            "from __future__ import annotations",
            "from typing import TYPE_CHECKING",
            "from servobus.frame import Frame",
            "from servobus.protocols import get_family, myactuator",
            "from servobus.sim.network import SimCanNetwork",
            "if TYPE_CHECKING:",
            "    from servobus.bus import Bus",
            "def f():",
            "    from servobus.protocols.lk.sim.device import LkMotor",
            "    import servobus.sim.plant",
            "    from . import base",
        ]
    )
    assert import_violations(source, "servobus.transports.example") == [
        "4: transports imports servobus.protocols.myactuator (family)",
        "7: transports imports servobus.bus (bus)",
        "9: transports imports servobus.protocols.lk.sim.device (sim)",
        "10: transports imports servobus.sim.plant (sim)",
    ]
    assert import_violations("from servobus.transports import base", "servobus.frame") == [
        "1: base imports servobus.transports.base (transports)"
    ]
    assert import_violations("from servobus.protocols.lk import codec", "servobus.protocols.lk.sim.x") == []
    assert import_violations("from servobus.protocols.lk import codec", "servobus.protocols.hollow.x") == [
        "1: family imports servobus.protocols.lk.codec (family)"
    ]
