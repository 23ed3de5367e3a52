"""``servobus demo``: simulated motors at a fixed rate, a summary with the achieved rate, missed ticks and
errors (and why, when the rate was not kept); the bus layout follows classic CAN's capacity; Ctrl-C
(SIGTERM) stops the motors, prints the summary and exits 130 (143)."""

from __future__ import annotations

import dataclasses
import signal
import subprocess
import time
from importlib.metadata import EntryPoint

import pytest

from cli._bus_cli import SERVOBUS, one_line, run, run_json
from servobus import _plugins
from servobus.cli._demo_report import Summary, layout, summary_lines
from servobus.cli.plugin import CliFamily
from servobus.protocols import ENTRY_POINT_GROUP, get_family
from servobus.protocols.myactuator.sim.device import DEFAULT_TURNAROUND_S


def test_the_default_demo_runs_32_motors_on_11_buses_with_no_errors(
    capsys: pytest.CaptureFixture[str],
) -> None:
    out, _ = run(capsys, ["demo", "--duration", "0.5"])
    assert "32 simulated myactuator motor(s) on 11 simulated CAN buses, 1000 Hz" in out
    assert "at most 3 motor(s) per 1 ms tick" in out
    lines = {
        line.split()[0]: line
        for line in out.splitlines()
        if line and not line.startswith(("servobus", "classic"))
    }
    assert {"achieved", "missed", "latency", "errors"} <= set(lines)
    assert lines["errors"].startswith("errors      0 ")


def test_json_summary(capsys: pytest.CaptureFixture[str]) -> None:
    summary = run_json(capsys, ["demo", "--duration", "0.5", "--motors", "3", "--hz", "200"])
    assert summary["motors"] == 3 and summary["buses"] == 1 and summary["errors"] == 0
    assert summary["ticks"] > 0 and summary["achieved_hz"] > 0 and summary["missed_ticks"] >= 0
    assert summary["pairs"] == 3 * summary["ticks"]
    assert summary["latency_p99_ms"] is not None and summary["bus_load_mean_pct"] > 0


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_the_demo_runs_on_either_backend(capsys: pytest.CaptureFixture[str], backend: str) -> None:
    args = ["demo", "--duration", "0.5", "--motors", "6", "--buses", "2", "--hz", "200", "--backend", backend]
    summary = run_json(capsys, args)
    assert summary["buses"] == 2 and summary["errors"] == 0 and summary["ticks"] > 0
    assert summary["pairs"] == 6 * summary["ticks"]  # every bus's cycle ran every tick


def test_the_layout_is_classic_cans_capacity_per_tick() -> None:
    at_1khz = layout(1000, 32, None, DEFAULT_TURNAROUND_S)
    assert at_1khz.capacity == 3 and at_1khz.buses == 11 and sum(at_1khz.per_bus) == 32
    assert max(at_1khz.per_bus) - min(at_1khz.per_bus) <= 1 and at_1khz.overload() is None
    assert layout(100, 32, None, DEFAULT_TURNAROUND_S).buses == 1
    crowded = layout(1000, 32, 2, DEFAULT_TURNAROUND_S)
    assert crowded.per_bus == (16, 16) and "ticks will be missed" in (crowded.overload() or "")


def _summary(**changes: float) -> Summary:
    values = dict(
        hz=1000.0,
        motors=32,
        buses=11,
        seconds=5.0,
        ticks=800,
        missed_ticks=4200,
        late_p99_ms=1.0,
        tick_p50_ms=6.0,
        wire_ms=0.75,
        pairs=25600,
        latency_p50_ms=0.6,
        latency_p99_ms=0.7,
        bus_load_mean_pct=10.0,
        bus_load_max_pct=10.5,
        timeouts=0,
        not_sent=0,
        malformed=0,
        faults=0,
        cpu_s=4.9,
        simulator_cpu_s=3.9,
    )
    values.update(changes)
    return Summary(**values)  # type: ignore[arg-type]


