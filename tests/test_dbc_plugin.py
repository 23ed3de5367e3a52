"""servobus.dbc on a family it has never heard of: ``servobus_toy`` (tests/plugins/, registered by entry
point) has no dbc part, so its DBC is derived from its classes' declarations (``CODE``, ``FIELDS``,
``reply_types()``) and its bound codec's identifiers; cantools decodes every frame of its codec as
servobus does. The contract a family's dbc part meets (``DbcFamily``) is checked on the built-in ones.
"""

from __future__ import annotations

import dataclasses
import os
import re
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import cantools
import pytest

from _dbc_check import check_frame
from _toy import PLUGINS, SERVOBUS
from servobus.protocols import get_family
from servobus.protocols._bound import EXTENDED
from servobus.protocols.dbc import DbcFamily, DbcOption, DbcQuery, Described, Layout, dbc_part
from servobus.tools.dbc import database, dbc_text, plan


def toy_commands(toy: ModuleType) -> list[Any]:
    return [
        toy.ReadState(),
        toy.SetSpeed(speed_dps=-12.34),
        toy.SetSpeed(speed_dps=1000.0),
        toy.Stop(),
        toy.WriteSpeedLimit(limit_dps=50.0),
        toy.Restart(),
    ]


def toy_replies(toy: ModuleType) -> list[Any]:
    return [
        toy.StateReply(position_deg=-1234.56, speed_dps=99.9, faults=toy.ToyFaults.STALL),
        toy.StateReply(position_deg=0.0, speed_dps=-3276.8),
        toy.SpeedLimitEcho(limit_dps=1000.0),
    ]


def test_a_plug_in_family_without_a_dbc_part_gets_one_derived_from_its_declarations(toy: ModuleType) -> None:
    family = get_family("toy")
    assert "dbc" not in family.parts and dbc_part(family) == DbcFamily()
    p = plan("toy", [1, 2])
    assert [(m.name, m.kind, m.frame_id) for m in p.messages] == [
        ("toy_request_1", "request", 0x601),
        ("toy_reply_1", "reply", 0x681),
        ("toy_request_2", "request", 0x602),
        ("toy_reply_2", "reply", 0x682),
    ]
    assert p.left_out == () and p.nodes == ("host", "motor_1", "motor_2")
    db = cantools.database.load_string(dbc_text(database(p)), "dbc")
    request = db.get_message_by_name("toy_request_2")
    assert request.get_signal_by_name("code").choices[0x20] == "SetSpeed"
    speed = request.get_signal_by_name("speed_dps")  # SetSpeed's ScaledField: int32 0.01 dps, ±1000
    assert (speed.start, speed.length, speed.is_signed, speed.scale, speed.unit) == (
        8,
        32,
        True,
        0.01,
        "deg/s",
    )
    assert (speed.minimum, speed.maximum) == (-1000, 1000)
    codec = family.bind(2)
    checked = 0
    for command in toy_commands(toy):
        frame = codec.encode(command)
        spec = next(m for m in p.messages if m.frame_id == frame.arbitration_id)
        check_frame(spec, db, frame.data, family.decode_request(frame.arbitration_id, frame.data))
        checked += 1
    reply_spec = next(m for m in p.messages if m.name == "toy_reply_2")
    for reply in toy_replies(toy):
        data = reply.encode()
        check_frame(reply_spec, db, data, family.decode_reply(reply_spec.frame_id, data))
        checked += 1
    assert checked == 9
    assert [m.kind for m in plan("toy", [3], direction="reply").messages] == ["reply"]


def test_a_plug_in_family_takes_no_option_of_another_and_no_id_outside_its_own(toy: ModuleType) -> None:
    with pytest.raises(ValueError, match="can_mode is an option of hollow, not of toy"):
        plan("toy", [1], can_mode="fd")
    family = get_family("toy")
    with pytest.raises(ValueError, match="motor_id"):
        plan("toy", [family.motor_ids[-1] + 1])


class _Ids:
    """What :func:`servobus.dbc.derived` reads of a bound codec: its identifiers."""

    def __init__(self, request_ids: set[int], reply_ids: set[int]) -> None:
        self.request_ids, self.reply_ids = frozenset(request_ids), frozenset(reply_ids)


def test_derived_messages_follow_the_bound_codecs_identifiers(toy: ModuleType) -> None:
    """One reply identifier for every motor is one message sent by all; an identifier both ways holds
    the replies unless the requests are asked for (and says so); a 29-bit identifier is extended."""
    family = get_family("toy")
    host = dataclasses.replace(family, bind=lambda motor_id, **_: _Ids({motor_id}, {100}))
    p = plan(host, [1, 2])
    assert [(m.name, m.frame_id, m.senders) for m in p.messages] == [
        ("toy_request_1", 1, ("host",)),
        ("toy_reply", 100, ("motor_1", "motor_2")),
        ("toy_request_2", 2, ("host",)),
    ]
    same = dataclasses.replace(family, bind=lambda motor_id, **_: _Ids({motor_id}, {motor_id}))
    p = plan(same, [3])
    assert [(m.name, m.kind) for m in p.messages] == [("toy_reply_3", "reply")]
    assert p.left_out and "direction 'request'" in p.left_out[0]
    assert [(m.name, m.kind) for m in plan(same, [3], direction="request").messages] == [
        ("toy_request_3", "request")
    ]
    extended = dataclasses.replace(
        family, bind=lambda motor_id, **_: _Ids({EXTENDED | 0x1000 | motor_id}, {0x700 + motor_id})
    )
    request, reply = plan(extended, [4]).messages
    assert (request.frame_id, request.extended, reply.frame_id, reply.extended) == (
        0x1004,
        True,
        0x704,
        False,
    )
    db = cantools.database.load_string(dbc_text(database(plan(extended, [4]))), "dbc")
    assert db.get_message_by_frame_id(0x1004).is_extended_frame


