"""What the bridge takes from a peer before it decodes anything: bytes per message on each key
(:func:`oversized`: a query's on Zenoh's thread, a set-point's as the loop takes it from Zenoh's
channel), and the queues, flights and rate of queries (``_queries``).

The byte limits come from the largest legitimate message. The largest command of any family, its
strings taken at 64 bytes (hollow's ``ModbusWrite`` carrying a ``HollowModel``), encodes in 183
bytes (myactuator ``MotionCommand`` 98, lk ``MultiMotorTorque`` 88); the largest reply in 191 (hollow
``ModbusReadReply``). A request or read is 26 bytes of header (version, kind, the 16-byte client id,
the f64 timeout) and one command: at most 209 bytes. A set-point message is 40 bytes of header
(version, kind, client id, u32 seq, u64 sent, u64 deadline, u16 count) and per motor its u16 id and
one command: at most 225 bytes for one motor, 47,400 for the 256 the wire allows in one batch.
tests/remote/test_wire.py computes these from the families' declarations and checks the margins.
"""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from servobus.remote._served import Served

#: ``request`` and ``read``: one command (at most 209 bytes), with room for a longer model name
REQUEST_BYTES = 1024
#: ``setpoint``: one motor's set-point (at most 225 bytes)
SETPOINT_BYTES = 1024
#: ``setpoints``: a batch of up to 256 set-points (at most 47,400 bytes)
SETPOINTS_BYTES = 65_536
#: ``info`` and ``metrics``: their payload is ignored; a client sends none
INFO_BYTES = 64

#: the most bytes a message may have, by its key's last segment
BYTES = {
    "request": REQUEST_BYTES,
    "read": REQUEST_BYTES,
    "setpoint": SETPOINT_BYTES,
    "setpoints": SETPOINTS_BYTES,
    "info": INFO_BYTES,
    "metrics": INFO_BYTES,
}

# Queries. A commander (a client whose liveliness token lives: ``request`` and ``read`` with its id)
# may pipeline a request to each of a bus's 32 motors at once, with as many more waiting; the bridge
# serves at most 64 commanders' queries at once, however many clients. A reader's queries (a ``read``
# or ``request`` of a client without a token, ``info``, ``metrics``) are few in normal use: a monitor
# reads states from the published ``state`` (no query); ``connect`` asks ``info`` once.

#: a commander's queries waiting / in flight, and all commanders' together
COMMANDER_WAITING, COMMANDER_RUNNING = 64, 32
COMMANDERS_WAITING, COMMANDERS_RUNNING = 256, 64
#: one reader's (one client id's, or all ``info``'s, or all ``metrics``') queries waiting / in flight
READER_WAITING, READER_RUNNING = 8, 2
#: all readers' queries waiting / in flight, and the most begun a second (in bursts of READ_BURST)
READERS_WAITING, READERS_RUNNING = 64, 4
READS_PER_S, READ_BURST = 100.0, 10
#: ``info`` (a client's ``connect`` asks it once): a class of its own, so that a flood of reads or
#: metrics never refuses a client its connection; waiting / in flight, begun a second (bursts)
INFO_WAITING, INFO_RUNNING = 16, 2
INFOS_PER_S, INFO_BURST = 50.0, 10

_lock = threading.Lock()  # (the counters are written by Zenoh's threads too)


def oversized(served: Served, key: str, payload: Any) -> bool:
    """(Zenoh's thread or the loop) Whether ``payload`` (a ``zenoh.ZBytes``: its length, no copy; or None) is
    too big for ``key``'s kind; one that is is counted ``oversized`` and is to be dropped."""
    size = 0 if payload is None else len(payload)
    if size <= BYTES.get(key.rsplit("/", 1)[-1], 0):
        return False
    with _lock:
        served.counts["oversized"] += 1
    return True


def count(served: Served, name: str) -> None:
    """(Any thread) Count one more ``name`` of ``served``."""
    with _lock:
        served.counts[name] += 1