def test_the_summary_says_why_the_rate_was_not_kept() -> None:
    slow = "\n".join(summary_lines(_summary()))
    assert "achieved    160.0 ticks/s of 1000 Hz" in slow and "missed      4,200 ticks" in slow
    assert "CPU-bound: a tick took 6.00 ms" in slow and "4.88 ms of it simulating 32 motors" in slow
    busy = "\n".join(summary_lines(_summary(cpu_s=1.0, tick_p50_ms=0.9)))
    assert "got only 20% of a CPU core" in busy and "CPU-bound" not in busy
    assert "got only 20% of a core" in "\n".join(summary_lines(_summary(cpu_s=1.0)))
    kept = summary_lines(_summary(ticks=5000, missed_ticks=0, tick_p50_ms=0.8))
    assert not any(line.startswith("why") for line in kept)


@pytest.mark.parametrize(
    ("args", "naming"),
    [
        (["demo", "--hz", "0"], "--hz"),
        (["demo", "--motors", "0"], "--motors"),
        (["demo", "--motors", "2", "--buses", "5"], "--buses"),
        (["demo", "--json"], "--duration"),
        (["demo", "--duration", "-1"], "--duration"),
    ],
)
def test_bad_arguments_are_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str], args: list[str], naming: str
) -> None:
    assert naming in one_line(capsys, args)


@pytest.mark.parametrize(
    ("signum", "code", "by", "said"),
    [
        (signal.SIGINT, 130, "Ctrl-C", "interrupted"),
        (signal.SIGTERM, 143, "SIGTERM", "interrupted by SIGTERM"),
    ],
)
def test_ctrl_c_or_sigterm_stops_the_motors_prints_the_summary_and_exits_128_plus_it(
    signum: signal.Signals, code: int, by: str, said: str
) -> None:
    demo = subprocess.Popen(
        [*SERVOBUS, "demo", "--motors", "3"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    assert demo.stdout is not None
    assert demo.stdout.readline().startswith("servobus demo: 3 simulated")
    time.sleep(1.0)
    demo.send_signal(signum)
    out, err = demo.communicate(timeout=20)
    assert demo.returncode == code, (out, err)
    assert f"stopped     {by}: stop sent to myactuator motors 1-3 on bus 1" in out and "errors      0 " in out
    assert err.strip().splitlines() == [f"servobus: {said}; stop sent to myactuator motors 1-3 on bus 1"]


@pytest.mark.parametrize("family", ["lk", "hollow"])
def test_another_familys_motors_follow_its_own_move(capsys: pytest.CaptureFixture[str], family: str) -> None:
    """The family's simulator part builds the motors and its cli part's move makes the set-point."""
    summary = run_json(
        capsys, ["demo", "--family", family, "--duration", "0.3", "--motors", "2", "--hz", "100", "--json"]
    )
    assert summary["motors"] == 2 and summary["errors"] == 0 and summary["timeouts"] == 0
    assert summary["ticks"] > 0 and summary["pairs"] == 2 * summary["ticks"]


#: plug-in families (LK's codec under other names): one without a simulator, one without a move
NO_MOVE = CliFamily(why_not={"move": "it has no position loop"})
BARE = dataclasses.replace(get_family("lk"), name="bare", parts={}, package=None)
STILL = dataclasses.replace(
    get_family("lk"),
    name="still",
    parts={"sim": "servobus.protocols.lk.sim:SIM", "cli": f"{__name__}:NO_MOVE"},
)


@pytest.mark.parametrize(
    ("family", "says"),
    [
        ("bare", "the bare family has no sim part"),
        ("still", "still motors have no move: it has no position loop"),
        ("nope", "'nope' is not one of"),
    ],
)
def test_a_family_the_demo_cannot_drive_is_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, family: str, says: str
) -> None:
    found = [EntryPoint(name, f"{__name__}:{name.upper()}", ENTRY_POINT_GROUP) for name in ("bare", "still")]
    monkeypatch.setattr(_plugins, "entry_points", lambda group: found if group == ENTRY_POINT_GROUP else [])
    err = one_line(capsys, ["demo", "--family", family, "--duration", "0.1"])
    assert "--family" in err and says in err, err
