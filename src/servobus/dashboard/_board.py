"""What the dashboard shows, gathered beside the control loop and sampled for the page (sans-IO).

The hot path pays a dictionary store or two per decoded reply (:meth:`Board.watch`'s subscriber)
and per frame (:meth:`Board.tap`'s callbacks: the frame, and a command sent, the Bus's own request
object): the latest of each is kept, nothing is decoded or copied there. Everything else (the rows,
the frames' names, the rates, the JSON) is made when a page asks, at most once per update period
(:meth:`Board.update`) however many pages are open, and not at all while none is.
"""

from __future__ import annotations

import dataclasses
import enum
import json
import math
import time
from collections import defaultdict
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from servobus.frame import Frame
from servobus.protocols import Command, Reply
from servobus.scheduler import Request
from servobus.tools.logs import FrameDecoder, message_values
from servobus.tools.recording import TapLink
from servobus.transports.base import SendReporter
from servobus.transports.contract import Consumer

if TYPE_CHECKING:
    from servobus.loop import Loop

__all__ = ["FIGURES_EVERY_S", "FRAMES_EVERY_S", "NAME_EVERY_S", "Board", "Watched"]

#: how often a bus's counters and latency and a loop's figures are made again, at most (the
#: percentiles sort thousands of samples: not for every update; one bus per update, in turn)
FIGURES_EVERY_S = 0.5
#: how often a bus's frame view is made again, at most (its ``frames`` is in those updates only)
FRAMES_EVERY_S = 0.25
#: a frame view row's name is decoded again at most this often (when its bytes changed)
NAME_EVERY_S = 1.0
#: a motor that restarted is shown ``restarted`` this long, then ``online`` (the reason says when)
RESTART_SHOWN_S = 10.0


@dataclass(eq=False, slots=True)
class Watched:
    """One motor on the board.

    Attributes:
        key: ``BUS/ID`` (``BUS/FAMILY/ID`` when two families share the id on one bus).
        bus: the bus's name on the board.
        family: the motor's family.
        motor_id: its id.
        motor: the Bus's Motor (or a bridge's RemoteMotor), what the page's stop goes to.
        reply: a bridge's motor's latest reply, as published or read (a Bus's Motor keeps its own:
            ``Motor.state``, read at each update; nothing is done per frame).
        status: ``"online"``, ``"offline"``, ``"restarted"``, or ``"unknown"`` before the watchdog said.
        reason: the watchdog's words for the status.
        replied_at: when its latest reply came, on the board's clock, where the board stamps it
            (``stamped``: a bridge's motor; a Bus's Motor keeps ``last_seen`` itself).
        restarted_at: when the watchdog last said it restarted (the board's clock).
    """

    key: str
    bus: str
    family: str
    motor_id: int
    motor: Any
    reply: Reply | None = None
    status: str = "unknown"
    reason: str = ""
    replied_at: float | None = None
    restarted_at: float | None = None
    stamped: bool = False


@dataclass(slots=True)
class _Bus:
    """A bus on the board: where its figures come from, its frames as last seen (per identifier and
    direction), each motor's last command sent, and what was last shown of them."""

    name: str
    source: Any  # a servobus Bus (metrics()), or a bridge's RemoteBus (its metrics set from outside)
    frames: dict[tuple[bool, int, bool], Frame] = field(default_factory=dict)
    frame_counts: defaultdict[tuple[bool, int, bool], int] = field(default_factory=lambda: defaultdict(int))
    commands: dict[int, Command] = field(default_factory=dict)  # by id(codec): the last not a read
    decoders: dict[str, FrameDecoder] = field(default_factory=dict)
    names: dict[tuple[bool, int, bool], tuple[bytes, str, float]] = field(default_factory=dict)
    metrics: dict[str, Any] | None = None  # a remote bus's, as last fetched
    figures: dict[str, Any] = field(default_factory=dict)
    figures_at: float | None = None
    last_requests: tuple[int, float] | None = None  # (the requests counter, when it was read)
    request_rate_hz: float | None = None
    frame_rows: list[dict[str, Any]] = field(default_factory=list)
    frames_at: float | None = None
    last_counts: dict[tuple[bool, int, bool], int] = field(default_factory=dict)

    def count_requests(self, requests: Any, at: float) -> None:
        """The requests counter read at ``at``: the rate since the last reading."""
        if not isinstance(requests, int):
            self.last_requests = self.request_rate_hz = None
            return
        if self.last_requests is not None and at > self.last_requests[1]:
            before, then = self.last_requests
            self.request_rate_hz = round((requests - before) / (at - then), 1)
        self.last_requests = (requests, at)


