"""``servobus config dump`` and ``config restore``: every setting of every simulated family goes to a
file and back, a bad file is one line and exit 2 with nothing written, and ``config list`` piped
keeps its keys whole.

The simulated motors here outlive a command (:class:`Bench`): ``--sim`` joins the same simulated
network each time, as a bench's motors stay powered between two commands.
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path
from typing import Any

import pytest

import servobus.cli._connect as connect
from cli._bus_cli import one_line, run
from servobus.cli import _config_file as cfg
from servobus.cli._families import settings
from servobus.protocols import FAMILIES, get_family
from servobus.protocols.myactuator import PidIndex
from servobus.sim.corenet import CoreCanNetwork
from servobus.transports.sim import SimTransport


class Bench:
    """Simulated motors that stay between commands: one network per (family, ids, revision)."""

    def __init__(self) -> None:
        self.networks: dict[tuple[str, tuple[int, ...], str], tuple[CoreCanNetwork, list[Any]]] = {}
        self.opened = 0

    def transport(self, conn: connect.Connection) -> SimTransport:
        family = get_family(conn.family)
        revision = family.revision(conn.revision) if conn.revision else family.default_revision
        key = (conn.family, conn.motor_ids, revision.name)
        if key not in self.networks:
            devices = connect.sim_devices(conn.family, conn.motor_ids, revision.name)
            self.networks[key] = (CoreCanNetwork(devices), devices)
        self.opened += 1
        return SimTransport(network=self.networks[key][0], name="sim")

    def devices(self, family: str, ids: tuple[int, ...], revision: str) -> list[Any]:
        return self.networks[(family, ids, revision)][1]


@pytest.fixture
def bench(monkeypatch: pytest.MonkeyPatch) -> Bench:
    kept = Bench()
    real = connect.Connection.transport

    def transport(conn: connect.Connection) -> Any:
        return kept.transport(conn) if conn.sim is not None else real(conn)

    monkeypatch.setattr(connect.Connection, "transport", transport)
    return kept


SIMULATED = [
    (name, revision.name)
    for name in FAMILIES
    if "sim" in get_family(name).parts
    for revision in get_family(name).revisions
]

#: a value for each write-only setting (the dump leaves them without one), and where the simulated
#: motor keeps it
WRITE_ONLY: dict[str, tuple[Any, str]] = {
    "comm_timeout_ms": (250, "comm_timeout_ms"),
    "can_id_filter": (True, "can_id_filter"),
    "error_reporting": (True, "error_reporting"),
    "limit.max_positive_angle_raw": (36000, "max_positive_angle"),
    "limit.max_negative_angle_raw": (-36000, "max_negative_angle"),
}

_LINE = re.compile(r'^(# )?("?)([\w.]+)\2 =(.*)$')


def edit(text: str, values: dict[int, dict[str, Any]]) -> str:
    """``text`` (a dump) with the keys of ``values`` (motor id -> key -> value) given new values, by
    line, as a human would: commented-out write-only lines are uncommented."""
    out, motor = [], None
    for line in text.splitlines():
        table = re.fullmatch(r"\[motor\.(\d+)\]", line)
        if table:
            motor = int(table.group(1))
        found = _LINE.match(line)
        if found and motor is not None and found.group(3) in values.get(motor, {}):
            key = found.group(3)
            line = cfg.key_line(key, values[motor][key])
        out.append(line)
    return "\n".join(out) + "\n"


def _candidates(value: Any) -> list[Any]:
    if isinstance(value, bool):
        return [not value]
    if isinstance(value, int):
        return [value // 2, value - 1, value + 1]
    if isinstance(value, float):
        return [value / 2, value + 1.0, value - 1.0]
    if isinstance(value, list):
        return [[v // 2 + 1 for v in value], [v + 1 for v in value]]
    return [500.0]  # "none"


def edited(family: str, revision: str, key: str, value: Any) -> Any:
    """A value other than ``value`` that the setting takes (a different write on the wire)."""
    s = settings(family)[key]
    codec = get_family(family).bind(1, revision=revision)
    before = codec.encode(s.write(s.parse(cfg.text_of(value)), False))  # type: ignore[misc]
    for candidate in _candidates(value):
        try:
            after = codec.encode(s.write(s.parse(cfg.text_of(candidate)), False))  # type: ignore[misc]
        except ValueError:
            continue
        if after != before:
            return candidate
    raise AssertionError(f"no other value for {key} = {value!r}")


def dump(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[str, dict[str, Any]]:
    out, _ = run(capsys, ["config", "dump", *args])
    return out, tomllib.loads(out)


@pytest.mark.parametrize(("family", "revision"), SIMULATED)
def test_dump_edit_restore_round_trips_every_setting(
    capsys: pytest.CaptureFixture[str], bench: Bench, tmp_path: Path, family: str, revision: str
) -> None:
    where = ["--family", family, "--revision", revision, "--sim", "2"]
    if not settings(family):
        assert "no settings" in one_line(capsys, ["config", "dump", *where])
        return
    text, before = dump(capsys, *where)
    assert (before["family"], before["revision"]) == (family, revision)
    assert set(before["motor"]) == {"1", "2"}
    readable = [s for s in settings(family).values() if s.read is not None]
    codec = get_family(family).bind(1, revision=revision)
    present = [s.key for s in readable if _has(codec, s)]
    assert present and set(before["motor"]["1"]) == set(present)  # every setting the revision reports
    write_only = [s.key for s in settings(family).values() if s.read is None]
    assert set(write_only) <= set(WRITE_ONLY)
    for key in write_only:
        assert re.search(rf'^# "?{re.escape(key)}"? =$', text, re.MULTILINE), key
    values = {
        motor: {
            **{
                key: edited(family, revision, key, value)
                for key, value in before["motor"][str(motor)].items()
            },
            **{key: WRITE_ONLY[key][0] for key in write_only},
        }
        for motor in (1, 2)
    }
    values[2] = {key: values[1][key] for key in list(values[1])[:2]}  # motor 2: only two keys change
    path = tmp_path / "edited.toml"
    path.write_text(edit(text, values))
    _, err = run(capsys, ["config", "restore", str(path), "--sim", "2", "--family", family, "--yes"])
    assert "read back the same" in err
    changed = sum(len(v) for v in values.values())
    assert f"wrote {changed} setting(s)" in err
    _, after = dump(capsys, *where)
    for motor in (1, 2):
        for key, value in after["motor"][str(motor)].items():
            expected = values[motor].get(key, before["motor"][str(motor)][key])
            assert value == expected, (motor, key)
    devices = bench.devices(family, (1, 2), revision)
    for key in write_only:
        attribute = WRITE_ONLY[key][1]
        assert getattr(devices[0].rom, attribute) == WRITE_ONLY[key][0], key
    _, err = run(capsys, ["config", "restore", str(path), "--sim", "2", "--family", family, "--yes"])
    # again: only the write-only ones are written (nothing to compare them with)
    assert (f"wrote {len(write_only)} setting(s)" if write_only else "nothing to write") in err


def _has(codec: Any, s: Any) -> bool:
    try:
        codec.encode(s.read())
    except ValueError:
        return False
    return True


@pytest.fixture
def dumped(capsys: pytest.CaptureFixture[str], bench: Bench, tmp_path: Path) -> tuple[Path, str]:
    """A dump of simulated myactuator motors 1 and 2 (the bench keeps them), and its text."""
    path = tmp_path / "motors.toml"
    run(capsys, ["config", "dump", "--sim", "2", "-o", str(path)])
    return path, path.read_text()


@pytest.mark.parametrize(
    ("change", "naming"),
    [
        (lambda t: t.replace('family = "myactuator"', 'family = "lk"'), "holds lk settings and --family is"),
        (lambda t: t.replace('revision = "V4_4"', 'revision = "V4_3"'), "--revision"),
        (lambda t: t.replace('revision = "V4_4"', 'revision = "V9"'), "V9"),
        (
            lambda t: t.replace("speed_acceleration_dps_s = 10000.0", "speed_acceleration_dps_s = 70000"),
            "speed_acceleration_dps_s = 70000: acceleration_dps_s=70000",
        ),
        (lambda t: t.replace('"pid.speed_kp" = 0.5', '"pid.speed_kp" = "fast"'), 'pid.speed_kp = "fast"'),
        (lambda t: t.replace("# comm_timeout_ms =", "comm_timeout_ms = 0"), "comm_timeout_ms = 0"),
        (lambda t: t + '"pid.speed_kpp" = 0.5\n', "no setting 'pid.speed_kpp'"),
        (lambda t: t.replace('"pid.speed_kp" = 0.5', '"pid.speed_kp" = '), "not TOML"),
        (lambda t: t.replace("[motor.2]", "[motor.two]"), "[motor.two]"),
        (lambda t: t.replace('family = "myactuator"\n', ""), "not a settings file"),
        (lambda t: t.replace('"pid.speed_kp" = 0.5', "pid.speed_kp = 2024-01-01"), "pid.speed_kp = datetime"),
        (lambda t: t.replace('"pid.speed_kp" = 0.5', "pid.speed_kp = [{a = 1}]"), "pid.speed_kp = [{"),
        (lambda t: t.replace('"pid.speed_kp" = 0.5', '"pid.speed_kp" = 0.5\npid.speed_kp = 0.6'), "twice"),
    ],
)
def test_a_bad_file_is_one_line_exit_2_and_nothing_written(
    capsys: pytest.CaptureFixture[str],
    bench: Bench,
    dumped: tuple[Path, str],
    change: Any,
    naming: str,
) -> None:
    path, text = dumped
    bad = path.with_name("bad.toml")
    bad.write_text(change(text).replace('"pid.speed_kp" = 0.5\n', '"pid.speed_kp" = 0.75\n', 1))
    opened = bench.opened
    args = ["config", "restore", str(bad), "--sim", "2", "--yes"]
    if "V4_3" in change(text):
        args += ["--revision", "V4_4"]
    assert naming in one_line(capsys, args)
    assert bench.opened == opened  # checked before any bus opened: nothing read, nothing written
    out, _ = run(capsys, ["config", "dump", "--sim", "2"])
    assert out == text  # pid.speed_kp still 0.5


def test_dotted_keys_may_go_unquoted(capsys: pytest.CaptureFixture[str], dumped: tuple[Path, str]) -> None:
    path, text = dumped
    path.write_text(text.replace('"pid.speed_kp" = 0.5', "pid.speed_kp = 0.75"))  # TOML: a table pid
    _, err = run(capsys, ["config", "restore", str(path), "--sim", "2", "--yes"])
    assert "wrote 2 setting(s)" in err
    _, after = dump(capsys, "--sim", "2")
    assert after["motor"]["2"]["pid.speed_kp"] == 0.75


def test_a_file_of_another_family_names_both(
    capsys: pytest.CaptureFixture[str], bench: Bench, tmp_path: Path
) -> None:
    path = tmp_path / "lk.toml"
    run(capsys, ["config", "dump", "--family", "lk", "--sim", "1", "-o", str(path)])
    err = one_line(capsys, ["config", "restore", str(path), "--sim", "1", "--yes"])
    assert "holds lk settings and --family is myactuator: give --family lk" in err


def test_dump_never_overwrites_without_force(
    capsys: pytest.CaptureFixture[str], bench: Bench, tmp_path: Path
) -> None:
    path = tmp_path / "kept.toml"
    path.write_text("mine\n")
    assert "exists (--force overwrites it)" in one_line(
        capsys, ["config", "dump", "--sim", "1", "-o", str(path)]
    )
    assert path.read_text() == "mine\n" and bench.opened == 0
    run(capsys, ["config", "dump", "--sim", "1", "-o", str(path), "--force"])
    assert tomllib.loads(path.read_text())["family"] == "myactuator"


def test_dump_writes_no_file_when_a_motor_does_not_answer(
    capsys: pytest.CaptureFixture[str], bench: Bench, tmp_path: Path
) -> None:
    path = tmp_path / "half.toml"
    run(capsys, ["config", "dump", "--sim", "1"])  # the bench has motor 1 only
    network, devices = bench.networks[("myactuator", (1,), "V4_4")]
    bench.networks[("myactuator", (1, 2), "V4_4")] = (network, devices)  # motor 2: nobody there
    err = one_line(capsys, ["config", "dump", "--sim", "2", "-o", str(path), "--timeout-ms", "20"], code=1)
    assert "motor 2" in err and "nothing written" in err
    assert not path.exists()


def test_dry_run_and_a_declined_question_write_nothing(
    capsys: pytest.CaptureFixture[str], dumped: tuple[Path, str]
) -> None:
    path, text = dumped
    path.write_text(text.replace('"pid.speed_kp" = 0.5', '"pid.speed_kp" = 0.75'))
    out, _ = run(capsys, ["config", "restore", str(path), "--sim", "2", "--dry-run"])
    assert re.search(r"1 │ pid\.speed_kp\s+│ 0\.5\s+│ 0\.75\s+│ RAM", out)
    err = one_line(capsys, ["config", "restore", str(path), "--sim", "2"], code=1)  # stdin: no answer
    assert "not confirmed" in err
    out, _ = run(capsys, ["config", "dump", "--sim", "2"])
    assert out == text


def test_the_question_says_which_writes_reach_rom(
    capsys: pytest.CaptureFixture[str], dumped: tuple[Path, str], monkeypatch: pytest.MonkeyPatch
) -> None:
    path, text = dumped
    path.write_text(
        text.replace('"pid.speed_kp" = 0.5', '"pid.speed_kp" = 0.75').replace(
            "position_acceleration_dps_s = 10000.0", "position_acceleration_dps_s = 2000.0"
        )
    )
    asked: list[str] = []
    monkeypatch.setattr("click.confirm", lambda text, **kw: asked.append(text) or True)
    run(capsys, ["config", "restore", str(path), "--sim", "2"])
    assert "to ROM (kept after power-off): position_acceleration_dps_s" in asked[0]
    assert "pid.speed_kp" not in asked[0]
    asked.clear()
    path.write_text(text.replace('"pid.speed_kp" = 0.5', '"pid.speed_kp" = 0.5'))
    out, _ = run(capsys, ["config", "restore", str(path), "--sim", "2", "--rom"])
    # --rom: the PID gains go to ROM even where RAM holds them already (the ROM cannot be read)
    assert "pid.speed_kp" in asked[0] and "ROM (RAM already holds it)" in out


def test_one_motor_restored_onto_several(
    capsys: pytest.CaptureFixture[str], bench: Bench, tmp_path: Path
) -> None:
    path = tmp_path / "one.toml"
    run(capsys, ["config", "dump", "--sim", "1", "-o", str(path)])
    path.write_text(path.read_text().replace('"pid.speed_kp" = 0.5', '"pid.speed_kp" = 0.75'))
    _, err = run(capsys, ["config", "restore", str(path), "--ids", "1-3", "--sim", "3", "--yes"])
    assert "wrote 3 setting(s) to motor(s) 1, 2, 3" in err
    _, after = dump(capsys, "--ids", "1-3", "--sim", "3")
    assert [after["motor"][m]["pid.speed_kp"] for m in "123"] == [0.75] * 3
    err = one_line(capsys, ["config", "restore", str(path.with_name("many.toml")), "--sim", "1"])
    assert "many.toml" in err
    run(capsys, ["config", "dump", "--ids", "1-3", "--sim", "3", "-o", str(path.with_name("many.toml"))])
    err = one_line(
        capsys, ["config", "restore", str(path.with_name("many.toml")), "--ids", "4", "--sim", "1"]
    )
    assert "has no [motor.4] (it holds 1, 2, 3)" in err


def test_a_read_only_setting_is_dumped_as_a_comment_and_compared_never_written(
    capsys: pytest.CaptureFixture[str], bench: Bench, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import dataclasses

    import servobus.cli.config as config_cli

    known = settings("myactuator")
    known["pid.speed_kp"] = dataclasses.replace(known["pid.speed_kp"], write=None)
    monkeypatch.setattr(config_cli, "settings", lambda family: known)
    path = tmp_path / "ro.toml"
    run(capsys, ["config", "dump", "--sim", "1", "-o", str(path)])
    text = path.read_text()
    assert '# "pid.speed_kp" = 0.5' in text and "read-only" in text
    path.write_text(text.replace('# "pid.speed_kp" = 0.5', '"pid.speed_kp" = 0.75'))
    out, err = run(capsys, ["config", "restore", str(path), "--sim", "1", "--yes"])
    assert "read-only: not written" in out and "nothing to write" in err
    monkeypatch.undo()
    _, after = dump(capsys, "--sim", "1")
    assert after["motor"]["1"]["pid.speed_kp"] == 0.5


def test_config_list_piped_prints_whole_keys(capsys: pytest.CaptureFixture[str]) -> None:
    for family in ("myactuator", "lk"):
        out, _ = run(capsys, ["config", "list", "--family", family])  # capsys: not a terminal
        for key in settings(family):
            assert re.search(rf"│ {re.escape(key)}\s+│", out), key
        assert "…" not in out
        body = [line for line in out.splitlines() if line.startswith("│")]
        assert len(body) == len(settings(family))  # one line per setting: grep finds it whole


class _Stubborn(dict):  # type: ignore[type-arg]
    """A simulated LK motor's control parameters that ignore writes to one of them."""

    def __init__(self, values: dict[Any, Any], ignored: Any) -> None:
        super().__init__(values)
        self.ignored = ignored

    def __setitem__(self, key: Any, value: Any) -> None:
        if key is not self.ignored:
            super().__setitem__(key, value)


