"""``--limits FILE`` on the command line: a command beyond a declared limit is refused (one line, exit
2, nothing sent) or clamped (a line says so), through ``--sim``, python-can's virtual bus, a bridge
started with ``--limits`` and a simulator served with ``--limits`` on a pty."""

from __future__ import annotations

import contextlib
import select
import signal
import subprocess
from pathlib import Path
from typing import Any

import pytest

from _ports import free_port as _free_port
from cli._bus_cli import SERVOBUS, one_line, pty_simulators, run, run_json
from cli._virtual import served_on_virtual
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from sim._standins import Sniffer

REFUSE = "[all]\nspeed_dps = 360\n[motor.2]\nposition_deg = [-90, 90]\n"
CLAMP = "clamp = true\n[all]\nspeed_dps = 360\n"


@pytest.fixture
def files(tmp_path: Path) -> tuple[str, str]:
    refuse, clamp = tmp_path / "refuse.toml", tmp_path / "clamp.toml"
    refuse.write_text(REFUSE)
    clamp.write_text(CLAMP)
    return str(refuse), str(clamp)


def test_a_command_beyond_a_limit_is_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str], files: tuple[str, str]
) -> None:
    refuse, _ = files
    err = one_line(capsys, ["speed", "--sim", "2", "--speed-dps", "1000", "--limits", refuse])
    assert "myactuator motor 1: SpeedControl.speed_dps=1000 is beyond the host limit speed_dps 360" in err
    err = one_line(capsys, ["move", "--sim", "2", "--angle-deg", "120", "--limits", refuse])
    assert (
        "motor 2: AbsolutePositionControl.angle_deg=120 is beyond the host limit position_deg [-90, 90]"
        in err
    )
    rows = run_json(
        capsys, ["speed", "--sim", "2", "--speed-dps", "-360", "--duration", "0.3", "--limits", refuse]
    )
    assert [round(r["speed_dps"]) for r in rows] == [-360, -360]


def test_a_clamping_file_sends_the_limit_and_says_so(
    capsys: pytest.CaptureFixture[str], files: tuple[str, str]
) -> None:
    _, clamp = files
    out, err = run(
        capsys,
        ["speed", "--sim", "1", "--speed-dps", "1000", "--duration", "0.3", "--limits", clamp, "--json"],
    )
    assert "servobus: myactuator motor 1: SpeedControl.speed_dps 1000 clamped to 360 (--limits)" in err
    assert '"speed_dps": 360' in out


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("[all]\nspeed = 1\n", "unknown limit 'speed'"),
        ("clamp = maybe\n", "not TOML"),
        (None, "No such file"),
    ],
)
def test_a_bad_limits_file_is_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, text: str | None, says: str
) -> None:
    path = tmp_path / "limits.toml"
    if text is not None:
        path.write_text(text)
    err = one_line(capsys, ["status", "--sim", "1", "--limits", str(path)])
    assert "--limits" in err and says in err


# ---- a real transport path: python-can's virtual bus, the simulated motors served on it ----


def _served_on_virtual(sniffer: Sniffer) -> contextlib.AbstractContextManager[str]:
    """Two simulated MyActuator motors and ``sniffer`` on a python-can virtual channel (named)."""
    return served_on_virtual([MyActuatorMotor(1), MyActuatorMotor(2), sniffer])


def _speeds(sniffer: Sniffer) -> list[float]:
    return [
        int.from_bytes(bytes(f.data[4:8]), "little", signed=True) / 100
        for _, f in list(sniffer.seen)
        if 0x141 <= f.arbitration_id <= 0x160 and f.data[:1] == b"\xa2"
    ]


def test_limits_hold_through_python_can_s_virtual_bus(
    capsys: pytest.CaptureFixture[str], files: tuple[str, str]
) -> None:
    refuse, clamp = files
    sniffer = Sniffer()
    with _served_on_virtual(sniffer) as channel:
        bus = ["-i", "virtual", "-c", channel, "--ids", "1-2", "--timeout-ms", "500"]
        one_line(capsys, ["speed", *bus, "--speed-dps", "-900", "--limits", refuse])
        assert _speeds(sniffer) == []  # refused before anything was sent
        run(capsys, ["speed", *bus, "--speed-dps", "-900", "--duration", "0.3", "--limits", clamp])
    speeds = _speeds(sniffer)
    assert speeds and set(speeds) == {-360.0}


# ---- the bridge and the simulator honour the same file ----


