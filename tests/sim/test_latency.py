"""The in-order latency of a link (``FaultPlan(latency_s=(lo, hi))``, issue 24 item 2).

Every item arrives ``uniform(lo, hi)`` late and never before the item sent ahead of it, as replies do
through a USB-CAN adapter polled every millisecond or on a busy host: in order, each late. The faults
apply on top of that time; off (the default), a seed gives exactly the decisions it gave before.
"""

from __future__ import annotations

import asyncio
import itertools
import math
import random

import pytest

from servobus.frame import Frame
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim import virtual
from servobus.sim.faults import FaultInjector, FaultPlan, Item
from servobus.sim.network import SimCanNetwork
from servobus.transports import SimTransport

LO, HI = 0.001, 0.004  # the adapter: 1 ms + uniform(0, 3 ms)
LATENCY = FaultPlan(latency_s=(LO, HI))
EPS = 1e-12


def _frame(i: int) -> Frame:
    return Frame(arbitration_id=0x141 + i % 32, data=bytes([0x9C, i % 256, 0, 0, 0, 0, 0, 0]))


def _items(n: int) -> list[Item]:
    """CAN frames and serial byte strings, alternately, each different."""
    return [_frame(i) if i % 2 else bytes([0x3E, i % 256, 0x08, 0x9C]) for i in range(n)]


def _run(plan: FaultPlan, seed: int, n: int = 400, spacing_s: float = 0.0002) -> list[tuple[float, Item]]:
    injector = FaultInjector(plan, seed)
    out: list[tuple[float, Item]] = []
    for i, item in enumerate(_items(n)):
        out += injector.apply(item, i * spacing_s)
    return out + injector.flush(n * spacing_s)


# ---- the injector alone ----


def test_every_item_arrives_once_in_order_within_the_latency() -> None:
    # Items 0.2 ms apart, latency spread 3 ms: without the FIFO rule most would overtake each other.
    items = _items(400)
    out = _run(LATENCY, seed=1)
    assert [item for _, item in out] == items  # nothing lost, nothing added, order kept
    times = [at for at, _ in out]
    assert times == sorted(times)
    latencies = [at - i * 0.0002 for i, at in enumerate(times)]
    assert all(LO - EPS <= x <= HI + EPS for x in latencies)
    # The FIFO rule did hold items back (an arrival equal to the one before).
    assert sum(a == b for a, b in itertools.pairwise(times)) > 50


def test_the_latency_is_uniform_over_its_window() -> None:
    # Items 10 ms apart never wait for each other: each latency is its draw.
    out = _run(LATENCY, seed=2, spacing_s=0.010)
    latencies = [at - i * 0.010 for i, (at, _) in enumerate(out)]
    assert all(LO - EPS <= x <= HI + EPS for x in latencies)
    assert min(latencies) < LO + 0.0001 and max(latencies) > HI - 0.0001
    mean = sum(latencies) / len(latencies)
    assert mean == pytest.approx((LO + HI) / 2, abs=0.0002)


def test_a_late_item_holds_back_the_next_however_small_its_draw() -> None:
    injector = FaultInjector(FaultPlan(latency_s=(0.0, 0.010)), seed=0)
    arrivals = [injector.apply(_frame(i), i * 1e-6)[0][0] for i in range(200)]
    assert arrivals == sorted(arrivals)
    assert all(0.0 <= at - i * 1e-6 <= 0.010 for i, at in enumerate(arrivals))


def test_a_duplicate_arrives_twice_at_the_latency_time() -> None:
    injector = FaultInjector(FaultPlan(duplicate=1.0, latency_s=(0.002, 0.003)), seed=4)
    last = 0.0
    for i in range(50):
        sent = i * 0.0001
        (at, first), (again, second) = injector.apply(_frame(i), sent)
        assert first == second == _frame(i) and at == again
        assert 0.002 - EPS <= at - sent <= 0.003 + EPS and at >= last
        last = at
    assert injector.counts["duplicate"] == 50


def test_duplicates_among_in_order_items_stay_in_order() -> None:
    out = _run(FaultPlan(duplicate=0.2, latency_s=(LO, HI)), seed=9)
    times = [at for at, _ in out]
    assert times == sorted(times)
    deduplicated = [item for k, (_, item) in enumerate(out) if k == 0 or out[k - 1] != out[k]]
    assert deduplicated == _items(400) and len(out) > 400


def test_faults_apply_on_top_of_the_latency() -> None:
    delay = FaultInjector(FaultPlan(delay=1.0, delay_s=(0.010, 0.010), latency_s=(0.001, 0.002)), seed=2)
    for i in range(20):
        [(at, _)] = delay.apply(_frame(i), float(i))
        assert 0.011 - EPS <= at - i <= 0.012 + EPS
    corrupt = FaultInjector(FaultPlan(corrupt=1.0, latency_s=(0.001, 0.001)))
    [(at, frame)] = corrupt.apply(_frame(0), 1.0)
    assert frame == _frame(0) and at == pytest.approx(1.0 + 0.001 + 0.000135)  # CAN: retransmitted