def test_a_value_that_does_not_take_is_exit_1_naming_the_key(
    capsys: pytest.CaptureFixture[str], bench: Bench, tmp_path: Path
) -> None:
    from servobus.protocols import lk

    path = tmp_path / "lk.toml"
    where = ["--family", "lk", "--sim", "1"]
    run(capsys, ["config", "dump", *where, "-o", str(path)])
    (motor,) = bench.devices("lk", (1,), "V2_36")
    memory = motor.memory
    memory.control = _Stubborn(memory.control, lk.ControlParam.TORQUE_LIMIT)
    text = path.read_text()
    path.write_text(
        text.replace("torque_limit_counts = 2000", "torque_limit_counts = 1000").replace(
            "speed_ramp_raw = 60000", "speed_ramp_raw = 30000"
        )
    )
    err = one_line(capsys, ["config", "restore", str(path), *where, "--yes"], code=1)
    assert "motor 1: torque_limit_counts did not take (wrote 1000, reads 2000)" in err
    assert "speed_ramp_raw" not in err  # that one took
    _, after = dump(capsys, *where)
    assert after["motor"]["1"]["speed_ramp_raw"] == 30000


@pytest.fixture
def virtual_bench() -> Any:
    """Simulated MyActuator motors 1 and 2 on a python-can ``virtual`` channel, served from a
    thread of their own (the CLI's python-can bus is a real transport path to them)."""
    import can
    from anyio.from_thread import start_blocking_portal

    from servobus.protocols.myactuator.sim import MyActuatorMotor
    from servobus.sim.attach import serve_python_can
    from servobus.sim.network import SimCanNetwork

    channel = f"servobus-config-{id(object())}"
    devices = [MyActuatorMotor(1), MyActuatorMotor(2)]
    sim_side = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    with start_blocking_portal() as portal:
        served = portal.start_task_soon(serve_python_can, SimCanNetwork(devices), sim_side)
        try:
            yield channel, devices
        finally:
            served.cancel()
            sim_side.shutdown()


