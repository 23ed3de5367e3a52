"""Fuzz targets: every decoder, every de-framer, the SLCAN and RS485 byte streams into their transports,
and the scheduler's frame intake, each a function of one ``bytes`` input that raises on a broken
promise and returns otherwise.

Two drivers use them: tests/test_fuzz.py (Hypothesis, in every CI run) and bench/reliability.py (the
long run: atheris, coverage-guided, with the C core built under ASan + UBSan). What each target
checks:

* **decoders** (``myactuator_can``, ``myactuator_rs485``, ``lk_can``, ``hollow_can``, ``hollow_rs485``):
  the input's first bytes pick a decoder of the family (its ``decode_request``/``decode_reply`` at
  every revision or model, every message class's own ``decode``, the serial-link decoders, and the
  bound codecs' ``classify`` + ``decode`` on every link) and its options; the rest is the payload.
  Only :class:`~servobus.errors.ProtocolError` may come out; what does decode is a Message whose
  ``encode()`` works. A bound codec's ``classify`` never raises at all.
* **de-framers** (``deframe_myactuator_rs485``, ``deframe_hollow_transparent``,
  ``deframe_modbus_rtu``, ``deframe_slcan``): the stream is fed in chunks the input chooses, with
  ``idle()`` where it says (RS485). Nothing raises; every frame out carries a valid CRC (checked again
  in Python); what is held back never exceeds the longest frame; the frames do not depend on where
  the stream was cut.
* **transports** (``transport_slcan``, ``transport_rs485``): a real transport, opened once on a pty
  (SLCAN: against the simulator's adapter, which answers the open), with a Bus attached; the
  input's bytes go in through the transport's own intake (``_on_bytes``, what the port's reader calls)
  in the chunks the input chooses, with the line going idle where it says. The transport stays OPEN,
  nothing is logged as an error (a consumer's exception is logged, not raised, by the transport), and
  the Bus resolves nothing (no request is pending).
* **scheduler intake** (``scheduler_intake``): a :class:`~servobus.scheduler.Scheduler` of one
  family's motors; the input is a program of requests, send reports, received frames (ours or
  not, any payload), cancels, failed sends and clock steps. ``receive`` never raises; a frame
  resolves only a request that was sent (at least ``min_reply_s`` before it) and waits for the key
  the frame carries, of the codec it belongs to; every request ends exactly once; the pending
  table holds only requests not ended; at the end, past every deadline, nothing is pending.
"""

from __future__ import annotations

import asyncio
import contextlib
import inspect
import logging
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

from servobus.core import (
    HollowTransparentDeframer,
    ModbusRtuDeframer,
    MyActuatorRs485Deframer,
    SlcanDeframer,
    crc16_modbus,
    crc32_ieee,
)
from servobus.errors import ProtocolError
from servobus.frame import Frame
from servobus.protocols import FrameKind, Message, get_family, lk
from servobus.protocols import hollow as ho
from servobus.protocols import myactuator as ma

__all__ = ["TARGETS", "Input", "Target", "target"]


class Input:
    """Reads an input's bytes as the choices a target makes (atheris' FuzzedDataProvider, small)."""

    __slots__ = ("data", "pos")

    def __init__(self, data: bytes) -> None:
        self.data = data
        self.pos = 0

    def byte(self) -> int:
        if self.pos >= len(self.data):
            return 0
        self.pos += 1
        return self.data[self.pos - 1]

    def pick(self, options: list[Any] | tuple[Any, ...]) -> Any:
        return options[self.byte() % len(options)]

    def take(self, n: int) -> bytes:
        out = self.data[self.pos : self.pos + n]
        self.pos += len(out)
        return out

    def rest(self) -> bytes:
        out = self.data[self.pos :]
        self.pos = len(self.data)
        return out

    @property
    def left(self) -> int:
        return len(self.data) - self.pos

    def chunks(self, stream: bytes) -> Iterator[bytes]:
        """``stream`` cut where the input's remaining bytes say (1..64 bytes a piece)."""
        i = 0
        while i < len(stream):
            n = 1 + self.byte() % 64
            yield stream[i : i + n]
            i += n


Target = Callable[[bytes], None]
TARGETS: dict[str, Target] = {}


def target(fn: Target) -> Target:
    TARGETS[fn.__name__] = fn
    return fn


# ---- decoders ----


