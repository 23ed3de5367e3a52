"""What the dashboard shows, gathered beside the control loop and sampled for the page (sans-IO).

The hot path pays one dictionary store per decoded reply (:meth:`Board.watch`'s subscriber) and one
per frame (:meth:`Board.tap`'s callback): the latest of each is kept, nothing is decoded or copied
there. Everything else (the rows, the frames' names, the rates, the JSON) is made when the page asks,
at most once per update period (:meth:`Board.update`), however many pages are open, and not at all
while none is.
"""

from __future__ import annotations

import dataclasses
import enum
import json
import math
from collections import defaultdict
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from servobus.frame import Frame
from servobus.protocols import Command, Reply
from servobus.tools.logs import FrameDecoder, message_values
from servobus.tools.recording import TapLink

if TYPE_CHECKING:
    from servobus.loop import Loop

__all__ = ["Board", "Watched"]

#: how often the figures that change slowly are made again (a bus's counters, load and latency, its
#: raw frame view, a loop's figures); the motors' rows are made every update. Each of them at every
#: update (30 Hz; the demo's 11 buses, its Loop) cost its 1 kHz loop a fifth of its core: a Bus's
#: metrics() and a Loop's sort their windows, and the frames' changing data is decoded again for names
SLOW_S = 0.25
#: how often a bus's counters, load and latency are fetched (one bus per update at most: its metrics()
#: sorts a latency window of thousands, and eleven at once held a 1 kHz loop up for ten milliseconds)
METRICS_S = 2.0


