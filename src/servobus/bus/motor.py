"""A motor on a Bus (:class:`Motor`: its codec, its latest telemetry, a method per command of its
family), its frames as an async iterator (:class:`MotorFrames`), and what the Bus knows of it
beside (:class:`MotorRecord`, one per motor, held in the Bus's :class:`Registry`); servobus.bus
re-exports Motor and MotorFrames.

A Motor knows its Bus only as a :class:`MotorHost` (its name, clock, scheduler and
``request``): this module imports nothing of the bus package above it."""

from __future__ import annotations

import contextlib
import dataclasses
import inspect
from collections import deque
from collections.abc import AsyncIterator, Awaitable, Callable, Iterable
from typing import TYPE_CHECKING, Any, Protocol, Self, TypeVar

import anyio

from servobus.errors import MotorFault, MotorTimeout, TransportError
from servobus.frame import Frame
from servobus.limits import LimitExceeded, Limits, safe_commands
from servobus.metrics import Metrics
from servobus.protocols import BoundCodec, Command, Family, Reply, get_family
from servobus.protocols._restart import Seen
from servobus.scheduler import Scheduler, Traffic

__all__ = ["Motor", "MotorFrames", "MotorHost", "MotorRecord", "NamedMotor", "Registry", "command_classes"]

R = TypeVar("R")


class MotorHost(Protocol):
    """What a :class:`Motor` asks of its Bus (:class:`servobus.bus.Bus` is one)."""

    name: str
    scheduler: Scheduler

    def time(self) -> float: ...

    async def request(
        self, motor: Motor, command: Command[R], *, timeout_s: float | None = None, retries: int = 0
    ) -> R: ...


class MotorRecord:
    """What the Bus knows of one motor beyond what the :class:`Motor` shows (its ``state``,
    ``last_seen``, ``online``, ``fault``, ``restarted_at``): one record per motor, in the Bus's
    :class:`Registry`, each field written by one part of the bus package.

    Attributes:
        motor, codec: the motor and its codec.
        misses: replies missed in a row (the watchdog's).
        probe_at: while offline, when a cycle may next send it a command as a probe (the engine's).
        remembers: the reply types its family's restart evidence asks the intake to remember;
            remembered: the last reply of each (the intake's; read by servobus.bus.restarts).
        known_since, readings, before: the restart check's (servobus.bus.restarts): running
            without a restart since; its probes' last replies; what it said before its silence.
        ending: streams switched off: the command byte -> (the "off" command, when it was last
            sent, the stream's interval in s) (the motor's; the intake sends a lost "off" again).
        watchers: the frame iterators open on it (:class:`MotorFrames`: each adds and removes itself).
        commanded: the order in which the Bus first sent it a command that is not a read (0: never).
        undecodable_logged, echo_logged: its undecodable reply, its echoed request, logged once.
        late: who takes its late replies (the reply of a request that timed out, and its frame),
            besides its state: a pipelined loop tracking it (servobus.loop), which attributes
            replies in order.
    """

    __slots__ = (
        "before",
        "codec",
        "commanded",
        "echo_logged",
        "ending",
        "known_since",
        "late",
        "misses",
        "motor",
        "probe_at",
        "readings",
        "remembered",
        "remembers",
        "undecodable_logged",
        "watchers",
    )

    motor: Motor  # (set by the Motor it is the record of, as it is made)

    def __init__(self, codec: BoundCodec) -> None:
        self.codec = codec
        self.misses = 0
        self.probe_at = 0.0
        self.late: Callable[[Reply, Frame], object] | None = None
        evidence = getattr(codec, "RESTART", None)
        self.remembers: frozenset[type] = evidence.remembers if evidence is not None else frozenset()
        self.remembered: dict[type, Seen] = {}
        self.known_since: float | None = None
        self.readings: dict[type, Seen] = {}
        self.before: dict[type, Seen] | None = None
        self.ending: dict[int, tuple[Command, float, float]] = {}
        self.watchers: list[MotorFrames] = []
        self.commanded = 0
        self.undecodable_logged = self.echo_logged = False


