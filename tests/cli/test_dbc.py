"""``servobus dbc``: the DBC it writes for each family loads in cantools and decodes frames (a simulator
recording for MyActuator and LK, frames built by the hollow codec) to the values servobus decodes, every
field compared (``_dbc_check.check_frame``); bad arguments are one line, exit 2; without cantools, one line
telling how to install it (exit 1)."""

from __future__ import annotations

import json
import math
import re
import sys
from pathlib import Path
from typing import Any

import cantools
import pytest

from _cli_run import invoke, moving_sim, one_line_error
from _dbc_check import check_frame, values_of
from servobus.frame import Frame
from servobus.protocols import hollow as ho
from servobus.protocols.dbc import Layout, MessageSpec, dbc_name
from servobus.tools.dbc import Plan, plan
from servobus.tools.logs import FrameDecoder, read_log


def _spec(p: Plan, frame: Frame) -> MessageSpec:
    return next(
        m for m in p.messages if m.frame_id == frame.arbitration_id and m.extended == frame.is_extended_id
    )


def _check_log(
    p: Plan, database: Any, family: str, logs: list[Path]
) -> set[tuple[str | None, str | None, int | None]]:
    decoder = FrameDecoder(family)
    seen = set()
    for frame in (frame for log in logs for frame in read_log(log)):
        ours = decoder.decode(frame)
        assert ours.message is not None, ours.error
        check_frame(_spec(p, frame), database, frame.data, ours.message)
        seen.add((ours.direction, ours.type, ours.motor_id))
    return seen


