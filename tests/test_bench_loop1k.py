"""bench/bench_loop1k.py: both modes run through real SLCAN ptys to the device process, and the figures,
targets and the RESULTS.md section come from the runs as documented.

Real time on a shared machine: the timing figures are not asserted, only that each mode did its work
(typed replies, the Loop's window of ticks and its counts) and that the summaries judge the targets the
docstring names on the Loop's figures, with the code before beside them.
"""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path
from typing import Any

BENCH = Path(__file__).resolve().parents[1] / "bench"
if str(BENCH) not in sys.path:
    sys.path.insert(0, str(BENCH))

import bench_loop1k as b  # noqa: E402
from servobus.protocols import Reply  # noqa: E402
from servobus.protocols import myactuator as ma  # noqa: E402


def _reply_classes(module: object) -> set[str]:
    return {
        name
        for name, value in vars(module).items()
        if isinstance(value, type) and issubclass(value, Reply) and value is not Reply
    }


def test_cycle_mode_through_slcan_ptys() -> None:
    layout = dataclasses.replace(b.LAYOUTS["loop1k"], motors=(3, 2))
    run = b.one_run(layout, 0.3, "cycle")
    assert run["mode"] == "cycle" and run["ticks_due"] == 300
    # a loaded machine may time a few requests out (counted, not fatal): most must be typed replies
    assert run["results_not_replies"] <= 0.2 * 5 * run["ticks_run"]
    assert run["latency_samples"] > 0 and run["ticks_run"] > 0 and run["host_cpu_pct"] > 0


def _loop_run(on_time: float, age_ms: float, cpu: float, jitter: float = 50.0) -> dict[str, Any]:
    keys = {k: 1.0 for k in b.LOOP_KEYS}
    metrics = dict.fromkeys(("overruns", "superseded", "not_sent", "lost", "stale_states"), 0)
    return {
        **keys,
        "on_time_pct": on_time,
        "state_age_p99_ms": age_ms,
        "host_cpu_pct": cpu,
        "jitter_p99_us": jitter,
        "metrics": metrics,
        "load_before": [0.0] * 3,
        "mode": "loop",
    }


def _cycle_run(on_time: float) -> dict[str, Any]:
    return {**{k: 2.0 for k in b.CYCLE_KEYS}, "on_time_pct": on_time, "mode": "cycle"}


def test_targets_are_judged_on_the_loop_with_the_code_before_beside() -> None:
    layout = b.LAYOUTS["loop1k"]
    runs = [_loop_run(99.9, 2.0, 30.0), _loop_run(99.0, 3.0, 60.0), _loop_run(99.8, 2.2, 40.0)]
    figures = b.summarise(layout, runs, [_cycle_run(0.0), _cycle_run(1.0), _cycle_run(0.5)], None)
    assert figures["on_time_pct"] == 99.8 and figures["state_age_p99_ms"] == 2.2
    assert figures["host_cpu_pct"] == 40.0
    assert figures["on_time_pct_cycle"] == 0.5 and figures["cycle"]["runs"] == 3
    assert figures["spread"]["on_time_pct"] == [99.0, 99.9]
    assert figures["targets_missed"] == []
    slow = b.summarise(layout, [_loop_run(90.0, 4.0, 80.0, 300.0)], [], None)
    assert slow["targets_missed"] == [
        "loop1k.on_time_pct = 90.0 (target >= 99.5)",
        "loop1k.state_age_p99_ms = 4.0 (target <= 2.5)",
        "loop1k.host_cpu_pct = 80.0 (target <= 50.0)",
        "loop1k.jitter_p99_us = 300.0 (target <= 200.0)",
    ]
    assert "cycle" not in slow


def test_a_missed_target_is_read_from_the_loop_s_counts_and_the_host_cost() -> None:
    runs = [{**_loop_run(0.0, 900.0, 60.0), "wall_s": 15.0} for _ in range(3)]
    for r, superseded in zip(runs, (10, 20, 30), strict=True):
        r["metrics"] = {**r["metrics"], "superseded": superseded, "overruns": 5}
    f = b.summarise(b.LAYOUTS["loop1k"], runs, [], None)
    f["profile"] = {"devices": {"by_area": [{"area": "waiting in select/epoll (idle)", "pct": 88.0}]}}
    text = b.why_missed(f, 1168.0)
    assert "20 commands were superseded" in text and "5 bodies ran past" in text
    assert "waited in select 88 %" in text and "1,168 µs" in text and "more than the 1,000 µs" in text
    assert "within the 1,000 µs" in b.why_missed(f, 120.0)
    del f["profile"]  # (a profile needs its own run's figures to render)
    assert "Reading: the host ran" in b.render_markdown({"loop1k": f}, _info(), 1168.0)


def _info() -> dict[str, Any]:
    import _meta

    return _meta.meta(
        "bench/bench_loop1k.py", ["--quick"], load_average_at_start=[0.0] * 3, runs=1, seconds=1
    )


def test_a_layout_its_bus_cannot_carry_says_no_host_can() -> None:
    figures = b.summarise(b.LAYOUTS["loop1k_fd"], [_loop_run(50.0, 9.0, 30.0)], [], None)
    assert not figures["feasible_at_1khz"]
    (missed,) = figures["targets_missed"]  # on time only: the other targets are classic CAN's
    assert missed.startswith("loop1k_fd.on_time_pct = 50.0 (target >= 99.5; its bus can carry at most")
    assert missed.endswith("so no host can)")


def test_quick_mode_writes_the_loop_and_the_code_before(tmp_path: Path) -> None:
    assert b.main(["--quick", "--only", "loop1k", "--output", str(tmp_path)]) == 0
    data = json.loads((tmp_path / "results.json").read_text(encoding="utf-8"))["loop1k"]
    for key in ("on_time_pct", "state_age_p99_ms", "host_cpu_pct", "jitter_p99_us", "on_time_pct_cycle"):
        assert isinstance(data[key], float), key
    (run,) = data["per_run"]
    # a state is a typed reply of the family (the Bus's probe of a motor it took offline answers with
    # another reply than the command's: counted, not an error)
    assert set(run["not_replies"]) <= _reply_classes(ma) and run["metrics"]["commands_sent"] > 0
    assert run["ticks_due"] == 1000 and run["ticks_run"] > 0 and run["latency_samples"] > 0
    text = (tmp_path / "RESULTS.md").read_text(encoding="utf-8")
    assert "<!-- loop1k:begin -->" in text and "state age p50 / p99 / max ms" in text
