"""bench/bench_loop.py: each runner (the Loop, the floor, ``Bus.cycle``) runs on the reflectors on both
backends and checks what it measured; the figures and targets come from the samples as documented.

CPU figures are machine-dependent and are not asserted; what is asserted is that every path did its
work (typed replies, every reply counted, fresh state each tick) and that the ratio and the targets are
computed from the medians the way the docstring says.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from servobus.frame import Frame
from servobus.protocols import myactuator as ma
from servobus.sim import virtual

BENCH = Path(__file__).resolve().parents[1] / "bench"
if str(BENCH) not in sys.path:
    sys.path.insert(0, str(BENCH))

import bench_loop  # noqa: E402

BACKENDS = ("asyncio", "trio")


def test_the_layout_is_32_motors_on_11_buses_3_per_bus_the_last_2() -> None:
    ids = bench_loop.bus_ids()
    assert [len(r) for r in ids] == [3] * 10 + [2]
    flat = [i for r in ids for i in r]
    assert flat == list(range(1, 33))  # distinct ids: one prebuilt reply table answers every bus


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("name", ["floor", "cycle", "pacer"])
def test_the_baselines_run_on_the_reflectors(backend: str, name: str) -> None:
    replies = bench_loop.prebuilt_replies(ma.ReadStatus2())
    sample = virtual.run(bench_loop.RUN[name](30, 5, replies), backend=backend)
    assert sample.cpu_us > 0 and sample.wall_us > 0


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_loop_runs_on_the_reflectors_every_state_fresh(backend: str) -> None:
    """run_loop raises unless every motor's state was fresh on every measured tick, nothing lost and
    no overrun (the reflectors answer at once): so a Loop that lost or misattributed replies fails."""
    replies = bench_loop.prebuilt_replies(ma.ReadStatus2())
    sample = virtual.run(bench_loop.run_loop(30, 5, replies), backend=backend)
    assert sample.cpu_us > 0 and sample.wall_us > 0


class _Silent(bench_loop.Reflector):
    """Motor 32 never answers: its request is reported sent, its reply dropped."""

    def send(self, frame: Frame, handle: object = None) -> None:
        super().send(frame, handle)
        if frame.arbitration_id == 0x140 + 32:
            self._out.pop()


def test_the_loop_runner_fails_when_a_motor_never_answers() -> None:
    replies = bench_loop.prebuilt_replies(ma.ReadStatus2())
    with pytest.raises(RuntimeError, match="states not fresh"):
        virtual.run(bench_loop.run_loop(30, 5, replies, _Silent))


def _samples(
    loop: float, floor: float, cycle: float, pacer: float = 0.0
) -> dict[str, list[bench_loop.Sample]]:
    """Three repeats: each runner's CPU µs per tick (its gross value: the idle pacer's added)."""
    spread = [0.9, 1.0, 1.1]
    return {
        name: [bench_loop.Sample(value * k + pacer, value * k + pacer) for k in spread]
        for name, value in (("loop", loop), ("floor", floor), ("cycle", cycle))
    } | {"pacer": [bench_loop.Sample(pacer, pacer)] * 3}


def test_figures_are_medians_the_idle_pacer_beside_and_the_ratio_is_loop_over_floor() -> None:
    cfg = bench_loop.QUICK
    figures = bench_loop.summarise(
        {"asyncio": _samples(60.0, 40.0, 900.0, 50.0), "trio": _samples(100.0, 75.0, 1200.0, 50.0)}, cfg
    )
    # the figures count the pacer's bookkeeping (every runner has it); net of it beside
    assert figures["host_us_per_tick"] == 110.0
    assert figures["floor_us_per_tick"] == 90.0
    assert figures["cycle_us_per_tick"] == 950.0
    assert figures["pacer_us_per_tick"] == 50.0
    assert figures["host_net_of_pacer_us_per_tick"] == 60.0
    net = figures["backends"]["asyncio"]["net_of_pacer_us_per_tick"]
    assert net == {"loop": 60.0, "floor": 40.0, "cycle": 900.0}
    assert figures["host_vs_floor"] == 1.22
    assert figures["trio_host_vs_floor"] == 1.2
    assert figures["backends"]["asyncio"]["host_vs_floor_per_repeat"] == [1.21, 1.23]
    assert figures["targets_missed"] == []
    text = bench_loop.render_markdown(figures, _info())
    assert "`loop.host_us_per_tick`" in text and "Met." in text and "| trio |" in text


def test_a_missed_target_is_named() -> None:
    figures = bench_loop.summarise({"asyncio": _samples(250.0, 50.0, 900.0, 50.0)}, bench_loop.QUICK)
    assert figures["targets_missed"] == [
        "loop.host_us_per_tick = 300.0 (target <= 150)",
        "loop.host_vs_floor = 3.0 (target <= 2)",
    ]
    assert "**Not met**" in bench_loop.render_markdown(figures, _info())


def _info() -> dict[str, object]:
    import _meta

    return _meta.meta("bench/bench_loop.py", ["--quick"], load_average_at_start=[0.0, 0.0, 0.0])


def test_the_halves_of_a_tick_are_read_from_the_profile() -> None:
    prof = {
        "inclusive": [
            {"function": "run_loop (bench_loop.py)", "pct": 90.0},
            {"function": "Loop._send (servobus/loop.py)", "pct": 40.0},
            {"function": "Reflector._flush (bench_bus.py)", "pct": 25.0},
        ]
    }
    halves = bench_loop._halves(prof, 200.0)
    assert len(halves) == 2  # no Timer.run in this profile: not named
    assert halves[0].endswith("40 % (80 µs)") and halves[1].endswith("25 % (50 µs)")
