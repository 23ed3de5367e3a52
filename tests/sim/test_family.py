"""The simulator part of a family (``FAMILY.part("sim")``, :class:`servobus.sim.family.SimFamily`): what
each built-in part declares agrees with its family, its generic refusals are one line naming the flag,
and the devices it builds serve every medium it declares, through the in-process bus."""

from __future__ import annotations

import asyncio
from collections.abc import Sequence
from enum import Enum

import pytest

from servobus.bus import Bus
from servobus.protocols import FAMILIES, get_family
from servobus.protocols import hollow as ho
from servobus.sim import virtual
from servobus.sim.family import MEDIA, OPTIONS, Setup, SimFamily, SimOptions, offered_by
from servobus.transports.sim import SimTransport

looptime = pytest.mark.looptime(noop_cycles=virtual.NOOP_CYCLES)


class Plain(SimFamily):
    """A part with nothing but the generic rules (its devices are never asked for here)."""

    def devices(self, ids: Sequence[int], revision: Enum, options: SimOptions) -> Setup:
        raise AssertionError("not built in these tests")


def refusal(sim: SimFamily, **options: object) -> str:
    with pytest.raises(ValueError) as caught:
        sim.check(SimOptions(**options))  # type: ignore[arg-type]
    message = str(caught.value)
    assert "\n" not in message
    return message


@pytest.mark.parametrize("name", sorted(FAMILIES))
def test_each_built_in_part_agrees_with_its_family(name: str) -> None:
    family = get_family(name)
    sim = family.part("sim")
    assert isinstance(sim, SimFamily) and sim.family == name and sim.protocol() is family
    assert set(sim.media) <= set(MEDIA) and set(sim.options) <= set(OPTIONS) and "can" in sim.media
    assert ("canfd" in sim.media) == ("canfd" in family.links)
    assert ("rs485" in sim.media) == bool(family.serial) == ("rs485" in family.links)
    assert sim.motor_ids(SimOptions()) == family.motor_ids
    assert 0 < sim.turnaround_s < 0.01


@pytest.mark.parametrize("name", sorted(FAMILIES))
def test_each_declared_medium_gets_devices_of_its_kind(name: str) -> None:
    family = get_family(name)
    sim: SimFamily = family.part("sim")
    asked = {"can": SimOptions(), "canfd": SimOptions(fd=True), "rs485": SimOptions(rs485=True)}
    for medium in sim.media:
        options = asked[medium]
        sim.check(options)
        setup = sim.devices(range(1, 4), family.default_revision, options)
        if medium == "rs485":
            assert not setup.can_devices and setup.serial_devices
            assert all(callable(getattr(d, "receive_bytes", None)) for d in setup.serial_devices)
            assert setup.baud in sim.serial_line(options).bauds
        else:
            assert len(setup.can_devices) == 3 and not setup.serial_devices
            assert all(callable(getattr(d, "receive", None)) for d in setup.can_devices)


def test_a_medium_or_flag_a_part_lacks_is_refused_naming_the_flag() -> None:
    sim = Plain(family="lk")
    assert refusal(sim, rs485=True) == "--rs485: the simulated lk devices have no RS485 line; use --slcan"
    assert refusal(sim, fd=True).startswith("--fd: the simulated lk motors speak classic CAN only")
    assert refusal(sim, modbus=True).startswith("--modbus: the simulated lk devices speak no Modbus RTU")
    assert refusal(sim, baud=9600) == "--baud 9600: the rate of an RS485 line; it needs --rs485"
    sim.check(SimOptions())


def test_a_reason_of_the_part_replaces_the_generic_one() -> None:
    sim = Plain(family="lk", refusals={"rs485": "no manual defines one", "canfd": "its drives are classic"})
    assert refusal(sim, rs485=True) == "--rs485: no manual defines one; use --slcan"
    assert refusal(sim, fd=True).startswith("--fd: its drives are classic")


def test_the_families_that_offer_a_refused_medium_are_named() -> None:
    def built_in(what: str) -> list[str]:  # (an installed plug-in may offer it too)
        return [name for name in offered_by(what) if name in FAMILIES]

    assert built_in("canfd") == ["hollow"] and built_in("modbus") == ["hollow"]
    assert built_in("rs485") == ["myactuator", "hollow"] and built_in("baud") == ["myactuator"]
    hint = ", ".join(f"--family {name}" for name in offered_by("canfd"))
    assert refusal(Plain(family="lk"), fd=True).endswith(f"(CAN FD: {hint})") and "--family hollow" in hint


