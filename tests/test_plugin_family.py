"""The family contract's proof: a fourth family, packaged apart from servobus and registered by entry
point, works through the Bus, the log decoder and the command line without a line of servobus changed.

The family is ``servobus_toy`` in tests/plugins/, with a ``servobus_toy-1.0.dist-info`` beside it whose
``entry_points.txt`` registers ``toy = servobus_toy:FAMILY`` under ``servobus.families``: that folder on
``sys.path`` (or ``PYTHONPATH``) is what installing the distribution would do, and nothing else tells
servobus of it.
"""

from __future__ import annotations

import asyncio
import json
import os
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

from _toy import PLUGINS, SERVOBUS, mypy_strict
from servobus import _plugins
from servobus.bus import Bus
from servobus.cli.plugin import OPERATIONS
from servobus.errors import MotorFault
from servobus.frame import Frame
from servobus.protocols import FAMILIES, FrameKind, available_families, check_bus, get_family
from servobus.protocols import myactuator as ma
from servobus.protocols._calls import render
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim import virtual
from servobus.sim.plant import Off, PositionControl
from servobus.tools.logs import FrameDecoder, read_log
from servobus.transports.sim import SimTransport

SRC = Path(__file__).resolve().parents[1] / "src" / "servobus"


def run_cli(*args: str, timeout_s: float = 60.0) -> subprocess.CompletedProcess[str]:
    """``servobus ARGS`` in a subprocess with the plug-in's folder on PYTHONPATH."""
    path = os.pathsep.join(p for p in (str(PLUGINS), os.environ.get("PYTHONPATH")) if p)
    return subprocess.run(
        [*SERVOBUS, *args],
        capture_output=True,
        text=True,
        timeout=timeout_s,
        env={**os.environ, "PYTHONPATH": path},
        check=False,
    )


def examples(toy: ModuleType) -> dict[type, Any]:
    """One command of each class of the toy family."""
    return {
        toy.ReadState: toy.ReadState(),
        toy.SetSpeed: toy.SetSpeed(speed_dps=-12.34),
        toy.Stop: toy.Stop(),
        toy.WriteSpeedLimit: toy.WriteSpeedLimit(limit_dps=50.0),
        toy.Restart: toy.Restart(),
    }


def run(coroutine: Any) -> Any:
    """``coroutine`` on the simulator's virtual clock (simulated seconds cost no real time)."""
    return virtual.run(coroutine)


# ---- registration ----


def test_without_its_distribution_the_family_is_unknown(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sys, "path", [p for p in sys.path if Path(p).resolve() != PLUGINS])
    monkeypatch.delitem(sys.modules, "servobus_toy", raising=False)  # (servobus keeps a loaded plug-in)
    assert "toy" not in available_families()
    with pytest.raises(ValueError, match=r"unknown protocol family 'toy' \(known: ") as refused:
        get_family("toy")
    # the families it names are those installed: the built-ins and any other plug-in, never the toy
    known = str(refused.value).partition("(known: ")[2].rstrip(")").split(", ")
    assert set(FAMILIES) <= set(known) and "toy" not in known and known == sorted(known)


def test_the_entry_point_alone_registers_the_family(toy: ModuleType) -> None:
    assert available_families()["toy"] == "servobus_toy:FAMILY"
    assert "toy" not in FAMILIES
    assert get_family("toy") is toy.FAMILY
    # servobus names the plug-in nowhere: everything it knows of it comes through the entry point
    mentions = [p for p in SRC.rglob("*.py") if "servobus_toy" in p.read_text()]
    assert mentions == []


# ---- the declarations and what is derived from them ----


