"""servobus.runtime: each backend's lane (clock, call_soon, waiters) behaves the same."""

from __future__ import annotations

import threading

import anyio
import pytest

from servobus import runtime

pytestmark = pytest.mark.anyio


async def _soon(seen: list[object]) -> None:
    """Until a callback "soon" ran (trio runs them from its own queue, a few checkpoints later)."""
    with anyio.fail_after(1):
        while not seen:
            await anyio.sleep(0)


async def test_the_lane_is_the_running_backends(anyio_backend: tuple[str, dict[str, object]]) -> None:
    lane = runtime.current()
    assert lane.name == anyio_backend[0]
    assert lane.is_current()
    assert abs(lane.time() - anyio.current_time()) < 0.5


def test_outside_a_loop_the_lane_is_refused_in_one_sentence() -> None:
    with pytest.raises(runtime.RuntimeMismatch, match="no event loop runs here"):
        runtime.current()


async def test_a_waiter_gives_its_result_to_the_task_awaiting_it() -> None:
    lane = runtime.current()
    waiter = lane.waiter()
    seen: list[object] = []
    waiter.add_done_callback(lambda w: seen.append(w.result()))
    lane.call_soon(waiter.set_result, 42)
    assert not waiter.done()
    assert await waiter == 42
    assert waiter.done() and not waiter.cancelled()
    await _soon(seen)
    assert seen == [42]
    with pytest.raises(Exception):  # noqa: B017 (asyncio's InvalidStateError, our RuntimeError)
        waiter.set_result(43)


async def test_a_waiter_raises_its_exception() -> None:
    lane = runtime.current()
    waiter = lane.waiter()
    lane.call_soon(waiter.set_exception, KeyError("x"))
    with pytest.raises(KeyError):
        await waiter
    assert isinstance(waiter.exception(), KeyError)


async def test_an_outcome_set_before_the_await_is_taken_at_once() -> None:
    waiter = runtime.current().waiter()
    waiter.set_result("early")
    assert await waiter == "early"


async def test_a_cancelled_await_cancels_the_waiter_and_its_callbacks_run() -> None:
    lane = runtime.current()
    waiter = lane.waiter()
    seen: list[bool] = []
    waiter.add_done_callback(lambda w: seen.append(w.cancelled()))
    with anyio.move_on_after(0.01) as scope:
        await waiter
    assert scope.cancelled_caught
    assert waiter.cancelled()
    await _soon(seen)
    assert seen == [True]
    assert not waiter.cancel()  # (once)


async def test_call_soon_threadsafe_hands_over_from_a_thread_in_order() -> None:
    lane = runtime.current()
    got: list[int] = []
    done = lane.waiter()

    def worker() -> None:
        for i in range(100):
            lane.call_soon_threadsafe(got.append, i)
        lane.call_soon_threadsafe(done.set_result, None)

    thread = threading.Thread(target=worker)
    thread.start()
    with anyio.fail_after(5):
        await done
    thread.join()
    assert got == list(range(100))


@pytest.mark.parametrize("anyio_backend", ["trio"])  # (asyncio's loop has its own exception handler)
async def test_on_trio_a_failing_callback_is_logged_and_the_run_goes_on(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """In trio's queue a callback's exception would end the whole run (TrioInternalError)."""
    lane = runtime.current()
    seen: list[int] = []

    def boom() -> None:
        raise ValueError("a callback's bug")

    lane.call_soon(boom)
    lane.call_soon(seen.append, 1)
    await _soon(seen)
    assert seen == [1]
    assert "a callback's bug" in caplog.text
