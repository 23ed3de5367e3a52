"""The "Writing a family" page (docs/api/families.md) as a family's author reads it: every name of
:mod:`servobus.authoring` listed with its docstring in the rendered site, the worked example's
excerpts word for word the test family's code (tests/plugins/servobus_dm), and every python block
run with that family installed."""

from __future__ import annotations

import ast
import importlib
import inspect
from pathlib import Path

import pytest

import servobus.authoring as authoring

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "api" / "families.md"
PLUGINS = ROOT / "tests" / "plugins"


def _body(module: str) -> list[ast.stmt]:
    return ast.parse(Path(importlib.import_module(module).__file__ or "").read_text(encoding="utf-8")).body


def _attribute_docstring(module: str, name: str) -> str | None:
    """The string right after ``name = ...`` at the top level of the module that assigns it
    (an attribute docstring), following ``from ... import name`` from ``module`` on."""
    body = _body(module)
    for node, after in zip(body, [*body[1:], None], strict=True):
        if (
            isinstance(node, ast.ImportFrom)
            and node.module
            and any((a.asname or a.name) == name for a in node.names)
        ):
            (alias,) = [a for a in node.names if (a.asname or a.name) == name]
            return _attribute_docstring(node.module, alias.name)
        targets = node.targets if isinstance(node, ast.Assign) else []
        if isinstance(node, ast.AnnAssign):
            targets = [node.target]
        if any(isinstance(t, ast.Name) and t.id == name for t in targets):
            if isinstance(after, ast.Expr) and isinstance(after.value, ast.Constant):
                return str(after.value.value)
            return None
    return None


@pytest.mark.parametrize("name", authoring.__all__)
def test_every_name_a_family_writes_with_has_a_docstring(name: str) -> None:
    obj = getattr(authoring, name)
    if inspect.isclass(obj) or inspect.isfunction(obj):
        doc = obj.__doc__ or ""
        assert doc.strip() and not doc.startswith(f"{obj.__name__}("), name  # (a dataclass's own)
    else:
        doc = _attribute_docstring(authoring.__name__, name)
        assert doc and doc.strip(), f"{name}: no docstring after its assignment"