class Board:
    """The motors, buses and loop a dashboard shows.

    Args:
        update_hz: the most updates per second the page gets (each is made once for all pages).
        clock: the clock of updates' times (default: the first watched Bus's, its event loop's; else
            ``time.monotonic``).
    """

    def __init__(self, *, update_hz: float = 30.0, clock: Callable[[], float] | None = None) -> None:
        if not (0.5 <= update_hz <= 100.0):
            raise ValueError(f"update_hz={update_hz}: expected 0.5 to 100 updates per second")
        self.period_s = 1.0 / update_hz
        self._clock = clock
        self._buses: dict[str, _Bus] = {}
        self._links: dict[int, tuple[TapLink, _Bus]] = {}  # the taps made, until their Bus is watched
        self._motors: dict[str, Watched] = {}
        self._by_motor: dict[int, Watched] = {}
        self._loops: list[Loop] = []
        self._noters: dict[str, Callable[..., None]] = {}
        self._cached: tuple[int, str] | None = None
        self._origin: float | None = None
        self._loops_at: float | None = None
        self._turn = -1  # the bus whose figures are made again in this update
        self._loop_figures: list[dict[str, Any]] = []

    # ---- what is watched ----

    def tap(self, link: Any) -> TapLink:
        """``link`` wrapped so that the board sees its frames, both ways (give the result to the
        Bus): the raw frame view lists them by identifier, like ``python -m can.viewer``, and each
        motor's set-point is the command of the last request sent to it that is not a read."""
        entry = _Bus(link.name, None)
        tapped = _BoardTap(link, entry)
        self._links[id(tapped)] = (tapped, entry)  # (the tap kept: its id is not reused meanwhile)
        return tapped

    def watch(self, bus: Any, *, name: str | None = None) -> None:
        """Show ``bus`` (a :class:`servobus.Bus`, or a bridge's ``RemoteBus``) and its motors: every
        reply (a Bus's motors' ``state``, read at each update; a bridge's, as it publishes them) and
        watchdog status from now on; motors added to it later appear too.

        Raises:
            ValueError: a bus of that name is on the board already.
        """
        label = name or bus.name
        if label in self._buses:
            raise ValueError(f"a bus named {label!r} is on the board already")
        link = getattr(getattr(bus, "engine", None), "link", None)
        tapped = self._links.pop(id(link), None)
        entry = tapped[1] if tapped is not None else _Bus(label, bus)
        entry.name, entry.source = label, bus
        self._buses[label] = entry
        if self._clock is None and hasattr(bus, "time"):
            self._clock = bus.time
        by_motor = self._by_motor

        now = self._now

        def replied(motor: Any, reply: Reply) -> None:  # (a bridge's motor: a state it published)
            watched = by_motor.get(id(motor)) or self._add(label, motor)
            watched.reply = reply
            watched.replied_at = now()

        self._noters[label] = replied

        def status(event: Any) -> None:
            watched = by_motor.get(id(event.motor)) or self._add(label, event.motor)
            reason = getattr(event, "reason", "")
            watched.status = "restarted" if reason == "restarted" else "online" if event.online else "offline"
            watched.reason = reason
            if reason == "restarted":
                watched.restarted_at = now()

        if not hasattr(bus, "engine"):  # (a Bus's Motor keeps its latest reply: nothing per frame)
            bus.subscribe(replied)
        bus.subscribe_status(status)

    def note(self, bus: str, motor: Any, reply: Reply) -> None:
        """A reply of ``motor`` on the watched bus ``bus`` that the subscriber does not see (a bridge's
        motor's reply to a request: only published states reach the subscriber)."""
        self._noters[bus](motor, reply)

    def watch_loop(self, loop: Loop) -> None:
        """Show ``loop``'s figures: its tick lateness, state age and counters."""
        self._loops.append(loop)

    @property
    def loops(self) -> tuple[Loop, ...]:
        """The loops watched."""
        return tuple(self._loops)

    def set_metrics(self, bus: str, metrics: dict[str, Any]) -> None:
        """A bus's metrics as fetched from elsewhere: a bridge's ``RemoteBus.metrics()`` (its Bus's
        are under ``"bus"``), or :class:`servobus.metrics.Metrics` as a dict."""
        found = metrics.get("bus", metrics)
        entry = self._buses[bus]
        entry.metrics = found if isinstance(found, dict) else metrics
        entry.count_requests(entry.metrics.get("requests"), self._now())

    # ---- the motors ----

    def motors(self) -> list[Watched]:
        """Every motor of the watched buses, by bus then id (new motors are picked up here)."""
        for entry in self._buses.values():
            for motor in _motors_of(entry.source):
                if id(motor) not in self._by_motor:
                    self._add(entry.name, motor)
        order = {name: n for n, name in enumerate(self._buses)}
        return sorted(self._motors.values(), key=lambda w: (order.get(w.bus, -1), w.motor_id, w.family))

    def find(self, key: str) -> Watched:
        """The motor of ``key`` (``BUS/ID``).

        Raises:
            KeyError: no such motor on the board.
        """
        self.motors()
        return self._motors[key]

    def _add(self, bus: str, motor: Any) -> Watched:
        family = _family_name(motor)
        key = f"{bus}/{motor.motor_id}"
        if key in self._motors:
            key = f"{bus}/{family}/{motor.motor_id}"
        watched = Watched(key, bus, family, motor.motor_id, motor, stamped=not hasattr(motor, "last_seen"))
        latest = getattr(motor, "state", None)  # (a bridge's motor: its last published state)
        if isinstance(latest, Reply):
            watched.reply = latest
        online = getattr(motor, "online", None)
        if isinstance(online, bool):
            watched.status = "online" if online else "offline"
        self._motors[key] = watched
        self._by_motor[id(motor)] = watched
        if (entry := self._buses.get(bus)) is not None:  # (its decoder knows the ids it was made for)
            entry.decoders.pop(family, None)
            entry.names.clear()
        return watched

    # ---- updates ----

    def _now(self) -> float:
        return self._clock() if self._clock is not None else time.monotonic()

    def update(self) -> str:
        """The page's update as JSON, made once per update period (the same text for every page
        that asks within one period)."""
        now = self._now()
        slot = math.floor(now / self.period_s)
        if self._cached is not None and self._cached[0] == slot:
            return self._cached[1]
        text = json.dumps(self.snapshot(now), allow_nan=False, default=_jsonable, separators=(",", ":"))
        self._cached = (slot, text)
        return text

    def snapshot(self, now: float | None = None) -> dict[str, Any]:
        """What the page shows now: the motors' rows (every update), each bus's figures and a loop's
        (every :data:`FIGURES_EVERY_S`), each bus's frames (every :data:`FRAMES_EVERY_S`: a bus's
        ``frames`` is left out of the updates between)."""
        now = self._now() if now is None else now
        if self._origin is None:
            self._origin = now
        rows = []
        for watched in self.motors():
            rows.append(self._row(watched, now))
        if self._loops_at is None or now - self._loops_at >= FIGURES_EVERY_S:
            self._loops_at, self._loop_figures = now, [_loop_figures(loop) for loop in self._loops]
        return {
            "t": round(now - self._origin, 4),
            "motors": rows,
            "buses": self._figures(now),
            "loops": self._loop_figures,
        }

    def _row(self, w: Watched, now: float) -> dict[str, Any]:
        reply = w.reply if w.stamped else w.motor.state
        fields = _numbers(reply) if reply is not None else {}
        setpoint = self._setpoint(w)
        fault = getattr(w.motor, "fault", None)  # (the Bus's record: kept until a reply without it)
        if fault is None and reply is not None and (faults := getattr(reply, "FAULTS", None)):
            fault = getattr(reply, faults)
        seen = w.replied_at if w.stamped else getattr(w.motor, "last_seen", None)
        status, reason = w.status, w.reason
        if status == "restarted" and w.restarted_at is not None and now - w.restarted_at > RESTART_SHOWN_S:
            status, reason = "online", f"restarted {now - w.restarted_at:.0f} s ago"
        return {
            "key": w.key,
            "bus": w.bus,
            "family": w.family,
            "id": w.motor_id,
            "status": status,
            "reason": reason,
            "reply": type(reply).__name__ if reply is not None else None,
            "age_s": None if seen is None else round(max(0.0, now - seen), 4),
            "fault": _fault_names(fault),
            "temperature_c": fields.get("temperature_c"),
            "fields": fields,
            "setpoint": setpoint,
        }

    def _setpoint(self, w: Watched) -> dict[str, Any] | None:
        """The last command that is not a read sent to the motor (seen by the tap), with its numbers."""
        codec = getattr(w.motor, "codec", None)
        command = self._buses[w.bus].commands.get(id(codec)) if codec is not None else None
        if command is None:
            return None
        return {"name": type(command).__name__, "fields": _numbers(command)}

    def _decoder(self, entry: _Bus, family: str) -> FrameDecoder:
        found = entry.decoders.get(family)
        if found is None:
            ids = sorted(
                {w.motor_id for w in self._motors.values() if w.bus == entry.name and w.family == family}
            )
            found = entry.decoders[family] = FrameDecoder(family, ids=ids or None)
        return found

    def _figures(self, now: float) -> list[dict[str, Any]]:
        """Each bus's figures: those of one bus made again per update, in turn (a bus's metrics sort
        its latency window: the demo's 11 buses at once took milliseconds), as they are due."""
        entries = list(self._buses.values())
        if not entries:
            return []
        self._turn = (self._turn + 1) % len(entries)
        return [self._bus(entry, now, n == self._turn) for n, entry in enumerate(entries)]

    def _bus(self, entry: _Bus, now: float, turn: bool) -> dict[str, Any]:
        since = None if entry.figures_at is None else now - entry.figures_at
        if since is None or (turn and since >= FIGURES_EVERY_S):
            figures = _bus_figures(entry)
            if entry.metrics is None:  # (a local Bus's, read now; a bridge's, when they were fetched)
                entry.count_requests(figures.get("requests"), now)
            figures["request_rate_hz"] = entry.request_rate_hz
            entry.figures, entry.figures_at = _finite_or_none(figures), now
        since = None if entry.frames_at is None else now - entry.frames_at
        if since is not None and (not turn or since < FRAMES_EVERY_S):
            return entry.figures
        entry.frame_rows, entry.frames_at = self._frames(entry, now, since), now
        return {**entry.figures, "frames": entry.frame_rows}

    def _frames(self, entry: _Bus, now: float, since: float | None) -> list[dict[str, Any]]:
        """One row per identifier and direction, like ``can.viewer``: its count, rate and last data,
        and what it decodes to."""
        rows = []
        families = sorted({w.family for w in self._motors.values() if w.bus == entry.name})
        for key in sorted(entry.frames, key=lambda k: (k[1], k[0])):
            received, ident, extended = key
            frame = entry.frames[key]
            count = entry.frame_counts.get(key, 0)
            before = entry.last_counts.get(key)
            entry.last_counts[key] = count
            rows.append(
                {
                    "dir": "rx" if received else "tx",
                    "id": f"0x{ident:08X}" if extended else f"0x{ident:03X}",
                    "data": frame.data.hex(" ").upper(),
                    "count": count,
                    "rate_hz": None if before is None or not since else round((count - before) / since, 1),
                    "name": self._name(entry, key, families, frame, now),
                }
            )
        return rows

    def _name(
        self, entry: _Bus, key: tuple[bool, int, bool], families: Iterable[str], frame: Frame, now: float
    ) -> str:
        """What ``frame`` decodes to, decoded again when its bytes changed, at most every
        :data:`NAME_EVERY_S` (a set-point's bytes change every tick; its name does not)."""
        data = bytes(frame.data)
        known = entry.names.get(key)
        if known is not None and (known[0] == data or now - known[2] < NAME_EVERY_S):
            return known[1]
        name = "?"
        for family in families:
            decoded = self._decoder(entry, family).decode(frame)
            if decoded.message is not None:
                who = "" if decoded.motor_id is None else f" (motor {decoded.motor_id})"
                name = f"{type(decoded.message).__name__}{who}"
                break
        entry.names[key] = (data, name, now)
        return name


