"""The "Writing a family" page (docs/api/families.md) as a family's author reads it: every name of
:mod:`servobus.authoring` listed with its docstring in the rendered site, the worked example's
excerpts word for word the test family's code (tests/plugins/servobus_dm), and every python block
run with that family installed."""

from __future__ import annotations

import ast
import importlib
import inspect
import os
import re
import subprocess
import sys
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


# ---- the page's blocks ----

_FENCE = re.compile(
    r"^(?:<!-- excerpt: (?P<file>\S+) -->\n)?```(?P<lang>\w+)\n(?P<code>.*?)^```$", re.S | re.M
)


def _page_blocks() -> list[tuple[int, str, str, str | None]]:
    """(line, language, code, the file it is an excerpt of) of each fenced block of the page."""
    text = PAGE.read_text(encoding="utf-8")
    return [
        (text.count("\n", 0, m.start()) + 1, m["lang"], m["code"], m["file"]) for m in _FENCE.finditer(text)
    ]


BLOCKS = _page_blocks()
EXCERPTS = [b for b in BLOCKS if b[3] is not None]
SCRIPTS = [b for b in BLOCKS if b[3] is None and b[1] == "python"]
COMMANDS = [b for b in BLOCKS if b[3] is None and b[1] == "console"]


def _env() -> dict[str, str]:
    """The environment with the test families installed (their folder on the path)."""
    path = os.pathsep.join(p for p in (str(PLUGINS), os.environ.get("PYTHONPATH")) if p)
    return {**os.environ, "PYTHONPATH": path}


def test_the_page_has_excerpts_scripts_and_commands() -> None:
    assert len(EXCERPTS) >= 8 and SCRIPTS and COMMANDS
    assert not [b for b in BLOCKS if b[3] is None and b[1] not in ("python", "console")], (
        "a block is neither an excerpt, a script nor commands: nothing would check it"
    )


@pytest.mark.parametrize(("line", "lang", "code", "file"), EXCERPTS, ids=[f"line {b[0]}" for b in EXCERPTS])
def test_every_excerpt_is_the_family_s_code_word_for_word(line: int, lang: str, code: str, file: str) -> None:
    source = (ROOT / file).read_text(encoding="utf-8")
    assert code in source, f"line {line}: not in {file} as written"


@pytest.mark.parametrize(("line", "lang", "code", "file"), SCRIPTS, ids=[f"line {b[0]}" for b in SCRIPTS])
def test_every_script_runs_with_the_family_installed(
    line: int, lang: str, code: str, file: None, tmp_path: Path
) -> None:
    result = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, env=_env(), capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, (line, result.stdout, result.stderr)
    text = PAGE.read_text(encoding="utf-8")
    after = text.split("\n", line - 1)[-1].split("```\n", 1)[-1]
    if after.lstrip("\n").startswith("It prints:"):
        expected = after.split("```\n", 2)[1]
        assert result.stdout == expected, line


@pytest.mark.parametrize(("line", "lang", "code", "file"), COMMANDS, ids=[f"line {b[0]}" for b in COMMANDS])
def test_every_command_runs_with_the_family_installed(
    line: int, lang: str, code: str, file: None, tmp_path: Path
) -> None:
    for command in [c[2:] for c in code.splitlines() if c.startswith("$ ")]:
        result = subprocess.run(
            command, shell=True, cwd=tmp_path, env=_env(), capture_output=True, text=True, timeout=120
        )
        assert result.returncode == 0, (line, command, result.stderr)


def test_the_rendered_page_lists_every_name_with_its_docstring(built_site: tuple[Path, float]) -> None:
    """The site built as CI builds it (``mkdocs build --strict``): the page has an entry, with a
    docstring, for each name of servobus.authoring."""
    site, _ = built_site
    html = (site / "api" / "families" / "index.html").read_text(encoding="utf-8")
    for name in authoring.__all__:
        entry = re.search(
            rf'id="servobus\.authoring\.{name}"(.*?)(?=id="servobus\.authoring\.|\Z)', html, re.S
        )
        assert entry is not None, f"{name} is not on the page"
        assert re.search(r"<p>\s*\S", entry[1]), f"{name} is on the page without its docstring"
