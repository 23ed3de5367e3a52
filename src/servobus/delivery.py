"""Frame intake of a Bus (:class:`Delivery`): each received frame judged by the scheduler, then
delivered to its motor (state, faults, the watchdog, frame iterators, subscribers) and to the request
it answers; a stream that goes on after it was switched off gets its "off" again."""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Any

from servobus._events import MotorEvents
from servobus._tick import detached
from servobus.errors import MotorFault, TransportError
from servobus.frame import Frame
from servobus.protocols._restart import Seen
from servobus.scheduler import Received, Traffic

if TYPE_CHECKING:
    from servobus.engine import Engine
    from servobus.motor import Motor

__all__ = ["Delivery"]

logger = logging.getLogger("servobus.bus")

_STREAM = Traffic.STREAM
_NOT_EXECUTED = Traffic.NOT_EXECUTED


class Delivery:
    """What came from the link, to where it goes (the link's consumer is :meth:`on_frames`)."""

    def __init__(self, engine: Engine) -> None:
        self.engine = engine
        self.bus = engine.bus
        self.name = engine.name
        self.scheduler = engine.scheduler
        self._warned: set[int] = set()  # motors (by codec id) whose undecodable reply was logged
        self._settle = engine.settle  # (once per reply: bound here)
        self._by_codec = engine.bus._by_codec  # (the Bus's, for good)
        self._subscribers = engine.bus._subscribers
        self.events = MotorEvents(engine)
        self._tripped = self.events.tripped  # (read on every reply: bound here)

    def on_frames(self, frames: list[Frame]) -> None:
        now = self.engine.time()
        receive = self.scheduler.receive
        for frame in frames:
            got = receive(frame, now)
            if got.codec is not None:
                if got.reply is not None:
                    self.deliver(got, now)
                elif got.traffic is _NOT_EXECUTED:  # its request's own bytes: echoed, not executed
                    self.events.not_executed(got)
                elif got.request is not None:  # an undecodable reply: its request fails with why
                    self.undecodable(got)
        self.engine.pump()

    def undecodable(self, got: Received) -> None:
        request = got.request
        assert request is not None and got.codec is not None
        if id(got.codec) not in self._warned:  # once per motor: a wrong revision repeats every frame
            self._warned.add(id(got.codec))
            logger.warning(
                "%s: %s: the reply does not decode (%s); check the motor's revision and model (bound as %s)",
                self.name,
                request.describe(),
                request.error,
                got.codec.revision.name,
            )
        self.engine.settle(request, request.error)

    def deliver(self, got: Received, now: float) -> None:
        """A decoded frame of one of our motors: its state, watchdog, watchers, and its request."""
        motor = self._by_codec.get(id(got.codec))
        reply = got.reply
        assert reply is not None
        if motor is not None:
            event = reply.EVENT
            if event is None:  # (an event measures nothing: the state stays the last reply's)
                motor.state = reply
            motor.last_seen = got.frame.timestamp or now
            if motor._remembers and type(reply) in motor._remembers:  # (servobus.restarts)
                motor._remembered[type(reply)] = Seen(reply, now)
            if motor._misses or motor.online is not True:
                self.engine.watchdog.answered(motor, now)
            if event is not None:
                self.events.event(motor, reply, now)
            elif self._tripped and got.request is not None:
                self.events.executed(motor)
            if reply.FAULTS is not None:
                self._note_faults(motor, getattr(reply, reply.FAULTS))
            if motor._ending and got.request is None and got.traffic is not _STREAM:
                self.stream_goes_on(motor, got.frame, now)
            for watcher in motor._watchers:
                watcher._push(got.traffic, reply)
            for callback in self._subscribers:
                try:
                    callback(motor, got.traffic, reply)
                except Exception:  # a subscriber's bug must not stop the reader
                    logger.exception("%s: subscriber %r failed", self.name, callback)
        if got.request is not None:
            self._settle(got.request, None)

    def _note_faults(self, motor: Any, flags: Any) -> None:
        if not flags:
            motor.fault = None
        elif motor.fault is None or motor.fault.flags != flags:
            motor.fault = MotorFault(f"{motor!r} reports {flags!r}", flags=flags, motor_id=motor.motor_id)
            logger.warning("%s: %s", self.name, motor.fault)

    def stream_goes_on(self, motor: Motor, frame: Frame, now: float) -> None:
        """A frame of a stream that was switched off came: if later than a reply to the "off"
        could take, the "off" was lost; it is sent again. Once the stream was quiet for a few of its
        intervals it ended: a frame with its command byte then is another (a read's late reply)."""
        engine = self.engine
        if not frame.data or self.bus._closing or engine.runtime is None:
            return
        code = frame.data[0]
        ending = motor._ending.get(code)
        if ending is None:
            return
        off, sent_at, interval_s = ending
        at = frame.timestamp or now
        reach_s = self.scheduler.motor_timeout_s(motor.codec)
        if at < sent_at + reach_s:
            return  # it may have left the motor before the "off" arrived
        if at > sent_at + reach_s + 4 * interval_s:
            del motor._ending[code]  # quiet since: the stream ended
            return
        motor._ending[code] = (off, now, interval_s)
        self.scheduler.motor_counts[id(motor.codec)]["stream_off_resent"] += 1
        logger.info("%s: %r still streams 0x%02X: switching it off again", self.name, motor, code)
        try:
            request = engine.prepare(motor, off, None, 0, detached(engine.runtime))
        except (ValueError, TransportError):  # (never out of the reader)
            logger.exception("%s: %r: the stream's 'off' could not be sent again", self.name, motor)
            return
        engine.enqueue(motor, request)
