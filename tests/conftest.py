"""Shared test set-up.

tests/reference/ (the pure-Python oracle of the C core) is imported as ``reference``: pytest's default
import mode already puts tests/ on sys.path; this keeps that true under --import-mode=importlib too.
"""

from __future__ import annotations

import sys
from pathlib import Path

_TESTS = str(Path(__file__).resolve().parent)
if _TESTS not in sys.path:
    sys.path.insert(0, _TESTS)