def test_a_dbc_part_gets_its_options_and_the_query(toy: ModuleType) -> None:
    """A part's ``describe`` gets the family, the ids once each, the revision asked for (None: its
    choice), the options given (parsed by the command line's ``-O``) and the direction."""
    family = get_family("toy")
    seen: list[DbcQuery] = []

    def describe(query: DbcQuery) -> Described:
        seen.append(query)
        return dataclasses.replace(DbcFamily().describe(query), left_out=("because",))

    part = DbcFamily(options=(DbcOption(name="gain", help="a gain", parse=float),), describe=describe)
    module = ModuleType("toy_dbc_part")
    module.DBC = part  # type: ignore[attr-defined]
    sys.modules["toy_dbc_part"] = module
    try:
        with_part = dataclasses.replace(family, parts={**family.parts, "dbc": "toy_dbc_part:DBC"})
        p = plan(with_part, [2, 1, 2], "V1", direction="request", gain=2.5, absent=None)
        assert seen[0].ids == (2, 1) and seen[0].revision is family.revisions[0]
        assert seen[0].options == {"gain": 2.5} and seen[0].direction == "request"
        assert [m.name for m in p.messages] == ["toy_request_2", "toy_request_1"] and p.left_out == (
            "because",
        )
        with pytest.raises(ValueError, match="max_torque_nm is an option of myactuator, not of toy"):
            plan(with_part, [1], max_torque_nm=3.0)
    finally:
        del sys.modules["toy_dbc_part"]


@pytest.mark.parametrize("name", ["myactuator", "lk", "hollow"])
def test_the_built_in_families_state_their_dbc_in_their_dbc_part(name: str) -> None:
    part = dbc_part(get_family(name))
    assert isinstance(part, DbcFamily) and part.describe is not DbcFamily().describe
    assert all(option.name.isidentifier() and option.help for option in part.options)


def _messages(layout: Layout, out: set[str]) -> set[str]:
    if layout.message:
        out.add(layout.message)
    for sub in layout.mux.layouts if layout.mux else ():
        _messages(sub, out)
    return out


#: The DBCs that together hold every frame a family has on CAN (one per CAN mode, per direction where
#: a revision's requests and replies share an identifier).
ALL_FRAMES: dict[str, list[dict[str, Any]]] = {
    "lk": [{"direction": "request"}, {"direction": "reply"}],
    "hollow": [{"can_mode": mode} for mode in ("normal", "extended", "fd")],
}


@pytest.mark.usefixtures("toy")
@pytest.mark.parametrize("name", ["myactuator", "lk", "hollow", "toy"])
def test_every_declared_command_and_reply_is_in_the_dbc_or_left_out_by_name(name: str) -> None:
    """Each command class of each revision, and each reply it declares, is the class a layout of the
    DBC decodes to (Echo for an echoed command), or the left-out list names it with the reason."""
    family = get_family(name)
    for revision in family.revisions:
        found: set[str] = set()
        left_out: list[str] = []
        for options in ALL_FRAMES.get(name, [{}]):
            p = plan(family, [1], revision, **options)
            for message in p.messages:
                _messages(message.root, found)
            left_out += p.left_out
        commands = [c for c in family.commands if revision in getattr(c, "REVISIONS", (revision,))]
        replies = [r for c in commands for r in c.reply_types()]
        for cls in dict.fromkeys((*commands, *replies)):
            if revision not in getattr(cls, "REVISIONS", (revision,)) or cls.__name__ in found:
                continue
            if cls.__name__ == "Echo":  # a command's echo: in the DBC as Echo_<command>
                continue
            named = [r for r in left_out if re.search(rf"\b{cls.__name__}\b", r)]
            assert named, f"{name} {revision.name}: {cls.__name__} is neither in the DBC nor left out"


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    path = os.pathsep.join(p for p in (str(PLUGINS), os.environ.get("PYTHONPATH")) if p)
    return subprocess.run(
        [*SERVOBUS, *args],
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, "PYTHONPATH": path},
        check=False,
    )


def test_servobus_dbc_family_toy_writes_the_derived_dbc(tmp_path: Path) -> None:
    out = tmp_path / "toy.dbc"
    done = run_cli("dbc", "--family", "toy", "--ids", "1-3", "-o", str(out))
    assert done.returncode == 0, done.stderr
    assert done.stderr == "dbc: 6 messages -> " + str(out) + "; nothing left out\n"
    db = cantools.database.load_file(str(out))
    assert [m.name for m in db.messages][:2] == ["toy_request_1", "toy_reply_1"]
    done = run_cli("dbc", "--family", "toy", "-O", "can_mode=fd")
    assert done.returncode == 2 and "can_mode is an option of hollow, not of toy" in done.stderr
