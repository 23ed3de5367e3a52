"""Every installed family keeps the family contract, and the contract's own rules (issues [families], 42).

The contract is servobus.testing's :class:`~servobus.testing.FamilyContract`, which a plug-in
family's package runs against its own ``FAMILY``; here it runs over every family installed where the
suite runs (found by ``available_families()``, the entry points: the built-ins, the plug-in
``servobus_toy`` of tests/plugins, and any other): the declarations, encode/decode round trips, the
bound codec's rules, the simulated motor answering its codec, the CLI and DBC parts. The per-family
``test_declarations`` modules check the same facts deeper for the built-ins (every class,
hand-written strategies). Below it, the rules the contract's pieces enforce themselves.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import pytest

from _toy import installed
from servobus.protocols import FAMILIES, Command, Family, Reply, available_families, get_family
from servobus.protocols import hollow as ho
from servobus.testing import FamilyContract, Strategies, message_classes

# Every family installed where the suite runs: the built-ins, the toy plug-in (its folder put on
# sys.path as installing it would) and any other distribution registering ``servobus.families``.
with installed():
    NAMES = sorted(available_families())

#: message classes of the built-in families the contract's strategies do not reach (a motor model or
#: a parameter chosen by name in a required field, a bit-packed or serial-only frame): their own
#: tests (tests/protocols/<family>/) draw them with hand-written strategies
BUILT_IN_UNBUILT = {
    "myactuator": frozenset({"MotionCommand", "Echo", "MotionReply"}),
    "lk": frozenset(
        {
            "WriteEncoderOffset",
            "MultiMotorTorque",
            "SpeedControl",
            "TorqueControl",
            "ReadParam",
            "WriteParamRam",
            "WriteParamRom",
            "ReadControlParam",
            "ReadSetting",
            "WriteControlParam",
            "WriteSetting",
            "Status1Reply",
            "Status1ReplyV235",
            "EchoReply",
            "AccelerationReply",
            "EncoderReply",
            "Status2Reply",
            "Status3Reply",
            "Status3ReplyV235",
            "EncoderOffsetReply",
            "ParamReply",
            "ParamWriteReply",
            "ControlParamReply",
            "SettingReply",
            "SaveSettingsReply",
        }
    ),
    "hollow": frozenset(
        {
            "CanModeSwitch",
            "IncrementalSetpoint",  # (HOLLOW_CONTEXT)
            "NormalReply",
            "ExtendedReply",
            "FdReply",
            "PiMultiplier",
            "ModbusRead",
            "ModbusWrite",
            "ModbusReadReply",
            "ModbusException",
            "ModbusWriteAck",
        }
    ),
}


#: hollow's bit layouts whose round trip needs what a drawn value lacks, left to tests/protocols/hollow:
#: the motor's CAN mode, not the bytes, tells an incremental setpoint from a setpoint, and the
#: replies are told apart by the mode and link of the motor that sent them
HOLLOW_CONTEXT: Strategies = dict.fromkeys(
    (ho.IncrementalSetpoint, ho.NormalReply, ho.ExtendedReply, ho.FdReply)
)


pytestmark = pytest.mark.usefixtures("toy")  # the plug-in installed (tests/_toy.py)


@pytest.fixture(params=NAMES)
def family(request: pytest.FixtureRequest) -> Family[Any]:
    return get_family(request.param)


class TestEveryInstalledFamily(FamilyContract):
    """servobus.testing's contract, run over every installed family (a plug-in's package runs the
    same class against its own FAMILY)."""

    @pytest.fixture
    def contract_family(self, family: Family[Any]) -> Family[Any]:
        return family

    @pytest.fixture
    def contract_strategies(self, family: Family[Any]) -> Strategies:
        return HOLLOW_CONTEXT if family.name == "hollow" else {}

    @pytest.fixture
    def contract_unbuilt_ok(self, family: Family[Any]) -> frozenset[str]:
        return BUILT_IN_UNBUILT.get(family.name, frozenset())


def test_the_suite_checks_the_built_ins_the_toy_and_whatever_else_is_installed() -> None:
    assert set(FAMILIES) | {"toy"} <= set(NAMES)


def test_the_built_ins_unbuilt_lists_name_real_classes() -> None:
    """A class renamed or gone is taken off BUILT_IN_UNBUILT (so the list never excuses a new one)."""
    for name, unbuilt in BUILT_IN_UNBUILT.items():
        assert unbuilt <= {cls.__name__ for cls in message_classes(get_family(name))}, name


def test_the_parts_load_as_their_contracts(family: Family[Any]) -> None:
    from servobus.protocols.cli import CliFamily
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
