"""The Loop's window (``max_outstanding``): a motor whose replies are not being taken in gets no
more commands than the window holds, so a host or link that falls behind never builds a backlog
whose states grow seconds old (bench loop1k on an overloaded host showed 1.3 s before the window)."""

from __future__ import annotations

import pytest

from servobus.loop import Loop
from test_loop import PERIOD, DelayLink, _check_attribution, _run
from test_loop import anyio_backend as anyio_backend  # (the fixture, on both backends)

pytestmark = pytest.mark.anyio


@pytest.mark.parametrize("window", [2, 4])
async def test_a_motor_never_has_more_commands_out_than_its_window(window: int) -> None:
    # replies take 10 ticks: without a window 10 commands per motor would be out at once
    link = DelayLink(lambda i: 10 * PERIOD)
    loop, seen = await _run([link], 60, loop_options={"max_outstanding": window})
    out_at: dict[int, list[float]] = {}
    for t, frame in link.frames_of(0xA2):  # (the loop's commands: not the Bus's stop at its exit)
        out_at.setdefault(frame.arbitration_id, []).append(t)
    for times in out_at.values():
        for n, t in enumerate(times):  # the command n + window left only after command n's reply came
            if n + window < len(times):
                assert times[n + window] >= t + 10 * PERIOD - 1e-9
    metrics = loop.metrics()
    assert metrics.throttled > 0 and metrics.lost == 0
    _check_attribution(seen, exact=False)  # (never younger than the truth)
    # bounded, not growing: a state answers one of the last commands that could be answered (a
    # round trip, plus the wait for a window's room: at most another round trip and a tick)
    worst = max(s.age_ticks for _, states in seen for s in states if s is not None)
    assert worst <= 2 * (10 + 1)


async def test_a_window_wide_enough_throttles_nothing() -> None:
    link = DelayLink(lambda i: 2.5 * PERIOD)
    loop, seen = await _run([link], 60)  # the default window, 4: 3 commands out at most here
    assert loop.metrics().throttled == 0
    assert _check_attribution(seen, exact=True) > 100


def test_the_window_is_checked() -> None:
    with pytest.raises(ValueError, match="max_outstanding"):
        Loop(100, max_outstanding=0)
