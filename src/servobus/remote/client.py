"""The client side: a bus on a bridge, with the calls of a Bus that make sense across a network.

``async with servobus.remote.connect("arm/can0") as bus:`` opens a Zenoh session to the bridge,
checks that the bridge is alive and speaks this servobus's messages, and gives:

- ``bus.motor(3)`` (or ``bus.motor(ma.FAMILY, 3)``): a :class:`RemoteMotor` with ``request()`` typed by
  the command (``await motor.request(ma.ReadStatus2())`` is a ``StatusReply``), a method per command
  of its family (``await motor.read_status2()``), and ``state``/``online``/``fault`` as last published;
- ``await bus.cycle([(motor, command), ...])``: one batch of set-points the bridge's own tick loop
  sends every tick until they go stale (``valid_for_s``); it returns each motor's latest state;
- ``subscribe``/``subscribe_status``, ``await bus.metrics()``.

Leaving the block (or losing this process) takes away the client's liveliness token: the bridge
stops the motors this client commanded. If the bridge vanishes, every pending and later call raises
:class:`BridgeLost` at once instead of waiting.
"""

from __future__ import annotations

import logging
import math
import os
import time
import uuid
from collections.abc import Awaitable, Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Self, TypeVar

import anyio
import zenoh

from servobus import runtime
from servobus.errors import MotorOffline, TransportError
from servobus.protocols import Command, Family, Reply, get_family
from servobus.remote import wire
from servobus.remote._asking import Asker
from servobus.remote._session import close_session, handed, sample_kind
from servobus.remote.keys import Keys, check_name
from servobus.remote.security import DEFAULT_ENDPOINT, client_config, open_error

__all__ = ["BridgeLost", "RemoteBus", "RemoteError", "RemoteMotor", "RemoteStatus", "connect"]

logger = logging.getLogger(__name__)

R = TypeVar("R")
StrPath = str | os.PathLike[str]


class RemoteError(TransportError):
    """The bridge could not be reached, did not answer, or answers in a way this client cannot read."""


class BridgeLost(RemoteError):
    """The bridge's liveliness token vanished: the bridge stopped, crashed or is unreachable."""


@dataclass(frozen=True, slots=True)
class RemoteStatus:
    """A motor went offline or came back, as the bridge published it."""

    motor: RemoteMotor
    online: bool
    stamp_unix_ns: int


class RemoteMotor:
    """A motor on a bridge's bus: its family's commands as methods, its latest published state."""

    def __init__(self, bus: RemoteBus, motor_id: int, family: Family[Any], revision: str, link: str) -> None:
        self.bus = bus
        self.motor_id = motor_id
        self.family = family
        self.revision = revision
        self.link = link
        self.schema = wire.Schema.of(family.name)
        self.state: Reply | None = None
        self.online: bool | None = None
        self.fault: Any = None  # its error flags, or the one code its family reports (None: none)
        self.stamp_unix_ns = 0
        self._methods = family.methods()

    async def request(self, command: Command[R], *, timeout_s: float | None = None) -> R:
        """Run ``command`` on the bridge's Bus; its reply, or the error the Bus raised there."""
        return await self.bus.request(self, command, timeout_s=timeout_s)

    def __getattr__(self, name: str) -> Callable[..., Awaitable[Any]]:
        try:
            cls = self.__dict__["_methods"][name]
        except KeyError:
            raise AttributeError(f"{self.family.name} motors have no command {name!r}") from None

        async def call(*, timeout_s: float | None = None, **fields: Any) -> Any:
            return await self.request(cls(**fields), timeout_s=timeout_s)

        call.__name__ = name
        call.__doc__ = cls.__doc__
        return call

    def __repr__(self) -> str:
        return f"<RemoteMotor {self.family.name} {self.motor_id} on {self.bus.node}/{self.bus.name}>"


