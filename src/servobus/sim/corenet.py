"""Simulated devices on one simulated CAN bus, run by the C core: :class:`CoreCanNetwork`.

The same network as :class:`~servobus.sim.network.SimCanNetwork` (the reference: same public API,
same traces, same device counters and plant states), with the bus model, the routing, the link
counts and the frame log in C (``csrc/sim_net.c``). A device with a C path (``CORE_FAMILY``,
``core_attach``, ``core_push``, ``core_detach``) gets its C twin, ``motors[node]``, and frames and
deadlines its family handles in C never reach Python. Everything else (a Python model, a frame the
C path leaves cold, a frame the host receives) comes back from one C call as an event: the network
then acts on it in Python exactly as the reference does, and calls C again to go on.

Which device is on which C node, and what C knows of each, is :mod:`~servobus.sim.corenodes`.

Python :class:`~servobus.frame.Frame` objects the host or a Python device sends are kept by their
slot in C and handed back as the same objects; frames made in C become Frame objects only when the
host or a Python model receives them. The host's raw path is :meth:`CoreCanNetwork.host_turn`: one C
call runs the network to the host's time and ahead past it, and the replies come back as bytes
from which the host's Frames (stamped with the time each ended) are made once, at the edge. Fault
injectors act in Python, in the reference's order, so a seed gives the same trace.
"""

from __future__ import annotations

import heapq
import itertools
import math
import struct
from collections.abc import Callable, Hashable, Iterable
from typing import Any, NoReturn

from servobus.core._lib import ffi, lib
from servobus.frame import Frame
from servobus.sim.canbus import CanBusModel
from servobus.sim.corenodes import CoreNodes
from servobus.sim.device import Device, Emission
from servobus.sim.faults import FaultInjector
from servobus.sim.network import LOG_LIMIT, FrameSlots, stamped

__all__ = ["CoreBus", "CoreCanNetwork", "CoreLink"]

#: events one C call may return before Python takes them
EVENTS = lib.SB_TURN_EVENTS
_INF = math.inf
# sb_netevent as bytes: kind, node, t, then the sb_simframe (t, id, flags, len, node, tag, data).
_EVENT = struct.Struct("<iiddIBBhI64s4x")
assert _EVENT.size == ffi.sizeof("sb_netevent") and ffi.offsetof("sb_netevent", "frame") == 16
assert ffi.offsetof("sb_simframe", "data") == 20

_RX, _DELIVER, _POLL = lib.SB_EV_RX, lib.SB_EV_DELIVER, lib.SB_EV_POLL
_IDLE, _LOG_FULL = lib.SB_RUN_IDLE, lib.SB_RUN_LOG_FULL
_ADVANCE, _AHEAD, _STOP_RX = lib.SB_RUN_ADVANCE, lib.SB_RUN_AHEAD, lib.SB_RUN_STOP_RX
_TURN, _HOST_SEND = lib.sb_simnet_turn, lib.sb_simnet_host_send
_TURN_HEAD = struct.Struct("<iii4xd")  # sb_netturn before its events: status, stage, n_events, next_s
assert ffi.offsetof("sb_netturn", "ev") == _TURN_HEAD.size and ffi.offsetof("sb_netturn", "next_s") == 16
_TURN_ADVANCE, _TURN_AHEAD = lib.SB_TURN_ADVANCE, lib.SB_TURN_AHEAD
# What the host's edge reads of an SB_EV_RX event: its time, the frame's id, flags, length and tag,
# and its first 8 data bytes (a classic frame's all); a longer frame's data are read at _RX_DATA.
_RX_EVENT = struct.Struct("<8xd8xIBB2xI8s")
_RX_DATA = ffi.offsetof("sb_netevent", "frame") + ffi.offsetof("sb_simframe", "data")
assert _RX_EVENT.size == _RX_DATA + 8
_FLAG_BITS = tuple((f & 1 == 1, f & 2 == 2, f & 4 == 4) for f in range(8))  # extended, FD, BRS

