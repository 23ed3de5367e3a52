"""What the real-I/O transport tests share to run on asyncio and trio (anyio's pytest plugin).

* :func:`within`: ``asyncio.wait_for``'s anyio form.
* :func:`serving`: run a simulator attachment in a task for the length of a block.
* :func:`needs_sim_on` / :func:`needs_bus_on`: the simulator's attachments (``servobus.sim.attach``,
  ``servobus.sim.pty``) and the Bus are converted to anyio by other branches of the same issue; until
  they are, a test that drives them is an expected failure on trio (they are asyncio-only code). The
  check reads their source, so it lifts itself once they no longer import asyncio: the test must then
  pass on trio.
"""

from __future__ import annotations

import contextlib
import importlib
from collections.abc import AsyncIterator, Awaitable, Coroutine
from pathlib import Path
from typing import Any, TypeVar

import anyio
import pytest
import sniffio

T = TypeVar("T")


async def within(timeout_s: float, awaitable: Awaitable[T]) -> T:
    """``await awaitable``, failing with TimeoutError after ``timeout_s``."""
    with anyio.fail_after(timeout_s):
        return await awaitable


@contextlib.asynccontextmanager
async def serving(coro: Coroutine[Any, Any, None]) -> AsyncIterator[None]:
    """Run ``coro`` in a task for the length of the block, cancelled at its end; an exception it died
    of is raised there."""
    async with anyio.create_task_group() as group:
        group.start_soon(_run, coro)
        try:
            yield
        finally:
            group.cancel_scope.cancel()


async def _run(coro: Coroutine[Any, Any, None]) -> None:
    await coro


def _asyncio_only(*modules: str) -> list[str]:
    out = []
    for name in modules:
        source = Path(importlib.import_module(name).__file__ or "").read_text()
        if "import asyncio" in source:
            out.append(name)
    return out


def _expect_failure_on_trio(backend: str, modules: list[str]) -> None:
    if backend == "trio" and modules:
        pytest.xfail(f"{', '.join(modules)} still asyncio-only (converted on another branch of issue 28)")


def needs_sim_on(backend: str | None = None) -> None:
    """An expected failure on trio while the simulator's attachments are asyncio-only (``backend``:
    the running one by default)."""
    backend = backend or sniffio.current_async_library()
    _expect_failure_on_trio(backend, _asyncio_only("servobus.sim.attach", "servobus.sim.pty"))


def needs_bus_on(backend: str | None = None) -> None:
    """An expected failure while the Bus is asyncio-only: on trio, and on asyncio too, where the old
    Bus leaves the transport's task group from another task than the one that entered it."""
    modules = _asyncio_only("servobus.bus")
    if modules:
        pytest.xfail(f"{', '.join(modules)} not yet converted to anyio (another branch of issue 28)")


def backend_of(anyio_backend: Any) -> str:
    """The backend's name from the ``anyio_backend`` fixture's value (a name or (name, options))."""
    return anyio_backend if isinstance(anyio_backend, str) else str(anyio_backend[0])
