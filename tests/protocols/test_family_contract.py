"""Every family's commands say their facts once, and every layer reads the same ones (issue [families]).

Across the built-in families and the plug-in ``servobus_toy`` (tests/plugins, registered by its
entry point): each command class declares its reply (``Command[R]``, or ``Command[None]`` with the
reason in ``NO_REPLY``); the bound codec's rules agree with the declarations (``retry_safe`` is
``READ``, no reply key exactly when no reply is declared); the typed motor has a method per command;
and the simulator, command line and DBC parts the family has load as their contracts' types. The
per-family ``test_declarations`` modules check the same facts deeper (every class, hypothesis-built
values, the simulated motor's answers).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import pytest

from servobus.protocols import FAMILIES, Command, Family, Reply, get_family

NAMES = [*sorted(FAMILIES), "toy"]


pytestmark = pytest.mark.usefixtures("toy")  # the plug-in installed (tests/_toy.py)


@pytest.fixture(params=NAMES)
def family(request: pytest.FixtureRequest) -> Family[Any]:
    return get_family(request.param)


def test_every_command_declares_its_reply_or_why_none_comes(family: Family[Any]) -> None:
    assert family.commands
    for cls in family.commands:
        assert cls.REPLY is not Reply, f"{cls.__name__} does not declare its reply type (Command[R])"
        assert (cls.REPLY is None) == (cls.NO_REPLY is not None), cls.__name__
        assert all(issubclass(r, Reply) for r in cls.reply_types()), cls.__name__
        assert isinstance(cls.READ, bool) and isinstance(cls.SLOW, bool), cls.__name__


def _default_instance(cls: type[Command]) -> Command | None:
    """``cls()`` where every field has a default (None where a field must be given)."""
    fields = [f for f in dataclasses.fields(cls) if f.init]  # type: ignore[arg-type]
    if any(f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING for f in fields):
        return None
    return cls()


def test_the_bound_codec_follows_the_declarations(family: Family[Any]) -> None:
    checked = 0
    for link in family.links:
        for revision in family.revisions:
            try:
                codec = family.bind(family.motor_ids[1], revision=revision, link=link)
            except ValueError:
                continue
            for cls in family.commands:
                command = _default_instance(cls)
                if command is None:
                    continue
                try:
                    codec.encode(command)
                    key = codec.reply_key(command)
                except ValueError:  # not on this link or revision: the codec says so
                    continue
                assert codec.retry_safe(command) is cls.READ, (cls.__name__, link, revision)
                assert (key is None) == (cls.REPLY is None), (cls.__name__, link, revision)
                checked += 1
    assert checked, f"{family.name}: no command could be checked"


def test_the_typed_motor_has_a_method_per_command(family: Family[Any]) -> None:
    assert family.motor is not None, f"{family.name} has no typed motor"
    motor = family.motor()
    for name, cls in family.methods().items():
        method = motor.__dict__.get(name)
        assert method is not None, f"{family.name}: no method {name} for {cls.__name__}"


def test_the_parts_load_as_their_contracts(family: Family[Any]) -> None:
    from servobus.cli.plugin import CliFamily
    from servobus.protocols.dbc import DbcFamily
    from servobus.sim.family import SimFamily

    kinds = {"sim": SimFamily, "cli": CliFamily, "dbc": DbcFamily}
    for part in family.parts:
        assert isinstance(family.part(part), kinds[part]), (family.name, part)
    if family.name in FAMILIES:  # every built-in family has all three
        assert set(family.parts) == set(kinds)


def test_a_command_says_its_reply_or_why_none_comes_not_both_or_neither() -> None:
    from dataclasses import dataclass

    from servobus.protocols.authoring import command_classes

    @dataclass(frozen=True)  # no slots: checked where the family lists its commands
    class Silent(Command[None]):
        pass

    @dataclass(frozen=True)
    class Both(Command[Reply]):
        NO_REPLY = "it restarts"

    for cls in (Silent, Both):
        with pytest.raises(TypeError, match=f"{cls.__name__}: a command declares a reply type or"):
            command_classes([cls])


def test_two_commands_with_one_method_name_are_refused() -> None:
    lk = get_family("lk")
    twin = type("ReadStatus1", (lk.commands[0],), {})  # another class, the same name
    copy = dataclasses.replace(lk, commands=(*lk.commands, twin), package=None)
    with pytest.raises(ValueError, match=r"lk: ReadStatus1 and ReadStatus1 are read_status1\(\)"):
        copy.methods()


def test_a_family_object_binds_without_being_registered() -> None:
    import asyncio

    from servobus import Bus
    from servobus.protocols import myactuator as ma
    from servobus.protocols.myactuator.sim import MyActuatorMotor
    from servobus.transports.sim import SimTransport

    unregistered = dataclasses.replace(ma.FAMILY, name="elsewhere")

    async def scenario() -> object:
        async with Bus(SimTransport(devices=[MyActuatorMotor(1)])) as bus:
            motor = bus.motor(unregistered, 1)
            return await motor.read_status1()

    assert isinstance(asyncio.run(scenario()), ma.Status1Reply)