def connect(
    target: str,
    *,
    bus: str | None = None,
    endpoints: Sequence[str] = (DEFAULT_ENDPOINT,),
    user: str | None = None,
    password: str | None = None,
    tls_cert: StrPath | None = None,
    tls_key: StrPath | None = None,
    tls_ca: StrPath | None = None,
    config_file: StrPath | None = None,
    read_only: bool = False,
    valid_for_s: float = 0.1,
    timeout_s: float = 2.0,
) -> RemoteBus:
    """A bus on a bridge, to use as ``async with connect("arm/can0") as bus:``.

    Args:
        target: ``NODE/BUS``, or ``NODE`` with ``bus=``.
        endpoints: where the bridge listens (Zenoh locators), default ``tcp/127.0.0.1:7447``.
        user, password: Zenoh user/password authentication, when the bridge asks for it.
        tls_cert, tls_key, tls_ca: a client certificate, its key and the CA (for ``tls/`` endpoints).
        config_file: a Zenoh JSON5 configuration to start from.
        read_only: declare no liveliness token and refuse commands here (reads and states only).
        valid_for_s: how long a set-point may be applied after it was sent.
        timeout_s: how long to wait for the bridge when connecting, and for a request's answer
            beyond the request's own timeout.
    """
    node, _, named = target.partition("/")
    if bus is None:
        if not named:
            raise ValueError(f"connect({target!r}): give NODE/BUS, or bus=")
        bus = named
    elif named:
        raise ValueError(f"connect({target!r}, bus={bus!r}): the bus is named twice")
    return RemoteBus(
        node,
        bus,
        endpoints=endpoints,
        user=user,
        password=password,
        tls=(tls_cert, tls_key, tls_ca),
        config_file=config_file,
        read_only=read_only,
        valid_for_s=valid_for_s,
        timeout_s=timeout_s,
    )


