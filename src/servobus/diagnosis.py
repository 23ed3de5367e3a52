"""What a bus saw instead of a reply: "no reply" is rarely all there is to say.

A motor of the wrong family, motors at other ids, and a dead line (wrong bit rate, wiring, a missing
terminator, another program on the port) all look like a silent motor. Two parts tell them apart:

* :class:`Seen`, sans-IO, fed by the scheduler with every frame no motor of the bus claims (counted
  ``foreign``; never on a reply's path): per arbitration id, how many came since it was first seen,
  when, and the last one.
  Bounded (the ids seen last), O(1) per frame.
* :func:`diagnose`, run only when a request times out (or ``servobus scan`` found nobody): for a
  silent motor, one line saying what came instead: frames of **another family** on its ids (each
  registered family is asked whether the frame is its reply for that motor id: families are
  plug-ins, none is named here), frames on **other ids** (and whose motors would send them, or
  another host's requests to them), or **nothing at all**. :func:`explain` says it for the whole
  bus.

A family is asked through its family-level reply decoder (``Family.decode_reply``: tens of µs), and
only where a frame's id fits the offsets between its motors' ids and their reply ids (read once from
one bound motor per revision: binding costs up to ms).
"""

from __future__ import annotations

import functools
from collections import defaultdict
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from enum import Enum

from servobus.frame import Frame
from servobus.protocols import BoundCodec, Family, available_families, get_family
from servobus.protocols._bound import KIND_NOT_OURS

__all__ = ["NOTHING_AT_ALL", "Seen", "SeenId", "diagnose", "explain"]

_ID_MASK = 0x1FFFFFFF

#: what a silent line is told (no frame of any kind came)
NOTHING_AT_ALL = "no frame at all: check bitrate, wiring and termination, or another program on the port"


class SeenId:
    """The frames seen on one arbitration id: how many, the first and last time, the last one."""

    __slots__ = ("count", "first_at", "frame", "last_at")

    def __init__(self, frame: Frame, now: float) -> None:
        self.count = 0
        self.first_at = now
        self.last_at = now
        self.frame = frame


class Seen:
    """Frames of no motor of the bus, per arbitration id (the ``limit`` ids seen last)."""

    __slots__ = ("ids", "limit")

    def __init__(self, limit: int = 64) -> None:
        self.ids: dict[int, SeenId] = {}  # in the order they were last seen: the oldest first
        self.limit = limit

    def note(self, frame: Frame, now: float) -> None:
        ids = self.ids
        entry = ids.pop(frame.arbitration_id, None)
        if entry is None:
            if len(ids) >= self.limit:
                del ids[next(iter(ids))]
            entry = SeenId(frame, now)
        entry.count += 1
        entry.last_at = now
        entry.frame = frame
        ids[frame.arbitration_id] = entry

    def since(self, at: float) -> list[SeenId]:
        """The ids seen at ``at`` or later, by id."""
        return sorted((e for e in self.ids.values() if e.last_at >= at), key=lambda e: e.frame.arbitration_id)


# ---- what the families say ----


@functools.lru_cache(maxsize=1)
def _families() -> tuple[Family, ...]:
    """The registered families, loaded once (looking up plug-ins reads every installed package's
    metadata: tens of ms)."""
    found = []
    for name in available_families():
        try:
            found.append(get_family(name))
        except Exception:  # (a plug-in that does not load is no witness)
            continue
    return tuple(found)


@functools.lru_cache(maxsize=128)
def _bound(family: str, revision: str, motor_id: int) -> BoundCodec | None:
    found = get_family(family)
    if motor_id not in found.motor_ids:
        return None
    try:
        return found.bind(motor_id, revision=found.revision(revision))
    except Exception:  # (an id or revision this family's CAN codec refuses: no witness)
        return None


@dataclass(frozen=True)
class _Ids:
    """A family revision's identifiers, from one motor's codec: the offsets ``reply id - motor id``
    and ``request id - motor id`` of its motors, and the ids all of them share (a host id)."""

    replies: tuple[int, ...] = ()
    requests: tuple[int, ...] = ()
    shared: frozenset[int] = frozenset()


@functools.lru_cache(maxsize=64)
def _ids(family: str, revision: str) -> _Ids:
    ids = get_family(family).motor_ids
    reference = 1 if 1 in ids else ids[0]
    codec = _bound(family, revision, reference)
    if codec is None:
        return _Ids()
    return _Ids(
        tuple(sorted({(i & _ID_MASK) - reference for i in codec.reply_ids})),
        tuple(sorted({(i & _ID_MASK) - reference for i in codec.request_ids})),
        frozenset(i & _ID_MASK for i in codec.shared_ids),
    )


def _decodes(family: Family, revision: Enum, frame: Frame) -> bool:
    """Whether ``frame`` is a reply of ``family`` in ``revision`` (its family-level decoder: no
    motor's codec to bind, which costs up to ms)."""
    try:
        family.decode_reply(frame.arbitration_id, frame.data, revision=revision)
    except Exception:
        return False
    return True


def _as_motor(frame: Frame, motor_id: int, skip: tuple[str, str]) -> tuple[str, str] | None:
    """(family, revision) whose motor ``motor_id`` would send ``frame`` (not ``skip``'s), or None."""
    fid = frame.arbitration_id
    for family in _families():
        for revision in family.revisions:
            if (family.name, revision.name) == skip:
                continue
            ids = _ids(family.name, revision.name)
            if any(fid == motor_id + o for o in ids.replies):
                if _decodes(family, revision, frame):
                    return family.name, revision.name
            elif fid in ids.shared:  # (a host id: which motor is in the data, as its codec reads it)
                codec = _bound(family.name, revision.name, motor_id)
                try:
                    if codec is not None and codec.classify(frame)[0] is not KIND_NOT_OURS:
                        return family.name, revision.name
                except Exception:
                    continue
    return None


