"""``servobus record --drive``: the motors follow a wave sent through the family's own move/speed, each
reply row carries the set-point last sent to its motor (the very value the log's request frames
carry), the Bus's safe stop goes out at the end and on Ctrl-C/SIGTERM, and ``servobus plot`` draws
the set-points dashed beside the responses. Through the in-process simulator and python-can's
``virtual`` bus with simulated motors attached."""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import anyio
import can
import pytest

from _cli_run import invoke, one_line_error
from cli._bus_cli import Devices, keep_devices, run
from servobus.bus import Bus
from servobus.cli.plot import draw, read_rows
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim.attach import serve_python_can
from servobus.sim.network import SimCanNetwork
from servobus.sim.plant import PositionControl, SpeedControl
from servobus.tools.recording import TelemetryWriter
from servobus.transports.can import message_from_frame

SCRIPT = [sys.executable, "-c", "import sys; from servobus.cli import main; sys.exit(main())"]
#: the README's record -> plot example, word for word (also on docs/recording.md)
README = (
    "servobus record --sim 4 --drive sine --stagger --duration 3 -o run.csv",
    "servobus plot run.csv -o run.png",
)
#: tab10's first four colours: motors 1-4 in a plot
MOTOR_COLOURS = ((0x1F, 0x77, 0xB4), (0xFF, 0x7F, 0x0E), (0x2C, 0xA0, 0x2C), (0xD6, 0x27, 0x28))


def _csv(path: Path) -> list[dict[str, Any]]:
    return read_rows(path)


def _by_motor(rows: list[dict[str, Any]]) -> dict[int, list[dict[str, Any]]]:
    out: dict[int, list[dict[str, Any]]] = {}
    for row in rows:
        out.setdefault(row["motor_id"], []).append(row)
    return out


def _sent_setpoints(log: Path, field: str) -> dict[int, list[tuple[dict[str, Any], float | None]]]:
    """For each status reply in the log, per motor: its fields, and the ``field`` of the last request
    to that motor that carried one (what was in effect when the reply came), in the log's order."""
    decoded = [json.loads(line) for line in invoke(["decode", "--json", str(log)]).stdout.splitlines()]
    last: dict[int, float] = {}
    out: dict[int, list[tuple[dict[str, Any], float | None]]] = {}
    for record in decoded:
        motor = record["motor_id"]
        if record["direction"] == "request" and field in record["fields"]:
            last[motor] = record["fields"][field]
        elif record["direction"] == "reply" and record["type"] == "StatusReply":
            out.setdefault(motor, []).append((record["fields"], last.get(motor)))
    return out


def _matches_the_log(telemetry: Path, log: Path, column: str, field: str) -> None:
    """Each row's set-point is the one in effect when its reply came, in the log: the rows and the
    log's replies walked together, each row found by its fields (a reply the Bus did not make a row
    of, such as a duplicate on a contended bus, is skipped: two at most)."""
    rows = _by_motor(read_rows(telemetry))
    sent = _sent_setpoints(log, field)
    assert sorted(rows) == sorted(sent)
    for motor, mine in rows.items():
        replies = iter(sent[motor])
        skipped = 0
        assert len(mine) >= 10
        for row in mine:
            fields = {k: v for k, v in row.items() if k not in ("time_s", "motor_id", "family", "reply")}
            fields = {k: v for k, v in fields.items() if not k.startswith("setpoint_")}
            value: float | None = None
            for theirs, effective in replies:
                if theirs == fields:
                    value = effective
                    break
                skipped += 1
            else:
                raise AssertionError(f"motor {motor}: no reply in the log for {row}")
            if value is None:  # (nothing sent to it yet)
                assert row[column] is None, (motor, row)
            else:
                assert row[column] == pytest.approx(value, abs=0.006), (motor, row)
        assert skipped <= 2, (motor, skipped)