def test_a_reordered_item_comes_right_after_the_next_one() -> None:
    out = _run(FaultPlan(reorder=0.3, latency_s=(LO, HI)), seed=5)
    times = [at for at, _ in out]
    assert times == sorted(times)  # the held item arrives with the next one, which is in order
    delivered = [item for _, item in out]
    assert sorted(map(repr, delivered)) == sorted(map(repr, _items(400))) and delivered != _items(400)


def test_flush_releases_a_held_item_not_before_its_latency() -> None:
    injector = FaultInjector(FaultPlan(reorder=1.0, latency_s=(0.005, 0.005)))
    assert injector.apply(_frame(0), 1.0) == []
    [(at, frame)] = injector.flush(1.001)  # the link went quiet before the item got through
    assert frame == _frame(0) and at == pytest.approx(1.005)


def test_a_dropped_item_holds_nothing_back() -> None:
    injector = FaultInjector(FaultPlan(drop=0.5, latency_s=(0.0, 0.010)), seed=6)
    kept: list[tuple[float, float]] = []  # (sent, arrival)
    for i in range(300):
        kept += [(i * 0.001, at) for at, _ in injector.apply(_frame(i), i * 0.001)]
    assert injector.counts["drop"] > 100
    assert [at for _, at in kept] == sorted(at for _, at in kept)
    assert all(0.0 <= at - sent <= 0.010 + EPS for sent, at in kept)


def test_the_same_seed_gives_the_same_run_and_another_seed_another() -> None:
    plan = FaultPlan(drop=0.05, corrupt=0.05, duplicate=0.05, reorder=0.05, delay=0.05, latency_s=(LO, HI))
    assert _run(plan, seed=7) == _run(plan, seed=7)
    assert _run(plan, seed=7) != _run(plan, seed=8)
    assert _run(LATENCY, seed=7) != _run(LATENCY, seed=8)


# ---- off: exactly the decisions of before ----


