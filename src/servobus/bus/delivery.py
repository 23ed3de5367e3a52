"""Frame intake of a Bus (:class:`Delivery`): a received frame the scheduler judged (the engine's
:meth:`~servobus.bus.engine.Engine.on_frames` asks it) is delivered to its motor (state, faults, the
watchdog, frame iterators, subscribers) and to the request it answers; a stream that goes on after
it was switched off gets its "off" again.

It also settles every request (:meth:`Delivery.settle`: its outcome into its waiter). It knows the
engine only as an :class:`IntakeHost` (counting, its clock's verdicts, sending an "off" again):
this module imports nothing of the bus package above it."""

from __future__ import annotations

import enum
import logging
from collections.abc import Callable, Iterable
from typing import Any, Protocol

from servobus.bus.events import MotorEvents
from servobus.bus.motor import Motor, MotorRecord
from servobus.bus.watchdog import Watchdog
from servobus.errors import MotorFault, MotorTimeout, TransportError
from servobus.frame import Frame
from servobus.protocols import BoundCodec, Command, Reply
from servobus.protocols._restart import Seen
from servobus.scheduler import Received, Request, RequestState, Traffic

__all__ = ["Delivery", "IntakeHost"]

logger = logging.getLogger("servobus.bus")

_STREAM, _LATE = Traffic.STREAM, Traffic.LATE
# RequestState members as globals for the per-reply path (an Enum member lookup is a metaclass call).
_REPLIED, _TIMED_OUT = RequestState.REPLIED, RequestState.TIMED_OUT


class IntakeHost(Protocol):
    """What the intake asks of the engine (:class:`servobus.bus.engine.Engine` is one)."""

    name: str
    #: the block is being left: nothing but the safe commands goes out
    closing: bool

    def timed_out(self, request: Request) -> MotorTimeout: ...

    def count(self, codec: BoundCodec, counter: str) -> None: ...

    def reach_s(self, codec: BoundCodec) -> float: ...

    def send_unawaited(self, motor: Motor, command: Command) -> None: ...