def test_each_command_is_declared_once_and_its_facts_reach_the_bound_codec(toy: ModuleType) -> None:
    family = toy.FAMILY
    assert family.methods() == {
        "read_state": toy.ReadState,
        "set_speed": toy.SetSpeed,
        "stop": toy.Stop,
        "write_speed_limit": toy.WriteSpeedLimit,
        "restart": toy.Restart,
    }
    codec = family.bind(3)
    assert (codec.request_ids, codec.reply_ids, codec.shared_ids) == ({0x603}, {0x683}, {0x600})
    made = examples(toy)
    assert set(made) == set(family.commands)
    for cls, command in made.items():
        frame = codec.encode(command)
        assert frame.arbitration_id == 0x603 and len(frame.data) == 8
        assert family.decode_request(0x603, frame.data) == command
        assert codec.retry_safe(command) is cls.READ
        assert codec.timeout_s(command) == (0.2 if cls.SLOW else 0.02)
        assert (codec.reply_key(command) is None) is (cls.NO_REPLY is not None)
    assert [cls.__name__ for cls in family.commands if cls.READ] == ["ReadState"]
    assert [cls.__name__ for cls in family.commands if cls.SLOW] == ["WriteSpeedLimit"]
    assert toy.Restart.NO_REPLY == "the device restarts" and toy.Restart.reply_types() == ()
    assert toy.SetSpeed.REPLY is toy.StateReply and toy.WriteSpeedLimit.REPLY is toy.SpeedLimitEcho


def test_the_bytes_are_those_the_protocol_states(toy: ModuleType) -> None:
    codec = toy.FAMILY.bind(2)
    assert codec.encode(toy.SetSpeed(speed_dps=12.34)).data == bytes.fromhex("20 D2 04 00 00 00 00 00")
    assert codec.encode(toy.SetSpeed(speed_dps=-1000)).data == bytes.fromhex("20 60 79 FE FF 00 00 00")
    assert codec.encode(toy.WriteSpeedLimit(limit_dps=50)).data == bytes.fromhex("30 F4 01 00 00 00 00 00")
    state = Frame(arbitration_id=0x682, data=bytes.fromhex("81 28 23 00 00 7D 00 02"))
    assert codec.decode(state) == toy.StateReply(
        position_deg=90.0, speed_dps=12.5, faults=toy.ToyFaults.STALL
    )
    assert codec.classify(state) == (FrameKind.REPLY, codec.reply_key(toy.ReadState()))
    assert codec.classify(Frame(arbitration_id=0x683, data=state.data))[0] is FrameKind.NOT_OURS


def test_a_value_out_of_range_is_refused_naming_field_and_limits(toy: ModuleType) -> None:
    with pytest.raises(ValueError, match=r"speed_dps=1000.5 is outside \[-1000.0, 1000.0\]"):
        toy.SetSpeed(speed_dps=1000.5)
    with pytest.raises(ValueError, match=r"limit_dps=-1 is outside \[0.0, 1000.0\]"):
        toy.WriteSpeedLimit(limit_dps=-1)
    with pytest.raises(ValueError, match=r"toy motor_id=32 is outside 1\.\.31"):
        toy.FAMILY.bind(32)
    with pytest.raises(ValueError, match=r"toy has no link 'rs485' \(links: can\)"):
        toy.FAMILY.bind(1, link="rs485")
    with pytest.raises(ValueError, match="toy has no revision 'V2'"):
        toy.FAMILY.bind(1, revision="V2")


def test_an_echo_of_another_written_value_never_answers_a_write(toy: ModuleType) -> None:
    codec = toy.FAMILY.bind(1)
    write_50, write_60 = toy.WriteSpeedLimit(limit_dps=50), toy.WriteSpeedLimit(limit_dps=60)
    echo_50 = Frame(arbitration_id=0x681, data=write_50.encode())
    assert codec.classify(echo_50) == (FrameKind.REPLY, codec.reply_key(write_50))
    assert codec.reply_key(write_50) != codec.reply_key(write_60)


def test_the_simulated_motor_handles_every_declared_command(toy: ModuleType) -> None:
    from servobus_toy.device import ToyMotor

    motor = ToyMotor(1)
    made = examples(toy)
    for cls in toy.FAMILY.commands:
        reply = motor.handle(made[cls])
        assert (type(reply),) == cls.reply_types() or (reply is None and cls.NO_REPLY is not None)


def test_the_typed_motor_methods_are_generated_from_the_declarations(toy: ModuleType) -> None:
    generated = PLUGINS / "servobus_toy" / "_motor.py"
    assert generated.read_text() == render(toy.FAMILY), "regenerate with servobus.protocols._calls.render"
    motor_class = toy.FAMILY.motor()
    assert set(toy.FAMILY.methods()) <= set(vars(motor_class))