def _only_protocol_error(decode: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
    """Call a decoder: its result, or None when it raised ProtocolError; anything else propagates."""
    try:
        result = decode(*args, **kwargs)
    except ProtocolError as exc:
        assert str(exc), "ProtocolError without a message"
        return None
    message = result[1] if isinstance(result, tuple) and len(result) == 2 else result
    if isinstance(message, Message):
        message.encode()  # what decoded encodes again (the simulator re-encodes what it decodes)
    return result


def _message_classes(module: Any) -> list[type[Message]]:
    """Every concrete message class a family package exports, with a ``decode`` of its own."""
    found = []
    for name in sorted(getattr(module, "__all__", ())):
        obj = getattr(module, name, None)
        if isinstance(obj, type) and issubclass(obj, Message) and "decode" in vars(obj):
            params = list(inspect.signature(obj.decode).parameters.values())[1:]
            if any(p.default is p.empty and p.kind is not p.VAR_KEYWORD for p in params):
                continue  # needs more than the bytes (Echo: the command it echoes): the family decodes it
            try:
                obj.decode(bytes(8))
            except NotImplementedError:
                continue  # a base class (LkCommand): its subclasses decode
            except Exception:
                pass
            found.append(obj)
    return found


def _class_decoders(module: Any) -> list[Callable[[bytes], Any]]:
    out: list[Callable[[bytes], Any]] = []
    for cls in _message_classes(module):
        out.append(cls.decode)
    return out


def _bound_codecs(family: str, ids: tuple[int, ...], **options: Any) -> list[Any]:
    fam = get_family(family)
    codecs = []
    for link in fam.links:
        for motor_id in ids:
            with contextlib.suppress(ValueError):
                codecs.append(fam.bind(motor_id, link=link, **options))
    return codecs


def _frame_from(inp: Input, *, serial: bool, ids: list[int]) -> Frame | None:
    """A Frame the input describes: one of ``ids`` (or any id), any payload the Frame type allows."""
    flags = inp.byte()
    if serial:
        address = inp.pick(ids) & 0xFF if flags & 1 else inp.byte()
        return Frame(arbitration_id=address, data=inp.take(inp.byte()), is_serial=True)
    extended = bool(flags & 2)
    fd = bool(flags & 4)
    if flags & 1:
        can_id = inp.pick(ids) & 0x1FFFFFFF
    else:
        can_id = int.from_bytes(inp.take(4).ljust(4, b"\0"), "little") & (0x1FFFFFFF if extended else 0x7FF)
    if not extended and can_id > 0x7FF:
        extended = True
    if fd:
        sizes = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)
        n = inp.pick(sizes)
        data = inp.take(n).ljust(n, b"\0")
    else:
        data = inp.take(inp.byte() % 9)
    return Frame(arbitration_id=can_id, data=data, is_extended_id=extended, is_fd=fd, is_rx=bool(flags & 8))


def _bound_decode(codec: Any, frame: Frame) -> None:
    kind, key = codec.classify(frame)  # never raises
    assert isinstance(kind, FrameKind)
    if kind is not FrameKind.NOT_OURS:
        hash(key)
        _only_protocol_error(codec.decode, frame)


@dataclass
class _Family:
    """One family's decoders, picked by the input's first byte."""

    functions: list[Callable[[Input], None]] = field(default_factory=list)

    def __call__(self, data: bytes) -> None:
        inp = Input(data)
        if not self.functions:
            return
        inp.pick(self.functions)(inp)


def _family_target(
    name: str,
    module: Any,
    options: list[dict[str, Any]],
    codecs: list[Any],
    *,
    serial: bool = False,
    extra: tuple[Callable[[Input], None], ...] = (),
    class_decoders: list[Callable[..., Any]] | None = None,
) -> Target:
    fam = get_family(name)
    family = _Family()
    ids = sorted({i for c in codecs for i in (*c.reply_ids, *c.request_ids, *c.shared_ids)})

    def family_level(inp: Input) -> None:
        opts = inp.pick(options)
        can_id = inp.pick(ids) if inp.byte() & 1 else int.from_bytes(inp.take(2).ljust(2, b"\0"), "little")
        payload = inp.rest()
        _only_protocol_error(fam.decode_reply, can_id, payload, **opts)
        _only_protocol_error(fam.decode_request, can_id, payload, **opts)

    def class_level(inp: Input) -> None:
        decode = inp.pick(decoders)
        payload = inp.rest()
        _only_protocol_error(decode, payload)

    def bound_level(inp: Input) -> None:
        codec = inp.pick(codecs)
        frame = _frame_from(inp, serial=codec.link not in ("can", "canfd"), ids=ids)
        if frame is not None:
            _bound_decode(codec, frame)

    decoders = class_decoders if class_decoders is not None else _class_decoders(module)
    family.functions += [family_level, class_level, bound_level, *extra]

    def run(data: bytes) -> None:
        family(data)

    run.__name__ = f"{name}_{'rs485' if serial else 'can'}"
    return run