def _implied(layout: Layout, data: bytes) -> dict[str, Any]:
    """The fields the multiplexer values of ``data`` stand for, down ``layout``'s tree (every
    multiplexer here is one little-endian byte)."""
    out = dict(layout.implies)
    if layout.mux is not None:
        mux = layout.mux.signal
        assert mux.length == 8 and mux.start % 8 == 0 and mux.byte_order == "little_endian"
        chosen = [sub for sub in layout.mux.layouts if sub.code == data[mux.start // 8]]
        assert len(chosen) == 1, (layout.mux.signal, data.hex())
        out |= _implied(chosen[0], data)
    return out


def _same_names_and_values(database: Any, p: Plan, frame: Frame, ours: Any) -> dict[str, str]:
    """cantools' decode of ``frame`` (by its identifier, from the DBC) against servobus' ``ours``, by
    name: each signal is the servobus field of the same name (``dbc_name``), with its value (enums by
    member name, numbers within 1e-9 of one LSB); each servobus field is a signal or stands for a
    multiplexer value. Returns the fields the DBC names otherwise (field -> signal), each checked to be
    the documented rule: a suffix of multiplexer values, while another signal of the message has the name.
    """
    message = database.get_message_by_frame_id(frame.arbitration_id)
    decoded = message.decode(frame.data)
    ours_values = {dbc_name(k): v for k, v in values_of(ours).items()}
    fields = {dbc_name(k): k for k in values_of(ours)}
    implied = {dbc_name(k): v for k, v in _implied(_spec(p, frame).root, frame.data).items()}
    renamed: dict[str, str] = {}
    seen: set[str] = set()
    for name, value in decoded.items():
        signal = message.get_signal_by_name(name)
        field = name
        if signal.is_multiplexer and name not in ours_values:
            continue  # ``code`` (DATA[0]): its value names the layout, servobus' message class
        if name not in ours_values:
            m = re.fullmatch(r"(.+?)((?:_[0-9A-F]{2})+)", name)
            assert m is not None and m[1] in ours_values, f"{type(ours).__name__}: no field {name}"
            field = m[1]
            assert field not in decoded and any(s.name == field for s in message.signals), name
            renamed[fields[field]] = name
        seen.add(field)
        expected = ours_values[field]
        if expected is None:
            continue  # a raw value servobus reads as "none" (the value check is _dbc_check's)
        if isinstance(expected, bool):
            assert str(value) == str(expected) or value == int(expected), (name, value, expected)
        elif isinstance(expected, str):
            assert str(value) == expected, (name, value, expected)
        else:
            assert math.isclose(value, expected, rel_tol=1e-9, abs_tol=1e-9 * signal.scale), (
                name,
                value,
                expected,
            )
    for field, value in ours_values.items():
        if field not in seen and value is not None:  # None: a value the layout does not carry
            assert field in implied and implied[field] == value, (
                f"{type(ours).__name__}.{fields[field]} = {value!r}: no signal"
            )
    return renamed


def _record(tmp_path: Path, family: str, polls: list[str], revision: str | None = None) -> list[Frame]:
    frames = []
    for poll in polls:
        log = tmp_path / f"{family}-{revision}-{poll}.log"
        args = ["record", "-f", family, "--sim", "4", "--duration", "0.1", "--poll", poll, "--log", str(log)]
        invoke([*args, *(["--revision", revision] if revision else [])])
        frames += read_log(log)
    return frames


@pytest.mark.parametrize(
    ("family", "revision", "polls", "renamed"),
    [
        (
            "myactuator",
            "V4_4",
            ["read_status2", "read_status1", "read_status3", "read_multi_turn_angle"],
            {("MultiTurnAngleReply", "angle_deg"): "angle_deg_92"},
        ),
        ("myactuator", "V4_3", ["read_status2", "read_status1", "read_status3"], {}),
        (
            "lk",
            "V2_36",
            ["read_status2", "read_status1", "read_status3", "read_single_turn_angle"],
            {
                ("Status1Reply", "current_a"): "current_a_9A",  # 0.01 A, status 2's is the motor's iq
                ("SingleTurnAngleReply", "angle_deg"): "angle_deg_94",
            },
        ),
    ],
)
def test_a_recording_decodes_to_servobus_field_names_and_values_in_cantools(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    family: str,
    revision: str,
    polls: list[str],
    renamed: dict[tuple[str, str], str],
) -> None:
    """The DBC's signal names are servobus' field names (issue 25: cantools said ``angle_deg_72`` for
    the 0x9C reply's ``angle_deg``): a simulator recording decoded by cantools from the DBC text and by
    servobus, every field compared by name and value; the fields the DBC must name otherwise (a field
    laid out two ways on one identifier) are named by the documented rule, and are exactly these."""
    moving_sim(monkeypatch)
    text = invoke(["dbc", "-f", family, "--revision", revision, "--ids", "1-4"]).stdout
    database = cantools.database.load_string(text, "dbc")
    p = plan(family, range(1, 5), revision)
    decoder = FrameDecoder(family, revision=revision)
    frames = _record(tmp_path, family, polls, revision)
    seen_renamed: dict[tuple[str, str], str] = {}
    types = set()
    fields = 0
    for frame in frames:
        ours = decoder.decode(frame)
        assert ours.message is not None, ours.error
        names = _same_names_and_values(database, p, frame, ours.message)
        seen_renamed |= {(type(ours.message).__name__, k): v for k, v in names.items()}
        types.add((ours.direction, ours.type))
        fields += len(values_of(ours.message))
    assert seen_renamed == renamed
    assert len(types) == 2 * len(polls) and fields > 200, (types, fields)


def test_the_myactuator_dbc_decodes_a_recording_as_servobus_does(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    moving_sim(monkeypatch)
    dbc = tmp_path / "myactuator.dbc"
    result = invoke(["dbc", "--family", "myactuator", "--ids", "1-4", "-o", str(dbc)])
    assert result.stderr.startswith("dbc: 17 messages -> ") and "0xB5" in result.stderr
    logs = [tmp_path / "status2.log", tmp_path / "status1.log"]
    for poll, log in zip(["read_status2", "read_status1"], logs, strict=True):
        invoke(["record", "--sim", "4", "--duration", "0.08", "--poll", poll, "--log", str(log)])
    database = cantools.database.load_file(dbc)
    seen = _check_log(plan("myactuator", range(1, 5)), database, "myactuator", logs)
    assert {(d, t) for d, t, _ in seen} == {
        ("request", "ReadStatus2"),
        ("reply", "StatusReply"),
        ("request", "ReadStatus1"),
        ("reply", "Status1Reply"),
    }
    assert {m for _, _, m in seen} == {1, 2, 3, 4}
    motion = database.get_message_by_name("myactuator_motion_command_3")
    assert motion.frame_id == 0x403 and motion.get_signal_by_name("kd").scale == 50 / 4095


def test_the_lk_dbc_decodes_a_recording_as_servobus_does(tmp_path: Path) -> None:
    dbc = tmp_path / "lk.dbc"
    result = invoke(["dbc", "--family", "lk", "--ids", "1-4", "-o", str(dbc)])
    assert result.stderr.startswith("dbc: 8 messages -> ")
    log = tmp_path / "lk.log"
    invoke(["record", "--family", "lk", "--sim", "4", "--duration", "0.08", "--log", str(log)])
    database = cantools.database.load_file(dbc)
    seen = _check_log(plan("lk", range(1, 5)), database, "lk", [log])
    assert {(d, t) for d, t, _ in seen} == {("request", "ReadStatus2"), ("reply", "Status2Reply")}
    assert {m for _, _, m in seen} == {1, 2, 3, 4}


def test_the_lk_v235_dbc_holds_the_replies_unless_asked_for_the_requests(tmp_path: Path) -> None:
    result = invoke(["dbc", "--family", "lk", "--revision", "V2_35", "--model", "MF", "--ids", "1-2"])
    database = cantools.database.load_string(result.stdout, "dbc")
    assert [m.name for m in database.messages] == ["lk_reply_1", "lk_reply_2", "lk_multi_motor"]
    assert "requests on 0x140+ID" in result.stderr
    assert (
        database.get_message_by_name("lk_multi_motor").get_signal_by_name("currents_a_0").scale == 33 / 4096
    )
    out = tmp_path / "requests.dbc"
    summary = json.loads(
        invoke(
            ["dbc", "-f", "lk", "--revision", "V2_35", "--direction", "request", "--json", "-o", str(out)]
        ).stdout
    )
    assert summary["messages"] == ["lk_request_1", "lk_multi_motor"] and summary["left_out"] == []


@pytest.mark.parametrize("mode", ["normal", "extended", "fd"])
def test_the_hollow_dbc_decodes_frames_of_the_codec_as_servobus_does(tmp_path: Path, mode: str) -> None:
    dbc = tmp_path / f"hollow-{mode}.dbc"
    result = invoke(
        ["dbc", "--family", "hollow", "--can-mode", mode, "--model", "3507", "--ids", "1-4", "-o", str(dbc)]
    )
    assert result.stderr.startswith("dbc: 9 messages -> ")
    database = cantools.database.load_file(dbc)
    model = ho.MODEL_3507
    frames = []
    for motor_id in range(1, 5):
        x = motor_id / 8
        if mode == "fd":
            command: Any = ho.FdCommand(
                position_deg=-720.5 * x,
                velocity_rpm=30 * x,
                current_raw=-100,
                mode=ho.ControlMode.POSITION,
                run=True,
                kp=9,
                kd=2,
                model=model,
            )
            reply: Any = ho.FdReply(
                position_deg=100 * x,
                velocity_rpm=-12 * x,
                temperature_c=-20,
                running=True,
                slave_id=motor_id,
                model=model,
            )
        elif mode == "normal":
            command = ho.Setpoint(
                position_deg=90 * x, speed_rad_s=-5 * x, kp=100, kd=3, current_a=x, model=model
            )
            reply = ho.NormalReply(
                motor_id=motor_id, position_deg=-45 * x, speed_rad_s=2 * x, current_a=-x, model=model
            )
        else:
            command = ho.IncrementalSetpoint(
                step_deg=-10 * x, speed_rad_s=5 * x, kp=1, kd=0, current_a=x, model=model
            )
            reply = ho.ExtendedReply(
                motor_id=motor_id, position_deg=-5000.25 * x, speed_rad_s=x, current_a=2 * x, model=model
            )
        frames += [
            ho.codec.request_frame(motor_id, command),
            ho.codec.request_frame(motor_id, ho.PiMultiplier(gain=ho.PiGain.CURRENT_KI, multiplier=1.25)),
            ho.codec.request_frame(motor_id, ho.CanModeSwitch(mode=ho.CanMode.EXTENDED)),
            ho.codec.reply_frame(ho.DEFAULT_HOST_ID, reply),
        ]
    p = plan("hollow", range(1, 5), model="3507", can_mode=mode)
    can_mode = ho.CanMode.EXTENDED if mode == "extended" else ho.CanMode.NORMAL
    for frame in frames:
        if frame.arbitration_id == ho.DEFAULT_HOST_ID:
            ours: Any = ho.codec.decode_reply_frame(frame, model=model)
        else:
            ours = ho.codec.decode_request_frame(frame, model=model, can_mode=can_mode)
        check_frame(_spec(p, frame), database, frame.data, ours)
    assert database.get_message_by_frame_id(1).is_fd == (mode == "fd")


def test_stdout_and_a_json_summary(tmp_path: Path) -> None:
    text = invoke(["dbc", "--revision", "V4_3"]).stdout
    database = cantools.database.load_string(text, "dbc")
    assert [m.frame_id for m in database.messages] == [0x141, 0x241, 0x401, 0x501, 0x280]
    result = invoke(["dbc", "--ids", "1-2", "--json", "-o", str(tmp_path / "ma.dbc")])
    summary = json.loads(result.stdout)
    assert summary["messages"] == [
        "myactuator_request_1",
        "myactuator_reply_1",
        "myactuator_motion_command_1",
        "myactuator_motion_reply_1",
        "myactuator_request_2",
        "myactuator_reply_2",
        "myactuator_motion_command_2",
        "myactuator_motion_reply_2",
        "myactuator_broadcast",
    ]
    assert any("0xB5" in reason for reason in summary["left_out"])
    # The CAN motion-mode frames are in the DBC; only the RS485 ones are left out.
    assert [r for r in summary["left_out"] if "motion" in r.lower()] == [
        "RS485 MIT frames (Rs485MotionCommand, Rs485MotionReply): serial frames, not CAN"
    ]


def test_max_torque_sets_the_v44_motion_torque_range() -> None:
    text = invoke(["dbc", "--max-torque", "60", "--ids", "3"]).stdout
    torque = (
        cantools.database.load_string(text, "dbc")
        .get_message_by_frame_id(0x403)
        .get_signal_by_name("torque_ff_nm")
    )
    assert (torque.minimum, torque.maximum, torque.scale) == (-60, 60, 120 / 4095)


def test_an_option_by_name_is_the_same_as_its_flag_and_the_help_lists_each_familys() -> None:
    by_flag = invoke(["dbc", "--family", "hollow", "--can-mode", "fd", "--host-id", "5", "--ids", "1-2"])
    by_name = invoke(["dbc", "--family", "hollow", "-O", "can_mode=fd", "-O", "host_id=5", "--ids", "1-2"])
    assert by_flag.stdout == by_name.stdout and "BusType" in by_name.stdout
    torque = invoke(["dbc", "-O", "max_torque_nm=60"]).stdout
    assert torque == invoke(["dbc", "--max-torque", "60"]).stdout
    help_text = invoke(["dbc", "--help"]).stdout
    for family, option in (("myactuator", "max_torque_nm"), ("lk", "encoder_bits"), ("hollow", "can_mode")):
        section = help_text.split(f"--family {family}:")[1]
        assert f"-O {option}=..." in section.split("--family ")[0]


def test_without_cantools_one_line_says_how_to_install(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setitem(sys.modules, "cantools", None)
    err = one_line_error(capsys, ["dbc", "-o", str(tmp_path / "x.dbc")], code=1)
    assert "pip install 'servobus[dbc]'" in err
    assert not (tmp_path / "x.dbc").exists()


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["--family", "bogus"], "bogus"),
        (["--revision", "V9"], "no revision"),
        (["--family", "lk", "--revision", "V4_4"], "no revision"),
        (["--ids", "0-2"], "motor_id"),
        (["--family", "lk", "--ids", "33"], "motor_id"),
        (["--family", "hollow", "--ids", "99-101"], "motor_id"),
        (["--family", "hollow", "--ids", "1-4,100"], "host id"),
        (["--family", "hollow", "--host-id", "2048"], "host_id"),
        (["--family", "hollow", "--model", "HO9999"], "no model"),
        (["--family", "lk", "--model", "XY"], "motor type"),
        (["--family", "lk", "--encoder-bits", "13"], "encoder_bits"),
        (["--family", "lk", "--can-mode", "fd"], "--can-mode is an option of hollow"),
        # (other installed families with a model option come first: "of dm, lk and hollow")
        (["--family", "myactuator", "--model", "MG"], "lk and hollow, not of myactuator"),
        (["--family", "hollow", "--max-torque", "3"], "--max-torque is an option of myactuator"),
        (["--revision", "V4_3", "--max-torque", "3"], "V4.4"),
        (["--family", "hollow", "--can-mode", "turbo"], "--can-mode"),
        (["--direction", "sideways"], "--direction"),
        (["--family", "hollow", "-O", "host_id=x"], "host_id: invalid literal"),
        (["-O", "nonsense"], "is not NAME=VALUE"),
        (["-O", "speed=3"], "speed is not an option of myactuator"),
        (["-O", "can_mode=fd"], "can_mode is an option of hollow, not of myactuator"),
        (["--ids", "x"], "--ids"),
        (["--json"], "give -o"),
        (["-o", "exists.dbc"], "exists"),
    ],
)
def test_bad_arguments_are_one_line_and_exit_2(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    args: list[str],
    says: str,
) -> None:
    monkeypatch.chdir(tmp_path)
    Path("exists.dbc").write_text("mine")
    assert says in one_line_error(capsys, ["dbc", *args])
    assert Path("exists.dbc").read_text() == "mine"
