"""Simulated devices served on a python-can ``virtual`` channel from a thread: a real transport path
for the CLI's tests (``-i virtual -c CHANNEL``)."""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Iterator, Sequence
from typing import Any

import anyio

__all__ = ["served_on_virtual"]


@contextlib.contextmanager
def served_on_virtual(devices: Sequence[Any], channel: str | None = None) -> Iterator[str]:
    """``devices`` on a python-can virtual channel (``channel``, else a fresh name), served from a thread."""
    import can

    from servobus.sim.attach import serve_python_can
    from servobus.sim.network import SimCanNetwork

    channel = channel or f"twin-{time.monotonic_ns()}"
    network = SimCanNetwork(list(devices))
    side = can.Bus(interface="virtual", channel=channel)
    stop = threading.Event()

    async def serve() -> None:
        async with anyio.create_task_group() as group:
            group.start_soon(lambda: serve_python_can(network, side))
            while not stop.is_set():
                await anyio.sleep(0.01)
            group.cancel_scope.cancel()

    thread = threading.Thread(target=anyio.run, args=(serve,), daemon=True)
    thread.start()
    try:
        yield channel
    finally:
        stop.set()
        thread.join(5)
        side.shutdown()