def _ma_rs485(inp: Input) -> None:
    from servobus.protocols.myactuator.rs485 import decode_rs485, decode_rs485_reply, decode_rs485_request

    revision = inp.pick(list(ma.Revision))
    frame = inp.rest()
    _only_protocol_error(decode_rs485, frame)
    _only_protocol_error(decode_rs485_request, frame, revision=revision)
    _only_protocol_error(decode_rs485_reply, frame, revision=revision)


def _ma_rs485_motion(inp: Input) -> None:
    crc = inp.pick([None, "default"])
    frame = inp.rest()
    for cls in (ma.Rs485MotionCommand, ma.Rs485MotionReply):
        if crc is None:
            _only_protocol_error(cls.decode, frame, crc=None)
        else:
            _only_protocol_error(cls.decode, frame)


def _ho_rs485(inp: Input) -> None:
    from servobus.protocols.hollow import rs485

    model = inp.pick(list(ho.MODELS.values()))
    which = inp.byte()
    frame = inp.rest()
    if which & 1:  # give it a valid CRC so the decoder sees past the check
        frame = frame + (crc32_ieee(frame) if which & 2 else crc16_modbus(frame)).to_bytes(
            4 if which & 2 else 2, "little"
        )
    _only_protocol_error(rs485.decode_transparent, frame)
    _only_protocol_error(rs485.TransparentRequest.decode, frame, model=model)
    _only_protocol_error(rs485.TransparentReply.decode, frame, model=model)
    _only_protocol_error(rs485.decode_modbus_request, frame, model=model)
    _only_protocol_error(rs485.decode_modbus_reply, frame, model=model)


def _ho_converter(inp: Input) -> None:
    from servobus.protocols.hollow.converter import decode_converter_config

    _only_protocol_error(decode_converter_config, inp.rest())


def _ho_can_options() -> list[dict[str, Any]]:
    out = []
    for model in ho.MODELS.values():
        for extended in (False, True):
            for fd in (False, True):
                out.append({"is_extended_id": extended, "is_fd": fd, "model": model})
    return out


def _mods_of(*names: str) -> list[Any]:
    import importlib

    return [importlib.import_module(n) for n in names]


def _classes_of(*modules: Any) -> list[Callable[..., Any]]:
    seen: dict[Any, None] = {}
    for module in modules:
        for cls in _message_classes(module):
            seen[cls.decode] = None
    return list(seen)


def _lk_options() -> list[dict[str, Any]]:
    from servobus.protocols.lk.model import LkModel, MotorType

    out: list[dict[str, Any]] = []
    for revision in lk.Revision:
        for motor_type in MotorType:
            for bits in (14, 15, 16, 18):
                model = LkModel(revision=revision, motor_type=motor_type, encoder_bits=bits)
                out.append({"revision": revision, "model": model})
    return out or [{}]


