"""The command line, the bridge and the tools (issue 38): no import cycle among their modules
(every import counted, function-local and TYPE_CHECKING too), no module over 600 lines, no class
over 300."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from test_layering import imported_modules

SRC = Path(__file__).resolve().parents[2] / "src" / "servobus"
AREAS = ("cli", "remote", "tools")


def _modules() -> dict[str, Path]:
    found = {}
    for area in AREAS:
        for path in sorted((SRC / area).rglob("*.py")):
            parts = path.relative_to(SRC.parent).with_suffix("").parts
            found[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return found


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle of ``graph`` (a path that comes back to its start), or None."""
    done: set[str] = set()

    def visit(module: str, path: list[str]) -> list[str] | None:
        if module in path:
            return [*path[path.index(module) :], module]
        if module in done:
            return None
        for imported in sorted(graph[module]):
            if (found := visit(imported, [*path, module])) is not None:
                return found
        done.add(module)
        return None

    for module in sorted(graph):
        if (found := visit(module, [])) is not None:
            return found
    return None


def test_no_import_cycle_among_the_command_line_the_bridge_and_the_tools() -> None:
    modules = _modules()
    graph = {
        module: {
            name
            for _, name in imported_modules(path.read_text(), module, package=path.name == "__init__.py")
            if name in modules and name != module
        }
        for module, path in modules.items()
    }
    assert _cycle(graph) is None


def test_the_cycle_finder_finds_one() -> None:
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": set()}) is None


@pytest.mark.parametrize("path", sorted(_modules().values()), ids=lambda p: str(p.relative_to(SRC)))
def test_no_module_over_600_lines_nor_class_over_300(path: Path) -> None:
    source = path.read_text()
    assert source.count("\n") <= 600
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ClassDef):
            assert node.end_lineno is not None
            assert node.end_lineno - node.lineno + 1 <= 300, node.name
