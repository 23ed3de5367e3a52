"""``servobus demo`` on the pipelined :class:`~servobus.loop.Loop`: the state a tick sees is the
previous deadline's (about a period old, not a round trip), the summary gives the host's CPU per
tick with the simulator's apart and the state's age, every tick counted was answered, failed
requests fail the run, and every family's motors follow their sine (hollow ones too: started in
their position mode)."""

from __future__ import annotations

import math
import signal
import subprocess
import time
from typing import Any

import pytest

import servobus.transports.sim as sim_transport
from cli._bus_cli import SERVOBUS, run, run_json
from servobus.cli._demo_report import Summary, live_view, summary_lines
from servobus.sim.faults import FaultInjector, FaultPlan


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_a_short_runs_json_has_the_state_age_and_the_host_cpu_per_tick(
    capsys: pytest.CaptureFixture[str], backend: str
) -> None:
    args = ["demo", "--duration", "0.5", "--motors", "6", "--buses", "2", "--hz", "200", "--backend", backend]
    summary = run_json(capsys, args)
    assert summary["errors"] == 0 and summary["lost"] == 0 and summary["superseded"] == 0
    assert summary["ticks"] > 0
    assert summary["pairs"] == 6 * summary["ticks"]  # the last ticks' replies were waited for
    # Pipelined: a tick sees the reply to the set-point that left at the previous deadline, one
    # period (5 ms) before it started; sending and waiting would show the round trip (~0.6 ms).
    ages = summary["state_age_p50_ms"], summary["state_age_p99_ms"], summary["state_age_max_ms"]
    assert 4.5 <= ages[0] <= ages[1] <= ages[2] and ages[0] < 10.0, ages
    assert summary["host_us_per_tick"] > 0 and summary["simulator_us_per_tick"] > 0
    host_s = summary["host_us_per_tick"] * summary["ticks"] / 1e6
    sim_s = summary["simulator_us_per_tick"] * summary["ticks"] / 1e6
    assert host_s + sim_s == pytest.approx(summary["cpu_s"], rel=0.01)
    assert 0 < summary["cpu_pct"] <= 100.0 * 1.05


def _summary(**changes: Any) -> Summary:
    values: dict[str, Any] = dict(
        hz=1000.0, motors=32, buses=11, seconds=10.0, ticks=10_000, missed_ticks=0, late_p99_ms=0.1,
        tick_p50_ms=0.55, wire_ms=0.75, pairs=320_000, latency_p50_ms=0.6, latency_p99_ms=0.7,
        bus_load_mean_pct=30.0, bus_load_max_pct=31.0, timeouts=0, not_sent=0, malformed=0, faults=0,
        cpu_s=5.5, simulator_cpu_s=2.5, state_age_p50_ms=1.02, state_age_p99_ms=1.31,
        state_age_max_ms=2.2, late_ticks=3, overruns=2, stale_states=7, superseded=1, lost=0, preempted=40,
    )  # fmt: skip
    values.update(changes)
    return Summary(**values)


def test_the_summary_gives_the_host_cpu_per_tick_the_simulators_apart_and_the_state_age() -> None:
    kept = _summary()
    assert kept.host_us_per_tick == pytest.approx(300.0)
    assert kept.simulator_us_per_tick == pytest.approx(250.0)
    assert kept.cpu_pct == pytest.approx(55.0) and kept.why() is None
    lines = {line[:12].strip(): line for line in summary_lines(kept)}
    assert lines["host CPU"].startswith("host CPU    300 µs per tick, the simulator's 250 µs apart (55 % ")
    assert "preempted 40 times" in lines["host CPU"]
    assert lines["state age"].startswith("state age   p50 1.02 ms, p99 1.31 ms, max 2.20 ms")
    assert "7 stale" in lines["state age"]
    assert "3 late ticks, 2 overruns, 1 commands superseded" in lines["missed"]
    out = kept.as_dict()
    assert out["host_us_per_tick"] == 300.0 and out["simulator_us_per_tick"] == 250.0
    assert out["state_age_p99_ms"] == 1.31 and out["overruns"] == 2 and out["preempted"] == 40