def _build_family_targets() -> None:
    ma_codecs = [
        *_bound_codecs("myactuator", (1, 2, 32)),
        ma.FAMILY.bind(1, revision=ma.Revision.V4_3, link="can"),
        ma.FAMILY.bind(1, revision=ma.Revision.V4_3, link="rs485"),
    ]
    can_codecs = [c for c in ma_codecs if c.link == "can"]
    rs485_codecs = [c for c in ma_codecs if c.link != "can"]
    rev_options = [{"revision": r} for r in ma.Revision]
    target(_family_target("myactuator", ma, rev_options, can_codecs))
    target(
        _family_target(
            "myactuator",
            ma,
            rev_options,
            rs485_codecs,
            serial=True,
            extra=(_ma_rs485, _ma_rs485_motion),
        )
    )
    lk_codecs = _bound_codecs("lk", (1, 2, 32)) + _bound_codecs("lk", (1,), revision=lk.Revision.V2_35)
    # LK's messages inherit their decode from the declared layout: the codec's classes are the list.
    lk_classes = (*lk.codec.COMMAND_CLASSES, *(reply for reply, _ in lk.codec.REPLY_LAYOUTS))
    lk_decoders = [cls.decode for cls in lk_classes]
    target(_family_target("lk", lk, _lk_options(), lk_codecs, class_decoders=lk_decoders))
    ho_mods = _mods_of("servobus.protocols.hollow", "servobus.protocols.hollow.converter")
    ho_codecs = _bound_codecs("hollow", (0, 1, 100))
    target(
        _family_target(
            "hollow",
            ho,
            _ho_can_options(),
            [c for c in ho_codecs if c.link in ("can", "canfd")],
            extra=(_ho_converter,),
            class_decoders=_classes_of(*ho_mods),
        )
    )
    rs485_mod = _mods_of("servobus.protocols.hollow.rs485")
    target(
        _family_target(
            "hollow",
            ho,
            _ho_can_options(),
            [c for c in ho_codecs if c.link not in ("can", "canfd")],
            serial=True,
            extra=(_ho_rs485,),
            class_decoders=_classes_of(*rs485_mod),
        )
    )


_build_family_targets()


# ---- de-framers ----


def _deframe(make: Callable[[], Any], check: Callable[[bytes], None], data: bytes, *, idles: bool) -> None:
    inp = Input(data)
    head = inp.byte()
    split = head % max(1, len(data))
    stream = data[split:]
    cut = Input(data[:split])  # the cut points come from the bytes before the stream
    deframer = make()
    whole = make()
    out: list[bytes] = []
    expected = whole.feed(stream)
    for chunk in cut.chunks(stream):
        out += deframer.feed(chunk)
        assert 0 <= deframer.pending <= deframer.max_frame, (deframer.pending, deframer.max_frame)
    assert out == expected, "the frames depend on where the stream was cut"
    for frame in out:
        check(frame)
    if idles:
        tail = deframer.idle()
        assert tail == whole.idle()
        for frame in tail:
            check(frame)
        assert deframer.pending == 0
        # After the silence the de-framer starts afresh: the same stream gives the same frames again.
        assert deframer.feed(stream) == expected


def _crc16_ok(frame: bytes) -> None:
    assert len(frame) >= 3 and crc16_modbus(frame[:-2]) == int.from_bytes(frame[-2:], "little"), frame.hex()


def _crc32_ok(frame: bytes) -> None:
    assert len(frame) >= 5 and crc32_ieee(frame[:-4]) == int.from_bytes(frame[-4:], "little"), frame.hex()


@target
def deframe_myactuator_rs485(data: bytes) -> None:
    def check(frame: bytes) -> None:
        assert frame[0] == 0x3E, frame.hex()
        _crc16_ok(frame)

    _deframe(MyActuatorRs485Deframer, check, data, idles=True)


@target
def deframe_hollow_transparent(data: bytes) -> None:
    _deframe(HollowTransparentDeframer, _crc32_ok, data, idles=True)


@target
def deframe_modbus_rtu(data: bytes) -> None:
    direction = ("requests", "replies", "both")[data[0] % 3] if data else "replies"
    _deframe(lambda: ModbusRtuDeframer(direction=direction), _crc16_ok, data[1:], idles=True)


@target
def deframe_slcan(data: bytes) -> None:
    inp = Input(data)
    split = inp.byte() % max(1, len(data))
    stream = data[split:]
    cut = Input(data[:split])
    deframer, whole = SlcanDeframer(timestamps=bool(split & 1)), SlcanDeframer(timestamps=bool(split & 1))
    expected = whole.feed(stream, 1.0)
    out: list[Frame] = []
    for chunk in cut.chunks(stream):
        out += deframer.feed(chunk, 1.0)
        assert 0 <= deframer.pending <= deframer.max_line
    assert out == expected, "the frames depend on where the stream was cut"
    for frame in out:
        assert isinstance(frame, Frame) and not frame.is_serial
    counts = (deframer.frames, deframer.malformed, deframer.overlong, deframer.remote)
    assert counts == (whole.frames, whole.malformed, whole.overlong, whole.remote)


# ---- transports, with a Bus on them ----


class _Errors(logging.Handler):
    """Collects what servobus logs at ERROR (a consumer's or listener's exception lands there)."""

    def __init__(self) -> None:
        super().__init__(logging.ERROR)
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)


