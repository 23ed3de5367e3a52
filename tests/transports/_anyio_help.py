"""What the real-I/O transport tests share to run on asyncio and trio (anyio's pytest plugin).

* :func:`within`: ``asyncio.wait_for``'s anyio form.
* :func:`serving`: run a simulator attachment for the length of a block (on trio, while the
  simulator's attachments are asyncio-only, on their own asyncio loop in a thread).
* :func:`needs_bus_on`: the Bus is converted to anyio on another branch of the same issue; until it
  is, a test that drives one is an expected failure. The check reads its source, so it lifts itself
  once ``servobus.bus`` no longer imports asyncio: the test must then pass, on both backends.
"""

from __future__ import annotations

import contextlib
import importlib
import threading
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
    """Run ``coro`` (a simulator attachment) for the length of the block, cancelled at its end; an
    exception it died of is raised there. One exception (the block's or the peer's) is raised as it
    is, not in a group, so ``pytest.raises`` around the block sees what the block raised.

    On asyncio the peer is a task of the test's loop. On another backend, while the simulator's
    attachments are asyncio-only (:func:`sim_is_asyncio_only`), it runs on its own asyncio loop in a
    thread: the transport under test still runs on trio, its far end is the same simulator.
    """
    if sniffio.current_async_library() != "asyncio" and sim_is_asyncio_only():
        async with _in_asyncio_thread(coro):
            yield
        return
    try:
        async with anyio.create_task_group() as group:
            group.start_soon(_run, coro)
            try:
                yield
            finally:
                group.cancel_scope.cancel()
    except BaseExceptionGroup as group_error:
        if len(group_error.exceptions) == 1:
            raise group_error.exceptions[0] from None
        raise


async def _run(coro: Coroutine[Any, Any, None]) -> None:
    await coro


@contextlib.asynccontextmanager
async def _in_asyncio_thread(coro: Coroutine[Any, Any, None]) -> AsyncIterator[None]:
    import asyncio

    started = threading.Event()
    box: dict[str, Any] = {}

    async def main() -> None:
        box["loop"], box["task"] = asyncio.get_running_loop(), asyncio.current_task()
        started.set()
        await coro

    def thread_main() -> None:
        try:
            asyncio.run(main())
        except asyncio.CancelledError:
            pass
        except BaseException as exc:  # handed to the test's task below
            box["error"] = exc
        finally:
            started.set()

    thread = threading.Thread(target=thread_main, name="simulated peer", daemon=True)
    thread.start()
    await anyio.to_thread.run_sync(started.wait)
    try:
        yield
    finally:
        loop, task = box.get("loop"), box.get("task")
        if loop is not None and task is not None:
            with contextlib.suppress(RuntimeError):  # the peer's loop ended already
                loop.call_soon_threadsafe(task.cancel)
        with anyio.CancelScope(shield=True):
            await anyio.to_thread.run_sync(thread.join)
    if "error" in box:
        raise box["error"]


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


def sim_is_asyncio_only() -> bool:
    """The simulator's attachments (``servobus.sim.attach``, ``servobus.sim.pty``) import asyncio."""
    return bool(_asyncio_only("servobus.sim.attach", "servobus.sim.pty"))


def needs_bus_on(backend: str | None = None) -> None:
    """An expected failure while the Bus is asyncio-only: on trio, and on asyncio too, where the old
    Bus leaves the transport's task group from another task than the one that entered it."""
    modules = _asyncio_only("servobus.bus")
    if modules:
        pytest.xfail(f"{', '.join(modules)} not yet converted to anyio (another branch of issue 28)")


def backend_of(anyio_backend: Any) -> str:
    """The backend's name from the ``anyio_backend`` fixture's value (a name or (name, options))."""
    return anyio_backend if isinstance(anyio_backend, str) else str(anyio_backend[0])