def _reference(
    plan: FaultPlan, seed: int, n: int = 400, spacing_s: float = 0.0002
) -> list[tuple[float, Item]]:
    """The injector as it was before latency existed (the seeded decisions existing tests replay)."""
    rng = random.Random(seed)
    held: Item | None = None
    out: list[tuple[float, Item]] = []
    for i, item in enumerate(_items(n)):
        now = i * spacing_s
        x, kind = rng.random(), "pass"
        for name in ("drop", "corrupt", "duplicate", "reorder", "delay"):
            p = getattr(plan, name)
            if x < p:
                kind = name
                break
            x -= p
        if kind == "drop":
            step: list[tuple[float, Item]] = []
        elif kind == "corrupt":
            if isinstance(item, Frame):
                step = [(now + plan.can_retransmit_s, item)]
            else:
                damaged = bytearray(item)
                bit = rng.randrange(8 * len(damaged))
                damaged[bit // 8] ^= 1 << (bit % 8)
                step = [(now, bytes(damaged))]
        elif kind == "duplicate":
            step = [(now, item), (now, item)]
        elif kind == "delay":
            step = [(now + rng.uniform(*plan.delay_s), item)]
        elif kind == "reorder" and held is None:
            held = item
            continue
        else:
            step = [(now, item)]
        if held is not None and kind != "reorder":
            step.append((now, held))
            held = None
        out += step
    return out + ([(n * spacing_s, held)] if held is not None else [])


@pytest.mark.parametrize("seed", [0, 7, 123])
def test_without_latency_a_seeded_plan_decides_exactly_as_before(seed: int) -> None:
    faults = {"drop": 0.1, "corrupt": 0.1, "duplicate": 0.1, "reorder": 0.1, "delay": 0.1}
    expected = _reference(FaultPlan(**faults), seed)  # type: ignore[arg-type]
    assert _run(FaultPlan(**faults), seed) == expected  # type: ignore[arg-type]
    assert _run(FaultPlan(**faults, latency_s=(0.0, 0.0)), seed) == expected  # type: ignore[arg-type]
    assert not FaultPlan().has_latency and FaultPlan().latency_s == (0.0, 0.0)


@pytest.mark.parametrize(
    "latency_s",
    [(0.002, 0.001), (-0.001, 0.001), (0.0, math.inf), (math.nan, 0.001), (0.001,), "1ms", (0.0, "1")],
    ids=repr,
)
def test_latency_must_be_0_le_low_le_high(latency_s: object) -> None:
    with pytest.raises(ValueError, match=r"^latency_s="):
        FaultPlan(latency_s=latency_s)  # type: ignore[arg-type]


# ---- through the simulated network and the in-process transport ----


def _requests() -> list[Frame]:
    """A status read to each of 8 motors, queued together: the replies come back to back."""
    return [ma.FAMILY.bind(i).encode(ma.ReadStatus1()) for i in range(1, 9)]


def _network_run(to_host: FaultInjector | None, rounds: int = 40) -> list[tuple[float, Frame]]:
    network = SimCanNetwork([MyActuatorMotor(i) for i in range(1, 9)], to_host=to_host)
    received: list[tuple[float, Frame]] = []
    for k in range(rounds):
        for request in _requests():
            network.send(request, k * 0.005)
        received += network.advance(k * 0.005 + 0.0049)
    return received + network.run_until_idle()


def test_replies_through_the_network_arrive_lo_to_hi_after_their_frame_ended_in_order() -> None:
    clean = _network_run(None)  # the replies' end times: latency to the host does not touch the bus
    late = _network_run(FaultInjector(LATENCY, seed=11))
    assert len(clean) == len(late) == 8 * 40
    assert [f for _, f in late] == [f for _, f in clean]  # in the order they ended on the wire
    times = [at for at, _ in late]
    assert times == sorted(times)
    latencies = [at - end for (at, _), (end, _) in zip(late, clean, strict=True)]
    assert all(LO - EPS <= x <= HI + EPS for x in latencies)
    # The replies end 0.12 ms apart, the latency spreads over 3 ms: the FIFO rule held some back.
    assert sum(a == b for a, b in itertools.pairwise(times)) > 0


async def _transport_run(to_host: FaultInjector | None) -> list[tuple[float, float, Frame]]:
    """(loop time at delivery, timestamp, frame) of every reply through a SimTransport."""
    bus = SimTransport(devices=[MyActuatorMotor(i) for i in range(1, 9)], to_host=to_host)
    loop = asyncio.get_running_loop()
    seen: list[tuple[float, float, Frame]] = []
    bus.set_consumer(lambda frames: seen.extend((loop.time(), f.timestamp, f) for f in frames))
    async with bus:
        start = loop.time()
        for k in range(20):
            for request in _requests():
                bus.send(request)
            await asyncio.sleep(start + (k + 1) * 0.005 - loop.time())
        await asyncio.sleep(0.01)
    return [(t - start, ts - start, f) for t, ts, f in seen]


def test_the_transport_delivers_late_replies_at_their_time_and_in_order() -> None:
    clean = virtual.run(_transport_run(None))
    late = virtual.run(_transport_run(FaultInjector(LATENCY, seed=3)))
    assert len(clean) == len(late) == 8 * 20
    assert [(f.arbitration_id, f.data) for *_, f in late] == [(f.arbitration_id, f.data) for *_, f in clean]
    stamps = [ts for _, ts, _ in late]
    assert stamps == sorted(stamps)
    for (delivered, stamp, _), (_, end, _) in zip(late, clean, strict=True):
        assert LO - 1e-9 <= stamp - end <= HI + 1e-9  # stamped with its (late) arrival time
        # Handed over then, not before (the virtual loop's clock has a 1 µs resolution).
        assert stamp - 1e-6 <= delivered <= stamp + 2e-6


def test_in_sender_order_each_identifiers_frames_stay_in_order_and_no_other_holds_them_back() -> None:
    injector = FaultInjector(FaultPlan(latency_s=(LO, HI), latency_order="sender"), seed=3)
    arrivals: dict[int, list[float]] = {}
    for i in range(2000):
        frame = _frame(i)
        ((at, item),) = injector.apply(frame, i * 0.0001)
        assert at - i * 0.0001 >= LO - EPS and item is frame
        arrivals.setdefault(frame.arbitration_id, []).append(at)
    assert all(times == sorted(times) for times in arrivals.values())
    # Unlike one queue, where every item waits for the slowest recent draw, each sender's frames
    # keep the drawn spread: the median latency is lower.
    link = FaultInjector(FaultPlan(latency_s=(LO, HI)), seed=3)
    one_queue = [link.apply(_frame(i), i * 0.0001)[0][0] - i * 0.0001 for i in range(2000)]
    sender = FaultInjector(FaultPlan(latency_s=(LO, HI), latency_order="sender"), seed=3)
    per_sender = [sender.apply(_frame(i), i * 0.0001)[0][0] - i * 0.0001 for i in range(2000)]
    assert sorted(per_sender)[1000] < sorted(one_queue)[1000]


def test_latency_order_is_link_or_sender() -> None:
    with pytest.raises(ValueError, match="latency_order"):
        FaultPlan(latency_s=(LO, HI), latency_order="motor")