# A frame made in C, built without Frame's checks (C checked it): through the slot descriptors.
_NEW = object.__new__
_SETTERS = {name: getattr(Frame, name).__set__ for name in Frame.__slots__}
_SET_ID, _SET_DATA = _SETTERS["arbitration_id"], _SETTERS["data"]
_SET_EXT, _SET_FD, _SET_BRS = _SETTERS["is_extended_id"], _SETTERS["is_fd"], _SETTERS["bitrate_switch"]
_SET_SERIAL, _SET_TS, _SET_RX, _SET_ESI = (
    _SETTERS["is_serial"],
    _SETTERS["timestamp"],
    _SETTERS["is_rx"],
    _SETTERS["error_state_indicator"],
)
_MADE_CACHE = 4096  # frames made in C kept by content (replies repeat; a Frame is immutable)


def _flags(frame: Frame) -> int:
    return frame.is_extended_id | (frame.is_fd << 1) | (frame.bitrate_switch << 2)


def _host_frames(view: Any, n: int, frames: list[Frame | None], stamp_s: float) -> list[Frame]:
    """The host's frames of ``n`` SB_EV_RX events in ``view``, each stamped with its end + ``stamp_s``:
    a frame made in C becomes its one Frame here, at the edge (unchecked: C checked it)."""
    unpack, size = _RX_EVENT.unpack_from, _EVENT.size
    out: list[Frame] = []
    append = out.append
    for at in range(0, n * size, size):
        t, can_id, flags, length, tag, data = unpack(view, at)
        if tag:  # the sender's own object (a Python model's)
            append(stamped(frames[tag - 1], t + stamp_s))
            continue
        if length != 8:
            data = data[:length] if length < 8 else view[at + _RX_DATA : at + _RX_DATA + length]
        frame = FrameSlots()
        frame.arbitration_id = can_id
        frame.data = data
        frame.is_extended_id, frame.is_fd, frame.bitrate_switch = _FLAG_BITS[flags]
        frame.is_serial = False
        frame.timestamp = t + stamp_s
        frame.is_rx = True
        frame.error_state_indicator = False
        frame.__class__ = Frame  # type: ignore[assignment]
        append(frame)  # type: ignore[arg-type]
    return out


def _refused(status: int, frame: Frame, ready_s: float, bus_now_s: float) -> NoReturn:
    """Raise what sb_simnet_send's ``status`` means."""
    if status == lib.SB_E_RANGE:
        raise ValueError(f"ready_s={ready_s} is before the bus time {bus_now_s} (time runs forward)")
    if status == lib.SB_E_FULL:
        raise RuntimeError(
            f"the simulated bus holds {lib.SB_NET_FRAMES} queued frames: {frame!r} is one too many"
        )
    raise ValueError(f"the simulated bus cannot queue {frame!r} at {ready_s}")


def _made(cache: dict[tuple[int, int, bytes], Frame], can_id: int, flags: int, data: bytes) -> Frame:
    key = (can_id, flags, data)
    frame = cache.get(key)
    if frame is None:
        if len(cache) >= _MADE_CACHE:
            cache.clear()
        frame = cache[key] = _NEW(Frame)
        _SET_ID(frame, can_id)
        _SET_DATA(frame, data)
        _SET_EXT(frame, bool(flags & 1))
        _SET_FD(frame, bool(flags & 2))
        _SET_BRS(frame, bool(flags & 4))
        _SET_SERIAL(frame, False)
        _SET_TS(frame, 0.0)
        _SET_RX(frame, True)
        _SET_ESI(frame, False)
    return frame


class _CoreLog:
    """What :class:`~servobus.sim.device.ListeningDevice` reads of a link's log: its frame count."""

    __slots__ = ("net",)

    def __init__(self, net: Any) -> None:
        self.net = net

    @property
    def count(self) -> int:
        return int(self.net.log_count)