class Delivery:
    """What came from the link, to where it goes.

    Args:
        engine: the Bus's engine.
        records: the Bus's motor records, by codec id (:attr:`servobus.bus.motor.Registry.records`).
        watchdog: the Bus's watchdog (told of the motors that answer again).
        subscribers: the Bus's ``subscribe`` callbacks.
    """

    def __init__(
        self,
        engine: IntakeHost,
        records: dict[int, MotorRecord],
        watchdog: Watchdog,
        subscribers: list[Callable[[Motor, Traffic, Reply], object]],
    ) -> None:
        self.engine = engine
        self.name = engine.name
        self._timed_out = engine.timed_out
        self._settle = self.settle  # (once per reply: bound here)
        self._records = records
        self._watchdog = watchdog
        self._subscribers = subscribers
        self.events = MotorEvents(engine.name, engine.count, self.settle, watchdog)
        self._tripped = self.events.tripped  # (read on every reply: bound here)

    def undecodable(self, got: Received) -> None:
        request = got.request
        assert request is not None and got.codec is not None
        record = self._records.get(id(got.codec))
        if record is None or not record.undecodable_logged:  # once per motor: a wrong revision repeats
            if record is not None:
                record.undecodable_logged = True
            logger.warning(
                "%s: %s: the reply does not decode (%s); check the motor's revision and model (bound as %s)",
                self.name,
                request.describe(),
                request.error,
                got.codec.revision.name,
            )
        self.settle(request, request.error)

    def not_executed(self, got: Received) -> None:
        """Its request's own bytes came back: echoed, not executed (:mod:`servobus.bus.events`)."""
        self.events.not_executed(got, self._records.get(id(got.codec)))

    def deliver(self, got: Received, now: float) -> None:
        """A decoded frame of one of our motors: its state, watchdog, watchers, and its request."""
        record = self._records.get(id(got.codec))
        reply = got.reply
        assert reply is not None
        if record is not None:
            motor = record.motor
            event = reply.EVENT
            if event is None:  # (an event measures nothing: the state stays the last reply's)
                motor.state = reply
            motor.last_seen = got.frame.timestamp or now
            if record.remembers and type(reply) in record.remembers:  # (servobus.bus.restarts)
                record.remembered[type(reply)] = Seen(reply, now)
            if record.misses or motor.online is not True:
                self._watchdog.answered(record, now)
            if event is not None:
                self.events.event(record, reply, now)
            elif self._tripped and got.request is not None:
                self.events.executed(record)
            if reply.FAULTS is not None:
                self._note_faults(motor, getattr(reply, reply.FAULTS))
            elif reply.FAULT_CODE is not None:
                self._note_code(motor, getattr(reply, reply.FAULT_CODE), reply.NO_FAULT_CODES)
            if record.ending and got.request is None and got.traffic is not _STREAM:
                self.stream_goes_on(record, got.frame, now)
            for watcher in record.watchers:
                watcher.push(got.traffic, reply)
            for callback in self._subscribers:
                try:
                    callback(motor, got.traffic, reply)
                except Exception:  # a subscriber's bug must not stop the reader
                    logger.exception("%s: subscriber %r failed", self.name, callback)
        request = got.request
        if request is not None:
            future = request.context
            # (settle()'s common case written out: once per reply)
            if future is not None and request.state is _REPLIED and not future.done():
                future.set_result(request.reply)
            else:
                self._settle(request, None)
        elif got.traffic is _LATE and record is not None and record.late is not None:
            record.late(reply, got.frame)

    def fail(self, requests: Iterable[Request]) -> None:
        """Each of ``requests`` ended with its error."""
        for request in requests:
            self.settle(request, request.error)

    def settle(self, request: Request, error: BaseException | None) -> None:
        """``request``'s outcome into its waiter (``request.context``): ``error``, its reply, or the
        error that ended it (once: a waiter already done is left alone)."""
        future = request.context
        if future is None or future.done():
            return
        if error is not None:
            future.set_exception(error)
        elif request.state is _REPLIED:
            future.set_result(request.reply)
        elif request.state is _TIMED_OUT:
            future.set_exception(self._timed_out(request))
        else:
            future.set_exception(
                request.error or TransportError(f"{self.name}: {request.describe()} {request.state.value}")
            )

    def _note_faults(self, motor: Any, flags: Any) -> None:
        if not flags:
            motor.fault = None
        elif motor.fault is None or motor.fault.flags != flags:
            motor.fault = MotorFault(f"{motor!r} reports {flags!r}", flags=flags, motor_id=motor.motor_id)
            logger.warning("%s: %s", self.name, motor.fault)

    def _note_code(self, motor: Any, code: int, no_fault: frozenset[int]) -> None:
        """A reply's error code (``Reply.FAULT_CODE``): a fault unless one of ``no_fault`` (a state)."""
        if code in no_fault:
            motor.fault = None
        elif motor.fault is None or motor.fault.code != code:
            said = f"{type(code).__name__}.{code.name}" if isinstance(code, enum.Enum) else f"code {code}"
            motor.fault = MotorFault(f"{motor!r} reports {said}", code=code, motor_id=motor.motor_id)
            logger.warning("%s: %s", self.name, motor.fault)

    def stream_goes_on(self, record: MotorRecord, frame: Frame, now: float) -> None:
        """A frame of a stream that was switched off came: if later than a reply to the "off"
        could take, the "off" was lost; it is sent again. Once the stream was quiet for a few of its
        intervals it ended: a frame with its command byte then is another (a read's late reply)."""
        engine = self.engine
        if not frame.data or engine.closing:
            return
        code = frame.data[0]
        ending = record.ending.get(code)
        if ending is None:
            return
        off, sent_at, interval_s = ending
        at = frame.timestamp or now
        reach_s = engine.reach_s(record.codec)
        if at < sent_at + reach_s:
            return  # it may have left the motor before the "off" arrived
        if at > sent_at + reach_s + 4 * interval_s:
            del record.ending[code]  # quiet since: the stream ended
            return
        record.ending[code] = (off, now, interval_s)
        engine.count(record.codec, "stream_off_resent")
        motor = record.motor
        logger.info("%s: %r still streams 0x%02X: switching it off again", self.name, motor, code)
        try:
            engine.send_unawaited(motor, off)
        except (ValueError, TransportError):  # (never out of the reader)
            logger.exception("%s: %r: the stream's 'off' could not be sent again", self.name, motor)