class _BoardTap(TapLink):
    """:class:`~servobus.tools.recording.TapLink` made cheap for the control loop: nothing wraps a
    send (the Bus's handle is its request: frame, command and motor, reported as they are); a
    received batch is counted in one loop; no clock is read. A frame sent is counted at its report."""

    def __init__(self, inner: Any, entry: _Bus) -> None:
        super().__init__(inner, _unused, _no_clock)
        self._entry = entry

    def send(self, frame: Frame, handle: object = None) -> None:
        self._inner.send(frame, handle)

    def set_consumer(self, consumer: Consumer | None) -> None:
        if consumer is None:
            self._inner.set_consumer(None)
            return
        frames, counts = self._entry.frames, self._entry.frame_counts

        def tapped(batch: list[Frame]) -> object:
            for frame in batch:
                key = (True, frame.arbitration_id, frame.is_extended_id)
                frames[key] = frame
                counts[key] += 1
            return consumer(batch)

        self._inner.set_consumer(tapped)

    def set_send_reporter(self, reporter: SendReporter | None) -> None:
        if reporter is None:
            self._inner.set_send_reporter(None)
            return
        frames, counts, commands = self._entry.frames, self._entry.frame_counts, self._entry.commands

        def tapped(handle: Any, sent_at: float | None, reason: str | None) -> object:
            if reason is None:
                if handle.__class__ is Request:
                    frame = handle.frame
                    if handle.writes:
                        commands[id(handle.codec)] = handle.command
                else:
                    frame = handle  # (a frame sent without a request: the Bus's broadcast)
                if frame.__class__ is Frame:
                    key = (False, frame.arbitration_id, frame.is_extended_id)
                    frames[key] = frame
                    counts[key] += 1
            return reporter(handle, sent_at, reason)

        self._inner.set_send_reporter(tapped)


