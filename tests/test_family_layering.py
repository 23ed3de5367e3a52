"""Nothing outside ``protocols/<family>/`` names a family or imports one (design.md: "a family is a
plug-in"; issue [families]).

Two checks on the source: no module outside a family's package imports it (any module of
``servobus``), and in the layers that must stay family-blind (the Bus, the scheduler, the
transports, the CLI, the DBC exporter, the simulator's generic modules) no identifier and no code
value names a built-in family; documentation (docstrings, comments, help texts, examples, messages:
strings with spaces in them) may.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from servobus.protocols import FAMILIES

SRC = Path(__file__).resolve().parents[1] / "src" / "servobus"
NAMES = sorted(FAMILIES)
FAMILY_DIRS = [SRC / "protocols" / name for name in NAMES]
WORD = re.compile(r"(?<![a-z])(" + "|".join(NAMES) + r")(?![a-z])", re.IGNORECASE)
#: the family-blind layers the issue names, and the simulator's and the transports' generic modules
BLIND = [
    "bus",
    "scheduler",
    "sync.py",
    "dbc.py",
    "tools",
    "transports",
    "cli",
    "sim",
    # the contracts a family implements, moved out of cli/ and dbc.py (issue 38)
    "protocols/cli.py",
    "protocols/dbc.py",
    "protocols/dbc_layouts.py",
    "protocols/dbc_packed.py",
    "protocols/_calls.py",
]
#: keyword arguments whose strings are documentation (click's and argparse's)
DOC_KEYWORDS = {"help", "epilog", "short_help", "description", "usage", "metavar"}
DOC_CALLS = {"examples"}


def _modules() -> list[Path]:
    return [p for p in sorted(SRC.rglob("*.py")) if not any(d in p.parents for d in FAMILY_DIRS)]


def _blind_modules() -> list[Path]:
    out: list[Path] = []
    for entry in BLIND:
        path = SRC / entry
        out += sorted(path.rglob("*.py")) if path.is_dir() else [path]
    return out


def family_imports(source: str) -> list[str]:
    """Line-numbered imports of a built-in family package in ``source``."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            modules = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module == "servobus.protocols":
            modules = [f"{node.module}.{alias.name}" for alias in node.names]  # a family as a name
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            modules = [node.module]
        else:
            continue
        for module in modules:
            parts = module.split(".")
            if parts[:2] == ["servobus", "protocols"] and len(parts) > 2 and parts[2] in FAMILIES:
                found.append(f"{node.lineno}: imports {module}")
    return found


def _documentation(tree: ast.AST) -> set[int]:
    """ids of the string nodes that are documentation."""
    docs: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                docs.add(id(body[0].value))
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant):
            docs.add(id(node.value))  # attribute docstrings (a string under an assignment)
        if isinstance(node, ast.keyword) and node.arg in DOC_KEYWORDS:
            docs.update(id(n) for n in ast.walk(node.value))
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in DOC_CALLS:
            docs.update(id(n) for arg in node.args for n in ast.walk(arg))
    return docs


def family_names(source: str) -> list[str]:
    """Line-numbered identifiers and code strings in ``source`` that name a built-in family."""
    tree = ast.parse(source)
    docs = _documentation(tree)
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs:
            if node.value.split() != [node.value]:
                continue  # prose: a message, a help text, an example (a value is one word)
            text = node.value
        elif isinstance(node, ast.Name):
            text = node.id
        elif isinstance(node, ast.Attribute):
            text = node.attr
        elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            text = node.name
        elif isinstance(node, ast.arg):
            text = node.arg
        else:
            continue
        if WORD.search(text.replace("_", " ")):
            found.append(f"{node.lineno}: {text[:60]!r}")
    return found


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(SRC)))
def test_no_module_outside_a_family_imports_one(path: Path) -> None:
    assert family_imports(path.read_text()) == []


@pytest.mark.parametrize("path", _blind_modules(), ids=lambda p: str(p.relative_to(SRC)))
def test_the_family_blind_layers_name_no_family_outside_documentation(path: Path) -> None:
    assert family_names(path.read_text()) == []


def test_the_checks_catch_what_they_look_for() -> None:
    source = "\n".join(
        [
            '"""A docstring may say myactuator."""',
            "from servobus.protocols import myactuator as ma",
            "from servobus.protocols.lk.codec import decode_reply",
            "import servobus.protocols.hollow",
            "from servobus.protocols import get_family",
            "def f(x):",
            '    """lk docstring"""',
            '    click.option("--x", help="hollow: documentation")',
            '    if x.family == "lk":',
            "        return _myactuator_identify(x)",
            '    return examples("servobus status --family lk")',
        ]
    )
    assert family_imports(source) == [
        "2: imports servobus.protocols.myactuator",
        "3: imports servobus.protocols.lk.codec",
        "4: imports servobus.protocols.hollow",
    ]
    assert family_names(source) == ["9: 'lk'", "10: '_myactuator_identify'"]
