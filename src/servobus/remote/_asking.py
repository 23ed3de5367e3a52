"""A client's queries to its bridge (:class:`Asker`), and the bridge's liveliness they wait on.

The answers to a query are gathered on one of Zenoh's threads and awaited on the client's event
loop. Once the bridge's liveliness token vanished, every query still waiting ends at once, and one
without an answer raises the client's ``lost`` error instead of waiting out its timeout.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

import anyio
import zenoh

from servobus import runtime
from servobus.remote._session import to_loop
from servobus.remote.keys import Keys

__all__ = ["Asker"]


class Asker:
    """The queries of one client and whether its bridge lives (every method runs on the loop).

    Args:
        lane: the client's event loop.
        timeout_s: how long an info or metrics query waits for its answers.
        gone: the error a query raises once the bridge's token vanished (built when it does).
    """

    def __init__(self, lane: runtime.Runtime, timeout_s: float, gone: Callable[[], Exception]) -> None:
        self._lane = lane
        self._timeout_s = timeout_s
        self._gone = gone
        self.alive = anyio.Event()  # (set when the bridge's token is first seen)
        self.lost: Exception | None = None  # (the bridge's token vanished: what queries raise)
        self._waiting: set[anyio.Event] = set()

    def on_alive(self, kind: str) -> None:
        """(The loop) the bridge's liveliness token appeared (``"PUT"``) or vanished."""
        if kind == "PUT":
            self.lost = None
            self.alive.set()
            return
        self.lost = self._gone()
        for event in self._waiting:
            event.set()

    async def get(self, session: Any, key: str, payload: bytes | None, timeout_s: float) -> list[bytes]:
        """The payloads of the answers to a query on ``session``, gathered on Zenoh's thread, awaited
        here.

        Raises:
            Exception: ``lost``, when the bridge vanished and nothing answered.
        """
        lane = self._lane
        done = anyio.Event()
        answers: list[bytes] = []

        def on_reply(reply: Any) -> None:
            ok = reply.ok
            if ok is not None:
                answers.append(ok.payload.to_bytes())

        def on_done() -> None:
            to_loop(lane, done.set)

        self._waiting.add(done)
        try:
            session.get(
                key,
                zenoh.handlers.Callback(on_reply, on_done),
                payload=payload,
                timeout=timeout_s,
                express=True,
                congestion_control=zenoh.CongestionControl.DROP,  # never block this loop
            )
            await done.wait()
        finally:
            self._waiting.discard(done)
        if self.lost is not None and not answers:
            raise self.lost
        return answers

    async def get_json(self, session: Any, key: str) -> dict[str, Any] | None:
        """The first answer to a query on ``key`` that is a JSON object (None: none was)."""
        answers = await self.get(session, key, None, self._timeout_s)
        for raw in answers:
            try:
                found = json.loads(raw)
            except ValueError:
                continue
            if isinstance(found, dict):
                return found
        return None

    async def list_buses(self, session: Any, keys: Keys) -> list[str]:
        """The names of the buses the bridge of ``keys`` serves (those that answered)."""
        answers = await self.get(session, keys.bus("*", "info"), None, self._timeout_s)
        names = []
        for raw in answers:
            try:
                names.append(str(json.loads(raw)["bus"]))
            except (ValueError, KeyError, TypeError):
                continue
        return sorted(names)