USER_FILE = """\
from servobus import Bus
import servobus_toy as toy


async def main(bus: Bus) -> None:
    motor = bus.motor(toy.FAMILY, 1)
    reveal_type(await motor.read_state())
    reveal_type(await motor.request(toy.WriteSpeedLimit(limit_dps=5.0)))
    reveal_type(await motor.restart())
    await motor.read_stat()
    await motor.set_speed(speed_rpm=3.0)
"""


def test_a_plug_in_motor_is_typed_for_a_user_s_type_checker(toy: ModuleType, tmp_path: Path) -> None:
    lines, _ = mypy_strict(USER_FILE, tmp_path)
    assert [line for line in lines if line.startswith("note: Revealed")] == [
        'note: Revealed type is "servobus_toy.messages.StateReply"',
        'note: Revealed type is "servobus_toy.messages.SpeedLimitEcho"',
        'note: Revealed type is "None"',
    ]
    errors = [line for line in lines if line.startswith("error:")]
    assert len(errors) == 2, errors
    assert 'has no attribute "read_stat"' in errors[0]
    assert 'Unexpected keyword argument "speed_rpm"' in errors[1]


# ---- through the Bus ----


def test_a_toy_motor_works_through_the_bus(toy: ModuleType) -> None:
    from servobus_toy.device import ToyMotor

    devices = [ToyMotor(1), ToyMotor(2), ToyMotor(3)]

    async def scenario() -> dict[str, Any]:
        async with Bus(SimTransport(devices=devices)) as bus:
            one = bus.motor(toy.FAMILY, 1)
            two, three = bus.motor("toy", 2), bus.motor("toy", 3)
            out: dict[str, Any] = {"typed": isinstance(one, toy.FAMILY.motor())}
            out["first"] = await one.read_state()
            out["set"] = await one.set_speed(speed_dps=90.0)
            await asyncio.sleep(1.0)
            out["moved"] = await one.request(toy.ReadState())
            out["echo"] = await two.write_speed_limit(limit_dps=40.0)
            out["tick"] = await bus.cycle([(one, toy.ReadState()), (two, toy.SetSpeed(speed_dps=-200.0))])
            await asyncio.sleep(1.0)
            out["limited"] = await two.read_state()
            out["all"] = await bus.broadcast(toy.ReadState(), [one, two, three])
            out["three"] = await three.read_state()
            out["commanded"] = [m.motor_id for m in bus.commanded]
            return out

    out = run(scenario())
    assert out["typed"]
    assert out["first"] == toy.StateReply(position_deg=0.0, speed_dps=0.0)
    assert isinstance(out["set"], toy.StateReply)
    assert 80.0 < out["moved"].position_deg < 90.0 and out["moved"].speed_dps == pytest.approx(90.0, abs=0.5)
    assert out["echo"] == toy.SpeedLimitEcho(limit_dps=40.0)
    assert [type(r) for r in out["tick"]] == [toy.StateReply, toy.StateReply]
    assert out["limited"].speed_dps == pytest.approx(-40.0, abs=0.5)  # the written limit holds
    assert sorted(out["all"]) == [1, 2, 3] and all(isinstance(r, toy.StateReply) for r in out["all"].values())
    assert out["commanded"] == [1, 2]
    # leaving the block stopped the motors it commanded, and only those (3 was only read)
    assert isinstance(devices[0].plant.control, PositionControl)
    assert isinstance(devices[1].plant.control, PositionControl)
    assert isinstance(devices[2].plant.control, Off)
    assert devices[2].counters["replied"] == 2  # its read and the broadcast: no stop


def test_a_value_out_of_range_leaves_nothing_on_the_bus(toy: ModuleType) -> None:
    from servobus_toy.device import ToyMotor

    device = ToyMotor(1)

    async def scenario() -> None:
        async with Bus(SimTransport(devices=[device])) as bus:
            motor = bus.motor(toy.FAMILY, 1)
            with pytest.raises(ValueError, match="speed_dps=2000"):
                await motor.set_speed(speed_dps=2000.0)
            assert bus.commanded == ()

    run(scenario())
    assert device.counters["received"] == 0


