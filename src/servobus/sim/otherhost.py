"""A second controller on the simulated bus: another host that sends its own requests to our motors.

CAN is a broadcast medium, and nothing stops a second PC, a teach pendant or a forgotten script from
commanding the same motors: they answer it on the identifier they answer us on, with the same
DATA[0]. :class:`OtherHost` is that node: every period (``rate_hz``, jittered, seeded) it sends its
frames, one after the other, and ignores the replies. It is a device like the motor models, so it
goes into any network's device list (SimTransport, the SLCAN pty and python-can ``virtual``
attachments, the soak)::

    other = OtherHost.commanding([ma.FAMILY.bind(i) for i in (1, 2, 3)], ma.SpeedControl(speed_dps=-50.0))
    SimTransport(devices=[*motors, other])

Sans-IO like every device: ``now_s`` comes from the network.
"""

from __future__ import annotations

import random
from collections import Counter
from collections.abc import Collection, Iterable, Sequence
from typing import Any

from servobus.frame import Frame
from servobus.sim.device import BusLink, Emission

__all__ = ["OtherHost"]


class OtherHost:
    """Another host on the bus, sending ``frames`` every ``1 / rate_hz`` seconds.

    Args:
        frames: the requests it sends each period, in order (to our motors' request identifiers).
        rate_hz: its loop's rate (each period sends every frame once).
        start_s: when its first period begins (plus a seeded phase of up to one period).
        jitter: each period is ``1 / rate_hz`` times ``1 + uniform(-jitter, jitter)``.
        seed: the seed of its phase and jitter.
        name: its name on the network.

    Raises:
        ValueError: no frames, a rate that is not positive, or a jitter outside 0..1.
    """

    def __init__(
        self,
        frames: Sequence[Frame],
        *,
        rate_hz: float = 500.0,
        start_s: float = 0.0,
        jitter: float = 0.1,
        seed: int = 0,
        name: str = "other host",
    ) -> None:
        if not frames or rate_hz <= 0 or not 0 <= jitter < 1:
            raise ValueError(
                f"frames={len(frames)} must not be empty, rate_hz={rate_hz} > 0, jitter={jitter} in [0, 1)"
            )
        # As received by any other node: ``is_rx`` (an encoder's frame says "ours, sent").
        self.frames = [
            Frame(
                arbitration_id=f.arbitration_id,
                data=f.data,
                is_extended_id=f.is_extended_id,
                is_fd=f.is_fd,
                bitrate_switch=f.bitrate_switch,
            )
            for f in frames
        ]
        self.rate_hz = rate_hz
        self.jitter = jitter
        self._name = name
        self._rng = random.Random(seed)
        self._next_s = start_s + self._rng.uniform(0.0, 1.0 / rate_hz)
        self.counters: Counter[str] = Counter()
        self._link: BusLink | None = None

    @classmethod
    def commanding(cls, codecs: Iterable[Any], command: Any, **options: Any) -> OtherHost:
        """Another host sending ``command`` to each motor of ``codecs`` (bound codecs: the frames are
        what that family's encoder makes)."""
        return cls([codec.encode(command) for codec in codecs], **options)

    @property
    def name(self) -> str:
        return self._name

    # ---- a device that listens to nothing (it does not read the replies) ----

    def listen_ids(self) -> Collection[int]:
        return frozenset()

    def attach(self, link: BusLink | None) -> None:
        self._link = link

    def settle(self) -> None:
        """Settle up with the network (it keeps no state of the frames it did not hear)."""
        link = self._link
        if link is not None and link.behind:
            link.catch_up(every_end=False)

    def receive(self, frame: Frame, now_s: float) -> list[Emission]:
        return []

    def next_deadline_s(self) -> float | None:
        return self._next_s

    def poll(self, now_s: float) -> list[Emission]:
        if now_s < self._next_s:
            return []
        at = self._next_s
        period = 1.0 / self.rate_hz
        self._next_s = at + period * (1.0 + self._rng.uniform(-self.jitter, self.jitter))
        if self._next_s <= now_s:  # (polled late: no burst of missed periods)
            self._next_s = now_s + period
        self.counters["sent"] += len(self.frames)
        return [Emission(now_s, frame) for frame in self.frames]
