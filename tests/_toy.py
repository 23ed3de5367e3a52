"""The toy plug-in family (tests/plugins): its folder, and ``servobus`` run the way an installed
plug-in is found (the folder on ``PYTHONPATH``, its dist-info registering the entry point)."""

from __future__ import annotations

import importlib
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import ModuleType

PLUGINS = Path(__file__).resolve().parent / "plugins"
#: ``servobus`` in a subprocess
SERVOBUS = [sys.executable, "-c", "import sys; from servobus.cli import main; sys.exit(main())"]


@contextmanager
def installed() -> Iterator[ModuleType]:
    """The ``servobus_toy`` package with its folder on ``sys.path`` (what installing it would do),
    removed again afterwards with every module of it."""
    sys.path.insert(0, str(PLUGINS))
    try:
        yield importlib.import_module("servobus_toy")
    finally:
        sys.path.remove(str(PLUGINS))
        for name in [n for n in sys.modules if n.partition(".")[0] == "servobus_toy"]:
            del sys.modules[name]