def test_requests_the_loop_lost_are_shown_once_and_the_rate_must_be_99_percent() -> None:
    """A command the loop calls lost timed out on its Bus first: an error counted there, once."""
    lost = _summary(lost=5, timeouts=5)
    lines = {line[:12].strip(): line for line in summary_lines(lost)}
    assert lost.errors == 5 and "5 lost" in lines["state age"] and "timeouts 5" in lines["errors"]
    assert _summary(ticks=9_950, missed_ticks=50).why() is None
    paused = _summary(ticks=9_850, missed_ticks=150, cpu_s=5.4).why()
    assert (
        paused is not None and "most ticks fit (median 0.55 ms" in paused and "0.55 ms on average" in paused
    )
    # half the ticks run, each 0.2 ms of CPU: the process ran 10 % of the time where it needed 20 %
    starved = _summary(ticks=5_000, missed_ticks=5_000, preempted=900, cpu_s=1.0).why()
    assert (
        starved is not None and "got only 10% of a CPU core" in starved and "preempted 900 times" in starved
    )


def test_requests_that_fail_fail_the_demo(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Replies dropped on the way to the host: counted, and the demo exits 1 after its summary."""
    made = sim_transport.SimTransport

    def lossy(*args: Any, **kwargs: Any) -> Any:
        return made(*args, to_host=FaultInjector(FaultPlan(drop=0.3), seed=7), **kwargs)

    monkeypatch.setattr(sim_transport, "SimTransport", lossy)
    out, err = run(capsys, ["demo", "--duration", "0.3", "--motors", "2", "--hz", "100"], code=1)
    errors = next(line for line in out.splitlines() if line.startswith("errors"))
    assert int(errors.split()[1]) > 0 and "request(s) failed during the demo" in err


@pytest.mark.parametrize("family", ["myactuator", "lk", "hollow"])
def test_every_familys_motors_follow_their_sine(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, family: str
) -> None:
    """The set-points reach the plants: hollow motors too, whose move starts with their mode and
    Start (before the Loop, the demo sent them Start alone every tick: they never moved)."""
    made = sim_transport.SimTransport
    devices: list[Any] = []

    def kept(*args: Any, **kwargs: Any) -> Any:
        devices.extend(kwargs["devices"])
        return made(*args, **kwargs)

    monkeypatch.setattr(sim_transport, "SimTransport", kept)
    duration = 0.6
    args = ["demo", "--family", family, "--duration", str(duration), "--motors", "4", "--buses", "2"]
    summary = run_json(capsys, [*args, "--hz", "200"])
    assert summary["errors"] == 0 and len(devices) == 4
    for n, device in enumerate(devices):  # (the demo's sine: 90° amplitude, 4 s period, phases spread)
        target = 90.0 * math.sin(2 * math.pi * duration / 4.0 + 2 * math.pi * n / 4)
        assert device.plant.position_deg == pytest.approx(target, abs=12.0), (n, target)


def test_ctrl_c_on_trio_stops_the_motors_and_exits_130() -> None:
    demo = subprocess.Popen(
        [*SERVOBUS, "demo", "--motors", "3", "--backend", "trio"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert demo.stdout is not None
    assert demo.stdout.readline().startswith("servobus demo: 3 simulated")
    time.sleep(1.0)
    demo.send_signal(signal.SIGINT)
    out, err = demo.communicate(timeout=20)
    assert demo.returncode == 130, (out, err)
    assert "stopped     Ctrl-C: stop sent to myactuator motors 1-3 on bus 1" in out
    assert "errors      0 " in out


def test_the_live_view_is_plain_fixed_width_lines_two_tables_side_by_side_where_they_fit() -> None:
    rows = [
        (str(n + 1), f"{n // 3 + 1}/{n % 3 + 1}", "   12.34", "  -12.30", "", "", "", "  1.02")
        for n in range(32)
    ]
    wide = live_view(["32 motors", "loop 999.0/s"], rows).plain.splitlines()
    assert wide[:3] == ["32 motors", "loop 999.0/s", ""]
    assert wide[3].count("age ms") == 2 and len(wide) == 3 + 2 + 16
    assert wide[5].split("|")[0].split() == ["1", "1/1", "12.34", "-12.30", "1.02"]
    assert wide[-1].split("|")[1].split()[:2] == ["32", "11/2"]
    narrow = live_view([], rows, width=80).plain.splitlines()
    assert narrow[1].count("age ms") == 1 and len(narrow) == 1 + 2 + 32
    assert len({len(line) for line in narrow[1:]}) == 1  # (every line as wide: the columns line up)
