"""``servobus config`` against the simulator: settings read back, writes reach the motor (ROM ones only
when confirmed), and a bad key, value or revision is one line, exit 2, with nothing sent."""

from __future__ import annotations

import pytest

from cli._bus_cli import Devices, keep_devices, one_line, run, run_json
from servobus.protocols.myactuator import AccelIndex, PidIndex


@pytest.fixture
def devices(monkeypatch: pytest.MonkeyPatch) -> Devices:
    return keep_devices(monkeypatch)


def test_list_names_every_key_of_the_family(capsys: pytest.CaptureFixture[str]) -> None:
    keys = {row["key"]: row for row in run_json(capsys, ["config", "list"])}
    assert {f"pid.{i.name.lower()}" for i in PidIndex} <= set(keys)
    assert {f"{a.name.lower()}_dps_s" for a in AccelIndex} <= set(keys)
    assert {"comm_timeout_ms", "can_id_filter", "limit.max_positive_angle_raw"} <= set(keys)
    assert keys["comm_timeout_ms"]["rom"] == "always" and not keys["comm_timeout_ms"]["read"]
    lk_keys = {row["key"] for row in run_json(capsys, ["config", "list", "--family", "lk"])}
    assert {"pid.speed", "torque_limit_counts", "acceleration_dps2"} <= lk_keys
    out, _ = run(capsys, ["config", "list"])
    assert "pid.speed_kp" in out


def test_get_reads_each_key_of_each_motor(capsys: pytest.CaptureFixture[str]) -> None:
    rows = run_json(capsys, ["config", "get", "--sim", "2", "pid.speed_kp", "speed_acceleration_dps_s"])
    assert [(r["id"], r["key"]) for r in rows] == [
        (1, "pid.speed_kp"),
        (1, "speed_acceleration_dps_s"),
        (2, "pid.speed_kp"),
        (2, "speed_acceleration_dps_s"),
    ]
    assert all(isinstance(r["value"], float) and r["error"] is None for r in rows)
    lk = run_json(
        capsys, ["config", "get", "--family", "lk", "--sim", "1", "pid.speed", "torque_limit_counts"]
    )
    assert set(lk[0]["value"]) == {"kp", "ki", "kd"} and isinstance(lk[1]["value"], int)
    v235 = run_json(
        capsys, ["config", "get", "--family", "lk", "--revision", "V2_35", "--sim", "1", "acceleration_dps2"]
    )
    assert isinstance(v235[0]["value"], float)


def test_set_writes_ram_without_asking_and_rom_only_when_confirmed(
    capsys: pytest.CaptureFixture[str], devices: Devices
) -> None:
    run_json(capsys, ["config", "set", "--sim", "1", "pid.speed_kp", "0.25"])
    motor = devices.last[0]
    assert motor.ram.pid[PidIndex.SPEED_KP] == pytest.approx(0.25)
    assert motor.rom.pid[PidIndex.SPEED_KP] != pytest.approx(0.25)
    made = len(devices.made)
    err = one_line(capsys, ["config", "set", "--sim", "1", "pid.speed_kp", "0.25", "--rom"], code=1)
    assert "not confirmed" in err and len(devices.made) == made  # asked first: no bus opened
    run_json(capsys, ["config", "set", "--sim", "1", "pid.speed_kp", "0.25", "--rom", "--yes"])
    run_json(capsys, ["config", "set", "--sim", "1", "comm_timeout_ms", "200", "--yes"])
    assert devices.last[0].rom.comm_timeout_ms == 200
    rows = run_json(capsys, ["config", "set", "--sim", "1", "comm_timeout_ms", "off", "--yes"])
    assert rows[0]["value"] == "off" and devices.last[0].rom.comm_timeout_ms == 0
    run_json(capsys, ["config", "set", "--sim", "1", "can_id_filter", "off", "--yes"])
    assert devices.last[0].rom.can_id_filter is False
    run_json(capsys, ["config", "set", "--family", "lk", "--sim", "1", "pid.speed", "100,20,0"])


@pytest.mark.parametrize(
    ("args", "naming"),
    [
        (["config", "get", "--sim", "1", "nope"], "no setting 'nope'"),
        (["config", "get", "--sim", "1", "comm_timeout_ms"], "cannot report"),
        (["config", "get", "--sim", "1"], "KEY"),
        (["config", "set", "--sim", "1", "comm_timeout_ms", "0", "--yes"], "timeout_ms=0"),
        (["config", "set", "--sim", "1", "position_acceleration_dps_s", "50", "--yes"], "acceleration_dps_s"),
        (["config", "set", "--sim", "1", "pid.speed_kp", "fast"], "VALUE"),
        (["config", "set", "--sim", "1", "can_id_filter", "maybe", "--yes"], "not on or off"),
        (["config", "set", "--sim", "1", "comm_timeout_ms", "200", "--rom", "--yes"], "--rom"),
        (["config", "set", "--family", "lk", "--sim", "1", "pid.speed", "1,2"], "kp,ki,kd"),
        (["config", "get", "--family", "lk", "--sim", "1", "acceleration_dps2"], "V2_35"),
        (["config", "get", "--family", "hollow", "--sim", "1", "x"], "hollow motors have no settings"),
        (["config", "list", "--family", "hollow"], "hollow motors have no settings"),
        (["config", "frobnicate"], "frobnicate"),
    ],
)
def test_bad_keys_and_values_are_one_line_and_exit_2_with_nothing_sent(
    capsys: pytest.CaptureFixture[str], devices: Devices, args: list[str], naming: str
) -> None:
    assert naming in one_line(capsys, args, code=2)
    assert not devices.made