def test_the_readme_example_moves_the_motors_and_plots_the_set_points(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    root = Path(__file__).resolve().parents[2]
    for page in ("README.md", "docs/recording.md"):  # (the example as both show it)
        text = (root / page).read_text(encoding="utf-8")
        assert all(line in text for line in README), page
    monkeypatch.chdir(tmp_path)
    record, plot = (line.split()[1:] for line in README)
    result = invoke(record)
    assert result.stderr.startswith("record: driven (sine, position 0 ± 90 deg, period 2 s)")
    assert result.stderr.rstrip().endswith("-> run.csv; stop sent to myactuator motors 1-4 on sim")
    rows = _by_motor(_csv(tmp_path / "run.csv"))
    assert sorted(rows) == [1, 2, 3, 4]
    for motor, mine in rows.items():
        assert len(mine) >= 200  # 100 Hz for 3 s
        setpoints = [row["setpoint_angle_deg"] for row in mine]
        angles = [row["angle_deg"] for row in mine]
        assert min(setpoints) <= -85 and max(setpoints) >= 85, motor  # a whole period and more
        assert max(angles) - min(angles) >= 150, motor  # the motor follows
        late = [abs(row["angle_deg"] - row["setpoint_angle_deg"]) for row in mine[len(mine) // 3 :]]
        assert max(late) < 30, motor  # once started, within a few ticks' lag of the set-point
    # --stagger: the motors' waves are apart (a quarter period over 4 motors)
    assert rows[1][-1]["setpoint_angle_deg"] != rows[2][-1]["setpoint_angle_deg"]
    invoke(plot)
    image = tmp_path / "run.png"
    assert image.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    import matplotlib.image
    import numpy as np

    pixels = (matplotlib.image.imread(image)[:, :, :3] * 255).round().astype(int)
    for colour in MOTOR_COLOURS:  # every motor's line is there, not a blank figure
        assert int((np.abs(pixels - colour).sum(axis=2) <= 6).sum()) >= 500, colour


def test_the_figure_draws_each_motor_s_set_point_dashed_in_its_colour(tmp_path: Path) -> None:
    """Through :func:`servobus.cli.plot.draw`, the lines the PNG is made of."""
    path = tmp_path / "run.csv"
    wave = ["--drive", "square", "--amplitude-deg", "30", "--period-s", "1"]
    invoke(["record", "--sim", "2", *wave, "--duration", "1.2", "-o", str(path)])
    figure = draw(read_rows(path), title="t")
    assert figure is not None
    position, speed, current = figure.axes[:3]
    solid = [line for line in position.get_lines() if line.get_linestyle() == "-"]
    dashed = [line for line in position.get_lines() if line.get_linestyle() == "--"]
    assert len(solid) == len(dashed) == 2
    for response, target in zip(solid, dashed, strict=True):
        assert response.get_color() == target.get_color()
        assert set(target.get_ydata()) == {-30.0, 30.0}  # the square wave, as sent
        assert max(response.get_ydata()) - min(response.get_ydata()) > 40  # the motor moved
    assert [line.get_linestyle() for line in speed.get_lines()] == ["-", "-"]  # (no speed set-point)
    labels = [text.get_text() for text in position.get_legend().get_texts()]
    assert labels == ["motor 1", "motor 2", "set-point"]
    assert current.get_lines()


def test_a_set_point_is_drawn_in_the_response_s_unit() -> None:
    """hollow replies give speed in rad/s, the drive's set-point is in dps: drawn in rad/s."""
    rows = [
        {"time_s": t, "motor_id": 1, "position_deg": 0.0, "speed_rad_s": 3.0, "setpoint_speed_dps": 180.0}
        for t in (0.0, 0.1)
    ]
    figure = draw(rows, title="t")
    assert figure is not None
    (target,) = [line for line in figure.axes[1].get_lines() if line.get_linestyle() == "--"]
    assert list(target.get_ydata()) == pytest.approx([math.pi, math.pi])


def test_a_recording_without_set_points_draws_none(tmp_path: Path) -> None:
    path = tmp_path / "ro.csv"
    invoke(["record", "--sim", "1", "--duration", "0.1", "-o", str(path)])
    figure = draw(read_rows(path), title="t")
    assert figure is not None
    assert all(line.get_linestyle() == "-" for ax in figure.axes for line in ax.get_lines())


@pytest.mark.parametrize(
    ("args", "column", "field"),
    [
        (["--drive", "sine", "--period-s", "0.5"], "setpoint_angle_deg", "angle_deg"),
        (["--drive", "square", "--mode", "speed", "--amplitude-dps", "120", "--period-s", "0.4"],
         "setpoint_speed_dps", "speed_dps"),
        (["--drive", "step", "--offset-deg", "10", "--amplitude-deg", "-20", "--period-s", "0.4"],
         "setpoint_angle_deg", "angle_deg"),
    ],
    ids=["sine", "speed square", "step"],
)  # fmt: skip
def test_each_row_s_set_point_is_the_one_the_log_s_request_carried(
    tmp_path: Path, args: list[str], column: str, field: str
) -> None:
    telemetry, log = tmp_path / "run.jsonl", tmp_path / "run.log"
    invoke(["record", "--sim", "2", *args, "--duration", "0.6", "-o", str(telemetry), "--log", str(log)])
    _matches_the_log(telemetry, log, column, field)
    values = {row[column] for row in read_rows(telemetry)}
    assert len(values) >= 2  # it moved
    assert {row["reply"] for row in read_rows(telemetry)} == {"StatusReply"}  # (not the stop's Echo)


def test_the_square_and_step_waves_take_the_values_asked(tmp_path: Path) -> None:
    path = tmp_path / "speed.csv"
    args = ["--mode", "speed", "--amplitude-dps", "120", "--offset-dps", "30", "--period-s", "0.4"]
    invoke(["record", "--sim", "1", "--drive", "square", *args, "--duration", "0.6", "-o", str(path)])
    assert {row["setpoint_speed_dps"] for row in _csv(path)} == {150.0, -90.0}
    path = tmp_path / "step.csv"
    invoke(["record", "--sim", "1", "--drive", "step", "--amplitude-deg", "45", "--period-s", "0.6",
            "--duration", "0.6", "-o", str(path)])  # fmt: skip
    values = [row["setpoint_angle_deg"] for row in _csv(path)]
    assert values[0] == 0.0 and values[-1] == 45.0 and values == sorted(values)  # held after the step


@pytest.mark.parametrize("family", ["hollow", "lk"])
def test_other_families_are_driven_through_their_own_move(tmp_path: Path, family: str) -> None:
    """hollow has no read to poll: its set-point's reply is the status; LK's move reads its angle."""
    path = tmp_path / "run.jsonl"
    result = invoke(["record", "--family", family, "--sim", "2", "--drive", "sine", "--duration", "0.5",
                     "-o", str(path)])  # fmt: skip
    assert f"stop sent to {family} motors 1, 2 on sim" in result.stderr
    rows = _csv(path)
    assert {row["motor_id"] for row in rows} == {1, 2}
    assert len({row["setpoint_angle_deg"] for row in rows}) > 10


def test_a_csv_of_two_reply_kinds_keeps_both(tmp_path: Path) -> None:
    """LK's move reads the multi-turn angle beside its set-point: one CSV holds both kinds of row,
    each blank where it has no value, and the position panel draws the angle."""
    path = tmp_path / "lk.csv"
    result = invoke(["record", "--family", "lk", "--sim", "1", "--drive", "sine", "--duration", "0.5",
                     "-o", str(path)])  # fmt: skip
    assert "left out of the CSV" not in result.stderr
    rows = read_rows(path)
    kinds = {row["reply"] for row in rows}
    assert kinds == {"Status2Reply", "MultiTurnAngleReply"}
    angles = [row for row in rows if row["reply"] == "MultiTurnAngleReply"]
    assert len(angles) >= 20 and all(isinstance(row["angle_deg"], float | int) for row in angles)
    assert all(row["speed_dps"] is None for row in angles)  # (a column of the other kind: blank)
    assert all(row["setpoint_angle_deg"] is not None for row in rows)
    figure = draw(rows, title="t")
    assert figure is not None and figure.axes[0].get_ylabel() == "angle_deg"


def test_the_telemetry_writer_holds_the_header_for_the_kinds_asked() -> None:
    text = io.StringIO()
    writer = TelemetryWriter(text, "csv", reply_types=2)
    writer.write({"time_s": 0.0, "reply": "A", "a": 1})
    assert text.getvalue() == ""  # held: the other kind may bring columns
    writer.write({"time_s": 0.1, "reply": "B", "b": 2})
    writer.write({"time_s": 0.2, "reply": "C", "c": 3})  # a column the header lacks: left out
    writer.write({"time_s": 0.3, "reply": "A", "a": 4})
    assert text.getvalue().splitlines() == ["time_s,reply,a,b", "0.0,A,1,", "0.1,B,,2", "0.3,A,4,"]
    assert (writer.count, writer.skipped) == (3, 1)
    alone = io.StringIO()
    held = TelemetryWriter(alone, "csv", reply_types=3)
    held.write({"time_s": 0.0, "a": 1})
    held.flush()  # (the end of a recording that never saw the other kinds)
    assert alone.getvalue().splitlines() == ["time_s,a", "0.0,1"]


def test_a_set_point_whose_reply_has_no_status_is_polled_beside() -> None:
    """The poll goes out with the set-point only where the set-point's reply says no position, speed
    or current (an Echo): record asks :meth:`Drive.shows_status`."""
    from servobus.cli._drive import Drive, Wave
    from servobus.cli.plugin import setpoint

    wave = Wave("sine", 1.0, 0.0, 1.0)
    codec = ma.FAMILY.bind(1)
    status = Drive(
        wave,
        "position",
        setpoint(lambda c, v: ma.AbsolutePositionControl(angle_deg=v["angle_deg"], max_speed_dps=90.0)),
        1.0,
    )
    echo = Drive(wave, "position", setpoint(lambda c, v: ma.BrakeLock()), 1.0)
    assert status.shows_status(codec) and not echo.shows_status(codec)


# ---- --limits ----

LIMITS = "[all]\nposition_deg = [-45, 45]\nspeed_dps = 360\n"


@pytest.mark.parametrize(
    ("clamp", "args", "says"),
    [
        (
            False,
            [],
            "myactuator motor 1: the wave reaches angle_deg=90: AbsolutePositionControl.angle_deg=90",
        ),
        (True, [], "the wave reaches angle_deg=90, which --limits clamps to 45: a smaller wave"),
        (False, ["--amplitude-deg", "40", "--max-speed-dps", "400"], "max_speed_dps=400 is beyond"),
        (
            True,
            ["--mode", "speed", "--amplitude-dps", "400"],
            "the wave reaches speed_dps=400, which --limits",
        ),
    ],
)
def test_a_wave_beyond_the_limits_is_one_line_and_exit_2_with_nothing_sent(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    clamp: bool,
    args: list[str],
    says: str,
) -> None:
    """The rows say what was sent: a wave the limits would refuse or clamp is refused before it starts."""
    limits = tmp_path / "limits.toml"
    limits.write_text(("clamp = true\n" if clamp else "") + LIMITS)
    devices = keep_devices(monkeypatch)
    output = tmp_path / "x.csv"
    full = ["record", "--sim", "2", "--drive", "sine", *args, "--limits", str(limits), "-o", str(output)]
    assert says in one_line_error(capsys, full)
    assert not output.exists() and devices.made == []


def test_a_wave_within_the_limits_runs_with_their_speed_limit(tmp_path: Path) -> None:
    """Without --max-speed-dps the set-points carry the limits' speed; clamped, another field is said."""
    limits, log = tmp_path / "limits.toml", tmp_path / "run.log"
    limits.write_text(LIMITS)
    args = ["record", "--sim", "1", "--drive", "sine", "--amplitude-deg", "40", "--limits", str(limits)]
    invoke([*args, "--duration", "0.3", "--log", str(log)])
    decoded = [json.loads(line) for line in invoke(["decode", "--json", str(log)]).stdout.splitlines()]
    moves = [r["fields"] for r in decoded if r["type"] == "AbsolutePositionControl"]
    assert moves and {m["max_speed_dps"] for m in moves} == {360.0}
    assert max(abs(m["angle_deg"]) for m in moves) <= 40.0
    limits.write_text("clamp = true\n" + LIMITS)
    result = invoke([*args, "--max-speed-dps", "400", "--duration", "0.1", "-o", str(tmp_path / "c.csv")])
    said = "servobus: myactuator motor 1: AbsolutePositionControl.max_speed_dps 400 clamped to 360 (--limits)"
    assert result.stderr.splitlines()[0] == said


# ---- through python-can's virtual bus, the simulated motors attached on another thread ----


#: the speeds another controller sends motor 1, in turn, every 20 ms (``virtual_motors(foreign=True)``)
FOREIGN_SPEEDS_DPS = (30.0, 60.0, 90.0)


@contextlib.contextmanager
def _virtual_motors(*, foreign: bool = False) -> Iterator[str]:
    """Simulated MyActuator motors 1 and 2 on a python-can ``virtual`` channel (returned), served on
    a thread of their own, as another node on the bus would be; ``foreign``: with another controller
    on that thread sending motor 1 speed set-points (:data:`FOREIGN_SPEEDS_DPS`)."""
    channel = f"record-drive-{os.getpid()}-{time.monotonic_ns()}"
    ready, stop = threading.Event(), threading.Event()
    devices = [MyActuatorMotor(1), MyActuatorMotor(2)]

    def serve() -> None:
        async def main() -> None:
            bus = can.Bus(interface="virtual", channel=channel)
            other = can.Bus(interface="virtual", channel=channel)
            codec = ma.FAMILY.bind(1)
            try:
                async with anyio.create_task_group() as group:
                    group.start_soon(serve_python_can, SimCanNetwork(devices), bus)
                    ready.set()
                    n = 0
                    while not stop.is_set():
                        if foreign:
                            speed = FOREIGN_SPEEDS_DPS[n % len(FOREIGN_SPEEDS_DPS)]
                            other.send(message_from_frame(codec.encode(ma.SpeedControl(speed_dps=speed))))
                            n += 1
                        await anyio.sleep(0.02)
                    group.cancel_scope.cancel()
            finally:
                bus.shutdown()
                other.shutdown()

        anyio.run(main)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    assert ready.wait(5.0)
    try:
        yield channel
    finally:
        stop.set()
        thread.join(5.0)


@pytest.fixture
def virtual_motors() -> Iterator[str]:
    with _virtual_motors() as channel:
        yield channel


@pytest.fixture
def controlled_motors() -> Iterator[str]:
    with _virtual_motors(foreign=True) as channel:
        yield channel


def test_through_python_can_virtual_the_set_points_are_stored_as_sent(
    tmp_path: Path, virtual_motors: str
) -> None:
    telemetry, log = tmp_path / "run.csv", tmp_path / "run.log"
    connection = ["-i", "virtual", "-c", virtual_motors, "--ids", "1,2"]
    result = invoke(["record", *connection, "--drive", "sine", "--period-s", "0.5", "--duration", "0.6",
                     "-o", str(telemetry), "--log", str(log), "--timeout-ms", "50"])  # fmt: skip
    assert "stop sent to myactuator motors 1, 2 on can:virtual" in result.stderr, result.stderr
    _matches_the_log(telemetry, log, "setpoint_angle_deg", "angle_deg")
    decoded = [json.loads(line) for line in invoke(["decode", "--json", str(log)]).stdout.splitlines()]
    last = {r["motor_id"]: r["type"] for r in decoded if r["direction"] == "request"}
    assert last == {1: "MotorStop", 2: "MotorStop"}  # the safe stop went out last, on the wire


def test_another_controller_s_set_points_are_recorded_as_the_bus_carried_them(
    tmp_path: Path, controlled_motors: str
) -> None:
    """--watch-setpoints: the speed set-points another node sends motor 1 (decoded from the bus with
    the family's codec) are on motor 1's rows, each the last sent before the reply; motor 2, sent
    none, has none; the replies to the other controller's requests are rows too."""
    telemetry, log = tmp_path / "run.jsonl", tmp_path / "run.log"
    connection = ["-i", "virtual", "-c", controlled_motors, "--ids", "1,2"]
    result = invoke(["record", *connection, "--watch-setpoints", "--duration", "0.6", "-o", str(telemetry),
                     "--log", str(log), "--timeout-ms", "50"])  # fmt: skip
    seen = int(result.stderr.split(" set-points of another controller")[0].rsplit(" ", 1)[1])
    assert seen >= 15  # every 20 ms for 0.6 s
    assert "stop" not in result.stderr  # nothing commanded: nothing to stop
    _matches_the_log(telemetry, log, "setpoint_speed_dps", "speed_dps")
    rows = _by_motor(read_rows(telemetry))
    assert {row["setpoint_speed_dps"] for row in rows[1]} - {None} == set(FOREIGN_SPEEDS_DPS)
    assert {row["setpoint_speed_dps"] for row in rows[2]} == {None}
    assert {row["setpoint_angle_deg"] for row in rows[1]} == {None}  # (a kind not sent stays empty)
    assert {row["command"] for row in rows[1]} == {"READ_STATUS_2", "SPEED_CONTROL"}  # theirs too
    decoded = [json.loads(line) for line in invoke(["decode", "--json", str(log)]).stdout.splitlines()]
    ours = {r["type"] for r in decoded if r["direction"] == "request" and not r["rx"]}
    assert ours == {"ReadStatus2"}  # record itself only read


def test_watching_without_another_controller_leaves_the_columns_empty(tmp_path: Path) -> None:
    path = tmp_path / "run.csv"
    invoke(["record", "--sim", "1", "--watch-setpoints", "--duration", "0.1", "-o", str(path)])
    rows = read_rows(path)
    assert list(rows[0])[4:7] == ["setpoint_angle_deg", "setpoint_speed_dps", "setpoint_current_a"]
    assert all(row[c] is None for row in rows for c in ("setpoint_angle_deg", "setpoint_speed_dps"))


# ---- the safe stop on Ctrl-C and SIGTERM ----


def _started(path: Path, timeout_s: float = 20.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and not (path.exists() and path.stat().st_size > 2000):
        time.sleep(0.05)


@pytest.mark.parametrize(
    ("signum", "extra", "code"),
    [(signal.SIGINT, [], 0), (signal.SIGTERM, ["--duration", "30"], 143)],
    ids=["ctrl-c ends an open recording", "sigterm cuts a timed one short"],
)
def test_a_signal_during_a_driven_recording_stops_the_motors(
    tmp_path: Path, signum: signal.Signals, extra: list[str], code: int
) -> None:
    telemetry, log = tmp_path / "run.csv", tmp_path / "run.log"
    args = [
        "record",
        "--sim",
        "2",
        "--drive",
        "sine",
        "--mode",
        "speed",
        "-o",
        str(telemetry),
        "--log",
        str(log),
    ]
    process = subprocess.Popen(
        [*SCRIPT, *args, *extra],
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        _started(telemetry)
        process.send_signal(signum)
        _, err = process.communicate(timeout=20)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    lines = err.strip().splitlines()
    assert process.returncode == code, err
    if code == 0:  # the recording's own end: its last line names the stop
        assert lines[-1].endswith("stop sent to myactuator motors 1, 2 on sim"), err
    else:
        assert "(interrupted)" in lines[0]
        assert lines[-1] == "servobus: interrupted by SIGTERM; stop sent to myactuator motors 1, 2 on sim", (
            err
        )
    decoded = [json.loads(line) for line in invoke(["decode", "--json", str(log)]).stdout.splitlines()]
    requests = [r for r in decoded if r["direction"] == "request"]
    assert {r["type"] for r in requests[:-2]} == {"SpeedControl"}  # driven: no poll, the set-point
    assert {(r["motor_id"], r["type"]) for r in requests[-2:]} == {(1, "MotorStop"), (2, "MotorStop")}
    replies = [r for r in decoded if r["direction"] == "reply"]
    assert {r["fields"].get("command") for r in replies[-2:]} == {"MotorStop"}  # acknowledged


def test_sigterm_in_process_leaves_the_simulated_motors_stopped(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    devices: Devices = keep_devices(monkeypatch)
    cycle: Callable[..., Any] = Bus.cycle
    ticks = 0

    async def cycle_then_terminate(self: Bus, *args: Any, **kwargs: Any) -> Any:
        nonlocal ticks
        ticks += 1
        if ticks == 5:
            os.kill(os.getpid(), signal.SIGTERM)
        return await cycle(self, *args, **kwargs)

    monkeypatch.setattr(Bus, "cycle", cycle_then_terminate)
    args = ["record", "--sim", "2", "--drive", "sine", "--mode", "speed", "--duration", "5"]
    _, err = run(capsys, [*args, "-o", str(tmp_path / "x.csv")], code=143)
    assert (
        err.strip().splitlines()[-1]
        == "servobus: interrupted by SIGTERM; stop sent to myactuator motors 1, 2 on sim"
    )
    assert all(isinstance(m.plant.control, PositionControl) for m in devices.last)  # stopped, holding
    assert ticks < 10


def test_the_drive_really_commands_the_simulated_motors(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """(The check above is not vacuous: while driven in speed mode, the plant is under speed control.)"""
    devices: Devices = keep_devices(monkeypatch)
    seen: list[bool] = []
    cycle: Callable[..., Any] = Bus.cycle

    async def cycle_and_look(self: Bus, *args: Any, **kwargs: Any) -> Any:
        result = await cycle(self, *args, **kwargs)
        seen.append(all(isinstance(m.plant.control, SpeedControl) for m in devices.last))
        return result

    monkeypatch.setattr(Bus, "cycle", cycle_and_look)
    invoke(["record", "--sim", "2", "--drive", "sine", "--mode", "speed", "--duration", "0.2",
            "-o", str(tmp_path / "x.csv")])  # fmt: skip
    assert seen and all(seen)


def test_without_drive_nothing_is_commanded_and_no_stop_is_claimed(tmp_path: Path) -> None:
    log = tmp_path / "ro.log"
    result = invoke(["record", "--sim", "2", "--duration", "0.2", "--log", str(log)])
    assert "stop" not in result.stderr and "driven" not in result.stderr
    decoded = [json.loads(line) for line in invoke(["decode", "--json", str(log)]).stdout.splitlines()]
    assert {r["type"] for r in decoded if r["direction"] == "request"} == {"ReadStatus2"}
    invoke(["record", "--sim", "1", "--duration", "0.1", "-o", str(tmp_path / "ro2.csv")])
    with (tmp_path / "ro2.csv").open(newline="") as f:
        assert not [c for c in next(csv.reader(f)) if c.startswith("setpoint")]  # no set-point column


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["--drive", "bogus"], "'bogus' is not one of 'sine', 'square', 'step'"),
        (["--drive", "sine", "--mode", "torque"], "--mode"),
        (["--stagger"], "--stagger: only with --drive"),
        (["--amplitude-deg", "10"], "--amplitude-deg: only with --drive"),
        (["--drive", "sine", "--amplitude-dps", "10"], "--amplitude-dps: not for --mode position"),
        (["--drive", "sine", "--mode", "speed", "--offset-deg", "1"], "--offset-deg: not for --mode speed"),
        (
            ["--drive", "sine", "--mode", "speed", "--max-speed-dps", "9"],
            "--max-speed-dps: not for --mode speed",
        ),
        (["--drive", "sine", "--amplitude-deg", "1e9"], "angle_deg=1000000000.0 is outside"),
        (["--drive", "sine", "--mode", "speed", "--amplitude-dps", "1e9"], "outside"),
        (["--drive", "sine", "--period-s", "0"], "--period-s"),
        (["--drive", "sine", "--offset-deg", "nan"], "not a number"),
        (["--drive", "sine", "--mode", "speed", "--amplitude-dps", "inf"], "inf is not a number"),
        (["--drive", "sine", "--period-s", "nan"], "not a number"),
        (["--drive", "sine", "--watch-setpoints"], "not with --drive"),
        (["--watch-setpoints", "--family", "hollow"], "hollow set-point frames do not say what they set"),
    ],
)
def test_bad_drive_options_are_one_line_and_exit_2_with_nothing_sent(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    args: list[str],
    says: str,
) -> None:
    monkeypatch.chdir(tmp_path)
    devices = keep_devices(monkeypatch)
    assert says in one_line_error(
        capsys, ["record", "--sim", "1", "--duration", "0.05", "-o", "x.csv", *args]
    )
    assert list(tmp_path.iterdir()) == [] and devices.made == []  # nothing created, no bus opened


def test_the_help_says_the_drive_and_the_rows(capsys: pytest.CaptureFixture[str]) -> None:
    out = invoke(["record", "--help"]).output
    for said in (
        "--drive [sine|square|step]",
        "setpoint_angle_deg",
        "setpoint_speed_dps",
        "safe stop",
        README[0],
    ):
        assert said in " ".join(out.split()), said
