"""bench/bench_limits.py: both runners run the Loop on the reflectors with every set-point within the
limits (a refused or clamped one fails the run: the bench measures the checks), and the figures are
the documented ratios. CPU figures are machine-dependent and not asserted."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from servobus.limits import LimitExceeded
from servobus.sim import virtual

BENCH = Path(__file__).resolve().parents[1] / "bench"
if str(BENCH) not in sys.path:
    sys.path.insert(0, str(BENCH))

import bench_limits  # noqa: E402
from bench_loop import Sample  # noqa: E402


@pytest.mark.parametrize("name", sorted(bench_limits.COMMANDS))
def test_the_loop_runs_with_and_without_limits_and_refuses_nothing(name: str) -> None:
    command = bench_limits.COMMANDS[name]
    replies = bench_limits.prebuilt_replies(command)
    for limited in (False, True):
        sample = virtual.run(bench_limits.run(20, 5, replies, command, limited))
        assert sample.cpu_us > 0


def test_a_set_point_beyond_the_limits_fails_the_run() -> None:
    assert not bench_limits.LIMITS.clamp  # (so that nothing is measured clamped)
    command = bench_limits.ma.SpeedControl(speed_dps=5000.0)
    replies = bench_limits.prebuilt_replies(command)
    with pytest.raises(LimitExceeded, match="beyond the host limit"):
        virtual.run(bench_limits.run(5, 1, replies, command, True))


def test_the_ratio_is_the_median_of_the_pairs() -> None:
    runs = {
        name: {"with": [Sample(110, 0), Sample(130, 0), Sample(105, 0)], "without": [Sample(100, 0)] * 3}
        for name in bench_limits.COMMANDS
    }
    figures = bench_limits.summarise(runs, 10, 3)
    assert figures["speed_ratio"] == 1.1 and figures["speed_ratio_per_repeat"] == [1.05, 1.3]
    assert figures["targets"]["speed_ratio"]["met"] and figures["targets_missed"] == []