class Registry:
    """The motors of one Bus, one :class:`MotorRecord` each, keyed once: by their codec (what every
    frame and request names). :attr:`named` is the index ``bus.motor(family, id)`` looks up.
    """

    def __init__(self) -> None:
        #: id(codec) -> its record (read by the intake on every reply)
        self.records: dict[int, MotorRecord] = {}
        #: (family, motor id) -> the motor (``Bus.motors``)
        self.named: dict[tuple[str, int], Motor] = {}
        self._commands = 0  # how many motors were commanded (their order)

    def add(
        self,
        key: tuple[str, int],
        cls: type[Motor],
        host: MotorHost,
        codec: BoundCodec,
        commands: dict[str, type[Command]],
    ) -> Motor:
        """A new motor of class ``cls`` for ``codec``, with its record, named ``key`` (family, id)."""
        record = MotorRecord(codec)
        motor = cls(host, codec, commands, record)
        self.records[id(codec)] = record
        self.named[key] = motor
        return motor

    def of(self, motor: Motor) -> MotorRecord:
        """``motor``'s record."""
        return self.records[id(motor.codec)]

    def command(self, motor: Motor) -> None:
        """The Bus sent ``motor`` a command that is not a read: it gets the safe command."""
        record = self.records.get(id(motor.codec))
        if record is not None and not record.commanded:
            self._commands += 1
            record.commanded = self._commands

    def commanded(self) -> tuple[Motor, ...]:
        """The motors commanded, in the order they first were."""
        found = sorted((r for r in self.records.values() if r.commanded), key=lambda r: r.commanded)
        return tuple(r.motor for r in found)

    def end_watchers(self) -> None:
        """The Bus closed: every frame iterator over its motors ends (not hangs)."""
        for record in self.records.values():
            for watcher in list(record.watchers):
                watcher.end()


def command_classes(family: str) -> dict[str, type[Command]]:
    """The command classes of ``family`` by method name (``ReadStatus2`` -> ``read_status2``): the
    names :class:`Motor` offers as methods (``await motor.read_status2()``).

    Raises:
        ValueError: no family has that name.
    """
    return get_family(family).methods()


class MotorFrames:
    """The decoded frames of one motor as an async iterator, buffered up to ``size``.

    Use ``async with motor.frames() as frames: async for reply in frames: ...``. When the reader falls
    behind, the oldest frames are dropped and counted in :attr:`dropped`, so a slow consumer never
    holds memory without end or slows the Bus.
    """

    def __init__(
        self, motor: Motor, size: int, kinds: frozenset[Traffic], watchers: list[MotorFrames]
    ) -> None:
        if size < 1:
            raise ValueError(f"size={size} must be at least 1")
        self.motor = motor
        self._watchers = watchers  # the motor's (MotorRecord.watchers): joined while open
        self.kinds = kinds
        self.dropped = 0
        self._size = size
        self._items: deque[Reply] = deque()
        self._ready: anyio.Event | None = None  # (anyio's events are one-shot: a new one per wait)
        self._closed = False

    def push(self, traffic: Traffic, reply: Reply) -> None:
        """A decoded frame of the motor (the Bus's intake calls this): kept if of :attr:`kinds`."""
        if traffic not in self.kinds:
            return
        if len(self._items) >= self._size:
            self._items.popleft()
            self.dropped += 1
        self._items.append(reply)
        if self._ready is not None:
            self._ready.set()

    async def __aenter__(self) -> Self:
        self._watchers.append(self)
        return self

    async def __aexit__(self, *exc: object) -> None:
        self.end()

    def end(self) -> None:
        """No more frames (the block was left, or the Bus closed): the iteration ends."""
        self._closed = True
        with contextlib.suppress(ValueError):
            self._watchers.remove(self)
        if self._ready is not None:
            self._ready.set()

    def __aiter__(self) -> Self:
        return self

    async def __anext__(self) -> Reply:
        while not self._items:
            if self._closed:
                raise StopAsyncIteration
            self._ready = ready = anyio.Event()
            await ready.wait()
            self._ready = None
        return self._items.popleft()


