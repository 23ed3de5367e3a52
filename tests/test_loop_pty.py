"""The pipelined loop through a real transport path, in real time: the native SLCAN transport over a
pseudo-terminal to the simulator's adapter and its MyActuator motors (tests/test_bus_pty.py's bench).
Each tick's commands leave as one batch (one write to the pty); the states come back ticks later."""

from __future__ import annotations

import pytest

from servobus.frame import Frame
from servobus.loop import Loop, LoopMetrics
from servobus.protocols import myactuator as ma
from servobus.sim.plant import PositionControl
from test_bus_pty import MA_IDS, CanBench, slcan_bus

pytestmark = pytest.mark.anyio

HZ = 200  # (a loaded machine takes a few ms to pass a frame through the pty and the simulator)


async def test_the_loop_runs_over_native_slcan_and_an_exception_stops_its_motors() -> None:
    bench = CanBench()
    states = 0
    speeds: dict[int, float] = {}
    metrics: LoopMetrics | None = None
    last_index = -1
    with pytest.raises(RuntimeError, match="user code failed"):
        async with slcan_bus(bench, safe_timeout_s=0.5) as bus:
            motors = [bus.motor("myactuator", i) for i in MA_IDS]
            async with Loop(HZ, timeout_s=0.05) as loop:
                async for tick in loop.ticks(count=200):
                    for m in motors:
                        state = tick.state(m)
                        if state is not None:
                            states += 1
                            assert state.age_ticks == tick.index - state.tick >= 1
                            # (the command left after its deadline: at most the ticks between, and
                            # this one's lateness)
                            assert 0 < state.age_s <= state.age_ticks / HZ + tick.late_s + 1e-9
                            speeds[m.motor_id] = state.reply.speed_dps  # type: ignore[attr-defined]
                        tick.command(m, ma.SpeedControl(speed_dps=10.0 * (1 + m.motor_id)))
                    if tick.index >= 80:  # (>=: on a loaded machine tick 80 may be skipped)
                        last_index = tick.index
                        metrics = loop.metrics()
                        raise RuntimeError("user code failed")
    # (real time on a shared machine: ticks may be skipped, and frames late; on an idle one every
    # command of ticks 1..79 leaves on time and none is lost)
    assert metrics is not None and states > 3 * 40
    assert metrics.ticks + metrics.skipped == last_index + 1
    assert metrics.commands_sent >= 2 * (metrics.ticks - 2)
    assert metrics.commands_on_time >= 0.5 * metrics.commands_sent
    assert metrics.lost <= metrics.commands_sent // 10 and metrics.superseded == 0
    assert all(speeds[i] > 0 for i in MA_IDS)  # (turning, as commanded)
    # The loop stopped every motor it commanded (0x81: hold where it is).
    for i in MA_IDS:
        assert isinstance(bench.myactuator[i].control, PositionControl)
        assert bench.heard(Frame(arbitration_id=0x140 + i, data=bytes([0x81, 0, 0, 0, 0, 0, 0, 0]))) >= 1
