"""The guides under docs/ run as written: every ```python block as a script (in a folder of its own),
its output compared with the block after "It prints:" where there is one; every ```toml block parses
(a limits file's with servobus.limits)."""

from __future__ import annotations

import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[1] / "docs"
#: the guides whose blocks are checked (more join as they are written to run)
PAGES = ["limits.md"]  # (recording.md: tests/test_taplink_doc.py runs and compares its blocks)


def _blocks(page: str) -> list[tuple[str, int, str, str | None]]:
    """(page, line, code, what it prints or None) for each ```python block of ``page``."""
    text = (DOCS / page).read_text(encoding="utf-8")
    found = []
    pattern = r"^```python\n(.*?)^```\n(?:\nIt prints:\n\n```\n(.*?)^```\n)?"
    for match in re.finditer(pattern, text, re.S | re.M):
        found.append((page, text.count("\n", 0, match.start()) + 1, match.group(1), match.group(2)))
    return found


BLOCKS = [block for page in PAGES for block in _blocks(page)]


@pytest.mark.parametrize(("page", "line", "code", "prints"), BLOCKS, ids=[f"{b[0]}:{b[1]}" for b in BLOCKS])
def test_every_python_block_runs_as_written(
    page: str, line: int, code: str, prints: str | None, tmp_path: Path
) -> None:
    result = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, (page, line, result.stderr)
    if prints is not None:
        assert result.stdout == prints, (page, line)


def test_the_limits_page_s_file_is_a_limits_file() -> None:
    from servobus.limits import parse

    text = (DOCS / "limits.md").read_text(encoding="utf-8")
    files = re.findall(r"^```toml\n(.*?)^```$", text, re.S | re.M)
    assert files
    for content in files:
        tomllib.loads(content)
        book = parse(content)
        assert book.all is not None and book.of(3) is not None
