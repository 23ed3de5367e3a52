"""The event loops a test runs on, through anyio's pytest plugin (``@pytest.mark.anyio``).

tests/conftest.py's ``anyio_backend`` fixture runs every anyio test on asyncio and on trio in real
time. A module whose tests want virtual time overrides it with :func:`virtual`::

    @pytest.fixture(params=BACKENDS)
    def anyio_backend(request: pytest.FixtureRequest) -> tuple[str, dict[str, object]]:
        return virtual(request.param)

Virtual time is looptime on asyncio (the loop's clock starts at 0 and jumps to the next timer when
every task waits) and ``trio.testing.MockClock(autojump_threshold=0)`` on trio (the same rule).
"""

from __future__ import annotations

import asyncio
from typing import Any

BACKENDS = ("asyncio", "trio")


def _looptime_loop() -> asyncio.AbstractEventLoop:
    from servobus.sim.virtual import new_event_loop  # (the simulator's own: no idle cycles before a jump)

    return new_event_loop(start=0)


def virtual(backend: str) -> tuple[str, dict[str, Any]]:
    """``anyio_backend``'s value for ``backend`` ("asyncio" or "trio") on a virtual clock."""
    if backend == "asyncio":
        return "asyncio", {"loop_factory": _looptime_loop}
    if backend == "trio":
        import trio.testing

        return "trio", {"clock": trio.testing.MockClock(autojump_threshold=0)}
    raise ValueError(f"unknown backend {backend!r}: one of {BACKENDS}")


def real(backend: str) -> tuple[str, dict[str, Any]]:
    """``anyio_backend``'s value for ``backend`` on the real clock."""
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}: one of {BACKENDS}")
    return backend, {}
