"""The Bus: one physical bus, its motors, and every request's life on it (:class:`Bus`).

``from servobus.bus import Bus, Motor, MotorStatus, FrameLink`` (``servobus.Bus`` is the same);
:mod:`servobus.bus.core` tells what a Bus does. Its modules, each the one owner of its state:

* ``core``: :class:`Bus`, the user's object: life cycle (the task group, SIGTERM, the safe stop),
  ``motor()``, ``request``, ``cycle``, ``broadcast``; it routes, it keeps no per-motor state.
* ``motor``: :class:`Motor` (what a user holds), :class:`~servobus.bus.motor.MotorRecord` (what the
  Bus knows of a motor: misses, probe time, remembered replies, stream endings, watchers, whether
  commanded), and :class:`~servobus.bus.motor.Registry` (one record per motor, keyed once, by codec).
* ``engine``: :class:`~servobus.bus.engine.Engine`, the ONE object that talks to the scheduler and
  the link (the tick, single requests, broadcasts, the safe stop and the intake all go through its
  public methods); its :class:`~servobus.bus.engine.Timer` and ``LinkKeeper``.
* ``tick``: a cycle's one waiter (``Tick``, ``Slot``) and how its items are sorted (``triage``).
* ``delivery``: a judged frame to its motor and its request's waiter; ``events``: what a motor
  tells of itself (0xF1) and echoed commands; ``watchdog``: online/offline; ``restarts``: a motor
  back online checked for a restart; ``safety``: the safe stop; ``broadcast``: one frame, many motors;
  ``pipeline``: one bus's batch of a pipelined tick (servobus.loop), sent without waiting.

One control tick, ``await bus.cycle([(motor, command), ...])`` of 32 motors, from the Bus to the link
and back (``tests/bus/test_tick_path.py`` traces it; the family's codec and ``servobus.frame``, the
link's currency, aside):

1. ``servobus.bus.core``: ``Bus.cycle`` checks the loop (one C call on asyncio) and calls
   ``Engine.cycle`` once.
2. ``servobus.bus.engine``: ``Engine.cycle`` makes the tick's waiter and has each item sorted;
3. ``servobus.bus.tick``: ``triage`` gives each item a ``Slot`` of the ``Tick`` and has the engine
   prepare its request (``Engine.prepare`` -> ``Scheduler.request``: the codec encodes the frame);
   an offline, busy or streaming motor's slot gets its outcome at once;
4. the scheduler (``servobus.scheduler._scheduler``, its request table ``_table``):
   ``Engine.enqueue`` -> ``Scheduler.submit``, then ``Engine.pump`` -> ``Scheduler.poll``
   (pacing: the table moves each request to SENDING), and the engine hands each frame to the link:
   ``link.send(frame, request)``. The link's send report comes back to ``Engine.on_report`` ->
   ``Scheduler.sent``: the table moves the request to SENT and its deadline starts, its timeout
   taken from the round-trip estimates (``servobus.rtt``).
5. Back: the link hands its frames to ``Engine.on_frames`` -> ``Scheduler.receive`` (matching,
   ``servobus.scheduler._match``: the reply is decoded and paired with its request; its round
   trip goes to the estimates) -> ``servobus.bus.delivery``:
   ``Delivery.deliver`` (the motor's state, record, watchers, subscribers) -> ``Delivery.settle``
   -> ``Slot.set_result`` (``servobus.bus.tick``): the last one wakes ``Bus.cycle``, once.

8 modules in all: the bus side's 4 (core, engine, tick, delivery) and the scheduler's 4
(``servobus.scheduler._scheduler``, ``._table``, ``._match`` and ``servobus.rtt``).
No call into ``servobus.runtime``, ``servobus.bus.watchdog`` (only on a miss or a motor's return) or
``servobus.bus.motor`` (records are read as data) on the way.

What this layer may import (``tests/test_layering.py``): servobus's base modules (errors, frame,
runtime, metrics, ...), the protocol contracts and families (a family's typed motor), the scheduler
and the transports' contract; never the simulator, the remote bridge, the tools or the command line.
Inside the package each module imports only those below it: motor; tick, watchdog; events;
delivery; engine; broadcast, safety, restarts, pipeline; core (no cycle: ``tests/bus/test_records.py``).
"""

from servobus.bus.core import Bus
from servobus.bus.motor import Motor, MotorFrames, command_classes
from servobus.bus.watchdog import MotorStatus
from servobus.transports.contract import FrameLink

__all__ = ["Bus", "FrameLink", "Motor", "MotorFrames", "MotorStatus", "command_classes"]
