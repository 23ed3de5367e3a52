"""A host's CAN controller with episodes, as python-can shows it: :class:`FaultyCanBus`.

It wraps a python-can bus (``virtual`` by default) and plays
:class:`~servobus.sim.episodes.ControllerEpisodes` on it in real time, the way SocketCAN reports them
through python-can: a send refused with ``CanOperationError`` errno ENOBUFS while the transmit queue is
full, errno ENETDOWN while bus-off; the BUS_OFF and RESTARTED error frames as received messages
(``is_error_frame``, the class in the identifier, as the kernel's ``CAN_RAW_ERR_FILTER`` passes them
whatever the data filters); nothing received while bus-off.

Registered as a python-can interface it is opened by name, so a transport that reopens gets a fresh
one on the same episodes (their times are from ``origin_s``, shared)::

    can.interfaces.BACKENDS["servobus-faulty"] = ("servobus.sim.canfaults", "FaultyCanBus")
    CanTransport("servobus-faulty", "chan", ignore_config=True, episodes=episodes, origin_s=t0)
"""

from __future__ import annotations

import errno
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import can

from servobus.sim.episodes import ControllerEpisodes

__all__ = ["FaultyCanBus"]


class FaultyCanBus(can.BusABC):
    """python-can's ``inner`` interface behind a controller that has ``episodes``.

    Args:
        channel: the inner bus's channel.
        episodes: what the controller does, at times ``clock() - origin_s``.
        origin_s: the episodes' time 0 on ``clock`` (default: now).
        inner: the python-can interface wrapped.
        clock: the clock (``time.monotonic``).
        **kwargs: the inner bus's other arguments.
    """

    def __init__(
        self,
        channel: Any = None,
        *,
        episodes: ControllerEpisodes,
        origin_s: float | None = None,
        inner: str = "virtual",
        clock: Callable[[], float] = time.monotonic,
        can_filters: can.typechecking.CanFilters | None = None,
        **kwargs: Any,
    ) -> None:
        self._inner = can.Bus(interface=inner, channel=channel, **kwargs)
        self._clock = clock
        self._origin_s = clock() if origin_s is None else origin_s
        self.episodes = episodes
        self._lock = threading.Lock()  # the episodes are asked from the sending and the reading thread
        self._errors: deque[can.Message] = deque()
        super().__init__(channel=channel, can_filters=can_filters)
        self.channel_info = f"faulty {self._inner.channel_info}"

    def _now(self) -> float:
        return self._clock() - self._origin_s

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        with self._lock:
            why = self.episodes.refusal(self._now())
        if why == "queue_full":
            raise can.CanOperationError("Failed to transmit: No buffer space available", errno.ENOBUFS)
        if why == "bus_off":
            raise can.CanOperationError("Failed to transmit: Network is down", errno.ENETDOWN)
        self._inner.send(msg, timeout)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        now = self._now()
        with self._lock:
            for _, classes in self.episodes.error_frames(now):
                self._errors.append(
                    can.Message(
                        timestamp=time.time(), arbitration_id=classes, is_error_frame=True, data=bytes(8)
                    )
                )
            next_s = self.episodes.next_error_frame_s()
        if self._errors:
            return self._errors.popleft(), True  # (error frames pass every data filter)
        if next_s is not None:
            timeout = max(0.0, next_s - now) if timeout is None else min(timeout, max(0.0, next_s - now))
        message = self._inner.recv(timeout)
        if message is None:
            return None, True
        with self._lock:
            heard = self.episodes.receiving(self._now())
        return (message if heard else None), True  # (the inner bus applied the filters)

    def _apply_filters(self, filters: can.typechecking.CanFilters | None) -> None:
        self._inner.set_filters(filters)

    def shutdown(self) -> None:
        super().shutdown()
        self._inner.shutdown()