def test_faults_reach_the_motor_and_a_restart_gets_no_reply(toy: ModuleType) -> None:
    from servobus_toy.device import ToyMotor

    device = ToyMotor(1)

    async def scenario() -> tuple[MotorFault | None, Any, MotorFault | None]:
        async with Bus(SimTransport(devices=[device])) as bus:
            motor = bus.motor(toy.FAMILY, 1)
            device.inject_fault(toy.ToyFaults.OVER_TEMPERATURE)
            await motor.set_speed(speed_dps=10.0)
            fault = motor.fault
            restarted = await motor.restart()
            await motor.read_state()
            return fault, restarted, motor.fault

    fault, restarted, after = run(scenario())
    assert fault is not None and fault.flags == toy.ToyFaults.OVER_TEMPERATURE
    assert device.counters["refused_fault"] == 1
    assert restarted is None and device.counters["restarts"] == 1
    assert after is None


def test_a_plug_in_motor_shares_a_bus_with_the_built_in_families(toy: ModuleType) -> None:
    from servobus_toy.device import ToyMotor

    check_bus(
        [
            toy.FAMILY.bind(1),
            get_family("myactuator").bind(1),
            get_family("lk").bind(2),
            get_family("hollow").bind(3),
        ]
    )

    async def scenario() -> tuple[Any, Any]:
        async with Bus(SimTransport(devices=[ToyMotor(1), MyActuatorMotor(1)])) as bus:
            return await bus.cycle(
                [
                    (bus.motor(toy.FAMILY, 1), toy.SetSpeed(speed_dps=5.0)),
                    (bus.motor(ma.FAMILY, 1), ma.ReadStatus2()),
                ]
            )

    first, second = run(scenario())
    assert isinstance(first, toy.StateReply) and isinstance(second, ma.StatusReply)


def test_a_plug_in_is_looked_up_once_not_per_motor_or_broadcast(
    toy: ModuleType, monkeypatch: pytest.MonkeyPatch
) -> None:
    from servobus_toy.device import ToyMotor

    scans: list[str] = []
    real = _plugins.entry_points

    def counted(group: str) -> Any:
        scans.append(group)
        return real(group=group)

    monkeypatch.setattr(_plugins, "entry_points", counted)

    async def scenario() -> None:
        async with Bus(SimTransport(devices=[ToyMotor(1), ToyMotor(2)])) as bus:
            motors = [bus.motor("toy", 1), bus.motor("toy", 2)]
            for _ in range(5):
                await bus.broadcast(toy.ReadState(), motors)

    run(scenario())
    assert len(scans) <= 1, scans


# ---- the command line ----


def test_the_cli_part_says_what_each_command_sends_or_why_not(toy: ModuleType) -> None:
    from servobus.cli.plugin import CliFamily

    part = toy.FAMILY.part("cli")
    assert isinstance(part, CliFamily)
    assert tuple(part.status_reads(toy.FAMILY)) == (toy.ReadState,)  # derived from the declarations
    for command in OPERATIONS[1:]:
        assert part.op(command) is not None or part.why_not[command], command
    codec = toy.FAMILY.bind(1)
    assert part.op("speed").first(codec, {"speed_dps": 12.5}) == (toy.SetSpeed(speed_dps=12.5),)
    assert part.op("stop").first(codec, {}) == (toy.Stop(),)  # the bound codec's safe command
    assert part.op("reset").first(codec, {}) == (toy.Restart(),)
    (limit,) = part.settings
    assert limit.key == "speed_limit_dps" and limit.read is None and limit.rom is True
    assert limit.write is not None
    assert limit.write(limit.parse("50"), True) == toy.WriteSpeedLimit(limit_dps=50)


def _records(result: subprocess.CompletedProcess[str]) -> list[dict[str, Any]]:
    assert result.returncode == 0, result.stderr
    return [json.loads(line) for line in result.stdout.splitlines()]


def test_servobus_status_monitor_and_speed_with_simulated_toy_motors() -> None:
    (status,) = _records(run_cli("status", "--family", "toy", "--sim", "2", "--json"))
    assert [(r["id"], r["angle_deg"], r["speed_dps"], r["errors"]) for r in status] == [
        (1, 0.0, 0.0, []),
        (2, 0.0, 0.0, []),
    ]
    samples = _records(
        run_cli("monitor", "-f", "toy", "--sim", "2", "--rate-hz", "20", "--duration", "0.2", "--json")
    )
    assert {r["id"] for r in samples} == {1, 2} and len(samples) >= 4
    (turned,) = _records(
        run_cli("speed", "-f", "toy", "--sim", "1", "--speed-dps", "90", "--duration", "1", "--json")
    )
    assert turned[0]["speed_dps"] == pytest.approx(90.0, abs=1.0) and 80 < turned[0]["angle_deg"] < 90


