"""The CLI's family contract (``servobus.cli.plugin``): every family's ``cli`` part offers or refuses
each command with a reason, its settings are said by their command classes, and a family without a
``cli`` part still gets the commands that need no table (status reads derived from its declarations,
``stop``/``off`` from its safe commands) and a one-line refusal for the rest."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from pathlib import Path

import pytest

import servobus.cli._families as families
from cli._bus_cli import one_line, run_json
from servobus.cli import COMMANDS, main
from servobus.cli.plugin import OPERATIONS, CliFamily, build, derived_status, parse_int, safe, setting_of
from servobus.protocols import FAMILIES, Command, Family, Reply, get_family
from servobus.protocols import myactuator as ma

CLI_SRC = Path(families.__file__).parent


def test_the_driven_commands_are_the_clis() -> None:
    assert set(OPERATIONS) <= set(COMMANDS)


@pytest.mark.parametrize("name", list(FAMILIES))
def test_each_built_in_family_offers_or_refuses_every_command_with_a_reason(name: str) -> None:
    part = families.cli_part(name)
    assert isinstance(part, CliFamily)
    for command in OPERATIONS:
        if command == "status":
            offered = bool(part.status_reads(get_family(name)))
        else:
            offered = part.op(command) is not None
        assert offered or part.why_not.get(command), (name, command)
    assert set(part.ops) | set(part.why_not) <= set(OPERATIONS)


@pytest.mark.parametrize("name", list(FAMILIES))
def test_each_setting_parses_and_builds_its_commands(name: str) -> None:
    for s in families.cli_part(name).settings:
        if s.read is not None:
            assert isinstance(s.read(), Command), s.key
        if s.write is None:
            continue
        for text in ("1", "1,2,3", "on", "0.5", "200"):
            try:
                value = s.parse(text)
                command = s.write(value, s.rom is None)
            except ValueError:
                continue
            assert isinstance(command, Command), s.key
            break
        else:
            pytest.fail(f"{name} {s.key}: no sample value parses and builds a write")


def test_every_readable_setting_reads_back_from_the_simulated_motor(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """The reply field each setting shows is the one its write sets (setting_of): read from a motor."""
    for name, revision in (("myactuator", "V4_4"), ("myactuator", "V4_3"), ("lk", "V2_36"), ("lk", "V2_35")):
        keys = [s.key for s in families.cli_part(name).settings if s.read is not None]
        args = ["config", "get", "--family", name, "--revision", revision, "--sim", "1"]
        # each revision reads its own keys; the others are refused (exit 2) before anything is sent
        readable = [key for key in keys if main(["config", "get", *args[2:], key]) == 0]
        capsys.readouterr()
        assert readable, (name, revision)
        rows = run_json(capsys, [*args, *readable])
        assert [r["key"] for r in rows] == readable
        assert all(r["value"] is not None and r["error"] is None for r in rows), rows
    assert len(readable) == 1  # LK V2.35: its acceleration only


@pytest.mark.parametrize("name", list(FAMILIES))
def test_what_the_cli_sends_to_look_is_declared_a_read(name: str) -> None:
    """status, monitor, scan and config get change nothing on a motor: every command they send is
    declared READ (so it is retried, and a Bus left after them stops no motor)."""
    family = get_family(name)
    part = families.cli_part(name)
    sent = [read() for read in part.status_reads(family)]
    sent += [s.read() for s in part.settings if s.read is not None]
    for revision in family.revisions:
        codec = family.bind(min(i for i in family.motor_ids if i > 0), revision=revision)
        for query in (part.identify, part.describe):
            sent += [] if query is None else list(query.reads(codec))
    assert [type(c).__name__ for c in sent if not type(c).READ] == []


# ---- ops said by their commands ----


def test_build_gives_the_values_to_the_fields_of_the_same_name() -> None:
    codec = get_family("myactuator").bind(1)
    values = {"speed_dps": 30.0, "max_current_a": None, "relative": False}
    assert build(ma.SpeedControl)(codec, values) == ma.SpeedControl(speed_dps=30.0)  # max_torque_pct: default
    moved = build(ma.IncrementalPositionControl, angle_deg="step_deg")(
        codec, {"step_deg": 5.0, "max_speed_dps": 9.0}
    )
    assert moved == ma.IncrementalPositionControl(angle_deg=5.0, max_speed_dps=9.0)
    with pytest.raises(TypeError, match="SpeedControl has no field speed_rpm"):
        build(ma.SpeedControl, speed_rpm="speed_dps")


# ---- settings said by their commands ----


def test_setting_of_takes_the_value_field_its_type_and_the_rom_form() -> None:
    pid = setting_of(
        "k", "h", read=ma.ReadPid, write=ma.WritePidRam, rom_write=ma.WritePidRom, keys={"index": 1}
    )
    assert pid.field == "value" and pid.rom is None and pid.parse("0.25") == 0.25
    assert pid.write is not None and pid.read is not None
    assert pid.write(0.25, False) == ma.WritePidRam(index=ma.PidIndex(1), value=0.25)
    assert pid.write(0.25, True) == ma.WritePidRom(index=ma.PidIndex(1), value=0.25)
    assert pid.read() == ma.ReadPid(index=ma.PidIndex(1))
    accel = setting_of(
        "a", "h", read=ma.ReadAcceleration, write=ma.WriteAcceleration, keys={"index": 0}, rom=True
    )
    assert accel.field == "acceleration_dps_s" and accel.rom is True
    assert accel.parse("none") is None and accel.parse("250") == 250.0
    timeout = setting_of("t", "h", write=ma.SetCommTimeout)
    assert timeout.read is None and timeout.parse("off") is None and timeout.parse("0x10") == 16
    assert setting_of("t", "h", write=ma.SetCommTimeout, parse=parse_int).parse("1e3") == 1000


def test_setting_of_refuses_a_write_that_does_not_name_one_value() -> None:
    with pytest.raises(TypeError, match="WritePidRam: a setting's write takes one value field"):
        setting_of("k", "h", write=ma.WritePidRam)  # index and value: which is the setting?


def test_a_part_refuses_repeated_keys_and_a_command_both_offered_and_refused() -> None:
    timeout = setting_of("t", "h", write=ma.SetCommTimeout)
    with pytest.raises(ValueError, match="settings keys repeat"):
        CliFamily(settings=(timeout, timeout))
    with pytest.raises(ValueError, match=r"both offered and refused: \['stop'\]"):
        CliFamily(ops={"stop": safe("stop")}, why_not={"stop": "x"})


# ---- a family without a cli part ----


@dataclasses.dataclass(frozen=True, slots=True)
class _State(Reply):
    position_deg: float = 0.0


@dataclasses.dataclass(frozen=True, slots=True)
class _Other(Reply):
    text: str = ""


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class _ReadState(Command[_State]):
    READ = True


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class _ReadOther(Command[_Other]):
    READ = True


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class _ReadIndexed(Command[_State]):
    READ = True
    index: int


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class _Move(Command[_State]):
    pass


def test_status_reads_are_derived_from_the_read_declarations() -> None:
    family = dataclasses.replace(
        get_family("myactuator"),
        commands=(_Move, _ReadOther, _ReadIndexed, _ReadState),
        parts={},
        package=None,
    )
    # only a read, without arguments, whose reply shows a status column
    assert derived_status(family) == (_ReadState,)


@pytest.fixture
def without_cli_part(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """MyActuator as a third-party family would be: no ``cli`` part, ReadStatus2 its one status read."""
    real = get_family

    def family(name: str | Family) -> Family:
        found = real(name) if isinstance(name, str) else name
        parts = {k: v for k, v in found.parts.items() if k != "cli"}
        return dataclasses.replace(
            found, parts=parts, package=None, commands=(ma.ReadStatus2, ma.SpeedControl)
        )

    monkeypatch.setattr(families, "get_family", family)
    monkeypatch.setattr(ma.ReadStatus2, "READ", True)
    monkeypatch.setattr(ma.ReadStatus2, "REPLY", ma.StatusReply)
    yield


@pytest.mark.usefixtures("without_cli_part")
def test_a_family_without_a_cli_part_gets_status_scan_stop_and_off(
    capsys: pytest.CaptureFixture[str],
) -> None:
    rows = run_json(capsys, ["status", "--sim", "2"])
    assert [r["id"] for r in rows] == [1, 2] and all(r["angle_deg"] is not None for r in rows)
    assert [r["id"] for r in run_json(capsys, ["scan", "--sim", "2", "--ids", "1-3"])] == [1, 2]
    for command, sent in (("stop", "MotorStop"), ("off", "MotorShutdown")):
        assert [r["sent"] for r in run_json(capsys, [command, "--sim", "1"])] == [[sent]]


def test_record_polls_the_first_status_read_of_a_family_without_read_status2(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import servobus.cli.record as record
    from servobus.cli._connect import Connection

    real = get_family
    monkeypatch.setattr(ma.ReadStatus1, "READ", True)
    monkeypatch.setattr(ma.ReadStatus1, "REPLY", ma.Status1Reply)
    lean = dataclasses.replace(
        real("myactuator"), parts={}, package=None, commands=(ma.SpeedControl, ma.ReadStatus1)
    )
    for module in (record, families):
        monkeypatch.setattr(module, "get_family", lambda name: lean)
    assert record._default_poll(Connection()) == "read_status1"
    monkeypatch.setattr(record, "get_family", real)
    assert record._default_poll(Connection()) == "read_status2"


@pytest.mark.usefixtures("without_cli_part")
def test_a_family_without_a_cli_part_refuses_the_rest_in_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    err = one_line(capsys, ["speed", "--sim", "1", "--speed-dps", "10"])
    assert err == "servobus speed: error: myactuator motors have no speed command\n"
    err = one_line(capsys, ["config", "get", "--sim", "1", "pid.speed_kp"])
    assert "myactuator motors have no settings the CLI can read or write" in err


def test_a_family_without_status_reads_says_so(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    real = get_family
    monkeypatch.setattr(
        families,
        "get_family",
        lambda name: dataclasses.replace(real(name), parts={}, package=None, commands=(ma.SpeedControl,)),
    )
    err = one_line(capsys, ["status", "--sim", "1"])
    assert "myactuator motors have no status command: none of its commands is declared a read" in err


def test_a_cli_part_of_another_kind_is_named(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    real = get_family
    parts = {"cli": "servobus.protocols:FAMILIES"}
    monkeypatch.setattr(
        families, "get_family", lambda name: dataclasses.replace(real(name), parts=parts, package=None)
    )
    err = one_line(capsys, ["stop", "--sim", "1"], code=1)
    assert "cli part (servobus.protocols:FAMILIES) is dict, not a servobus.cli.plugin.CliFamily" in err
    parts = {"cli": "servobus.protocols.nowhere:CLI"}
    err = one_line(capsys, ["stop", "--sim", "1"], code=1)
    assert "cli part (servobus.protocols.nowhere:CLI): No module named 'servobus.protocols.nowhere'" in err
