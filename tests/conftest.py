"""Shared test set-up.

tests/reference/ (the pure-Python oracle of the C core) is imported as ``reference``: pytest's default
import mode already puts tests/ on sys.path; this keeps that true under --import-mode=importlib too.

Hypothesis profiles, chosen with HYPOTHESIS_PROFILE (or hypothesis' own ``--hypothesis-profile``):
``default`` (200 examples per property, the everyday run), ``ci`` (3,000, the long run) and ``quick``
(50, the sanitizer smoke run of .ci/sanitize --quick). Every property follows the profile, the oracle
tests included (tests/reference/settings.py); a test keeps a lower count of its own only where one
example is expensive.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import pytest
from hypothesis import settings

# No deadline: what an example costs is measured in bench/, and on a shared 2-core host a slow
# example is the machine's load, not a failure of the property.
settings.register_profile("default", max_examples=200, deadline=None)
settings.register_profile("ci", max_examples=3000, deadline=None)
settings.register_profile("quick", max_examples=50, deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))

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


@pytest.fixture(params=["asyncio", "trio"])
def anyio_backend(request: pytest.FixtureRequest) -> tuple[str, dict[str, object]]:
    """Every ``@pytest.mark.anyio`` test runs on asyncio and on trio (real time; tests/_backends.py
    has the virtual-time form a module can override this with)."""
    from _backends import real

    return real(request.param)


@pytest.fixture(scope="module")
def toy() -> Iterator[ModuleType]:
    """The toy plug-in family's package, installed for the tests of one module (tests/_toy.py)."""
    from _toy import installed

    with installed() as package:
        yield package


@pytest.fixture(scope="session")
def built_site(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, float]:
    """The docs site built once per run as CI builds it (``mkdocs build --strict``: a warning fails
    it), and the seconds the build took; the pages' tests read it."""
    out = tmp_path_factory.mktemp("site") / "site"
    started = time.monotonic()
    result = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(out)],
        cwd=Path(__file__).resolve().parents[1],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    return out, time.monotonic() - started