def _sender(frame: Frame, prefer: str | None) -> tuple[str, str, int] | None:
    """(family, revision, motor id) of a motor that would send ``frame`` (``prefer``'s family
    first), from the offsets between motor and reply ids; None when none would."""
    families = sorted(_families(), key=lambda f: f.name != prefer)
    for family in families:
        for revision in family.revisions:
            for offset in _ids(family.name, revision.name).replies:
                motor_id = frame.arbitration_id - offset
                if motor_id in family.motor_ids and _decodes(family, revision, frame):
                    return family.name, revision.name, motor_id
    return None


# ---- the words ----


def _span(values: Iterable[int], form: Callable[[int], str] = str) -> str:
    """``1-4, 7`` (runs of consecutive values joined)."""
    runs: list[list[int]] = []
    for value in sorted(set(values)):
        if runs and value == runs[-1][-1] + 1:
            runs[-1].append(value)
        else:
            runs.append([value])
    return ", ".join(form(r[0]) if len(r) == 1 else f"{form(r[0])}-{form(r[-1])}" for r in runs)


def _motors(family: str, ids: Iterable[int]) -> str:
    """``lk motor 5`` or ``lk motors 1-2``."""
    ids = set(ids)
    return f"{family} motor{'s' if len(ids) > 1 else ''} {_span(ids)}"


def _hex(value: int) -> str:
    return f"0x{value:03X}"


def _frames(entries: list[SeenId]) -> str:
    count = sum(e.count for e in entries)
    ids = _span((e.frame.arbitration_id for e in entries), _hex)
    return f"{count} frame{'s' if count != 1 else ''} on {ids}"


def _revision_hint(family: str, revision: str) -> str:
    default = get_family(family).default_revision.name
    return f"--family {family}" + ("" if revision == default else f" --revision {revision}")


def _senders(entries: list[SeenId], expected: str | None) -> dict[int, tuple[str, str, int] | None]:
    return {e.frame.arbitration_id: _sender(e.frame, expected) for e in entries}


def _requests(senders: dict[int, tuple[str, str, int] | None]) -> dict[int, tuple[str, str, int]]:
    """The ids that are the requests of motors whose replies came on other ids: another host asks
    them (a frame on a request id can look like a reply where a revision answers on that id)."""
    asked: dict[int, tuple[str, str, int]] = {}
    for ident, sender in senders.items():
        if sender is not None:
            for offset in _ids(*sender[:2]).requests:
                request_id = sender[2] + offset
                if request_id != ident and request_id in senders:
                    asked[request_id] = sender
    return asked


def explain(entries: list[SeenId], expected: str | None = None) -> str | None:
    """What frames of no motor of the bus were, in one line: whose motors would send them (grouped by
    family and revision; ``expected``, the family looked for, is tried first), another host's
    requests to them, and the ids nobody's motor would use; None for no entries."""
    if not entries:
        return None
    senders = _senders(entries, expected)
    asked = _requests(senders)
    requests: dict[tuple[str, str], list[tuple[SeenId, int]]] = defaultdict(list)
    groups: dict[tuple[str, str], list[tuple[SeenId, int]]] = defaultdict(list)
    unknown: list[SeenId] = []
    for entry in entries:
        ident = entry.frame.arbitration_id
        sender = senders[ident]
        if ident in asked:
            requests[asked[ident][:2]].append((entry, asked[ident][2]))
        elif sender is None:
            unknown.append(entry)
        else:
            groups[sender[:2]].append((entry, sender[2]))
    said = []
    for (family, _), found in requests.items():
        motors = _motors(family, (m for _, m in found))
        said.append(f"{_frames([e for e, _ in found])}: another host's requests to {motors}")
    for (family, revision), found in groups.items():
        ids = _span(m for _, m in found)
        motors = _motors(family, (m for _, m in found))
        seen = _frames([e for e, _ in found])
        if family == expected:
            said.append(f"{seen}, as {motors} would answer: other ids (--ids {ids})?")
        else:
            hint = _revision_hint(family, revision)
            said.append(f"{seen} answered as {motors} ({revision}) would: {hint}?")
    if unknown:
        said.append(f"{_frames(unknown)}, which no known family's motor sends")
    return "; ".join(said)


def diagnose(
    codec: BoundCodec,
    seen: Seen,
    since: float,
    *,
    heard: bool,
    sent: Frame | None = None,
) -> str:
    """What came instead of ``codec``'s motor's reply since ``since``, in one line.

    Args:
        codec: the silent motor's codec.
        seen: the bus's record of frames of no motor.
        since: when the request that got no reply left.
        heard: whether any motor of the bus sent a frame since then.
        sent: the request's frame (an adapter that echoes our own frames is not a witness).
    """
    entries = [
        e
        for e in seen.since(since)
        if sent is None or (e.frame.arbitration_id, e.frame.data) != (sent.arbitration_id, sent.data)
    ]
    if not entries:
        if heard:
            return f"other frames came, none from motor {codec.motor_id}: check its id, power and wiring"
        return NOTHING_AT_ALL
    ours = (codec.family, codec.revision.name)
    asked = _requests(_senders(entries, codec.family))
    for entry in entries:
        if entry.frame.arbitration_id in asked:
            continue  # (another host's request, not a reply)
        other = _as_motor(entry.frame, codec.motor_id, ours)
        if other is not None:
            family, revision = other
            return (
                f"{_hex(entry.frame.arbitration_id)} answered as {family} ({revision}) would: "
                f"{_revision_hint(family, revision)}?"
            )
    said = explain(entries, codec.family)
    assert said is not None
    return said