def _unused(*_: Any) -> None:
    raise AssertionError("(the board's tap counts frames itself)")


def _no_clock() -> float:
    return 0.0


def _motors_of(source: Any) -> list[Any]:
    motors = getattr(source, "motors", {})
    found = list(motors.values())
    found.sort(key=lambda m: m.motor_id)
    return found


def _family_name(motor: Any) -> str:
    codec = getattr(motor, "codec", None)
    if codec is not None:
        return str(codec.family)
    family = getattr(motor, "family", None)
    return str(getattr(family, "name", family))


def _numbers(message: Any) -> dict[str, float | int]:
    """A command's or reply's numeric fields (the ones a plot can show), finite; a message with other
    kinds of fields (tuples, nested messages) through :func:`~servobus.tools.logs.message_values`."""
    names = _FIELDS.get(type(message))
    if names is None:
        names = _FIELDS[type(message)] = tuple(f.name for f in dataclasses.fields(message))
    out: dict[str, float | int] = {}
    for name in names:
        value = getattr(message, name)
        kind = type(value)
        if kind is float:
            if math.isfinite(value):
                out[name] = value
        elif kind is int:
            out[name] = value
        elif isinstance(value, enum.Flag):  # (a reply's fault flags: their bits, as message_values)
            out[name] = int(value.value)
        elif not (value is None or isinstance(value, bool | str | enum.Enum)):
            return _finite(message_values(message))
    return out


