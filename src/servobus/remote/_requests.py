"""A bridge's answer to one query on ``servobus/N/B/M/request`` or ``.../read`` (:func:`answer`):
the command decoded by its family's declarations, checked against who may send it, run through the
Bus, and its typed reply or error encoded back; every failure is an answer, never a silent client."""

from __future__ import annotations

import logging
from typing import Any

import anyio

from servobus import runtime
from servobus.bus import Motor
from servobus.errors import ServobusError
from servobus.limits import LimitExceeded
from servobus.remote import wire
from servobus.remote._clients import Clients, safe_done
from servobus.remote._served import Served
from servobus.remote._withdraw import Withdrawn
from servobus.remote.keys import Keys

logger = logging.getLogger("servobus.remote.bridge")


async def answer(served: Served, query: Any, keys: Keys, clients: Clients) -> None:
    """Answer ``query`` (one of ``served``'s motors' ``request`` or ``read``), then end it."""
    try:
        schema, result = await _outcome(served, query, keys, clients)
    except BaseException:  # cancelled (the bridge is closing): answered nothing, at once
        finish(query)
        raise
    if isinstance(result.error, Withdrawn) and result.error.client_left:
        finish(query)  # (no answer to a client that is gone: no worker thread ahead of its stop)
        return
    try:
        payload = wire.encode_result(schema, result)
    except wire.WireError as exc:  # (a plug-in's reply with a value the encoding has no form for)
        logger.warning("%s: the reply cannot be encoded: %s", query.key_expr, exc)
        payload = wire.encode_result(schema, wire.Result(error=ServobusError(f"reply not encodable: {exc}")))
    await reply(query, str(query.key_expr), payload)


async def _outcome(
    served: Served, query: Any, keys: Keys, clients: Clients
) -> tuple[wire.Schema, wire.Result]:
    """The result of the query, and the schema to encode it with."""
    schema = next(iter(served.schemas.values()))  # (for an error before the motor is known)
    try:
        try:
            bus, mid, leaf = keys.parse_motor(str(query.key_expr))
        except ValueError as exc:  # a client's key (servobus/N/B/x/request): malformed, not a bug
            raise wire.WireError(str(exc)) from None
        motor = served.motors.get(mid)
        if bus != served.name or motor is None:  # (servobus/N/*/3/request: one motor per request)
            raise wire.WireError(f"no motor {mid} on bus {served.name}")
        schema = served.schemas[mid]
        payload = query.payload
        request = wire.decode_request(schema, payload.to_bytes() if payload is not None else b"")
        return schema, await _run(served, motor, leaf, request, clients)
    except wire.WireError as exc:
        served.counts["malformed"] += 1
        return schema, wire.Result(error=ValueError(f"malformed request: {exc}"))
    except PermissionError as exc:
        served.counts["refused"] += 1
        return schema, wire.Result(error=exc)
    except Exception as exc:  # a bug must not leave the client waiting; it is logged here
        logger.exception("%s: request failed", query.key_expr)
        return schema, wire.Result(error=exc)


async def _run(
    served: Served, motor: Motor, leaf: str, request: wire.Request, clients: Clients
) -> wire.Result:
    """Run one request through the Bus; the Bus's error as a value.

    Raises:
        PermissionError: a command through ``read``, a client without a token, a motor another live
            client holds.
    """
    command, mid = request.command, motor.motor_id
    safe = leaf == "request" and command in served.safe_commands[mid]
    if leaf == "read":
        served.counts["reads"] += 1
        if not type(command).READ:
            raise PermissionError(f"{type(command).__name__} is not a read: send it as a request")
    else:
        served.counts["requests"] += 1
        clients.command(served, mid, request.client_id, command)
    commanded = served.commanded[mid]  # (for a stop: whether a command followed it, at safe_done)
    try:
        reply = await served.bus.request(motor, command, timeout_s=request.timeout_s)
    except Withdrawn as exc:  # (its client lost the motor while it was queued: counted withdrawn)
        return wire.Result(error=exc)
    except LimitExceeded as exc:  # (the Bus counts it too: limit_refused)
        served.counts["limited"] += 1
        return wire.Result(error=exc)
    except ServobusError as exc:
        if safe:
            safe_done(served, mid, request.client_id, False, runtime.current().time(), commanded)
        return wire.Result(error=exc)
    if safe:
        safe_done(served, mid, request.client_id, True, runtime.current().time(), commanded)
    return wire.Result(reply=reply)


def finish(query: Any) -> None:
    """No more answers to ``query``: the client's get ends now (not at its timeout)."""
    query.drop()


async def reply(query: Any, key: str, payload: bytes) -> None:
    """Answer ``query`` and end it, on a worker thread: Zenoh's reply follows the congestion control
    the querier chose, and one that blocks (a client that reads no more) must not block the loop."""

    def send() -> None:
        try:
            query.reply(key, payload)
        except Exception:  # the client went away meanwhile
            logger.debug("reply to %s failed", key, exc_info=True)
        finally:
            query.drop()

    with anyio.CancelScope(shield=True):  # (answered once begun: a cancelled task still ends it)
        await anyio.to_thread.run_sync(send)