class RemoteBus:
    """One bus of a bridge, seen from another process (see :func:`connect`)."""

    def __init__(
        self,
        node: str,
        bus: str,
        *,
        endpoints: Sequence[str] = (DEFAULT_ENDPOINT,),
        user: str | None = None,
        password: str | None = None,
        tls: tuple[StrPath | None, StrPath | None, StrPath | None] = (None, None, None),
        config_file: StrPath | None = None,
        read_only: bool = False,
        valid_for_s: float = 0.1,
        timeout_s: float = 2.0,
    ) -> None:
        _check_valid(valid_for_s)
        if not (math.isfinite(timeout_s) and timeout_s > 0):
            raise ValueError(f"timeout_s={timeout_s!r} must be > 0")
        self.keys = Keys(node)
        self.node = node
        self.name = check_name("bus", bus)
        self.endpoints = tuple(endpoints)
        self.read_only = read_only
        self.valid_for_s = valid_for_s
        self.timeout_s = timeout_s
        self.client_id = uuid.uuid4().hex  # a secret: only this client's messages carry it
        self.token_id = wire.public_id(self.client_id)  # its liveliness token's name
        self.shown_id = wire.shown_id(self.token_id)  # what the bridge's metrics call it (owners)
        self.info: dict[str, Any] = {}
        self.motors: dict[int, RemoteMotor] = {}
        self._config = (user, password, tls, config_file)
        self._session: Any = None
        self._declared: list[Any] = []
        self._lane: runtime.Runtime | None = None
        self._asker: Asker | None = None  # (made on entering: it needs the loop)
        self._subscribers: list[Callable[[RemoteMotor, Reply], object]] = []
        self._status: list[Callable[[RemoteStatus], object]] = []
        self._setpoints: Any = None
        self._seq = 0
        self.counts = {"states": 0, "malformed": 0, "setpoints_sent": 0}

    # ---- life cycle ----

    async def __aenter__(self) -> Self:
        user, password, (cert, key, ca), config_file = self._config
        config = client_config(
            self.endpoints,
            user=user,
            password=password,
            tls_cert=_path(cert),
            tls_key=_path(key),
            tls_ca=_path(ca),
            config_file=_path(config_file),
            connect_timeout_s=self.timeout_s,
        )
        self._lane = runtime.current()
        self._asker = Asker(self._lane, self.timeout_s, self._gone)
        try:
            self._session = await anyio.to_thread.run_sync(zenoh.open, config)
        except zenoh.ZError as exc:
            raise RemoteError(open_error(self.endpoints, exc)) from None
        try:
            await self._start()
        except BaseException:
            await self._close()
            raise
        return self

    async def _start(self) -> None:
        session, keys, lane, asker = self._session, self.keys, self._lane, self._asker
        assert lane is not None and asker is not None
        self._declared.append(
            session.liveliness().declare_subscriber(
                keys.alive, handed(lane, asker.on_alive, sample_kind), history=True
            )
        )
        with anyio.move_on_after(self.timeout_s):
            await asker.alive.wait()
        if not asker.alive.is_set():
            raise RemoteError(
                f"no bridge named {self.node!r} at {', '.join(self.endpoints)} "
                f"(none running, or this client may not see it)"
            )
        if not self.read_only:
            self._declared.append(session.liveliness().declare_token(keys.client(self.token_id)))
        info = await asker.get_json(session, keys.bus(self.name, "info"))
        if info is None:
            buses = await asker.list_buses(session, keys)
            raise RemoteError(
                f"bridge {self.node!r} has no bus {self.name!r} (its buses: {', '.join(buses) or 'none'})"
            )
        self.info = info
        for entry in info["motors"]:
            family = get_family(entry["family"])
            motor = RemoteMotor(self, int(entry["id"]), family, entry["revision"], entry["link"])
            if motor.schema.digest != entry["schema"]:
                raise RemoteError(
                    f"the bridge's {family.name} messages differ from this servobus's "
                    f"(bridge runs servobus {info.get('servobus')}): upgrade one side"
                )
            self.motors[motor.motor_id] = motor
        self._declared.append(
            session.declare_subscriber(
                keys.motor(self.name, "*", "state"),
                handed(lane, self._on_state, lambda s: s.payload.to_bytes()),
            )
        )
        if not self.read_only:
            self._setpoints = session.declare_publisher(
                keys.bus(self.name, "setpoints"), express=True, priority=zenoh.Priority.REAL_TIME
            )
            self._declared.append(self._setpoints)

    async def __aexit__(self, *exc: object) -> None:
        await self._close()

    async def _close(self) -> None:
        session, self._session = self._session, None
        declared, self._declared = self._declared, []
        self._setpoints = None
        await close_session(session, declared)

    def _gone(self) -> BridgeLost:
        return BridgeLost(f"bridge {self.node!r} is gone (its liveliness token vanished)")

    @property
    def lost(self) -> BridgeLost | None:
        """Why every call raises now: the bridge's liveliness token vanished (None: it lives)."""
        lost = self._asker.lost if self._asker is not None else None
        assert lost is None or isinstance(lost, BridgeLost)
        return lost

    def _check(self) -> None:
        if self.lost is not None:
            raise self.lost
        if self._session is None:
            raise RemoteError(f"{self.node}/{self.name}: not connected (use async with)")

    # ---- motors and state ----

    def motor(self, family_or_id: Family[Any] | str | int, motor_id: int | None = None) -> RemoteMotor:
        """The motor ``motor_id`` of this bus; given a family too, checked to be of that family.

        Raises:
            ValueError: no such motor on the bus, or it is of another family.
        """
        if isinstance(family_or_id, int):
            wanted, family = family_or_id, None
        else:
            if motor_id is None:
                raise ValueError("motor(family, motor_id): give the motor id")
            wanted = motor_id
            family = get_family(family_or_id) if isinstance(family_or_id, str) else family_or_id
        found = self.motors.get(wanted)
        if found is None:
            raise ValueError(f"{self.node}/{self.name} has no motor {wanted} (motors: {sorted(self.motors)})")
        if family is not None and found.family.name != family.name:
            raise ValueError(
                f"motor {wanted} on {self.node}/{self.name} is {found.family.name}, not {family.name}"
            )
        return found

    def _on_state(self, payload: bytes) -> None:
        try:
            head = wire.peek_motor(payload)
            motor = self.motors[head]
            state = wire.decode_state(motor.schema, payload)
        except (wire.WireError, KeyError):
            self.counts["malformed"] += 1
            return
        self.counts["states"] += 1
        was = motor.online
        motor.online = state.online
        motor.fault = state.fault
        motor.stamp_unix_ns = state.stamp_unix_ns
        if state.reply is not None and state.reply is not motor.state:
            motor.state = state.reply
            for callback in self._subscribers:
                _guarded(callback, motor, state.reply)
        if was is not None and was != state.online:
            status = RemoteStatus(motor, state.online, state.stamp_unix_ns)
            for listener in self._status:
                _guarded(listener, status)

    def subscribe(self, callback: Callable[[RemoteMotor, Reply], object]) -> None:
        """Call ``callback(motor, reply)`` for every state the bridge publishes with a reply."""
        self._subscribers.append(callback)

    def subscribe_status(self, callback: Callable[[RemoteStatus], object]) -> None:
        """Call ``callback(status)`` when a motor goes offline or comes back."""
        self._status.append(callback)

    # ---- commands ----

    async def request(self, motor: RemoteMotor, command: Command[R], *, timeout_s: float | None = None) -> R:
        """Run ``command`` on the bridge's Bus (reads go to ``read``, the rest to ``request``).

        Raises:
            PermissionError: a command that is not a read on a read-only connection, a motor another
                client holds, or a refusal by the bridge.
            MotorTimeout, ProtocolError, TransportError, ...: as the Bus raised them on the bridge.
            BridgeLost: the bridge vanished before answering.
            RemoteError: no answer within the request's timeout and ``timeout_s``.
        """
        self._check()
        leaf = "read" if type(command).READ else "request"
        if leaf == "request" and self.read_only:
            raise PermissionError(
                f"{type(command).__name__} commands the motor: this connection is read-only"
            )
        payload = wire.encode_request(motor.schema, wire.Request(self.client_id, command, timeout_s))
        key = self.keys.motor(self.name, motor.motor_id, leaf)
        assert self._asker is not None  # (connected: _check)
        answers = await self._asker.get(self._session, key, payload, (timeout_s or 1.0) + self.timeout_s)
        if not answers:
            raise RemoteError(
                f"no answer from {self.node}/{self.name} for {type(command).__name__} to motor "
                f"{motor.motor_id} (the bridge's access control refused it, or it is overloaded)"
            )
        try:
            result = wire.decode_result(motor.schema, answers[0])
        except wire.WireError as exc:
            raise RemoteError(f"an answer this client cannot read: {exc}") from None
        if result.error is not None:
            raise result.error
        return result.reply  # type: ignore[return-value]

    async def cycle(
        self, items: Iterable[tuple[RemoteMotor, Command]], *, valid_for_s: float | None = None
    ) -> list[Reply | BaseException | None]:
        """Publish one batch of set-points; the bridge sends each, every tick, until it goes stale.

        Returns:
            Per item, the motor's latest published state: its reply, :class:`MotorOffline` while the
            bridge's watchdog has it offline, or None before any state came.

        Raises:
            ValueError: a motor of another bus, or a ``valid_for_s`` outside (0, 3600].
            PermissionError: a read-only connection.
        """
        self._check()
        if self._setpoints is None:
            raise PermissionError("this connection is read-only: it cannot send set-points")
        items = list(items)
        for motor, _ in items:
            if self.motors.get(motor.motor_id) is not motor:
                raise ValueError(f"{motor!r} is not a motor of {self.node}/{self.name}")
        valid = self.valid_for_s if valid_for_s is None else _check_valid(valid_for_s)
        now = time.time_ns()
        self._seq = (self._seq + 1) & 0xFFFFFFFF
        message = wire.Setpoints(
            self.client_id,
            self._seq,
            now,
            now + int(valid * 1e9),
            tuple((m.motor_id, command) for m, command in items),
        )
        self._setpoints.put(wire.encode_setpoints(lambda mid: self.motors[mid].schema, message))
        self.counts["setpoints_sent"] += len(items)
        return [_latest(motor) for motor, _ in items]

    # ---- numbers ----

    async def metrics(self) -> dict[str, Any]:
        """The bridge's metrics of this bus: the Bus's counters and latency, the bridge's counters."""
        self._check()
        assert self._asker is not None  # (connected: _check)
        found = await self._asker.get_json(self._session, self.keys.bus(self.name, "metrics"))
        if found is None:
            raise RemoteError(f"no metrics from {self.node}/{self.name}")
        return found


def _check_valid(valid_for_s: float) -> float:
    """``valid_for_s`` if it is a set-point's possible validity (the bridge holds one at most its
    ``max_valid_s``, 1 s by default), else ValueError."""
    if not (math.isfinite(valid_for_s) and 0 < valid_for_s <= 3600):
        raise ValueError(f"valid_for_s={valid_for_s!r} must be in (0, 3600]")
    return valid_for_s


def _path(value: StrPath | None) -> Path | None:
    return None if value is None else Path(value)


def _latest(motor: RemoteMotor) -> Reply | BaseException | None:
    if motor.online is False:
        return MotorOffline(f"motor {motor.motor_id} on {motor.bus.node}/{motor.bus.name} is offline")
    return motor.state


def _guarded(callback: Callable[..., object], *args: Any) -> None:
    try:
        callback(*args)
    except Exception:
        logger.exception("a remote subscriber raised")
