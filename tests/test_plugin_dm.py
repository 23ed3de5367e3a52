"""A family from outside, of the kind the declarations were made for: Damiao DM-J motors in MIT mode
over classic CAN (``servobus_dm`` in tests/plugins, registered by its ``servobus_dm-1.0.dist-info``
entry point, written from the public driver code without a line of servobus changed).

Its frames are bit-packed, their ranges depend on the motor's model, four of its commands are told
by their whole payload (FF x 7 + a code) and its feedback comes on another identifier than its
commands: everything is declared (:mod:`servobus.protocols.bits`), nothing encoded or decoded by
hand. The tests prove the declarations' bytes, the bound codec, the simulated motor, the Bus on
:class:`SimTransport` and on python-can's ``virtual`` bus at 200 Hz (asyncio and trio), the command
line (``scan``, ``status``, ``mit``, ``move``, ``demo``, ``stop``, ``dbc``) and the typed calls
under ``mypy --strict``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import importlib
import inspect
import json
import math
import os
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

import anyio
import can
import pytest

from _backends import BACKENDS, virtual
from _toy import PLUGINS, SERVOBUS, mypy_strict
from servobus.bus import Bus
from servobus.cli import main
from servobus.frame import Frame
from servobus.protocols import FrameKind, available_families, check_bus, get_family
from servobus.protocols.bits import BitLayout
from servobus.sim.attach import serve_python_can
from servobus.sim.network import SimCanNetwork
from servobus.testing import FamilyContract
from servobus.transports.can import CanTransport
from servobus.transports.sim import SimTransport

SRC = Path(__file__).resolve().parents[1] / "src" / "servobus"
PACKAGE = PLUGINS / "servobus_dm"


@contextlib.contextmanager
def _installed() -> Iterator[ModuleType]:
    """``servobus_dm`` with its folder on ``sys.path`` (what installing it would do), removed again
    afterwards with every module of it."""
    sys.path.insert(0, str(PLUGINS))
    try:
        yield importlib.import_module("servobus_dm")
    finally:
        sys.path.remove(str(PLUGINS))
        for name in [n for n in sys.modules if n.partition(".")[0] == "servobus_dm"]:
            del sys.modules[name]


@pytest.fixture(scope="module")
def dm() -> Iterator[ModuleType]:
    with _installed() as package:
        yield package


def _codes(value: float, lo: float, hi: float, bits: int) -> int:
    """The MIT linear map of the public driver's ``float_to_uint``, rounded to the nearest code, ties
    up (servobus's scales round; the driver truncates, at most one code lower)."""
    return math.floor((value - lo) * ((1 << bits) - 1) / (hi - lo) + 0.5)


def _mit_bytes(p: int, v: int, kp: int, kd: int, t: int) -> bytes:
    """The public driver's packing of a MIT frame's codes: p 16 | v 12 | kp 12 | kd 12 | t 12."""
    return ((p << 48) | (v << 36) | (kp << 24) | (kd << 12) | t).to_bytes(8, "big")


# ---- registration ----


def test_the_entry_point_alone_registers_the_family(dm: ModuleType) -> None:
    assert available_families()["dm"] == "servobus_dm:FAMILY"
    assert get_family("dm") is dm.FAMILY
    assert [p for p in SRC.rglob("*.py") if "servobus_dm" in p.read_text()] == []


def test_its_messages_are_declared_not_hand_encoded(dm: ModuleType) -> None:
    from servobus_dm import messages

    classes = [*dm.FAMILY.commands, dm.Feedback]
    assert [c.__name__ for c in dm.FAMILY.commands] == [
        "MitControl", "Enable", "Disable", "SaveZero", "ClearError", "RefreshState",
    ]  # fmt: skip
    for cls in classes:
        assert issubclass(cls, BitLayout)
        assert not {"encode", "decode"} & set(vars(cls)), cls
    source = inspect.getsource(messages)
    assert "def encode" not in source and "def decode" not in source


def test_it_is_written_with_the_one_public_authoring_module() -> None:
    """Every servobus name the package uses comes from ``servobus.authoring``, the generated
    ``_motor.py``'s too (the generator writes a plug-in's imports from it)."""
    imported = {
        (path.name, line.split()[1])
        for path in PACKAGE.glob("*.py")
        for line in path.read_text().splitlines()
        if line.lstrip().startswith(("from servobus", "import servobus"))
        and not line.split()[1].startswith("servobus_dm")
    }
    assert {module for _, module in imported} == {"servobus.authoring"}, imported


# ---- the bytes ----


def test_a_mit_frame_is_the_public_driver_s_packing_scaled_by_the_model(dm: ModuleType) -> None:
    for name, model in dm.MODELS.items():
        codec = dm.FAMILY.bind(5, model=name)
        command = dm.MitControl(position_rad=1.25, velocity_rad_s=-2.5, kp=33.0, kd=1.5, torque_nm=3.0)
        frame = codec.encode(command)
        expected = _mit_bytes(
            _codes(1.25, -model.p_max, model.p_max, 16),
            _codes(-2.5, -model.v_max, model.v_max, 12),
            _codes(33.0, 0.0, 500.0, 12),
            _codes(1.5, 0.0, 5.0, 12),
            _codes(3.0, -model.t_max, model.t_max, 12),
        )
        assert (frame.arbitration_id, frame.data) == (5, expected), name
        back = dm.FAMILY.decode_request(5, frame.data, model=model)
        assert back.model is model
        assert back.position_rad == pytest.approx(1.25, abs=25 / 65535)
        assert back.torque_nm == pytest.approx(3.0, abs=2 * model.t_max / 4095)


def test_the_range_ends_are_the_code_ends(dm: ModuleType) -> None:
    codec = dm.FAMILY.bind(1, model="DM8009")
    m = codec.model
    top = dm.MitControl(
        position_rad=m.p_max, velocity_rad_s=-m.v_max, kp=500.0, kd=0.0, torque_nm=m.t_max, model=m
    )
    assert codec.encode(top).data == bytes.fromhex("FFFF000FFF000FFF")
    bottom = dm.MitControl(
        position_rad=-m.p_max, velocity_rad_s=m.v_max, kp=0.0, kd=5.0, torque_nm=-m.t_max, model=m
    )
    assert codec.encode(bottom).data == bytes.fromhex("0000FFF000FFF000")


def test_the_special_commands_and_the_refresh_are_fixed_payloads(dm: ModuleType) -> None:
    codec = dm.FAMILY.bind(7)
    for cls, last in ((dm.Enable, 0xFC), (dm.Disable, 0xFD), (dm.SaveZero, 0xFE), (dm.ClearError, 0xFB)):
        frame = codec.encode(cls())
        assert (frame.arbitration_id, frame.data) == (7, b"\xff" * 7 + bytes([last]))
        assert dm.FAMILY.decode_request(7, frame.data) == cls()
    refresh = codec.encode(dm.RefreshState())
    assert (refresh.arbitration_id, refresh.data) == (0x7FF, bytes.fromhex("07 00 CC 00 00 00 00 00"))
    assert dm.FAMILY.decode_request(0x7FF, refresh.data).motor_id == 7


def test_a_set_point_whose_payload_is_a_special_command_is_never_sent(dm: ModuleType) -> None:
    codec = dm.FAMILY.bind(1)
    m = codec.model
    # every code at its top but the torque's, whose low byte is then FC: Enable's payload
    enable = dm.MitControl(
        position_rad=m.p_max,
        velocity_rad_s=m.v_max,
        kp=500.0,
        kd=5.0,
        torque_nm=-m.t_max + 0xFFC * 2 * m.t_max / 0xFFF,
    )
    with pytest.raises(ValueError, match=r"encodes to FF FF FF FF FF FF FF FC, the Enable command's payload"):
        codec.encode(enable)
    assert codec.encode(dataclasses.replace(enable, kd=4.99)).data[:7] != b"\xff" * 7


def test_the_feedback_decodes_with_the_model_s_ranges(dm: ModuleType) -> None:
    # ERR 1 (enabled), motor 3; position code 0xFFFF, velocity 0x000, torque 0xFFF; 41 °C, 37 °C
    data = bytes.fromhex("13 FF FF 00 0F FF 29 25")
    small = dm.FAMILY.decode_reply(0x13, data)  # the default model, DM4310
    assert small == dm.Feedback(
        state=dm.DmState.ENABLED,
        motor_id=3,
        position_rad=12.5,
        velocity_rad_s=-30.0,
        torque_nm=10.0,
        temperature_c=41,
        rotor_temperature_c=37,
    )
    big = dm.FAMILY.bind(3, model="DM10010L").decode(Frame(arbitration_id=0x13, data=data))
    assert (big.velocity_rad_s, big.torque_nm, big.model.name) == (-25.0, 200.0, "DM10010L")
    assert dm.FAMILY.decode_reply(0x13, bytes.fromhex("C3 80 00 80 08 00 19 19")).state is (
        dm.DmState.COIL_OVER_TEMPERATURE
    )


def test_a_value_out_of_the_model_s_range_is_refused_naming_field_limits_and_model(dm: ModuleType) -> None:
    fast = dm.MitControl(position_rad=0.0, velocity_rad_s=10.0)
    dm.FAMILY.bind(1).encode(fast)  # within a DM4310's ±30 rad/s
    with pytest.raises(ValueError, match=r"velocity_rad_s=10(\.0)?\b.*-8\.0.*8\.0.*DM4340"):
        dm.FAMILY.bind(1, model="DM4340").encode(fast)
    with pytest.raises(ValueError, match=r"kp=501(\.0)?\b.*0\.0.*500\.0"):
        dm.FAMILY.bind(1).encode(dm.MitControl(position_rad=0.0, kp=501.0))
    with pytest.raises(ValueError, match=r"dm motor_id=16 is outside 1\.\.15"):
        dm.FAMILY.bind(16)
    with pytest.raises(ValueError, match=r"dm has no model 'DM9999' \(known: DM4310, DM4340"):
        dm.FAMILY.bind(1, model="DM9999")
    with pytest.raises(ValueError, match=r"dm has no link 'rs485'"):
        dm.FAMILY.bind(1, link="rs485")


def test_bytes_that_are_not_a_dm_frame_do_not_decode(dm: ModuleType) -> None:
    from servobus.errors import ProtocolError

    with pytest.raises(ProtocolError):
        dm.FAMILY.decode_reply(0x13, bytes.fromhex("F3 00 00 00 00 00 00 00"))  # ERR 0xF: no code
    with pytest.raises(ProtocolError):
        dm.FAMILY.decode_reply(0x20, bytes(8))  # motor 16's: no dm feedback identifier
    # the identifier says whose the feedback is; D0's nibble comes as it is
    assert dm.FAMILY.decode_reply(0x13, bytes.fromhex("14 00 00 00 00 00 00 00")).motor_id == 4
    with pytest.raises(ProtocolError):
        dm.FAMILY.decode_reply(0x13, bytes.fromhex("13 00"))
    with pytest.raises(ProtocolError):
        dm.FAMILY.decode_request(0x7FF, bytes.fromhex("01 00 CD 00 00 00 00 00"))
    with pytest.raises(ProtocolError):
        dm.FAMILY.decode_request(0x20, bytes(8))


# ---- the bound codec ----


def test_the_bound_codec_keeps_the_contract(dm: ModuleType) -> None:
    codec = dm.FAMILY.bind(3)
    assert (codec.request_ids, codec.reply_ids, codec.shared_ids) == ({3}, {0x13}, {0x7FF})
    feedback = Frame(arbitration_id=0x13, data=bytes.fromhex("03 80 00 80 08 00 19 19"), is_rx=True)
    for cls in (dm.MitControl, dm.Enable, dm.Disable, dm.RefreshState):
        command = cls(position_rad=0.0) if cls is dm.MitControl else cls()
        assert codec.classify(feedback) == (FrameKind.REPLY, codec.reply_key(command))
    assert codec.reply_key(dm.SaveZero()) is None and codec.reply_key(dm.ClearError()) is None
    assert codec.classify(Frame(arbitration_id=0x14, data=feedback.data, is_rx=True))[0] is FrameKind.NOT_OURS
    assert codec.safe_command("stop") == dm.Disable() == codec.safe_command("shutdown")
    assert [codec.retry_safe(cls()) for cls in (dm.RefreshState, dm.Enable)] == [True, False]
    assert codec.timeout_s(dm.SaveZero()) > codec.timeout_s(dm.Enable())
    with pytest.raises(ValueError, match="no broadcast"):
        dm.FAMILY.broadcast(dm.Enable(), [codec])
    # its 15 motors share a bus, and a bus with the built-in families' motors on other ids
    check_bus([dm.FAMILY.bind(i) for i in dm.FAMILY.motor_ids])
    check_bus([dm.FAMILY.bind(1), get_family("myactuator").bind(1), get_family("hollow").bind(40)])


# ---- the simulated motor ----


def test_the_simulated_motor_acts_as_the_drive(dm: ModuleType) -> None:
    from servobus_dm.device import DmMotor

    motor = DmMotor(2, model=dm.MODELS["DM4340"])
    point = dm.MitControl(position_rad=1.0, kp=20.0, kd=1.0, model=motor.model)
    assert motor.handle(point).state is dm.DmState.DISABLED  # answered, not acted on
    assert motor.counters["refused_disabled"] == 1
    assert motor.handle(dm.Enable()).state is dm.DmState.ENABLED
    motor.handle(point)
    motor.receive(Frame(arbitration_id=0x7FF, data=bytes.fromhex("02 00 CC 00 00 00 00 00")), 1.0)
    state = motor.feedback()
    assert state.position_rad == pytest.approx(1.0, abs=0.01) and state.model is motor.model
    motor.inject_fault(dm.DmState.OVER_CURRENT)
    assert motor.handle(dm.Enable()).state is dm.DmState.OVER_CURRENT
    assert motor.handle(dm.ClearError()) is None
    assert motor.handle(dm.RefreshState()).state is dm.DmState.DISABLED
    assert motor.handle(dm.SaveZero()) is None and motor.feedback().position_rad == pytest.approx(
        0.0, abs=1e-3
    )
    refresh_of_3 = Frame(arbitration_id=0x7FF, data=bytes.fromhex("03 00 CC 00 00 00 00 00"))
    assert motor.receive(refresh_of_3, 2.0) == [] and motor.counters["not_mine"] == 1


def test_the_typed_motor_methods_are_generated_from_the_declarations(dm: ModuleType) -> None:
    from servobus.protocols._calls import render

    assert (PACKAGE / "_motor.py").read_text() == render(dm.FAMILY), (
        "regenerate: python -m servobus.protocols._calls servobus_dm"
    )
    assert set(dm.FAMILY.methods()) <= set(vars(dm.FAMILY.motor()))


# ---- through the Bus: MIT set-points at 200 Hz ----

TICKS, MOTORS, HZ = 400, 4, 200.0


def _trajectory_rad(tick: int, motor_id: int) -> float:
    return 0.5 * math.sin(2 * math.pi * tick / HZ) * motor_id / MOTORS


async def _drive(
    bus: Bus, dm: ModuleType, motor_ids: range, *, model: str = "DM4310", timeout_s: float | None = None
) -> dict[str, Any]:
    """Enable ``motor_ids``, send each a MIT set-point every tick at 200 Hz; the feedback counted."""
    motors = [bus.motor(dm.FAMILY, i, model=model) for i in motor_ids]
    for motor in motors:
        assert (await motor.enable()).state is dm.DmState.ENABLED
    replies: list[Any] = []
    tick = 0
    async for _ in bus.ticks(HZ, count=TICKS):
        tick += 1
        replies += await bus.cycle(
            [
                (m, dm.MitControl(position_rad=_trajectory_rad(tick, m.motor_id), kp=30.0, kd=1.0))
                for m in motors
            ],
            timeout_s=timeout_s,
        )
    last = {m.motor_id: await m.refresh_state() for m in motors}
    typed = all(isinstance(m, dm.FAMILY.motor()) for m in motors)
    return {"replies": replies, "last": last, "typed": typed, "metrics": bus.metrics()}


@pytest.mark.parametrize("backend", BACKENDS)
def test_mit_set_points_at_200_hz_through_the_bus_on_sim_transport(dm: ModuleType, backend: str) -> None:
    from servobus_dm.device import DmMotor

    devices = [DmMotor(i, model=dm.MODELS["DM6006"]) for i in range(1, MOTORS + 1)]

    async def scenario() -> dict[str, Any]:
        async with Bus(SimTransport(devices=devices)) as bus:
            return await _drive(bus, dm, range(1, MOTORS + 1), model="DM6006")

    name, options = virtual(backend)
    out = anyio.run(scenario, backend=name, backend_options=options)
    replies = out["replies"]
    assert out["typed"] and len(replies) == TICKS * MOTORS
    assert all(isinstance(r, dm.Feedback) and r.state is dm.DmState.ENABLED for r in replies)
    assert all(r.model.name == "DM6006" for r in replies)
    # the joints follow their trajectories: motor N swings to about ±0.5 N / 4 rad
    for motor_id in range(1, MOTORS + 1):
        swing = max(abs(r.position_rad) for r in replies[motor_id - 1 :: MOTORS])
        assert swing == pytest.approx(0.5 * motor_id / MOTORS, rel=0.25), motor_id
    # leaving the Bus disabled every motor it drove: the safe stop
    assert all(not d.enabled for d in devices)


def test_a_value_out_of_range_names_the_model_and_leaves_nothing_on_the_bus(dm: ModuleType) -> None:
    from servobus_dm.device import DmMotor

    device = DmMotor(1, model=dm.MODELS["DM4340"])

    async def scenario() -> None:
        async with Bus(SimTransport(devices=[device])) as bus:
            motor = bus.motor(dm.FAMILY, 1, model="DM4340")
            with pytest.raises(ValueError, match=r"velocity_rad_s.*DM4340"):
                await motor.mit_control(position_rad=0.0, velocity_rad_s=9.0)
            assert bus.commanded == ()

    name, options = virtual("asyncio")
    anyio.run(scenario, backend=name, backend_options=options)
    assert device.counters["received"] == 0


def test_a_typed_call_is_checked_against_the_motor_s_own_model(dm: ModuleType) -> None:
    """40 rad/s is beyond the default DM4310's ±30 but within a DM6006's ±45: the typed call
    builds the command with the model the motor was bound with (servobus.protocols._calls.given_model)."""
    from servobus_dm.device import DmMotor

    model = dm.MODELS["DM6006"]
    device = DmMotor(1, model=model)

    async def scenario() -> None:
        async with Bus(SimTransport(devices=[device])) as bus:
            motor = bus.motor(dm.FAMILY, 1, model="DM6006")
            await motor.enable()
            await motor.mit_control(position_rad=0.0, velocity_rad_s=40.0, kd=1.0)
            with pytest.raises(
                ValueError, match=r"^velocity_rad_s=46\.0 is outside \[-45\.0, 45\.0\] for model DM6006$"
            ):
                await motor.mit_control(position_rad=0.0, velocity_rad_s=46.0)

    name, options = virtual("asyncio")
    anyio.run(scenario, backend=name, backend_options=options)
    assert device.counters["received"] == 3  # (the enable, the 40 rad/s set-point, the stop on leaving)


def test_an_error_code_is_the_motor_s_fault_and_its_states_are_none(dm: ModuleType) -> None:
    from servobus_dm.device import DmMotor

    from servobus.errors import MotorFault

    device = DmMotor(1)

    async def scenario() -> list[MotorFault | None]:
        async with Bus(SimTransport(devices=[device])) as bus:
            motor = bus.motor(dm.FAMILY, 1)
            faults = [None if (await motor.enable()).state is not dm.DmState.ENABLED else motor.fault]
            device.inject_fault(dm.DmState.OVER_CURRENT)
            await motor.refresh_state()
            faults.append(motor.fault)
            await motor.clear_error()
            await motor.refresh_state()  # DISABLED: a state, no fault
            faults.append(motor.fault)
            return faults

    name, options = virtual("asyncio")
    enabled, fault, cleared = anyio.run(scenario, backend=name, backend_options=options)
    assert enabled is None and cleared is None
    assert isinstance(fault, MotorFault) and fault.flags is None
    assert fault.code is dm.DmState.OVER_CURRENT and fault.motor_id == 1


@contextlib.contextmanager
def _virtual_dm_motors(ids: range) -> Iterator[str]:
    """Simulated DM-J motors ``ids`` on a python-can ``virtual`` channel (returned), served on a thread
    of their own, as other nodes on the bus are."""
    from servobus_dm.device import DmMotor

    channel = f"dm-{os.getpid()}-{time.monotonic_ns()}"
    ready, stop = threading.Event(), threading.Event()

    def serve() -> None:
        async def main() -> None:
            bus = can.Bus(interface="virtual", channel=channel)
            try:
                async with anyio.create_task_group() as group:
                    group.start_soon(serve_python_can, SimCanNetwork([DmMotor(i) for i in ids]), bus)
                    ready.set()
                    while not stop.is_set():
                        await anyio.sleep(0.01)
                    group.cancel_scope.cancel()
            finally:
                bus.shutdown()

        anyio.run(main)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    assert ready.wait(5.0)
    try:
        yield channel
    finally:
        stop.set()
        thread.join(5.0)


@pytest.mark.parametrize("backend", BACKENDS)
def test_mit_set_points_at_200_hz_through_python_can_virtual(dm: ModuleType, backend: str) -> None:
    """Real time: 2 s of 4 motors at 200 Hz, every set-point answered (the motors' thread holds the
    GIL up to its 5 ms switch interval: a reply may come a tick late, so the tick waits 50 ms)."""
    with _virtual_dm_motors(range(1, MOTORS + 1)) as channel:

        async def scenario() -> dict[str, Any]:
            async with Bus(CanTransport("virtual", channel, ignore_config=True)) as bus:
                return await _drive(bus, dm, range(1, MOTORS + 1), timeout_s=0.05)

        out = anyio.run(scenario, backend=backend)
    replies = out["replies"]
    assert len(replies) == TICKS * MOTORS
    failed = [r for r in replies if not isinstance(r, dm.Feedback)]
    assert failed == [], (len(failed), failed[:3], out["metrics"])
    assert all(r.state is dm.DmState.ENABLED for r in replies)


# ---- the command line (in this process: the family installed as the fixture put it) ----


def _json(capsys: pytest.CaptureFixture[str], args: list[str]) -> Any:
    capsys.readouterr()
    code = main(args)
    out, err = capsys.readouterr()
    assert code == 0, err
    return [json.loads(line) for line in out.splitlines()]


def _refused(capsys: pytest.CaptureFixture[str], args: list[str]) -> str:
    capsys.readouterr()
    assert main(args) == 2
    out, err = capsys.readouterr()
    assert out == "" and len(err.splitlines()) == 1, err
    return err


def test_servobus_scan_finds_dm_motors_on_the_ids_the_family_allows(
    dm: ModuleType, capsys: pytest.CaptureFixture[str]
) -> None:
    # without --ids: 1..15 of scan's 1..32 (the family's motor_ids), their feedback ids 0x11..0x1F
    # never another's command id
    (found,) = _json(capsys, ["scan", "-f", "dm", "--sim", "3", "--json"])
    assert [(r["id"], r["family"]) for r in found] == [(1, "dm"), (2, "dm"), (3, "dm")]
    (found,) = _json(capsys, ["scan", "-f", "dm", "--sim", "2", "--ids", "1-8", "--json"])
    assert [(r["id"], r["errors"]) for r in found] == [(1, []), (2, [])]  # DISABLED: a state, no fault
    assert get_family("dm").part("cli").scan_ids == range(1, 16)


def test_servobus_status_mit_and_move_drive_simulated_dm_motors(
    dm: ModuleType, capsys: pytest.CaptureFixture[str]
) -> None:
    (status,) = _json(capsys, ["status", "-f", "dm", "--sim", "2", "--json"])
    assert [r["id"] for r in status] == [1, 2]
    assert all(abs(r["angle_deg"]) < 0.1 and r["temperature_c"] == 25 for r in status)
    mit = ["mit", "-f", "dm", "--sim", "1", "--position-rad", "1", "--kp", "20", "--kd", "1"]
    (held,) = _json(capsys, [*mit, "--duration", "0.5", "--json"])
    assert held[0]["angle_deg"] == pytest.approx(math.degrees(1.0), abs=1.0)
    capsys.readouterr()
    assert main(["move", "-f", "dm", "--sim", "1", "--angle-deg", "45", "--duration", "0.5", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)[0]["angle_deg"] == pytest.approx(45.0, abs=1.0)


def test_servobus_refuses_what_a_dm_motor_cannot_do_in_one_line(
    dm: ModuleType, capsys: pytest.CaptureFixture[str]
) -> None:
    err = _refused(capsys, ["move", "-f", "dm", "--sim", "1", "--angle-deg", "800"])
    assert "position_rad" in err and "12.5" in err and "DM4310" in err
    err = _refused(
        capsys, ["mit", "-f", "dm", "--sim", "1", "--position-rad", "0", "--kp", "600", "--kd", "1"]
    )
    assert "kp" in err and "500" in err
    err = _refused(capsys, ["torque", "-f", "dm", "--sim", "1", "--current-a", "1"])
    assert "servobus mit --kp 0 --kd 0 --torque-ff-nm" in err
    # its move is the MIT law: the gains set the pace, so a speed limit would be a promise not kept
    err = _refused(capsys, ["move", "-f", "dm", "--sim", "1", "--angle-deg", "10", "--max-speed-dps", "50"])
    assert "dm move carries no speed limit: drop --max-speed-dps" in err


def test_servobus_zero_clear_errors_off_and_monitor_on_dm_motors(
    dm: ModuleType, capsys: pytest.CaptureFixture[str]
) -> None:
    (zeroed,) = _json(capsys, ["zero", "-f", "dm", "--sim", "1", "--yes", "--json"])
    assert zeroed[0]["sent"] == ["Disable", "SaveZero"]
    (cleared,) = _json(capsys, ["clear-errors", "-f", "dm", "--sim", "1", "--json"])
    assert cleared[0]["sent"] == ["ClearError"]
    (off,) = _json(capsys, ["off", "-f", "dm", "--sim", "2", "--json"])
    assert [(r["id"], r["sent"]) for r in off] == [(1, ["Disable"]), (2, ["Disable"])]
    samples = _json(
        capsys, ["monitor", "-f", "dm", "--sim", "2", "--rate-hz", "20", "--duration", "0.2", "--json"]
    )
    assert {r["id"] for r in samples} == {1, 2} and len(samples) >= 4


def test_servobus_demo_runs_simulated_dm_motors(dm: ModuleType, capsys: pytest.CaptureFixture[str]) -> None:
    (summary,) = _json(
        capsys, ["demo", "-f", "dm", "--motors", "2", "--duration", "0.5", "--hz", "200", "--json"]
    )
    assert summary["errors"] == 0, summary
    # its move takes no speed limit (the MIT law's gains set the pace): the demo gives it none
    from servobus.cli._demo_parts import MAX_SPEED_DPS, parts

    assert parts("dm").values(10.0)["max_speed_dps"] is None
    assert parts("myactuator").values(10.0)["max_speed_dps"] == MAX_SPEED_DPS


def test_servobus_scan_status_and_stop_through_python_can_virtual(
    dm: ModuleType, capsys: pytest.CaptureFixture[str]
) -> None:
    with _virtual_dm_motors(range(1, 3)) as channel:
        connection = ["-f", "dm", "-i", "virtual", "-c", channel]
        (found,) = _json(capsys, ["scan", *connection, "--ids", "1-4", "--json", "--timeout-ms", "50"])
        assert [r["id"] for r in found] == [1, 2]
        (status,) = _json(capsys, ["status", *connection, "--ids", "1-2", "--json"])
        assert [(r["id"], r["error"]) for r in status] == [(1, None), (2, None)]
        (moved,) = _json(
            capsys, ["move", *connection, "--ids", "1", "--angle-deg", "30", "--duration", "0.5", "--json"]
        )
        assert moved[0]["angle_deg"] == pytest.approx(30.0, abs=1.5)
        capsys.readouterr()
        assert main(["stop", *connection, "--ids", "1-2"]) == 0, capsys.readouterr().err


def test_servobus_dbc_family_dm(dm: ModuleType, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cantools = pytest.importorskip("cantools")
    out = tmp_path / "dm.dbc"
    capsys.readouterr()
    assert main(["dbc", "--family", "dm", "--ids", "1-2", "--option", "model=DM8009", "-o", str(out)]) == 0
    db = cantools.database.load_file(str(out))
    assert sorted(m.frame_id for m in db.messages) == [0x01, 0x02, 0x11, 0x12, 0x7FF]
    codec = dm.FAMILY.bind(2, model="DM8009")
    point = dm.MitControl(
        position_rad=1.25, velocity_rad_s=-2.5, kp=33.0, kd=1.5, torque_nm=-20.0, model=codec.model
    )
    decoded = db.decode_message(0x02, codec.encode(point).data)
    sent = dm.FAMILY.decode_request(2, codec.encode(point).data, model="DM8009")
    assert decoded == pytest.approx({k: getattr(sent, k) for k in decoded})
    # the refresh's 16-bit little-endian id: two signals (bit_signals splits a field over bytes into
    # runs whose values add up to it)
    assert db.decode_message(0x7FF, codec.encode(dm.RefreshState()).data) == {
        "motor_id_b0": 2,
        "motor_id_b8": 0,
    }
    feedback = bytes.fromhex("12 FF FF 00 0F FF 29 25")
    assert db.decode_message(0x12, feedback, decode_choices=False) == pytest.approx(
        {
            "state": 1,
            "motor_id": 2,
            "position_rad": 12.5,
            "velocity_rad_s": -45.0,
            "torque_nm": 54.0,
            "temperature_c": 41,
            "rotor_temperature_c": 37,
        }
    )


# ---- typed calls ----

USER_FILE = """\
from servobus import Bus
import servobus_dm as dm


async def main(bus: Bus) -> None:
    motor = bus.motor(dm.FAMILY, 1, model="DM4340")
    reveal_type(await motor.enable())
    reveal_type(await motor.mit_control(position_rad=1.0, kp=20.0, kd=1.0))
    reveal_type(await motor.save_zero())
    reveal_type((await motor.refresh_state()).state)
    await motor.mit_contrl(position_rad=1.0)
    await motor.mit_control(position_deg=1.0)
    await motor.request(dm.MitControl(position_rad="1"))
"""


def test_a_dm_motor_is_typed_for_a_user_s_type_checker(dm: ModuleType, tmp_path: Path) -> None:
    lines, stdout = mypy_strict(USER_FILE, tmp_path)
    assert [line for line in lines if line.startswith("note: Revealed")] == [
        'note: Revealed type is "servobus_dm.messages.Feedback"',
        'note: Revealed type is "servobus_dm.messages.Feedback"',
        'note: Revealed type is "None"',
        'note: Revealed type is "servobus_dm.messages.DmState"',
    ]
    errors = [line for line in lines if line.startswith("error:")]
    assert len(errors) == 3, stdout
    assert 'has no attribute "mit_contrl"' in errors[0]
    assert 'Unexpected keyword argument "position_deg"' in errors[1]
    assert 'incompatible type "str"; expected "float"' in errors[2]
    assert [
        line for line in stdout.splitlines() if "servobus_dm" in line.split(":")[0]
    ] == []  # the package is clean


# ---- served by `servobus sim`, and a log decoded (subprocesses: the family installed by PYTHONPATH) ----


def _run_cli(*args: str, timeout_s: float = 60.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*SERVOBUS, *args], capture_output=True, text=True, timeout=timeout_s, env=_env(), check=False
    )


def _env() -> dict[str, str]:
    path = os.pathsep.join(p for p in (str(PLUGINS), os.environ.get("PYTHONPATH")) if p)
    return {**os.environ, "PYTHONPATH": path}


def test_servobus_sim_family_dm_serves_an_slcan_adapter() -> None:
    server = subprocess.Popen(
        [*SERVOBUS, "sim", "--family", "dm", "--motors", "2"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=_env(),
    )
    try:
        assert server.stdout is not None
        pty = server.stdout.readline().strip()
        assert pty.startswith("/"), (pty, server.stderr.read() if server.poll() is not None else "")
        result = _run_cli("status", "-f", "dm", "-i", "servobus-slcan", "-c", pty, "--ids", "1-2", "--json")
        assert result.returncode == 0, result.stderr
        assert [(r["id"], r["error"]) for r in json.loads(result.stdout)] == [(1, None), (2, None)]
    finally:
        server.terminate()
        assert server.wait(timeout=5) == 0


LOG = """\
(1700000000.000100) can0 7FF#0100CC0000000000 T
(1700000000.000400) can0 011#0180008008001919 R
(1700000000.001000) can0 001#FFFFFFFFFFFFFFFC T
(1700000000.002000) can0 001#FFFF000FFF000FFF T
(1700000000.002400) can0 011#11FFFF000FFF2925 R
(1700000000.003000) can0 001#FFFFFFFFFFFFFFFD T
"""


def test_servobus_decode_family_dm(tmp_path: Path) -> None:
    log = tmp_path / "dm.log"
    log.write_text(LOG)
    result = _run_cli("decode", "--family", "dm", "--json", str(log))
    assert result.returncode == 0, result.stderr
    records = [json.loads(line) for line in result.stdout.splitlines()]
    assert [(r["direction"], r["motor_id"], r["type"]) for r in records] == [
        ("request", None, "RefreshState"),  # on 0x7FF, which every motor shares: the address is a field
        ("reply", 1, "Feedback"),
        ("request", 1, "Enable"),
        ("request", 1, "MitControl"),
        ("reply", 1, "Feedback"),
        ("request", 1, "Disable"),
    ]
    assert records[0]["fields"] == {"motor_id": 1}
    mit, feedback = records[3]["fields"], records[4]["fields"]
    assert (mit["position_rad"], mit["velocity_rad_s"], mit["kp"], mit["torque_nm"]) == (
        12.5,
        -30.0,
        500.0,
        10.0,
    )
    assert (feedback["position_rad"], feedback["torque_nm"], feedback["temperature_c"]) == (12.5, 10.0, 41)


# ---- the public contract suite (servobus.testing) ----


class TestDm(FamilyContract):
    """servobus.testing's contract, as dm's own package runs it: every model bound (its messages
    drawn from their declarations: each bit field's codes)."""

    bind_options = tuple(
        {"model": name} for name in ("DM4310", "DM4340", "DM6006", "DM8006", "DM8009", "DM10010L")
    )
    max_examples = 30

    @pytest.fixture
    def contract_family(self, dm: ModuleType) -> Any:
        return dm.FAMILY


@pytest.mark.parametrize(
    ("args", "error"),
    [
        (("--rs485",), "--rs485: DM-J motors in MIT mode speak classic CAN only; use --slcan"),
        (("--fd",), "--fd: DM-J motors in MIT mode speak classic CAN only (CAN FD: --family hollow)"),
        (
            ("--motors", "2", "--first-id", "15"),
            "--first-id 15 --motors 2: ids 15..16, but dm motor ids are 1..15",
        ),
    ],
)
def test_servobus_sim_refuses_what_the_dm_sim_part_cannot_serve(args: tuple[str, ...], error: str) -> None:
    result = _run_cli("sim", "--family", "dm", *args, timeout_s=20)
    assert (result.returncode, result.stdout, result.stderr) == (2, "", f"servobus.sim: error: {error}\n")


def test_a_fault_code_crosses_the_bridge_s_wire(dm: ModuleType) -> None:
    """A bridge publishes a family's fault code as it publishes error flags (remote/_served.py)."""
    import time

    from servobus.remote import wire

    schema = wire.Schema.of("dm")
    reply = dm.Feedback.decode(bytes.fromhex("A1 80 00 80 08 00 28 1E"))
    state = wire.State(1, time.time_ns(), True, reply, dm.DmState.OVER_CURRENT)
    assert wire.decode_state(schema, wire.encode_state(schema, state)) == state