class CoreLink:
    """One device's account with a :class:`CoreCanNetwork`: :class:`~servobus.sim.device.BusLink`'s
    interface over the counts the C engine keeps for the node.

    Args:
        net: the network's ``sb_simnet *``.
        node: the device's node in it.
        name: the device's name.
        buffers: the network's scratch cdata for :meth:`catch_up` (end times, missed counts, count).
        notify: what :meth:`changed` calls with the name (the network's dirty list).
    """

    __slots__ = ("_count", "_ends", "_lib_net", "_missed", "_node", "_notify", "_state", "log", "name")

    def __init__(
        self, net: Any, node: int, name: str, buffers: tuple[Any, Any, Any], notify: Callable[[str], None]
    ) -> None:
        self._lib_net = net
        self._node = node
        self._state = net.nodes + node
        self.log = _CoreLog(net)
        self._ends, self._missed, self._count = buffers
        self._notify = notify
        self.name = name

    @property
    def cursor(self) -> int:
        return int(self._state.cursor)

    @property
    def own(self) -> int:
        return int(self._state.own)

    @property
    def taken(self) -> int:
        return int(self._state.taken)

    @property
    def behind(self) -> bool:
        """Frames have gone by since the last :meth:`catch_up`."""
        return bool(self._state.cursor != self._lib_net.log_count)

    def catch_up(self, *, every_end: bool) -> tuple[int, int, list[float]]:
        """Settle up: (frames missed, of which odd, end times) since the last call (BusLink.catch_up)."""
        missed, ends, count_out = self._missed, self._ends, self._count
        status = lib.sb_simnet_catch_up(
            self._lib_net, self._node, every_end, missed, missed + 1, ends, lib.SB_NET_LOG, count_out
        )
        if status != lib.SB_OK:
            raise RuntimeError(f"{self.name}: the network dropped frames this link had not settled up for")
        count = count_out[0]
        return int(missed[0]), int(missed[1]), ffi.unpack(ends, count) if count else []

    def changed(self) -> None:
        """The device's identifiers or deadline changed outside the network's calls: ask again."""
        self._notify(self.name)


class CoreBus:
    """The bus model of a :class:`CoreCanNetwork` as :class:`~servobus.sim.canbus.CanBusModel` reads."""

    def __init__(self, net: Any, nodes: CoreNodes) -> None:
        self._net = net
        self._nodes = nodes

    @property
    def busy_s(self) -> float:
        """Total time the wire carried frames."""
        return float(self._net.busy_s)

    @property
    def frames(self) -> int:
        return int(self._net.frames)

    @property
    def bitrate(self) -> float:
        """Nominal bit rate, bit/s. Settable: later frames use it."""
        return float(self._net.bitrate)

    @bitrate.setter
    def bitrate(self, value: float) -> None:
        self._set_rates(value, self.data_bitrate)

    @property
    def data_bitrate(self) -> float | None:
        """CAN FD data-phase bit rate (None: the nominal rate). Settable."""
        rate = float(self._net.data_bitrate)
        return rate if rate > 0 else None

    @data_bitrate.setter
    def data_bitrate(self, value: float | None) -> None:
        self._set_rates(self.bitrate, value)

    def _set_rates(self, bitrate: float, data_bitrate: float | None) -> None:
        if lib.sb_simnet_set_rates(self._net, bitrate, data_bitrate or 0.0) != lib.SB_OK:
            raise ValueError(f"bit rates must be positive (bitrate={bitrate}, data_bitrate={data_bitrate})")

    def frame_time_s(self, frame: Frame) -> float:
        """Seconds ``frame`` occupies this bus (:func:`servobus.timing.frame_time_s`)."""
        data = frame.data
        return float(
            lib.sb_simnet_frame_time(self._net, frame.arbitration_id, _flags(frame), data, len(data))
        )

    @property
    def pending(self) -> int:
        """Frames queued and not yet on the wire."""
        return sum(int(self._net.nodes[k].queued) for k in range(lib.SB_NET_NODES))

    def queued(self, source: Hashable) -> int:
        """Frames node ``source`` has queued and not yet on the wire."""
        node = self._nodes.source_node(source)
        return 0 if node is None else int(self._net.nodes[node].queued)

    def head(self, source: Hashable) -> tuple[float, float] | None:
        """(joined_s, ready_s) of the frame node ``source`` sends next, or None if it has none queued."""
        node = self._nodes.source_node(source)
        if node is None or self._net.nodes[node].head < 0:
            return None
        slot = self._net.slots[self._net.nodes[node].head]
        return float(slot.joined_s), float(slot.f.t)

    def next_completion(self) -> tuple[float, Hashable] | None:
        """(end_s, node) of the transmission that completes next, or None if the bus is idle."""
        out = ffi.new("double *"), ffi.new("int *")
        if lib.sb_simnet_next_completion(self._net, out[0], out[1]) != 1:
            return None
        return float(out[0][0]), self._nodes.names[out[1][0]]

    def next_event_s(self) -> float | None:
        """When the next transmission will complete, as far as the bus knows now (None: idle)."""
        t = lib.sb_simnet_next_event(self._net, 1)
        return None if t == _INF else float(t)