def test_contradictory_flags_are_refused() -> None:
    sim = Plain(family="myactuator", media=("can", "canfd", "rs485"), options=("modbus", "baud"))
    assert refusal(sim, modbus=True) == "--modbus: a mode of the RS485 line; it needs --rs485"
    assert refusal(sim, rs485=True, fd=True).startswith("--fd:") and "--rs485" in refusal(
        sim, rs485=True, fd=True
    )
    assert refusal(Plain(family="myactuator", media=("can", "rs485")), rs485=True, baud=115_200) == (
        "--baud 115200: the myactuator RS485 line has one rate; drop --baud"
    )


def test_a_baud_rate_is_checked_against_the_familys_serial_line() -> None:
    sim: SimFamily = get_family("myactuator").part("sim")
    line = get_family("myactuator").serial[0]
    for baud in line.bauds:
        sim.check(SimOptions(rs485=True, baud=baud))
        assert sim.baud(SimOptions(rs485=True, baud=baud)) == baud
    message = refusal(sim, rs485=True, baud=2_000_000)
    assert message.startswith("--baud 2000000: the myactuator RS485 line runs at one of 115200, ")
    assert sim.baud(SimOptions(rs485=True)) == sim.default_baud == 1_000_000  # the part's own default
    assert Plain(family="myactuator", media=("can", "rs485")).baud(SimOptions(rs485=True)) == line.bauds[0]


def test_a_mode_narrows_the_motor_ids_and_says_why() -> None:
    sim: SimFamily = get_family("hollow").part("sim")
    modbus = SimOptions(rs485=True, modbus=True)
    assert sim.motor_ids(SimOptions()) == range(0, 101) and sim.motor_ids(modbus) == range(1, 101)
    assert sim.motor_ids_note(SimOptions()) == "" and "broadcast" in sim.motor_ids_note(modbus)
    assert sim.serial_line(modbus).bauds == (19_200,) and sim.serial_line(SimOptions(rs485=True)).bauds == (
        1_000_000,
    )
    converter = sim.devices(range(1, 3), ho.Revision.HO_SERIES, modbus)
    assert converter.baud == 19_200


def test_a_part_declares_only_known_media_and_options() -> None:
    with pytest.raises(ValueError, match=r"unknown media or options \['isotp'\]"):
        Plain(family="lk", media=("can", "isotp"))
    with pytest.raises(ValueError, match="turnaround_s=-1"):
        Plain(family="lk", turnaround_s=-1)


def test_a_setup_is_can_or_serial_and_a_line_has_a_rate() -> None:
    motors = (
        get_family("myactuator")
        .part("sim")
        .devices([1], get_family("myactuator").default_revision, SimOptions())
    )
    serial = (
        get_family("myactuator")
        .part("sim")
        .devices([1], get_family("myactuator").default_revision, SimOptions(rs485=True))
    )
    with pytest.raises(ValueError, match="not both"):
        Setup(can_devices=motors.can_devices, serial_devices=serial.serial_devices, baud=9600)
    with pytest.raises(ValueError, match="baud=0"):
        Setup(serial_devices=serial.serial_devices)


@pytest.mark.asyncio
@looptime
async def test_can_fd_devices_answer_can_fd_requests_on_the_in_process_bus() -> None:
    """``fd`` reaches the devices: hollow motors built for CAN FD answer 16-byte requests (classic
    ones would stay silent), through the Bus and the in-process transport."""
    family = get_family("hollow")
    sim: SimFamily = family.part("sim")
    setup = sim.devices([1, 2], family.default_revision, SimOptions(fd=True))
    async with Bus(SimTransport(devices=setup.can_devices)) as bus:
        motors = [bus.motor("hollow", i, link="canfd") for i in (1, 2)]
        replies = await asyncio.gather(*(m.request(ho.FdCommand()) for m in motors))
    assert [type(r) for r in replies] == [ho.FdReply, ho.FdReply]
