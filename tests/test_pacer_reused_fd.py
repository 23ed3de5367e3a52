"""A pacer's timer closed by the garbage collector before its wait object must not take the loop's
reader from another descriptor that reuses its number (the full suite's python-can SLCAN test over
a pty heard no frame at all: a collected pacer had unregistered the pty's reader)."""

from __future__ import annotations

import asyncio
import os

import pytest

from servobus import ticks as ticks_module
from servobus.core import timer as timer_module

pytestmark = pytest.mark.skipif(not timer_module.available(), reason="no timerfd here")


def test_a_collected_timer_leaves_a_reused_descriptor_registered() -> None:
    async def main() -> None:
        loop = asyncio.get_running_loop()
        timer = timer_module.MonotonicTimer()
        ready = ticks_module._AsyncioReady(timer)
        number = timer.fileno()
        timer.close()  # (the collector finalised the timer first)
        read_end, write_end = os.pipe()
        try:
            if read_end != number:  # make the pipe take the timer's old number
                os.dup2(read_end, number)
                os.close(read_end)
                read_end = number
            heard = asyncio.Event()
            loop.add_reader(read_end, heard.set)
            ready.close()  # the wait object finalised after: it must not touch the pipe's reader
            os.write(write_end, b"x")
            await asyncio.wait_for(heard.wait(), 1.0)
            loop.remove_reader(read_end)
        finally:
            os.close(read_end)
            os.close(write_end)

    asyncio.run(main())