class CoreCanNetwork:
    """Devices, a bus and the pending frames between them, run in C (see the module docstring).

    Args:
        devices: the simulated devices on this bus (unique ``name``\\ s).
        bus: a bus model whose bit rates this network takes (1 Mbit/s classic by default); its
            ``busy_s`` and ``frames`` then follow this network's after every run, so a caller that
            kept the model reads the bus load from it as from SimCanNetwork's.
        to_devices, to_host: fault injectors on each direction (None: a perfect link).

    Raises:
        ValueError: two devices share a name; more devices than the C network holds (63).
    """

    def __init__(
        self,
        devices: Iterable[Device] = (),
        *,
        bus: CanBusModel | None = None,
        to_devices: FaultInjector | None = None,
        to_host: FaultInjector | None = None,
    ) -> None:
        model = bus or CanBusModel()
        self._model = bus
        self._net = ffi.new("sb_simnet *")
        if lib.sb_simnet_init(self._net, model.bitrate, model.data_bitrate or 0.0) != lib.SB_OK:
            raise ValueError(f"bad bit rates (bitrate={model.bitrate}, data_bitrate={model.data_bitrate})")
        self._turn = ffi.new("sb_netturn *")  # sb_simnet_turn's; its events are every run's
        self._turn_head = ffi.buffer(self._turn, _TURN_HEAD.size)
        self._events = self._turn.ev
        self._event_bytes = ffi.buffer(self._events)
        self._n_events = ffi.new("int *")
        self._ends = ffi.new("double[]", lib.SB_NET_LOG)
        self._missed = ffi.new("int64_t[]", 2)  # a link's catch_up: missed, missed odd
        self._count = ffi.new("int *")
        net, buffers = self._net, (self._ends, self._missed, self._count)
        self._nodes = nodes = CoreNodes(
            net, lambda node, name: CoreLink(net, node, name, buffers, nodes.dirty.append)
        )
        self.bus = CoreBus(net, nodes)
        self.devices: dict[str, Device] = nodes.devices
        self._core = nodes.core  # which nodes run a C path (the tests read it)
        self._by_node, self._filter = nodes.by_node, nodes.filter  # the event handlers' lookups
        self.to_devices = to_devices
        self.to_host = to_host
        self._seq = itertools.count()
        self._host_pending: list[tuple[float, int, Frame]] = []  # faults can delay delivery to the host
        self._frames: list[Frame | None] = [None] * lib.SB_NET_FRAMES  # Python frames by C slot
        self._made: dict[tuple[int, int, bytes], Frame] = {}
        for device in devices:
            self.add(device)

    # ---- the public API of SimCanNetwork ----

    @property
    def now_s(self) -> float:
        """The network's time."""
        return float(self._net.now_s)

    @now_s.setter
    def now_s(self, value: float) -> None:
        self._net.now_s = value

    def add(self, device: Device) -> None:
        """Put ``device`` on the bus (:meth:`CoreNodes.add <servobus.sim.corenodes.CoreNodes.add>`).

        Raises:
            ValueError: another device has the same name, the device is on another network, or the
                network is full.
        """
        self._nodes.add(device)

    def remove(self, name: str) -> Device:
        """Take a device off the bus (unplugged, powered off).

        Raises:
            KeyError: no device of that name.
            RuntimeError: called from inside the network's own run (a device's receive or poll).
        """
        return self._nodes.remove(name)

    def send(self, frame: Frame, now_s: float | None = None) -> None:
        """The host queues ``frame`` for transmission at ``now_s`` (default: the network's time)."""
        at = self._net.now_s if now_s is None else now_s
        if self.to_devices is not None:
            for when, item in self.to_devices.apply(frame, at):
                assert isinstance(item, Frame)
                self._schedule(item, when, 0)
            return
        data = frame.data  # _schedule inlined (node 0), id and flags in one key: once per request
        key = (
            frame.arbitration_id | (frame.is_extended_id | frame.is_fd << 1 | frame.bitrate_switch << 2) << 29
        )
        slot = _HOST_SEND(self._net, key, data, len(data), at)
        if slot < 0:
            _refused(slot, frame, at, self._net.bus_now_s)
        self._frames[slot] = frame

    def next_event_s(self) -> float | None:
        """The earliest time anything happens on this network (None: nothing will)."""
        nodes = self._nodes
        if nodes.dirty or nodes.unlinked:
            nodes.refresh()
        t = lib.sb_simnet_next_event(self._net, 0)
        pending = self._host_pending
        if pending and pending[0][0] < t:
            t = pending[0][0]
        return None if t == _INF else float(t)

    def advance(self, until_s: float) -> list[tuple[float, Frame]]:
        """Run the network to ``until_s``; return (time, frame) the host received, in order."""
        received: list[tuple[float, Frame]] = []
        self._run(until_s, _ADVANCE, _INF, received)
        net = self._net
        if until_s > net.now_s:
            net.now_s = until_s
        self._tidy()
        return received

    def run_ahead(self, host_time_s: float) -> float | None:
        """Run on, past ``host_time_s``, over what the host can neither see nor change
        (:meth:`SimCanNetwork.run_ahead <servobus.sim.network.SimCanNetwork.run_ahead>`); return
        :meth:`next_event_s` after it (one call where a driver wants both)."""
        if self.to_devices is None and math.isfinite(self._net.bitrate):
            received: list[tuple[float, Frame]] = []
            self._run(_INF, _AHEAD, host_time_s, received)
            assert not received, "run_ahead() went past a frame the host receives"
            self._tidy()
        return self.next_event_s()

    def host_turn(self, until_s: float, stamp_s: float = 0.0) -> tuple[list[Frame], float | None]:
        """:meth:`SimCanNetwork.host_turn <servobus.sim.network.SimCanNetwork.host_turn>`: advance,
        then run ahead, in one C call while nothing needs Python, the host's Frames made here once."""
        nodes = self._nodes
        plain = self.to_devices is None and self.to_host is None and not self._host_pending
        if not plain or nodes.dirty or nodes.unlinked:
            received = self.advance(until_s)
            return [stamped(frame, at + stamp_s) for at, frame in received], self.run_ahead(until_s)
        turn = self._turn
        n = _TURN(self._net, until_s, LOG_LIMIT, turn)  # < 0: not all done (turn's header says)
        if n < 0:
            return self._turn_on(until_s, stamp_s)
        frames = _host_frames(self._event_bytes, n, self._frames, stamp_s) if n else []
        if (model := self._model) is not None:
            model.busy_s, model.frames = float(self._net.busy_s), int(self._net.frames)
        at = turn.next_s
        return frames, None if at == _INF else at

    def _turn_on(self, until_s: float, stamp_s: float) -> tuple[list[Frame], float | None]:
        """Go on with a turn C stopped for Python (its events handled first), as advance and run_ahead
        (or done with the log to drop: as run_ahead's end)."""
        status, stage, n, _ = _TURN_HEAD.unpack_from(self._turn_head)
        received: list[tuple[float, Frame]] = []
        if n:
            self._handle(n, received)
        if stage == _TURN_ADVANCE:
            self._after(status)
            self._run(until_s, _ADVANCE, _INF, received)
            self._net.now_s = max(until_s, self._net.now_s)
        elif stage == _TURN_AHEAD:
            self._after(status)
            self._run(_INF, _AHEAD, until_s, received)
        self._tidy()
        at = self.next_event_s() if stage >= _TURN_AHEAD else self.run_ahead(until_s)
        return [stamped(frame, t + stamp_s) for t, frame in received], at

    def run_until_idle(self, limit_s: float = 1.0) -> list[tuple[float, Frame]]:
        """Advance until nothing is pending or ``limit_s`` of virtual time has passed."""
        received: list[tuple[float, Frame]] = []
        deadline = self.now_s + limit_s
        while (t := self.next_event_s()) is not None and t <= deadline:
            received += self.advance(t)
        last = lib.sb_simnet_last_ready(self._net, deadline)
        if last > self._net.now_s:
            self._net.now_s = last
        return received

    # ---- the C calls and their events ----

    def _schedule(self, frame: Frame, ready_s: float, node: int) -> None:
        data = frame.data
        flags = frame.is_extended_id | frame.is_fd << 1 | frame.bitrate_switch << 2
        slot = lib.sb_simnet_send(self._net, node, frame.arbitration_id, flags, data, len(data), ready_s, 1)
        if slot < 0:
            _refused(slot, frame, ready_s, self._net.bus_now_s)
        self._frames[slot] = frame

    def _run(
        self, until_s: float, mode: int, host_time_s: float, received: list[tuple[float, Frame]]
    ) -> None:
        net, events, n_events = self._net, self._events, self._n_events
        run = lib.sb_simnet_run
        pending, nodes = self._host_pending, self._nodes
        if self.to_host is not None:
            mode |= _STOP_RX
        while True:
            if nodes.dirty or nodes.unlinked:
                nodes.refresh()
            before = pending[0][0] if pending else _INF
            status = run(net, until_s, before, host_time_s, mode, events, EVENTS, n_events)
            n = n_events[0]
            if n:
                self._handle(n, received)
            if status == _IDLE:
                # SimCanNetwork._step: a frame delayed towards the host arrives before anything else at t
                if mode & _AHEAD == 0 and pending and pending[0][0] <= until_s:
                    at, _, frame = heapq.heappop(pending)
                    if at > net.now_s:
                        net.now_s = at
                    received.append((at, frame))
                    continue
                return
            self._after(status)

    def _after(self, status: int) -> None:
        """What a run that stopped with ``status`` needs before the next: the log dropped, or an error."""
        if status == _LOG_FULL:
            base = self._net.log_base
            self._drop_log()
            if self._net.log_base == base:
                raise RuntimeError("a device on the simulated bus does not settle up with its link")
        elif status < 0:
            raise RuntimeError(
                f"the simulated network failed (status {status}): a C family path answered badly"
            )

    def _handle(self, n: int, received: list[tuple[float, Frame]]) -> None:
        unpack, view, size = _EVENT.unpack_from, self._event_bytes, _EVENT.size
        frames, made, to_host, append = self._frames, self._made, self.to_host, received.append
        for i in range(n):
            kind, node, t, _, can_id, flags, length, _source, tag, data = unpack(view, i * size)
            if kind == _POLL:
                self._poll(node, t)
                continue
            if tag:
                frame = frames[tag - 1]
            else:  # made in C: one Frame per distinct content (_made, inlined for the replies' sake)
                key = (can_id, flags, data[:length])
                frame = made.get(key)
                if frame is None:
                    frame = _made(made, *key)
            assert frame is not None
            if kind == _RX:
                if to_host is None:
                    append((t, frame))
                    continue
                for at, item in to_host.apply(frame, t):
                    assert isinstance(item, Frame)
                    if at <= t:
                        received.append((t, item))
                    else:
                        heapq.heappush(self._host_pending, (at, next(self._seq), item))
            else:
                self._receive(node, frame, t, flags)

    def _receive(self, node: int, frame: Frame, t: float, flags: int) -> None:
        only = self._filter.get(node)
        if only is not None and frame.arbitration_id not in only:
            # more identifiers than C routes by: C handed it every frame; this one it missed
            state = self._net.nodes[node]
            state.taken -= 1
            state.taken_odd -= bool(flags & 3)
            return
        device = self._by_node[node]
        assert device is not None
        for emission in device.receive(frame, t):
            self._schedule(emission.frame, emission.ready_s, node)  # a device's frames: no faults
        self._nodes.called(node, device)

    def _poll(self, node: int, t: float) -> None:
        device = self._by_node[node]
        assert device is not None
        emissions: list[Emission] = device.poll(t)
        for emission in emissions:
            self._schedule(emission.frame, emission.ready_s, node)
        self._nodes.called(node, device)

    def _tidy(self) -> None:
        net = self._net
        if (model := self._model) is not None:
            model.busy_s = float(net.busy_s)
            model.frames = int(net.frames)
        if net.log_count - net.log_base >= LOG_LIMIT:
            self._drop_log()

    def _drop_log(self) -> None:
        """Settle every listening device up and forget the frame ends they have all settled for."""
        for device in self._nodes.listeners.values():
            device.settle()
        lib.sb_simnet_drop_log(self._net)