class Motor:
    """One motor on a Bus: its codec, its latest telemetry, and a method per command of its family.

    ``await motor.speed_control(speed_dps=100)`` builds ``SpeedControl(speed_dps=100)`` (its range
    checks raise ValueError before anything is sent) and awaits the typed reply.

    Attributes:
        codec: the bound codec (family, id, revision, link).
        state: the latest reply, stream frame or error report received from this motor (None yet).
        last_seen: when it was received (the loop's clock; None yet).
        fault: the error flags the motor last reported (a :class:`~servobus.errors.MotorFault`, to
            read or raise), or None when its last report of them had none (or none came yet).
        online: the host-side watchdog's verdict: True once it answered, False after
            ``offline_after_misses`` missed replies in a row or ``offline_after_s`` of silence, None
            before either happened. A motor that answers again is online again.
        restarted_at: when the motor last came back online from a restart (the loop's clock; None:
            none was found). Its ``"restarted"`` MotorStatus says so too (servobus.bus.restarts).
        limits: its host-side envelope (:class:`~servobus.limits.Limits`), applied to every command
            before its frame leaves; None: none (set it at any time, or give ``Bus(limits=...)``).
    """

    def __init__(
        self,
        bus: MotorHost,
        codec: BoundCodec,
        commands: dict[str, type[Command]] | None = None,
        record: MotorRecord | None = None,
    ) -> None:
        self.bus = bus
        self.codec = codec
        self.state: Reply | None = None
        self.last_seen: float | None = None
        self.online: bool | None = None
        self.fault: MotorFault | None = None
        self.restarted_at: float | None = None
        self.limits: Limits | None = None
        # its safe commands by class, never limited (made when first needed)
        self._safe: dict[type, list[Command]] | None = None
        # by method name; from the Family the Bus bound it with (a plug-in may be unregistered)
        self._commands = command_classes(codec.family) if commands is None else commands
        self._record = MotorRecord(codec) if record is None else record  # (the Bus's Registry's)
        self._record.motor = self

    def metrics(self) -> Metrics:
        """This motor's counters and request-to-reply latency (see :class:`~servobus.metrics.Metrics`)."""
        scheduler = self.bus.scheduler
        key = id(self.codec)
        return Metrics.of(scheduler.motor_counts[key], scheduler.motor_latency[key].snapshot())

    def limited(self, command: Command[R], slot: int | None = None) -> Command[R]:
        """``command`` within :attr:`limits` (clamped, when they say so), counted in :meth:`metrics`
        as ``limit_clamped`` or ``limit_refused``. The family's safe commands (stop, shutdown,
        brake) are never limited: stopping a motor is always allowed. ``slot``: this motor's value
        in a frame that carries one per motor (``Limits.apply``).

        Raises:
            LimitExceeded: a ValueError naming the field, the value and the limit it went beyond.
        """
        limits = self.limits
        if limits is None:
            return command
        safe = self._safe
        if safe is None:
            safe = self._safe = {}
            for made in safe_commands(self.codec):
                safe.setdefault(type(made), []).append(made)
        same = safe.get(type(command))  # (a class test first: a control command is never one)
        if same is not None and command in same:
            return command
        try:
            checked = limits.apply(command, self.state, slot)
        except LimitExceeded as exc:
            self.bus.scheduler.count(self.codec, "limit_refused")
            where = f"{self.codec.family} motor {self.codec.motor_id} on {self.bus.name}"
            raise LimitExceeded(f"{where}: {exc}", exc.field, exc.value, exc.limit) from None
        if checked is not command:
            self.bus.scheduler.count(self.codec, "limit_clamped")
        return checked

    @contextlib.asynccontextmanager
    async def stream(
        self, command: int | type[Command], *, interval_ms: int, size: int = 64
    ) -> AsyncIterator[MotorFrames]:
        """Have the motor stream ``command``'s reply every ``interval_ms`` (MyActuator 0xB6) and iterate
        the frames; the stream is switched off when the block is left, however it is left.

        ``async with motor.stream(ma.ReadStatus2, interval_ms=10) as frames: async for r in frames``.
        While a stream is on the motor answers no requests (MyActuator §9 item 18), except reads of
        the streamed command, which the next stream frame answers.

        Raises:
            ValueError: the family has no streams, the command cannot be streamed, or a bad interval.
        """
        active_reply: Callable[..., Command] | None = self._commands.get("active_reply")
        if active_reply is None:
            raise ValueError(f"{self.codec.family} motors have no active-reply streams")
        code = command if isinstance(command, int) else command.CODE
        if code is None:
            raise ValueError(f"{command!r} has no command byte to stream")
        on = active_reply(command=code, enabled=True, interval_ms=interval_ms)
        off = active_reply(command=code, enabled=False)
        async with self.frames(size=size, kinds=(Traffic.STREAM,)) as frames:
            self._record.ending.pop(code, None)
            await self.request(on)
            try:
                yield frames
            finally:
                with anyio.CancelScope(shield=True), contextlib.suppress(TransportError, MotorTimeout):
                    await self.request(off)
                    # "off" gets no reply: if it was lost, the frames that keep coming say so, and
                    # the Bus sends it again (servobus.bus.delivery).
                    self._record.ending[code] = (off, self.bus.time(), interval_ms / 1000)

    def frames(
        self, *, size: int = 64, kinds: Iterable[Traffic] = (Traffic.STREAM, Traffic.REPORT)
    ) -> MotorFrames:
        """This motor's decoded frames of ``kinds`` (default: 0xB6 stream frames and error reports)
        as an async iterator; enable a stream first (MyActuator: ``await motor.active_reply(...)``).

        Raises:
            ValueError: ``size`` below 1.
        """
        return MotorFrames(self, size, frozenset(kinds), self._record.watchers)

    @property
    def motor_id(self) -> int:
        return self.codec.motor_id

    def __repr__(self) -> str:
        return f"<Motor {self.codec.family} {self.codec.motor_id} on {self.bus.name}>"

    async def request(self, command: Command[R], *, timeout_s: float | None = None, retries: int = 0) -> R:
        """Send ``command`` and await its reply: the type its class declares (``Command[StatusReply]``),
        None for commands that get none. A command to a motor that streams gets no reply either
        (MyActuator §4.36): then it is None too, whatever its class declares.

        Raises:
            ValueError: the command is refused by the codec (before any frame is sent).
            MotorTimeout: no reply within the timeout (the codec's default for the command).
            TransportError: the transport was lost or refused the frame.
            RuntimeError: called from another event loop than the Bus's (servobus.sync.Bus is for threads).
        """
        return await self.bus.request(self, command, timeout_s=timeout_s, retries=retries)

    if not TYPE_CHECKING:  # the typed subclass (Family.motor) spells each method; this is for the rest

        def __getattr__(self, name: str) -> Callable[..., Awaitable[Reply | None]]:
            try:
                cls = self.__dict__["_commands"][name]
            except KeyError:
                raise AttributeError(f"{self.codec.family} motors have no command {name!r}") from None

            async def call(
                *args: Any, timeout_s: float | None = None, retries: int = 0, **fields: Any
            ) -> Reply | None:
                if args:  # the command's fields in their declaration order, as the command lists them
                    fields = _positional_fields(cls, name, args, fields)
                return await self.request(cls(**fields), timeout_s=timeout_s, retries=retries)

            call.__name__ = name
            call.__doc__ = f"Send {cls.__name__} and await its reply.\n\n{cls.__doc__ or ''}"
            return call

    def __dir__(self) -> list[str]:
        return [*super().__dir__(), *self._commands]