def test_servobus_refuses_what_the_toy_cli_part_refuses_in_one_line() -> None:
    result = run_cli("move", "--family", "toy", "--sim", "1", "--angle-deg", "10")
    assert result.returncode == 2 and result.stdout == ""
    assert result.stderr == (
        "servobus move: error: toy motors have no move command: the toy protocol has no position "
        "set-point; servobus speed, then stop\n"
    )
    result = run_cli("demo", "--family", "toy", "--motors", "2", "--duration", "0.5")
    assert result.returncode == 2 and result.stderr.endswith(
        "toy motors have no move: the toy protocol has no position set-point; servobus speed, then stop\n"
    )


def test_servobus_scan_finds_simulated_toy_motors() -> None:
    result = run_cli("scan", "--family", "toy", "--sim", "3", "--json")
    assert [r["id"] for r in _records(result)[0]] == [1, 2, 3]


def test_servobus_sim_family_toy_serves_an_slcan_adapter() -> None:
    path = os.pathsep.join(p for p in (str(PLUGINS), os.environ.get("PYTHONPATH")) if p)
    server = subprocess.Popen(
        [*SERVOBUS, "sim", "--family", "toy", "--motors", "2"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": path},
    )
    try:
        assert server.stdout is not None
        pty = server.stdout.readline().strip()
        assert pty.startswith("/"), (pty, server.stderr.read() if server.poll() is not None else "")
        (status,) = _records(
            run_cli("status", "-f", "toy", "-i", "servobus-slcan", "-c", pty, "--ids", "1-2", "--json")
        )
        assert [(r["id"], r["error"]) for r in status] == [(1, None), (2, None)]
    finally:
        server.terminate()
        assert server.wait(timeout=5) == 0


@pytest.mark.parametrize(
    ("args", "error"),
    [
        (("--rs485",), "--rs485: the toy protocol is CAN only; use --slcan"),
        (("--fd",), "--fd: the simulated toy motors speak classic CAN only (CAN FD: {canfd})"),
        (
            ("--motors", "2", "--first-id", "31"),
            "--first-id 31 --motors 2: ids 31..32, but toy motor ids are 1..31",
        ),
    ],
)
def test_servobus_sim_refuses_what_the_toy_sim_part_cannot_serve(args: tuple[str, ...], error: str) -> None:
    from servobus.sim.family import offered_by

    # the families offering CAN FD: hollow, and any installed plug-in that does
    assert "hollow" in offered_by("canfd")
    error = error.format(canfd=", ".join(f"--family {name}" for name in offered_by("canfd")))
    result = run_cli("sim", "--family", "toy", *args, timeout_s=20)
    assert (result.returncode, result.stdout, result.stderr) == (2, "", f"servobus.sim: error: {error}\n")


def test_servobus_record_and_decode_round_trip_a_toy_bus(tmp_path: Path) -> None:
    rows, log = tmp_path / "toy.jsonl", tmp_path / "toy.log"
    args = ("-f", "toy", "--sim", "2", "--duration", "0.3", "--hz", "20", "-o", str(rows), "--log", str(log))
    result = run_cli("record", *args)
    assert result.returncode == 0, result.stderr
    recorded = [json.loads(line) for line in rows.read_text().splitlines()]
    assert {(r["motor_id"], r["family"], r["reply"]) for r in recorded} == {
        (1, "toy", "StateReply"),
        (2, "toy", "StateReply"),
    }
    decoded = _records(run_cli("decode", "-f", "toy", "--json", str(log)))
    assert decoded and all("error" not in r for r in decoded)
    assert {(r["direction"], r["type"]) for r in decoded} == {
        ("request", "ReadState"),
        ("reply", "StateReply"),
    }


# ---- DBC ----


def _toy_frames(toy: ModuleType) -> list[tuple[int, Any]]:
    """(identifier, message) of every command and reply class, motors 1 and 2."""
    replies = [
        toy.StateReply(position_deg=-1234.56, speed_dps=321.4, faults=toy.ToyFaults.STALL),
        toy.SpeedLimitEcho(limit_dps=999.9),
    ]
    return [(0x602, command) for command in examples(toy).values()] + [(0x681, reply) for reply in replies]


def test_the_dbc_of_a_plug_in_is_derived_from_its_declarations(toy: ModuleType) -> None:
    pytest.importorskip("cantools")
    from _dbc_check import check_frame
    from servobus.tools.dbc import database, plan

    p = plan("toy", [1, 2])
    assert not p.left_out
    assert sorted(m.frame_id for m in p.messages) == [0x601, 0x602, 0x681, 0x682]
    db = database(p)
    specs = {m.frame_id: m for m in p.messages}
    for frame_id, message in _toy_frames(toy):
        check_frame(specs[frame_id], db, message.encode(), message)


def test_servobus_dbc_family_toy(toy: ModuleType, tmp_path: Path) -> None:
    cantools = pytest.importorskip("cantools")
    out = tmp_path / "toy.dbc"
    result = run_cli("dbc", "--family", "toy", "--ids", "1-2", "-o", str(out))
    assert result.returncode == 0, result.stderr
    db = cantools.database.load_file(str(out))
    assert sorted(m.frame_id for m in db.messages) == [0x601, 0x602, 0x681, 0x682]
    assert db.decode_message(0x681, bytes.fromhex("81 28 23 00 00 7D 00 02")) == {
        "code": "StateReply",
        "position_deg": 90.0,
        "speed_dps": 12.5,
        "faults": 2,
    }
    assert db.decode_message(0x602, toy.SetSpeed(speed_dps=12.34).encode()) == {
        "code": "SetSpeed",
        "speed_dps": 12.34,
    }


# ---- decoding logs ----

LOG = """\
(1700000000.000100) can0 601#1000000000000000 T
(1700000000.000400) can0 681#81282300007D0002 R
(1700000000.001000) can0 602#20D2040000000000 T
(1700000000.002000) can0 602#30F4010000000000 T
(1700000000.022000) can0 682#30F4010000000000 R
(1700000000.023000) can0 600#2100000000000000 T
(1700000000.024000) can0 601#7F00000000000000 T
(1700000000.025000) can0 681#9900000000000000 R
(1700000000.026000) can0 123#0102 R
"""

#: each frame of LOG: (direction, motor id, type, fields) or the error
DECODED: list[tuple[str, int | None, str, dict[str, Any]] | str] = [
    ("request", 1, "ReadState", {}),
    ("reply", 1, "StateReply", {"position_deg": 90.0, "speed_dps": 12.5, "faults": 2}),
    ("request", 2, "SetSpeed", {"speed_dps": 12.34}),
    ("request", 2, "WriteSpeedLimit", {"limit_dps": 50.0}),
    ("reply", 2, "SpeedLimitEcho", {"limit_dps": 50.0}),
    ("request", None, "Stop", {}),  # the broadcast: to every motor
    ("request", 1, "Restart", {}),
    "unknown toy reply command byte (command 0x99, raw 99 00 00 00 00 00 00 00)",
    "0x123 is no identifier of the toy motors",
]


def _expected(record: dict[str, Any]) -> tuple[str, int | None, str, dict[str, Any]] | str:
    if "error" in record:
        return str(record["error"])
    return (record["direction"], record["motor_id"], record["type"], record["fields"])


def test_a_candump_log_decodes_for_the_plug_in(toy: ModuleType, tmp_path: Path) -> None:
    log = tmp_path / "toy.log"
    log.write_text(LOG)
    decoder = FrameDecoder("toy")
    assert [_expected(decoder.decode(frame).as_dict()) for frame in read_log(log)] == DECODED


def test_servobus_decode_family_toy(tmp_path: Path) -> None:
    log = tmp_path / "toy.log"
    log.write_text(LOG)
    result = run_cli("decode", "--family", "toy", "--json", str(log))
    assert result.returncode == 0, result.stderr
    assert [_expected(json.loads(line)) for line in result.stdout.splitlines()] == DECODED
    assert result.stderr.strip().endswith("decode: 9 frames, 7 decoded, 2 not decoded")