@dataclass(eq=False, slots=True)
class Watched:
    """One motor on the board.

    Attributes:
        key: ``BUS/ID`` (``BUS/FAMILY/ID`` when two families share the id on one bus).
        bus: the bus's name on the board.
        family: the motor's family.
        motor_id: its id.
        motor: the Bus's Motor (or a bridge's RemoteMotor), what the page's stop goes to.
        reply: its latest decoded reply (any traffic: a reply, a stream frame, another host's).
        replies: how many were seen (counted at each update, not per frame).
        status: ``"online"``, ``"offline"``, ``"restarted"``, or ``"unknown"`` before the watchdog said.
        reason: the watchdog's words for the status.
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


@dataclass(slots=True)
class _Bus:
    """A bus on the board: where its figures come from, its frames as last seen, per identifier."""

    name: str
    source: Any  # a servobus Bus (metrics()), or a bridge's RemoteBus (its metrics set from outside)
    frames: dict[tuple[bool, int, bool], Frame] = field(default_factory=dict)
    frame_counts: dict[tuple[bool, int, bool], int] = field(default_factory=lambda: defaultdict(int))
    decoders: dict[str, FrameDecoder] = field(default_factory=dict)
    names: dict[tuple[int, bool, bytes], str] = field(default_factory=dict)  # decoded names, cached
    metrics: dict[str, Any] | None = None  # a remote bus's, as last fetched
    last_requests: int | None = None
    figures: dict[str, Any] | None = None  # its counters as last fetched (at most every METRICS_S)
    figures_at: float = 0.0
    frame_rows: list[dict[str, Any]] | None = None  # its frame view as last made (every SLOW_S)
    frames_at: float = 0.0
    setpoints: dict[tuple[int, bytes], dict[str, Any] | None] = field(default_factory=dict)  # decoded
    last_counts: dict[tuple[bool, int, bool], int] = field(default_factory=dict)


class Board:
    """The motors, buses and loop a dashboard shows.

    Args:
        update_hz: the most updates per second the page gets (each is made once for all pages).
        clock: the clock of updates' times (the buses' event loop's; set by the first ``watch``).
    """

    def __init__(self, *, update_hz: float = 30.0, clock: Callable[[], float] | None = None) -> None:
        if not (0.5 <= update_hz <= 100.0):
            raise ValueError(f"update_hz={update_hz}: expected 0.5 to 100 updates per second")
        self.period_s = 1.0 / update_hz
        self._clock = clock
        self._buses: dict[str, _Bus] = {}
        self._links: dict[str, _Bus] = {}  # by link name, until the Bus is watched
        self._motors: dict[str, Watched] = {}
        self._by_motor: dict[int, Watched] = {}
        self._loops: list[Loop] = []
        self._cached: tuple[int, str] | None = None
        self._loop_figures: tuple[float, list[dict[str, Any]]] | None = None  # (made at, figures)
        self._origin: float | None = None

    # ---- what is watched ----

    def tap(self, link: Any) -> TapLink:
        """``link`` wrapped so that the board sees its frames, both ways (give the result to the
        Bus): the raw frame view lists them by identifier, like ``python -m can.viewer``."""
        entry = self._links.setdefault(link.name, _Bus(link.name, None))
        frames, counts = entry.frames, entry.frame_counts

        def seen(frame: Frame, received: bool, _at: float) -> None:
            key = (received, frame.arbitration_id, frame.is_extended_id)
            frames[key] = frame
            counts[key] += 1  # (a defaultdict: a third cheaper than get() and a store, every frame)

        return TapLink(link, seen, self._now)

    def watch(self, bus: Any, *, name: str | None = None) -> None:
        """Show ``bus`` (a :class:`servobus.Bus`, or a bridge's ``RemoteBus``) and its motors: every
        decoded reply and watchdog status from now on; motors added to it later appear too.

        Raises:
            ValueError: a bus of that name is on the board already.
        """
        label = name or bus.name
        if label in self._buses:
            raise ValueError(f"a bus named {label!r} is on the board already")
        link = getattr(getattr(bus, "engine", None), "link", None)
        entry = self._links.pop(link.name, None) if isinstance(link, TapLink) else None
        entry = entry or _Bus(label, bus)
        entry.name, entry.source = label, bus
        self._buses[label] = entry
        if self._clock is None and hasattr(bus, "time"):
            self._clock = bus.time
        by_motor = self._by_motor

        def replied(motor: Any, *rest: Any) -> None:  # (motor, traffic, reply) or a bridge's (motor, reply)
            watched = by_motor.get(id(motor))
            if watched is not None:
                watched.reply = rest[-1]
                watched.replied_at = None  # (stamped at the next update: no clock read per frame)

        def status(event: Any) -> None:
            watched = by_motor.get(id(event.motor))
            if watched is not None:
                watched.status = "online" if event.online else "offline"
                reason = getattr(event, "reason", "")
                if reason == "restarted":
                    watched.status = "restarted"
                watched.reason = reason

        bus.subscribe(replied)
        bus.subscribe_status(status)

    def watch_loop(self, loop: Loop) -> None:
        """Show ``loop``'s figures: its tick lateness, state age and counters."""
        self._loops.append(loop)

    def set_metrics(self, bus: str, metrics: dict[str, Any]) -> None:
        """A bus's metrics as fetched from elsewhere (a bridge's ``RemoteBus.metrics()``)."""
        self._buses[bus].metrics = metrics

    # ---- the motors ----

    def motors(self) -> list[Watched]:
        """Every motor of the watched buses, by bus then id (new motors are picked up here)."""
        for entry in self._buses.values():
            for motor in _motors_of(entry.source):
                if id(motor) not in self._by_motor:
                    self._add(entry.name, motor)
        return list(self._motors.values())

    def find(self, key: str) -> Watched:
        """The motor of ``key`` (``BUS/ID``).

        Raises:
            KeyError: no such motor on the board.
        """
        self.motors()
        return self._motors[key]

    def _add(self, bus: str, motor: Any) -> None:
        family = _family_name(motor)
        key = f"{bus}/{motor.motor_id}"
        if key in self._motors:
            key = f"{bus}/{family}/{motor.motor_id}"
        watched = Watched(key, bus, family, motor.motor_id, motor)
        latest = getattr(motor, "state", None)  # (a bridge's motor: its last published state)
        if isinstance(latest, Reply):
            watched.reply = latest
        online = getattr(motor, "online", None)
        if isinstance(online, bool):
            watched.status = "online" if online else "offline"
        self._motors[key] = watched
        self._by_motor[id(motor)] = watched

    # ---- updates ----

    def _now(self) -> float:
        return self._clock() if self._clock is not None else 0.0

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
        """What the page shows now: the motors' rows, each bus's figures and frames, the loops'."""
        now = self._now() if now is None else now
        if self._origin is None:
            self._origin = now
        rows = []
        for watched in self.motors():
            if watched.reply is not None and watched.replied_at is None:
                watched.replied_at = now
            rows.append(self._row(watched, now))
        due = [e for e in self._buses.values() if e.figures is None or now - e.figures_at >= METRICS_S]
        fetch = min(due, key=lambda e: e.figures_at) if due else None  # (the longest waiting)
        return {
            "t": round(now - self._origin, 4),
            "motors": rows,
            "buses": [self._bus(entry, now, entry is fetch) for entry in self._buses.values()],
            "loops": self._loops_now(now),
        }

    def _loops_now(self, now: float) -> list[dict[str, Any]]:
        if self._loop_figures is None or now - self._loop_figures[0] >= SLOW_S:
            self._loop_figures = (now, [_loop_figures(loop) for loop in self._loops])
        return self._loop_figures[1]

    def _row(self, w: Watched, now: float) -> dict[str, Any]:
        reply = w.reply
        fields = _numbers_of(reply) if reply is not None else {}
        setpoint = self._setpoint(w)
        faults = getattr(reply, "FAULTS", None) if reply is not None else None
        fault = getattr(reply, faults) if faults else None
        return {
            "key": w.key,
            "bus": w.bus,
            "family": w.family,
            "id": w.motor_id,
            "status": w.status,
            "reason": w.reason,
            "reply": type(reply).__name__ if reply is not None else None,
            "age_s": None if w.replied_at is None else round(now - w.replied_at, 4),
            "fault": _fault_names(fault),
            "temperature_c": fields.get("temperature_c"),
            "fields": fields,
            "setpoint": setpoint,
        }

    def _setpoint(self, w: Watched) -> dict[str, Any] | None:
        """The last command that left for the motor (seen by the tap), with its numbers."""
        entry = self._buses[w.bus]
        if not entry.frames:
            return None
        codec = getattr(w.motor, "codec", None)
        if codec is None:
            return None
        for ident in sorted(codec.request_ids):
            frame = entry.frames.get((False, ident & 0x1FFFFFFF, ident > 0x7FF))
            if frame is None:
                continue
            # (decoded once per identifier and data: a set-point resent unchanged, a read, costs a lookup)
            cache_key = (ident, bytes(frame.data))
            if cache_key not in entry.setpoints:
                if len(entry.setpoints) > 4096:
                    entry.setpoints.clear()
                decoded = self._decoder(entry, w.family).decode(frame)
                message = decoded.message
                entry.setpoints[cache_key] = (
                    {"name": type(message).__name__, "fields": _numbers_of(message)}
                    if isinstance(message, Command) and decoded.motor_id == w.motor_id
                    else None
                )
            if (found := entry.setpoints[cache_key]) is not None:
                return found
        return None

    def _decoder(self, entry: _Bus, family: str) -> FrameDecoder:
        found = entry.decoders.get(family)
        if found is None:
            ids = sorted(
                {w.motor_id for w in self._motors.values() if w.bus == entry.name and w.family == family}
            )
            found = entry.decoders[family] = FrameDecoder(family, ids=ids or None)
        return found

    def _bus(self, entry: _Bus, now: float, fetch: bool) -> dict[str, Any]:
        if fetch or entry.figures is None:
            since = now - entry.figures_at if entry.figures is not None else None
            figures = _bus_figures(entry)
            requests = figures.get("requests")
            rate = None
            if isinstance(requests, int) and entry.last_requests is not None and since:
                rate = round((requests - entry.last_requests) / since, 1)
            entry.last_requests = requests if isinstance(requests, int) else None
            figures["request_rate_hz"] = rate
            entry.figures, entry.figures_at = figures, now
        if entry.frame_rows is None or now - entry.frames_at >= SLOW_S:
            since = now - entry.frames_at if entry.frame_rows is not None else None
            entry.frame_rows, entry.frames_at = self._frames(entry, since), now
        return {**entry.figures, "frames": entry.frame_rows}

    def _frames(self, entry: _Bus, dt: float | None) -> list[dict[str, Any]]:
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
                    "rate_hz": None if before is None or not dt else round((count - before) / dt, 1),
                    "name": self._name(entry, families, frame),
                }
            )
        return rows

    def _name(self, entry: _Bus, families: Iterable[str], frame: Frame) -> str:
        cache_key = (frame.arbitration_id, frame.is_extended_id, bytes(frame.data))
        name = entry.names.get(cache_key)
        if name is None:
            name = "?"
            for family in families:
                decoded = self._decoder(entry, family).decode(frame)
                if decoded.message is not None:
                    who = "" if decoded.motor_id is None else f" (motor {decoded.motor_id})"
                    name = f"{type(decoded.message).__name__}{who}"
                    break
            if len(entry.names) > 4096:  # (changing data: a set-point a tick; kept bounded)
                entry.names.clear()
            entry.names[cache_key] = name
        return name


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