def test_dump_and_restore_over_python_can_virtual(
    capsys: pytest.CaptureFixture[str], virtual_bench: Any, tmp_path: Path
) -> None:
    channel, devices = virtual_bench
    # python-can's threads on a loaded machine: more than the library's few ms for a reply
    link = ["-i", "virtual", "-c", channel, "--timeout-ms", "1000"]
    where = [*link, "--ids", "1,2"]
    path = tmp_path / "virtual.toml"
    _, err = run(capsys, ["config", "dump", *where, "-o", str(path)])
    assert "2 motor(s)" in err
    text = path.read_text()
    path.write_text(
        text.replace('"pid.speed_kp" = 0.5', '"pid.speed_kp" = 0.75').replace(
            "# comm_timeout_ms =", "comm_timeout_ms = 300", 1
        )
    )
    _, err = run(capsys, ["config", "restore", str(path), *link, "--yes"])
    assert "wrote 3 setting(s) to motor(s) 1, 2, read back the same" in err
    assert [d.ram.pid[PidIndex.SPEED_KP] for d in devices] == [0.75, 0.75]
    assert [d.rom.comm_timeout_ms for d in devices] == [300, 0]
    again, _ = run(capsys, ["config", "dump", *where])
    assert tomllib.loads(again)["motor"]["2"]["pid.speed_kp"] == 0.75
