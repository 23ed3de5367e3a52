"""The modules the DBC exporter and the family contracts moved into (issue 38) stay family-blind, as
``servobus/dbc.py`` was (test_family_layering.py's BLIND): no identifier or code value names a
built-in family, documentation aside."""

from __future__ import annotations

import pytest

import test_family_layering as blind

MOVED = [
    "tools/dbc.py",
    "protocols/cli.py",
    "protocols/dbc.py",
    "protocols/dbc_layouts.py",
    "protocols/_calls.py",
    "cli/plugin.py",
]


@pytest.mark.parametrize("name", MOVED)
def test_the_moved_modules_name_no_family(name: str) -> None:
    path = blind.SRC / name
    assert blind.family_names(path.read_text()) == []
    assert blind.family_imports(path.read_text()) == []