def test_a_bridge_started_with_limits_refuses_a_remote_command_beyond_them(
    capsys: pytest.CaptureFixture[str], files: tuple[str, str]
) -> None:
    pytest.importorskip("zenoh")
    refuse, _ = files
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    args = ["bridge", "--sim", "2", "--node", "lim", "--listen", endpoint, "--limits", refuse]
    process = subprocess.Popen([*SERVOBUS, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert process.stdout is not None
        ready, _, _ = select.select([process.stdout], [], [], 20)
        assert ready and process.stdout.readline().startswith("serving"), process.poll()
        remote = ["--remote", "lim/sim1", "--endpoint", endpoint, "--ids", "1"]
        err = one_line(capsys, ["speed", *remote, "--speed-dps", "1000", "--duration", "0.3"], code=2)
        assert "SpeedControl.speed_dps=1000 is beyond the host limit speed_dps 360" in err
        rows = run_json(capsys, ["speed", *remote, "--speed-dps", "300", "--duration", "0.5"])
        assert rows[0]["speed_dps"] == pytest.approx(300, abs=10)
        process.send_signal(signal.SIGTERM)
        process.communicate(timeout=20)
        assert process.returncode == 0
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()


def test_a_simulator_served_with_limits_keeps_its_motors_within_them(
    capsys: pytest.CaptureFixture[str], files: tuple[str, str]
) -> None:
    refuse, _ = files
    with pty_simulators() as start:
        path = start("--family", "myactuator", "--motors", "2", "--limits", refuse)
        bus = ["-i", "servobus-slcan", "-c", path, "--ids", "1-2"]
        rows: Any = run_json(capsys, ["speed", *bus, "--speed-dps", "900", "--duration", "1"])
    assert [r["speed_dps"] for r in rows] == [pytest.approx(360, abs=10)] * 2


def test_a_setting_beyond_a_field_range_is_refused_by_set_and_restore(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    limits = tmp_path / "pid.toml"
    limits.write_text('clamp = true\n[all]\nfields = { "WritePidRam.value" = [0, 10] }\n')
    err = one_line(capsys, ["config", "set", "--sim", "1", "pid.speed_kp", "99999", "--limits", str(limits)])
    assert "WritePidRam.value=99999 is beyond the host limit fields value [0, 10]" in err  # (never clamped)
    dump = tmp_path / "motor.toml"
    run(capsys, ["config", "dump", "--sim", "1", "-o", str(dump)])
    text = dump.read_text()
    dump.write_text(text.replace('"pid.speed_kp" = 0.5', '"pid.speed_kp" = 99999'))
    err = one_line(capsys, ["config", "restore", str(dump), "--sim", "1", "--yes", "--limits", str(limits)])
    assert (
        "pid.speed_kp = 99999: WritePidRam.value=99999 is beyond the host limit fields value [0, 10]" in err
    )


def test_a_relative_move_beyond_the_range_is_exit_2_once_the_angle_is_read(
    capsys: pytest.CaptureFixture[str], files: tuple[str, str]
) -> None:
    refuse, _ = files
    err = one_line(
        capsys, ["move", "--sim", "1", "--ids", "2", "--angle-deg", "120", "--relative", "--limits", refuse]
    )
    assert "IncrementalPositionControl.angle_deg=120 (to 120 deg from 0) is beyond the host limit" in err


def test_a_sim_bus_given_limits_has_drives_within_them(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, files: tuple[str, str]
) -> None:
    from cli._bus_cli import keep_devices

    refuse, _ = files
    devices = keep_devices(monkeypatch)
    run(capsys, ["status", "--sim", "2", "--limits", refuse])
    assert [d.plant.params.speed_limit_dps for d in devices.last] == [360.0, 360.0]


def test_record_s_rows_say_the_set_point_the_limits_left(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """A speed step past the range: once the motor is out, the range's rule sends 0, and the rows
    say 0, not the wave's value."""
    import csv

    limits = tmp_path / "range.toml"
    limits.write_text("clamp = true\n[all]\nposition_deg = [-90, 90]\n")
    out = tmp_path / "run.csv"
    args = ["record", "--sim", "1", "--drive", "step", "--mode", "speed", "--amplitude-dps", "180"]
    run(capsys, [*args, "--duration", "2.5", "-o", str(out), "--limits", str(limits)])
    rows = list(csv.DictReader(out.open()))
    angles = [float(r["angle_deg"]) for r in rows if r["angle_deg"]]
    assert 90 < max(angles) < 130, max(angles)  # stopped past the edge, not 270 deg on
    last = rows[-1]
    assert float(last["setpoint_speed_dps"]) == 0.0 and abs(float(last["speed_dps"])) < 5
    assert any(float(r["setpoint_speed_dps"]) == 180.0 for r in rows)


def test_restore_names_only_the_motors_it_wrote(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    dump = tmp_path / "two.toml"
    run(capsys, ["config", "dump", "--sim", "2", "-o", str(dump)])
    text = dump.read_text()
    head, motor_2 = text.split("[motor.2]")
    dump.write_text(head + "[motor.2]" + motor_2.replace('"pid.speed_kp" = 0.5', '"pid.speed_kp" = 0.75', 1))
    _, err = run(capsys, ["config", "restore", str(dump), "--sim", "2", "--yes"])
    assert err.splitlines()[-1] == "wrote 1 setting(s) to motor(s) 2, read back the same", err