def _finite(values: dict[str, Any]) -> dict[str, float | int]:
    return {
        name: value
        for name, value in values.items()
        if isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
    }


#: each message class's field names (read once per class)
_FIELDS: dict[type, tuple[str, ...]] = {}


def _fault_names(fault: Any) -> list[str]:
    """A fault as flag names: a MotorFault's flags (or its code), a flag enum's members, a list's items."""
    if hasattr(fault, "flags"):  # a MotorFault: its flags, or its code (Reply.FAULT_CODE)
        fault = fault.flags if fault.flags is not None else getattr(fault, "code", None)
    if not fault:
        return []
    if isinstance(fault, enum.Flag):
        return [member.name or str(member) for member in fault]
    if isinstance(fault, Iterable) and not isinstance(fault, str):
        return [getattr(f, "name", str(f)) for f in fault]
    return [getattr(fault, "name", None) or str(fault)]


def _bus_figures(entry: _Bus) -> dict[str, Any]:
    """The counters the page shows of a bus (a local Bus's metrics, or a bridge's as fetched)."""
    out: dict[str, Any] = {"name": entry.name}
    names = ("requests", "replies", "timeouts", "late", "ambiguous", "duplicate", "malformed", "restarts")
    if entry.metrics is None and hasattr(entry.source, "engine"):  # a local Bus
        metrics = entry.source.metrics()
        out.update({name: getattr(metrics, name) for name in names})
        out["bus_load_pct"] = metrics.bus_load_pct
        out["latency_p99_s"] = metrics.latency.p99_s
        return out
    found = entry.metrics or {}
    latency = found.get("latency")
    out.update({name: found.get(name) for name in names})
    out["bus_load_pct"] = found.get("bus_load_pct")
    out["latency_p99_s"] = latency.get("p99_s") if isinstance(latency, dict) else None
    return out


def _loop_figures(loop: Loop) -> dict[str, Any]:
    metrics = loop.metrics()
    figures = {f.name: getattr(metrics, f.name) for f in dataclasses.fields(metrics)}
    figures["hz"] = loop.hz
    return _finite_or_none(figures)


def _finite_or_none(figures: dict[str, Any]) -> dict[str, Any]:
    """``figures`` with a NaN or an infinity as None (JSON has neither: the page's parse would fail)."""
    return {k: None if isinstance(v, float) and not math.isfinite(v) else v for k, v in figures.items()}


def _jsonable(value: Any) -> Any:
    """What JSON has no type for (floats never come here: NaN is kept out by _finite_or_none)."""
    if isinstance(value, bytes):
        return value.hex()
    return str(value)