if TYPE_CHECKING:

    class NamedMotor(Motor):
        """What a type checker knows of a motor bound by its family's name: its methods exist,
        untyped (``bus.motor(FAMILY, id)`` gives the typed ones)."""

        def __getattr__(self, name: str) -> Callable[..., Awaitable[Any]]: ...

else:
    NamedMotor = Motor


#: a family's typed calls class that is not a Motor -> the Motor class made for it (once)
_MADE: dict[type, type[Motor]] = {}
#: the typed classes whose methods got their commands' docstrings
_DOCUMENTED: set[type] = set()


def motor_class(family: Family[Any]) -> type[Motor]:
    """The family's typed Motor class (Motor itself where it has none), its methods documented
    with their commands' docstrings (the generated file keeps one line a method).

    A family's typed class (``family.motor()``) is either a Motor subclass, used as it is, or a
    calls class that only spells the methods (``servobus.protocols._calls``): then a class of both
    is made once per family, so ``isinstance(motor, family.motor())`` holds and the Bus's Motor
    answers what both define (``request``, ``__init__``, ...).
    """
    if family.motor is None:
        return Motor
    calls: type = family.motor()
    if calls not in _DOCUMENTED:
        for name, command in family.methods().items():
            if name in Motor.__dict__:
                raise TypeError(f"{family.name}: command {command.__name__} would hide Motor.{name}")
            method = calls.__dict__.get(name)
            if method is not None and method.__doc__ is None:
                method.__doc__ = f"Send {command.__name__} and await its reply.\n\n{command.__doc__ or ''}"
        _DOCUMENTED.add(calls)
    if issubclass(calls, Motor):
        return calls
    made = _MADE.get(calls)
    if made is None:
        ours = {  # what Motor defines that the calls class (or its bases) defines too: Motor's wins
            name: value
            for name, value in Motor.__dict__.items()
            if not name.startswith("__") or name in ("__init__", "__repr__", "__getattr__", "__dir__")
            if any(name in vars(base) for base in calls.__mro__[:-1])
        }
        namespace = {
            "__module__": calls.__module__,
            "__doc__": calls.__doc__,
            "__qualname__": calls.__qualname__,
        }
        made = _MADE[calls] = type(calls.__name__, (calls, Motor), {**namespace, **ours})
    return made


def _positional_fields(
    cls: type[Command], name: str, args: tuple[Any, ...], fields: dict[str, Any]
) -> dict[str, Any]:
    """``args`` given to ``motor.<name>(...)`` as keyword fields of ``cls``, in declaration order."""
    names = [f.name for f in dataclasses.fields(cls) if f.init]  # type: ignore[arg-type]
    if len(args) > len(names):
        listed = ", ".join(names) or "none"
        raise TypeError(f"{name}() takes {len(names)} positional field(s) ({listed}), {len(args)} given")
    for field_name, value in zip(names, args, strict=False):
        if field_name in fields:
            raise TypeError(f"{name}() got {field_name!r} both by position and by keyword")
        fields[field_name] = value
    return fields


def refuse_coroutine(callback: Callable[..., object], method: str) -> None:
    if inspect.iscoroutinefunction(callback) or inspect.iscoroutinefunction(type(callback).__call__):
        raise TypeError(
            f"{method}() takes a plain function: {callback!r} is async and would never be awaited "
            "(start it in a task group from a plain one)"
        )
