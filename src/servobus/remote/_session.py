"""What the bridge and the client do alike with their Zenoh session."""

from __future__ import annotations

import logging
from typing import Any

import anyio
import zenoh

logger = logging.getLogger(__name__)


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
