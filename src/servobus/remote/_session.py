"""What the bridge and the client do alike with their Zenoh session."""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

import anyio
import zenoh

from servobus import runtime

logger = logging.getLogger(__name__)


def to_loop(lane: runtime.Runtime, fn: Callable[..., object], *args: Any) -> None:
    """(On one of Zenoh's threads) call ``fn(*args)`` soon on the event loop of ``lane``; nothing
    once that loop is closed (its owner is shutting down)."""
    try:
        lane.call_soon_threadsafe(fn, *args)
    except RuntimeError:
        logger.debug("a zenoh callback after the loop closed was dropped")


def handed(
    lane: runtime.Runtime, handler: Callable[[Any], object], extract: Callable[[Any], Any]
) -> Callable[[Any], None]:
    """A Zenoh callback that hands ``extract(item)`` to ``handler`` on the loop of ``lane``."""
    return lambda item: to_loop(lane, handler, extract(item))


def sample_kind(sample: zenoh.Sample) -> str:
    """``"PUT"`` or ``"DELETE"`` (a liveliness token appeared or vanished)."""
    return "PUT" if sample.kind == zenoh.SampleKind.PUT else "DELETE"


async def close_session(session: Any, declared: list[Any]) -> None:
    """Undeclare ``declared`` (last first) and close ``session`` (a ``zenoh.Session``), on a thread
    (Zenoh blocks), shielded: a cancelled owner still leaves nothing declared behind."""
    if session is None:
        return

    def close() -> None:
        for item in reversed(declared):
            try:
                item.undeclare()
            except Exception:  # already gone with its session
                logger.debug("undeclare failed", exc_info=True)
        session.close()

    with anyio.CancelScope(shield=True):
        await anyio.to_thread.run_sync(close)