_FIELD_NAMES: dict[type, tuple[str, ...]] = {}


def _numbers_of(message: Any) -> dict[str, float | int]:
    """``_numbers(message_values(message))``, the short way for a message of plain numbers (a reply a
    motor sends a thousand times a second: its fields read, not converted one by one)."""
    names = _FIELD_NAMES.get(type(message))
    if names is None:
        names = _FIELD_NAMES[type(message)] = tuple(f.name for f in dataclasses.fields(message))
    out: dict[str, float | int] = {}
    for name in names:
        value = getattr(message, name)
        kind = type(value)
        if kind is float:
            if math.isfinite(value):
                out[name] = value
        elif kind is int:
            out[name] = value
        elif isinstance(value, enum.Flag):
            out[name] = int(value.value)
        elif value is not None and kind is not str and kind is not bool and not isinstance(value, enum.Enum):
            return _numbers(message_values(message))  # (tuples, messages, the rest: the long way)
    return out


def _numbers(values: dict[str, Any]) -> dict[str, float | int]:
    """The numeric fields (the ones a plot can show), finite."""
    return {
        name: value
        for name, value in values.items()
        if isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
    }


def _fault_names(fault: Any) -> list[str]:
    if fault is None:
        return []
    if isinstance(fault, Iterable) and not isinstance(fault, str):
        return [getattr(f, "name", str(f)) for f in fault]
    names = getattr(fault, "name", None)
    if names is None:
        return [str(fault)] if fault else []
    return [n for n in str(names).split("|") if n] if fault else []


def _bus_figures(entry: _Bus) -> dict[str, Any]:
    """The counters the page shows of a bus (a local Bus's metrics, or a bridge's as fetched)."""
    metrics: Any = entry.metrics
    if metrics is None and hasattr(entry.source, "metrics") and hasattr(entry.source, "engine"):
        metrics = dataclasses.asdict(entry.source.metrics())
    metrics = metrics or {}
    latency = metrics.get("latency") or {}
    out: dict[str, Any] = {"name": entry.name}
    for name in (
        "requests",
        "replies",
        "timeouts",
        "late",
        "ambiguous",
        "duplicate",
        "malformed",
        "restarts",
    ):
        out[name] = metrics.get(name)
    out["bus_load_pct"] = metrics.get("bus_load_pct")
    out["latency_p99_s"] = latency.get("p99_s") if isinstance(latency, dict) else None
    return out


def _loop_figures(loop: Loop) -> dict[str, Any]:
    figures = dataclasses.asdict(loop.metrics())
    figures["hz"] = loop.hz
    return figures


def _jsonable(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, bytes):
        return value.hex()
    return str(value)
