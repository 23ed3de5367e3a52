"""The bridge's stops (:class:`Stops`): a motor its client lost is released at once and sent its
safe command by a task.

A client loses a motor when it leaves (its liveliness token went), when its set-points stay stale
for the bridge's ``stop_after_s``, and when the bridge closes. Releasing runs on the loop, in the
step that decides it: the motor's set-point and holder go, and its holder's commands still queued
on the Bus are withdrawn before the stop is submitted (``_withdraw``). The safe commands go out in
a task of the bridge's group (:meth:`Stops.run`), each stop shielded and sent again until
acknowledged, as the Bus's own safe stop does.
"""

from __future__ import annotations

import logging
import math
import time
from collections import deque
from collections.abc import Iterable

import anyio
import anyio.abc

from servobus.bus import Motor
from servobus.bus.safety import stop_motors
from servobus.protocols import Command
from servobus.remote._served import Served
from servobus.remote._withdraw import withdraw

__all__ = ["LEFT", "Stops"]

logger = logging.getLogger("servobus.remote.bridge")

LEFT = "client left"  # why a motor is stopped when its client's token went


class Stops:
    """The motors to stop, waiting for the task that sends their safe commands, and the log of
    every stop (``log``: the bridge's ``stop_log``)."""

    def __init__(self, node: str) -> None:
        self.node = node
        self._queue, self._queued = anyio.create_memory_object_stream[tuple[Served, list[Motor]]](math.inf)
        self.log: deque[tuple[int, str, int, str]] = deque(maxlen=1000)  # (unix ns, bus, id, why)

    def stop(self, served: Served, motor_ids: Iterable[int], why: str) -> None:
        """Release the motors (set-points, holder) and send each its safe command, in a task."""
        motors = self.release(served, motor_ids, why)
        if motors:
            try:
                self._queue.send_nowait((served, motors))
            except (anyio.BrokenResourceError, anyio.ClosedResourceError):  # (closed: stopped on exit)
                logger.warning("%s/%s: the bridge is closed: no stop for %s", self.node, served.name, motors)

    def release(self, served: Served, motor_ids: Iterable[int], why: str) -> list[Motor]:
        """Release the motors, withdraw their holders' commands still queued (before the stop is
        submitted: they would follow it) and write down why they are stopped; the motors."""
        motors = [served.motors[mid] for mid in motor_ids]
        for motor in motors:
            withdraw(served, motor.motor_id, why, client_left=why == LEFT)
            served.release(motor.motor_id)
        if motors:
            served.counts["stops"] += len(motors)
            now = time.time_ns()
            self.log.extend((now, served.name, m.motor_id, why) for m in motors)
            ids = [m.motor_id for m in motors]
            logger.warning("%s/%s: stopping motors %s (%s)", self.node, served.name, ids, why)
        return motors

    async def run(self, group: anyio.abc.TaskGroup) -> None:
        """Start a task in ``group`` for each stop queued (:meth:`send`), until cancelled; the stops
        queued meanwhile still go."""
        async with self._queued:
            try:
                async for served, motors in self._queued:
                    group.start_soon(self.send, served, motors)
            finally:  # (cancelled: the stops queued meanwhile still go; send is shielded)
                while True:
                    try:
                        served, motors = self._queued.receive_nowait()
                    except (anyio.WouldBlock, anyio.EndOfStream):
                        break
                    group.start_soon(self.send, served, motors)

    async def send(self, served: Served, motors: list[Motor]) -> None:
        """The motors' safe commands, past the watchdog, again until acknowledged or the Bus's
        ``safe_timeout_s`` ended (what the Bus's own safe stop does); shielded."""
        commands: dict[Motor, Command] = {}
        for motor in motors:
            command = served.stop_commands[motor.motor_id]
            if command is not None:
                commands[motor] = command
        with anyio.CancelScope(shield=True):
            try:
                outcome = await stop_motors(served.bus, commands, served.bus.safe_timeout_s)
            except Exception:  # the bridge must outlive a stop that failed; it is logged
                logger.exception("%s/%s: the stop of %s failed", self.node, served.name, motors)
                return
        missing = [m.motor_id for m in commands if m not in outcome.acknowledged]
        if missing:
            logger.warning("%s/%s: motors %s did not acknowledge their stop", self.node, served.name, missing)
