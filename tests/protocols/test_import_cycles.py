"""No import cycle among the protocols layer and the families' codecs (issue 38), counting every
import: function-local and ``if TYPE_CHECKING:`` ones too, since a lazy import does not break a cycle.
The families' simulators (``<family>/sim``) are the simulator's to keep acyclic."""

from __future__ import annotations

from pathlib import Path

import test_layering as lay

SRC = Path(__file__).resolve().parents[2] / "src" / "servobus"


def _graph() -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {}
    for path in sorted((SRC / "protocols").rglob("*.py")):
        parts = list(path.relative_to(SRC.parent).with_suffix("").parts)
        if "sim" in parts:
            continue
        package = parts[-1] == "__init__"
        module = ".".join(parts[:-1] if package else parts)
        imported = lay.imported_modules(path.read_text(), module, package=package)
        graph[module] = {name for _, name in imported if name != module}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's, iteratively)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, edges = work[-1]
            for nxt in edges:
                if nxt not in graph:
                    continue
                if nxt not in index:
                    index[nxt] = low[nxt] = len(index)
                    stack.append(nxt)
                    on_stack.add(nxt)
                    work.append((nxt, iter(sorted(graph[nxt]))))
                    break
                if nxt in on_stack:
                    low[node] = min(low[node], index[nxt])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    if len(component) > 1:
                        found.append(sorted(component))
    return found


def test_the_cycle_finder_finds_cycles() -> None:
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": set(), "e": {"e", "d"}}
    assert cycles(graph) == [["a", "b", "c"]]


def test_no_import_cycle_in_the_protocols_and_the_families() -> None:
    assert cycles(_graph()) == []
