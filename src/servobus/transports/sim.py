"""The in-process bus: a transport straight onto a simulated CAN network, on the event loop's clock.

:class:`SimTransport` joins the orchestrator to a simulated CAN network with no pty, adapter or
thread between them: a :class:`~servobus.sim.corenet.CoreCanNetwork` (the C engine) unless it is
given a network, or a :class:`~servobus.sim.network.SimCanNetwork` (the Python reference) given.

* **Zero-copy out**: :meth:`SimTransport.send` hands the caller's own :class:`~servobus.frame.Frame`
  to the network (``network.send(frame, now)``) from the caller's stack, with no queue hop; the
  network's bus model then gives it its exact bit time and arbitration.
* **One clock in**: the transport keeps one wake-up armed on the network's next event: a task in
  its task group (any backend) or, on asyncio, the loop's ``call_at`` (the measured fast lane:
  :mod:`servobus.transports._simclock`). When it fires, one call
  (:meth:`~servobus.sim.corenet.CoreCanNetwork.host_turn`: one C call on the C engine) runs the
  network up to the loop's time and then ahead over what the host can neither see nor change
  (:meth:`~servobus.sim.network.SimCanNetwork.run_ahead`: while the host still has a frame queued,
  its later frames wait behind it), and the frames the host received come back as the host's
  Frames, made once at that edge, stamped with the time their transmission ended (on the loop's
  clock); they are delivered as one batch. Nothing polls: an idle network arms nothing. The clock
  is next armed for the next frame the host receives rather than for every frame on the wire: a
  burst of requests costs one wake-up, not one per request. The trace is the same; device state (a
  simulated motor's counters, say) may read ahead of the loop's clock by the host's queued burst.
* **Time**: network time = loop time - ``t0``, where ``t0`` is fixed the first time the transport
  opens on a loop (so that the network's clock continues from its ``now_s`` at that moment; a fresh
  network on a virtual clock that starts at 0 gets ``t0 = 0``, and the two clocks are the same
  numbers). On a real clock the network then runs in real time; on a virtual one (``looptime``,
  :func:`servobus.sim.virtual.run`, trio's ``MockClock(autojump_threshold=0)``) it runs as fast as
  the host can compute it, because the only deadlines are the network's own events and the host's
  sleeps. It runs on asyncio and on trio.
* **The host's controller**: ``episodes=`` (:class:`~servobus.sim.episodes.ControllerEpisodes`, on
  the network's clock) gives it a full send queue (a send refused fails at once with
  :class:`~servobus.transports.base.SendQueueFull`, counted ``enobufs_dropped``, reported
  ``"queue_full"``) and bus-off (BUS_OFF and RESTARTED error frames at their times, sends refused
  meanwhile, nothing received): what :class:`~servobus.transports.can.CanTransport` makes of
  python-can's ENOBUFS, ENETDOWN and error frames.
* **Loss**: :meth:`SimTransport.unplug` pulls the adapter: pending receivers and drains fail at once
  with :class:`~servobus.errors.TransportError`, the state goes to ``LOST`` and reopening fails until
  :meth:`SimTransport.replug`. The devices keep running meanwhile; what they sent while the host was
  away is lost (counted in ``stats().ignored``), as on a real bus.

Everything else (counters, send reports, push delivery, events) is the base
:class:`~servobus.transports.base.Transport`'s.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any, ClassVar

import anyio.lowlevel

from servobus.errors import TransportError
from servobus.frame import Frame
from servobus.sim.canbus import CanBusModel
from servobus.sim.corenet import CoreCanNetwork
from servobus.sim.device import Device
from servobus.sim.episodes import ControllerEpisodes
from servobus.sim.faults import FaultInjector
from servobus.sim.network import SimCanNetwork, stamped
from servobus.transports._simclock import Clock, start_clock
from servobus.transports.base import BusOffError, Outgoing, SendQueueFull, Transport
from servobus.transports.events import CanErrorClass

__all__ = ["SimTransport"]


class SimTransport(Transport[Frame, Frame]):
    """A host on a simulated CAN (FD) bus, in the same process.

    Args:
        network: the simulated network to join; None builds a CoreCanNetwork from the next four
            arguments.
        devices: the simulated devices of a new network.
        bus: its bus model (1 Mbit/s classic CAN by default).
        to_devices, to_host: fault injectors on each direction of a new network's link.
        episodes: the host controller's full-queue and bus-off episodes (network time).
        name: a label for errors and logs.
        queue_size, rx_buffer, stale_after_s, reopen, reopen_backoff_s: see
            :class:`~servobus.transports.base.Transport`. Sends are written at once, so the queue
            only holds frames sent while an earlier batch is being transmitted.

    Raises:
        ValueError: both a network and the parts of a new one were given.
    """

    #: run the clock as a task on asyncio too (trio always does): the tests of both lanes set it
    task_clock: ClassVar[bool] = False

    def __init__(
        self,
        network: SimCanNetwork | CoreCanNetwork | None = None,
        *,
        devices: Iterable[Device] = (),
        bus: CanBusModel | None = None,
        to_devices: FaultInjector | None = None,
        to_host: FaultInjector | None = None,
        episodes: ControllerEpisodes | None = None,
        name: str = "sim",
        queue_size: int = 256,
        rx_buffer: int = 65536,
        stale_after_s: float | None = 0.5,
        reopen: bool = True,
        reopen_backoff_s: tuple[float, float] = (0.05, 2.0),
    ) -> None:
        if network is None:
            network = CoreCanNetwork(devices, bus=bus, to_devices=to_devices, to_host=to_host)
        elif devices or bus is not None or to_devices is not None or to_host is not None:
            raise ValueError("give a network, or the devices, bus and faults of a new one, not both")
        super().__init__(
            name=name,
            queue_size=queue_size,
            rx_buffer=rx_buffer,
            stale_after_s=stale_after_s,
            reopen=reopen,
            reopen_backoff_s=reopen_backoff_s,
        )
        self.network = network
        self.episodes = episodes
        self._load_known = True  # measured exactly: the bus model's busy time
        self._plugged = True
        self._anchor: object = None  # the loop (its native token) t0 was fixed on
        self._t0 = 0.0
        #: network time the clock task is armed for (None: idle, nothing to wait for)
        self._timer_at: float | None = None
        self._clock: Clock | None = None  # this connection's clock (see _simclock.py)
        self._busy_s = 0.0  # the bus model's busy time already added to the load meter

    # ----------------------------------------------------------------- public API

    def send(self, frame: Frame, handle: Any = None) -> None:
        """Put ``frame`` (this very object) on the simulated bus now; it never blocks. Its send
        report carries ``handle`` (``frame`` when None).

        Raises:
            ValueError: a serial-link message.
            SendQueueFull: the queue is full (only while a queued batch is being written).
            TransportError: the transport is not open (lost, unplugged or closed).
        """
        if frame.is_serial:
            raise ValueError(f"{self.name}: {frame!r} is a serial-link message, not a CAN frame")
        self._enqueue(frame, None, handle)

    @property
    def t0(self) -> float:
        """The loop time at which the network's clock read 0 (network time = loop time - t0)."""
        return self._t0

    def network_time(self, loop_time: float) -> float:
        """A time on the loop's clock as the network's time."""
        return loop_time - self._t0

    def loop_time(self, network_time: float) -> float:
        """A time on the network's clock as the loop's time (what received frames are stamped with)."""
        return network_time + self._t0

    #: a send report says when the frame was queued on the simulated wire, a received frame is
    #: stamped when it ended there, on the loop's clock (:attr:`rules`' ``exact_times``)
    exact_times = True

    @property
    def bitrate(self) -> int | None:
        """The simulated bus's nominal bit rate (None for an infinitely fast one): :attr:`rules`."""
        rate = self.network.bus.bitrate
        return int(rate) if math.isfinite(rate) and rate > 0 else None

    def unplug(self) -> None:
        """Pull the simulated adapter out: the transport is lost at once and cannot reopen until
        :meth:`replug`."""
        self._plugged = False
        self._lose(TransportError(f"{self.name}: adapter unplugged"), self._generation)

    def replug(self) -> None:
        """Plug the adapter back in: the transport's recovery reopens it on its next attempt."""
        self._plugged = True

    # ----------------------------------------------------------------- connection

    async def _connect(self) -> None:
        if not self._plugged:
            raise TransportError(f"{self.name}: cannot open: adapter unplugged")
        now = self._now()
        loop = anyio.lowlevel.current_token().native_token
        network = self.network
        if self._anchor is not loop:
            self._t0 = now - network.now_s
            self._anchor = loop
        else:  # reopened on the same loop: the devices ran on while we were away, unheard
            self._stats.ignored += len(network.advance(max(network.now_s, now - self._t0)))
        self._busy_s = network.bus.busy_s
        self._direct = True
        self._stop_clock()
        assert self._runtime is not None
        self._clock = start_clock(
            self._runtime,
            self._tasks,
            self._armed_loop_time,
            self._on_timer,
            self._generation,
            name=f"{self.name} clock",
            task_lane=self.task_clock,
        )
        self._rearm()

    async def _disconnect(self) -> None:
        self._direct = False
        self._stop_clock()

    # ----------------------------------------------------------------- sending

    def _write_now(self, frame: Frame, handle: Any) -> bool:
        if not self._plugged:
            self._lose(TransportError(f"{self.name}: adapter unplugged"), self._generation)
            raise self._error()
        now = self._now()
        if self.episodes is not None and (why := self._refusal(now)) is not None:
            if why == "queue_full":
                self._stats.enobufs_dropped += 1
                raise SendQueueFull(f"{self.name}: the controller's send queue is full (ENOBUFS)")
            self._stats.bus_off_dropped += 1
            raise BusOffError(f"{self.name}: the CAN controller is bus-off (ENETDOWN)")
        self._put(frame, handle, now)
        return True

    async def _transmit(self, batch: list[Outgoing[Frame]]) -> None:
        while batch:
            if not self._plugged:
                self._lose(TransportError(f"{self.name}: adapter unplugged"), self._generation)
                return  # what is left in batch is counted as purged by the base
            outgoing = batch.pop(0)
            now = self._now()
            if self.episodes is not None and (why := self._refusal(now)) is not None:
                self._dropped(
                    why, [outgoing.handle], "enobufs_dropped" if why == "queue_full" else "bus_off_dropped"
                )
                continue
            self._put(outgoing.item, outgoing.handle, now)

    def _refusal(self, now: float) -> str | None:
        """Whether the controller refuses a send now ("queue_full", "bus_off"), as its episodes say;
        a refused ENETDOWN is bus-off, and a send that goes through after one ends it."""
        assert self.episodes is not None
        why = self.episodes.refusal(now - self._t0)
        if why == "bus_off":
            self._bus_off.went_off(now)
        elif why is None and self._bus_off.since is not None:
            self._bus_off.came_back(now)
        return why

    def _put(self, frame: Frame, handle: Any, now: float) -> None:
        network = self.network
        at = now - self._t0
        if at < (network_now := network.now_s):  # the network ran ahead: queued at its time
            at = network_now
        network.send(frame, at)
        stats = self._stats
        stats.frames_out += 1
        stats.bytes_out += len(frame.data)
        self._sent(handle, now)
        self._arm(at)

    # ----------------------------------------------------------------- the network's clock

    def _arm(self, at: float) -> None:
        """Have the clock fire at network time ``at`` (or earlier, if it already would)."""
        armed = self._timer_at
        if armed is not None and armed <= at:
            return
        self._timer_at = at
        if self._clock is not None:
            self._clock.poke(at + self._t0)

    def _armed_loop_time(self) -> float | None:
        at = self._timer_at
        return None if at is None else at + self._t0

    def _stop_clock(self) -> None:
        clock, self._clock = self._clock, None
        if clock is not None:
            clock.stop()
        self._timer_at = None

    def _rearm(self) -> None:
        at = self.network.next_event_s()
        if at is not None:
            self._arm(at)
        if self.episodes is not None and (at := self.episodes.next_error_frame_s()) is not None:
            self._arm(at)

    def _on_timer(self, generation: int) -> None:
        armed, self._timer_at = self._timer_at, None
        if generation != self._generation or armed is None:
            return
        network, t0, episodes = self.network, self._t0, self.episodes
        # asyncio runs a timer that is due within its clock's resolution: never run short of the
        # event the clock was armed for, or it would be re-armed for the same instant.
        until = max(self._now() - t0, armed)
        if episodes is None:
            # One call: the network runs to now, then ahead over what the host can neither see nor
            # change (so the next timer is for the next frame the host receives), and the frames
            # received come as the host's Frames, stamped on the loop's clock. A consumer sending
            # from the delivery below queues behind the host's frames the run-ahead went past, where
            # it changes nothing (SimCanNetwork.run_ahead), and arms the clock itself.
            frames, at = network.host_turn(until, t0)
        else:
            received = self._controller(episodes, network.advance(until), until)
            frames = [stamped(frame, end + t0) for end, frame in received]
            at = None
        busy = network.bus.busy_s
        if busy != self._busy_s:
            self._load.add(until + t0, busy - self._busy_s)
            self._busy_s = busy
        if frames:
            stats = self._stats
            stats.frames_in += len(frames)
            for frame in frames:
                stats.bytes_in += len(frame.data)
            self._deliver(frames)  # a consumer may send (and arm) from here
        if generation != self._generation:
            return
        if episodes is not None:
            at = network.run_ahead(until)  # after the consumer's sends, as host_turn's docstring says
            if (error_at := episodes.next_error_frame_s()) is not None:
                self._arm(error_at)
        if at is not None:
            self._arm(at)

    def _controller(
        self, episodes: ControllerEpisodes, received: list[tuple[float, Frame]], until: float
    ) -> list[tuple[float, Frame]]:
        """The controller's error frames due by ``until`` (network time), and what it received of
        ``received``: nothing while it is bus-off (counted ``ignored``)."""
        for at, classes in episodes.error_frames(until):
            self._bus_off.error_frame(CanErrorClass(classes), bytes(8), at + self._t0)
        heard = [(at, frame) for at, frame in received if episodes.receiving(at)]
        self._stats.ignored += len(received) - len(heard)
        return heard