class TransportRig:
    """A real transport on a pty, a Bus on it, and an event loop of its own: built once per process."""

    def __init__(self, kind: str) -> None:
        from servobus.bus import Bus
        from servobus.sim.pty import PtyPort

        self.kind = kind
        self.loop = asyncio.new_event_loop()
        self.errors = _Errors()
        logging.getLogger("servobus").addHandler(self.errors)
        self.ports: list[PtyPort] = []
        self.transports: list[Any] = []
        self.buses: list[Any] = []
        self._tasks: list[asyncio.Task[None]] = []
        self._holders: list[tuple[asyncio.Task[None], asyncio.Event]] = []
        if kind == "slcan":
            from servobus.sim.attach import serve_slcan
            from servobus.sim.network import SimCanNetwork
            from servobus.transports import SlcanTransport

            port = PtyPort()
            self.ports.append(port)
            network = SimCanNetwork([])
            self._tasks.append(self.loop.create_task(serve_slcan(network, port)))
            transport = SlcanTransport(port.path, bitrate=1_000_000, reopen=False)
            self._open(transport, Bus, [("myactuator", i, {}) for i in (1, 2, 3)])
        else:
            from servobus.transports import SerialTransport

            links = [
                ("myactuator", [("myactuator", i, {"link": "rs485"}) for i in (1, 2, 3)]),
                ("hollow-transparent", [("hollow", i, {"link": "rs485"}) for i in (1, 2, 3)]),
                ("modbus-rtu", [("hollow", i, {"link": "modbus"}) for i in (1, 2, 3)]),
            ]
            for mode, motors in links:
                port = PtyPort()
                self.ports.append(port)
                self._open(SerialTransport(port.path, mode=mode, reopen=False), Bus, motors)

    def _open(self, transport: Any, bus_type: Any, motors: list[tuple[str, int, dict[str, Any]]]) -> None:
        # One task opens the link and enters the Bus, and leaves both (a Bus owns a task group,
        # entered and left by one task); it holds them until close().
        ready: asyncio.Future[Any] = self.loop.create_future()
        stop = asyncio.Event()

        async def hold() -> None:
            try:
                await transport.open()
                try:
                    async with bus_type(transport, safe=None) as bus:
                        for family, motor_id, options in motors:
                            bus.motor(family, motor_id, **options)
                        ready.set_result(bus)
                        await stop.wait()
                finally:
                    await transport.close()
            except BaseException as exc:
                if not ready.done():
                    ready.set_exception(exc)
                raise

        self._holders.append((self.loop.create_task(hold()), stop))
        self.buses.append(self.loop.run_until_complete(ready))
        self.transports.append(transport)

    def feed(self, data: bytes) -> None:
        self.loop.run_until_complete(self._feed(data))

    async def _feed(self, data: bytes) -> None:
        from servobus.transports.events import TransportState

        inp = Input(data)
        index = inp.byte() % len(self.transports)
        transport, bus = self.transports[index], self.buses[index]
        before = bus.stats()
        stream = self._stream(inp, transport, bus)
        for chunk in Input(stream[::-1]).chunks(stream):  # the cuts come from the bytes themselves
            transport._on_bytes(chunk, transport._generation)  # what the port's reader calls
            if self.kind == "rs485" and chunk and chunk[-1] % 7 == 0:  # the line went quiet here
                transport._take(transport._deframer.idle(), transport._now())
        if self.kind == "rs485":
            transport._take(transport._deframer.idle(), transport._now())
        await asyncio.sleep(0)
        assert transport.state is TransportState.OPEN, f"{transport!r} left OPEN: {transport.state}"
        assert not self.errors.records, [r.getMessage() for r in self.errors.records]
        after = bus.stats()
        assert bus.scheduler.pending == 0
        assert after.get("replies", 0) == before.get("replies", 0), "a reply resolved a request nobody made"

    def _stream(self, inp: Input, transport: Any, bus: Any) -> bytes:
        """The bytes to feed: raw, or (first byte odd) a mix of raw runs and whole frames the link's
        framing encodes for the Bus's motors (any body), some with a flipped bit, so the input
        reaches the decoders past the de-framer as well as the de-framer itself."""
        if not inp.byte() & 1:
            return inp.rest()
        from servobus.transports.slcan import encode_line

        addresses = sorted({i & 0x7FF for m in bus.motors.values() for i in m.codec.reply_ids}) or sorted(
            m.motor_id for m in bus.motors.values()
        )
        out = bytearray()
        while inp.left:
            op = inp.byte() % 4
            if op == 0:
                out += inp.take(inp.byte() % 16)
                continue
            size = inp.byte()
            size = size % 9 if self.kind == "slcan" else (8, 8, 16, 17, 4, 6, size % 40)[size % 7]
            body = inp.take(size).ljust(size, b"\0")
            address = inp.pick(addresses) if op != 3 else inp.byte()
            try:
                if self.kind == "slcan":
                    encoded = encode_line(Frame(arbitration_id=address & 0x7FF, data=body))
                else:
                    encoded = transport.framing.encode(
                        Frame(arbitration_id=address & 0xFF, data=body, is_serial=True)
                    )
            except ValueError:
                encoded = body
            if op == 2 and encoded:  # one bit flipped
                bit = inp.byte() % (8 * len(encoded))
                encoded = bytearray(encoded)
                encoded[bit // 8] ^= 1 << (bit % 8)
            out += encoded
        return bytes(out)

    def close(self) -> None:
        async def stop() -> None:
            for holder, stopping in self._holders:
                stopping.set()
                await holder
            for task in self._tasks:
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await task

        self.loop.run_until_complete(stop())
        for port in self.ports:
            port.close()
        self.loop.close()
        logging.getLogger("servobus").removeHandler(self.errors)


_RIGS: dict[str, TransportRig] = {}


def rig(kind: str) -> TransportRig:
    """The process's transport rig of ``kind`` (built on first use; :func:`close_rigs` ends them)."""
    if kind not in _RIGS:
        _RIGS[kind] = TransportRig(kind)
    return _RIGS[kind]


def close_rigs() -> None:
    while _RIGS:
        _RIGS.popitem()[1].close()


@target
def transport_slcan(data: bytes) -> None:
    rig("slcan").feed(b"\0" + data)


@target
def transport_rs485(data: bytes) -> None:
    rig("rs485").feed(data)


# ---- the scheduler's frame intake ----


def _sched_codecs() -> dict[str, list[Any]]:
    return {
        "myactuator": [ma.FAMILY.bind(i) for i in (1, 2, 3)],
        "myactuator-rs485": [ma.FAMILY.bind(i, link="rs485") for i in (1, 2, 3)],
        "lk": [lk.FAMILY.bind(i) for i in (1, 2, 3)],
        "hollow": [ho.FAMILY.bind(i) for i in (1, 2, 3)],
        "hollow-fd": [ho.FAMILY.bind(i, link="canfd") for i in (1, 2, 3)],
    }


_SCHED = _sched_codecs()
_READS: dict[str, list[Any]] = {
    "myactuator": [ma.ReadStatus1(), ma.ReadStatus2(), ma.ReadMultiTurnAngle(), ma.MotorStop()],
    "lk": [lk.ReadStatus1(), lk.ReadStatus2(), lk.ReadMultiTurnAngle(), lk.MotorStop()],
    "hollow": [ho.Stop(), ho.Start()],
}


def _sched_commands(codec: Any) -> list[Any]:
    commands = list(_READS.get(codec.family) or [])
    with contextlib.suppress(ValueError):
        commands.append(codec.safe_command("stop"))
    out = []
    for command in commands:
        with contextlib.suppress(ValueError):
            codec.encode(command)
            out.append(command)
    return out


@target
def scheduler_intake(data: bytes) -> None:
    from servobus.scheduler import FINAL, RequestState, Scheduler, Traffic

    inp = Input(data)
    name = inp.pick(sorted(_SCHED))
    codecs = _SCHED[name]
    commands = {id(c): _sched_commands(c) for c in codecs}
    min_reply_s = inp.pick((0.0, 0.0001))
    scheduler = Scheduler(
        codecs,
        max_in_flight=1 + inp.byte() % 8,
        one_at_a_time=bool(inp.byte() & 1),
        gap_s=0.0002,
        min_reply_s=min_reply_s,
        late_hold_s=inp.pick((None, 0.0, 0.003)),
    )
    ids = sorted({i & 0x1FFFFFFF for c in codecs for i in (*c.reply_ids, *c.shared_ids, *c.request_ids)})
    serial = codecs[0].link not in ("can", "canfd")
    now = 0.0
    made: list[Any] = []
    ended: dict[int, str] = {}
    sending: list[Any] = []

    def note_end(request: Any, how: str) -> None:
        assert id(request) not in ended, f"{request.describe()} ended twice ({ended[id(request)]}, {how})"
        assert request.state in FINAL
        ended[id(request)] = how

    while inp.left:
        op = inp.byte() % 8
        if op == 0:  # a request
            codec = inp.pick(codecs)
            if commands[id(codec)]:
                request = scheduler.request(
                    codec, inp.pick(commands[id(codec)]), timeout_s=0.001 * (1 + inp.byte() % 8)
                )
                scheduler.submit(request, now)
                made.append(request)
        elif op == 1:  # what may go, goes
            sending += scheduler.poll(now)[0]
        elif op == 2 and sending:  # a send report
            request = sending.pop(inp.byte() % len(sending))
            early = scheduler.sent(request, now)
            if request.state in FINAL:  # a reply that beat the report: taken, or failed with why
                note_end(request, "replied" if request.state is RequestState.REPLIED else "failed")
            if early is not None and early.request is not None:
                assert early.request is request
        elif op == 3:  # a frame comes in
            frame = _frame_from(inp, serial=serial, ids=ids)
            if frame is None:
                continue
            frame = Frame(
                arbitration_id=frame.arbitration_id,
                data=frame.data,
                is_extended_id=frame.is_extended_id,
                is_fd=frame.is_fd,
                is_serial=frame.is_serial,
                is_rx=frame.is_rx,
                timestamp=now,
            )
            got = scheduler.receive(frame, now)  # never raises
            if got.request is not None and got.traffic in (Traffic.MALFORMED, Traffic.NOT_EXECUTED):
                # the motor answered it in a way that is no reply: a frame that does not decode, or
                # its own bytes back; it fails with why, never resolved with data
                request = got.request
                assert got.codec is request.codec, "a frame failed another motor's request"
                assert request.state is RequestState.FAILED and request.error is not None
                assert request.reply is None and got.reply is None
                note_end(request, "failed")
            elif got.request is not None:
                request = got.request
                assert got.codec is request.codec, "a reply went to another motor's request"
                _kind, key = request.codec.classify(frame)
                assert key == request.key, f"a reply with key {key!r} resolved a request for {request.key!r}"
                assert request.state is RequestState.REPLIED and request.reply is got.reply
                assert (
                    request.sent_at is not None and frame.timestamp >= request.sent_at + min_reply_s - 1e-12
                )
                note_end(request, "replied")
        elif op == 4:  # time passes
            now += 0.0001 * (1 + inp.byte() % 64)
            for request in scheduler.expire(now):
                note_end(request, "timed out")
        elif op == 5 and made:  # a caller gives up
            request = inp.pick(made)
            was_final = request.state in FINAL
            scheduler.cancel(request, now)
            if request in sending:
                sending.remove(request)
            if not was_final:
                note_end(request, "cancelled")
        elif op == 6 and sending:  # the transport drops a frame
            request = sending.pop(inp.byte() % len(sending))
            was_final = request.state in FINAL
            scheduler.not_sent(request, "stale", now)
            if not was_final:
                note_end(request, "failed")
        elif op == 7:
            deadline = scheduler.next_deadline()
            assert deadline is None or deadline >= 0
        open_ = [r for r in made if r.state not in FINAL]
        assert scheduler.pending == len(open_), (scheduler.pending, len(open_))
        assert all(r.state in FINAL for r in made if id(r) in ended)
    # The end: every send is reported, time runs past every deadline and every hold (a key in doubt
    # is held for each reply still owed to it, one after the other: up to a few tenths of a second
    # each here); nothing stays pending.
    for _ in range(4 * len(made) + 400):
        for request in sending:
            scheduler.sent(request, now)
            if request.state in FINAL:
                note_end(request, "replied" if request.state is RequestState.REPLIED else "failed")
        sending = list(scheduler.poll(now)[0])
        now += 0.01
        for request in scheduler.expire(now):
            note_end(request, "timed out")
        if not scheduler.pending and not sending:
            break
    assert scheduler.pending == 0, f"{scheduler.pending} requests still pending"
    assert all(r.state in FINAL for r in made)
    assert len(ended) == len(made)
    counts = scheduler.counts
    assert counts["requests"] == len(made)
    assert counts["replies"] == sum(1 for how in ended.values() if how == "replied")
    assert counts["timeouts"] == sum(1 for how in ended.values() if how == "timed out")
