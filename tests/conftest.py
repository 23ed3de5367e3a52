"""Shared test set-up.

tests/reference/ (the pure-Python oracle of the C core) is imported as ``reference``: pytest's default
import mode already puts tests/ on sys.path; this keeps that true under --import-mode=importlib too.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

_TESTS = str(Path(__file__).resolve().parent)
if _TESTS not in sys.path:
    sys.path.insert(0, _TESTS)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """``slow`` tests (soak runs) run only when asked for: ``pytest -m slow``."""
    if "slow" in (config.getoption("-m") or ""):
        return
    skip = pytest.mark.skip(reason="slow soak run: select it with -m slow")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)
