"""One bus's batch of one pipelined tick (:func:`pipeline`): what a fixed-rate loop
(:mod:`servobus.loop`) sends at a tick's deadline, without waiting for the replies.

Unlike :meth:`Engine.cycle <servobus.bus.engine.Engine.cycle>` (send and wait), each request is
``pipelined`` (``servobus.scheduler``: it leaves while requests with its key are still in flight, so
a motor commanded every tick has several out at once), its outcome goes into the caller's context
(anything with ``done``/``set_result``/``set_exception``/``cancel``/``cancelled``, as
:class:`~servobus.bus.tick.Slot`), and nothing awaits here.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from servobus.errors import MotorOffline, MotorStreaming, TransportError
from servobus.protocols import Command
from servobus.runtime import RuntimeMismatch
from servobus.scheduler import batch_requests, submit_batch

if TYPE_CHECKING:
    from servobus.bus.engine import Engine
    from servobus.bus.motor import Motor
    from servobus.scheduler import Request

__all__ = ["Superseded", "pipeline", "prepare", "send"]


class Superseded(TransportError):
    """A pipelined command still queued when the next one for its motor was given: withdrawn, never
    sent (a stale command is worse than none)."""


def pipeline(
    engine: Engine,
    items: Sequence[tuple[Motor, Command]],
    contexts: Sequence[Any],
    timeout_s: float | None,
    probe_interval_s: float,
) -> tuple[list[Request], int]:
    """Send one tick's ``items`` on ``engine``'s bus, each request's outcome into the context of
    the same index in ``contexts``: :func:`prepare` (ValueError before anything is queued: nothing
    of the batch leaves), then :func:`send`. (A loop over several buses prepares every bus's batch
    before it sends any.)"""
    return send(engine, items, prepare(engine, items, contexts, timeout_s), contexts, probe_interval_s)


def prepare(
    engine: Engine, items: Sequence[tuple[Motor, Command]], contexts: Sequence[Any], timeout_s: float | None
) -> list[Request | None]:
    """Each command encoded into its pipelined request (ValueError: one the codec refuses; nothing is
    queued here); None for a streaming motor's, which it would not answer."""
    if engine.runtime is None:
        raise RuntimeMismatch(f"{engine.name}: use the Bus inside 'async with'")
    if engine.closing:
        raise engine.closed_error()
    # (Engine.prepare written out for a batch: its checks once, a call less per request)
    made = batch_requests(
        engine.scheduler,
        [
            (motor.codec, command if motor.limits is None else motor.limited(command), context)
            for (motor, command), context in zip(items, contexts, strict=True)
        ],
        timeout_s,
    )
    requests: list[Request | None] = []
    for request in made:
        codec = request.codec
        if request.key is None and codec.streams and not request.writes:
            requests.append(None)  # (it would not answer: told by send, once nothing can raise)
            continue
        request.pipelined = True
        requests.append(request)
    return requests


def send(
    engine: Engine,
    items: Sequence[tuple[Motor, Command]],
    requests: Sequence[Request | None],
    contexts: Sequence[Any],
    probe_interval_s: float,
) -> tuple[list[Request], int]:
    """The ``requests`` :func:`prepare` made of ``items``, sent: the requests of the same motors still
    queued from an earlier batch are withdrawn (counted ``superseded``; their contexts get
    :class:`Superseded`); an offline motor's command goes as a probe every ``probe_interval_s`` and
    is else not sent (counted ``skipped_offline``, its context gets MotorOffline), as in
    ``Bus.cycle``; all are queued, then ONE pump hands what may leave to the link.

    Returns:
        The requests queued (in order; those with ``state`` QUEUED after it still wait for their
        turn), and how many commands were not sent (offline, streaming).
    """
    scheduler = engine.scheduler
    now = engine.time()
    if scheduler.table.queue:  # (the common case: the last batch left whole, nothing to withdraw)
        _supersede(engine, {id(m.codec) for m, _ in items}, now)
    records = engine.registry.records
    queued: list[Request] = []
    not_sent = 0
    for (motor, command), request, context in zip(items, requests, contexts, strict=True):
        if request is None:
            not_sent += 1
            engine.count(motor.codec, "skipped_streaming")
            context.set_exception(_streaming_error(motor, command))
            continue
        codec = motor.codec
        if motor.online is False:
            record = records[id(codec)]
            if now < record.probe_at:
                not_sent += 1
                engine.count(motor.codec, "skipped_offline")
                why = f"{motor!r} is offline ({record.misses} replies missed): not sent this tick"
                context.set_exception(MotorOffline(why))
                continue
            record.probe_at = now + probe_interval_s  # a probe: its reply brings the motor back
            engine.count(motor.codec, "probes")
        # (Engine.enqueue written out: a call less per request)
        if request.writes:
            known = records.get(id(codec))
            if known is not None and not known.commanded:
                engine.registry.command(motor)
        codec.note_sent(request.command)  # (the command sent: within the motor's limits)
        queued.append(request)
    submit_batch(scheduler, queued, now)
    engine.pump()
    return queued, not_sent


def _supersede(engine: Engine, codecs: set[int], now: float) -> None:
    """The pipelined requests to the motors of ``codecs`` still queued never leave: withdrawn."""
    scheduler = engine.scheduler
    stale = [r for r in scheduler.table.queue if r.pipelined and id(r.codec) in codecs]
    for request in stale:
        scheduler.cancel(request, now)
        engine.count(request.codec, "superseded")
        engine.settle(request, Superseded(f"{engine.name}: {request.describe()} superseded before it left"))


def _streaming_error(motor: Motor, command: Command) -> MotorStreaming:
    return MotorStreaming(f"{motor!r} streams and answers no {type(command).__name__}: not sent")
