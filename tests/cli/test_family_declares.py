"""What the CLI asks of a family, declared by the family: the ids ``scan`` probes and the rounds it
probes them in (a family whose reply id of motor N is motor N + 16's request id, like Damiao's, scans
1-32), what its ``cli`` part supports (the demo moves motors with ``move``, else ``mit``, else says
what it needs), and ``move``'s speed limit passed as the user gave it (None without one).

The colliding family is ``twin`` (tests/cli/_twin.py: the toy plug-in with Damiao's ids), through
``--sim`` and python-can's ``virtual`` bus."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator
from importlib.metadata import EntryPoint
from types import ModuleType
from typing import Any

import click
import pytest

import servobus.cli._connect as connect
import servobus.cli.setpoints as setpoints
from cli._bus_cli import one_line, run, run_json
from cli._virtual import served_on_virtual
from servobus import _plugins
from servobus.cli._demo_parts import MAX_SPEED_DPS, MIT_KD, MIT_KP, parts
from servobus.cli.plugin import CliFamily, sharing_rounds
from servobus.cli.scan import DEFAULT_IDS, default_ids
from servobus.frame import Frame
from servobus.protocols import ENTRY_POINT_GROUP, get_family
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim.device import MyActuatorMotor


@pytest.fixture(scope="module")
def twin(toy: ModuleType) -> Iterator[ModuleType]:
    from cli._twin import installed

    with installed() as module:
        yield module


# ---- scan: the ids a family declares, probed in rounds of motors that can share a bus ----


def test_ids_whose_frames_collide_are_probed_in_rounds(twin: ModuleType) -> None:
    family = get_family("twin")
    rounds = sharing_rounds([family.bind(i) for i in range(1, 33)])
    assert [[c.motor_id for c in r] for r in rounds] == [list(range(1, 17)), list(range(17, 33))]
    mixed = sharing_rounds([family.bind(i) for i in (17, 1, 2, 18)])
    assert [[c.motor_id for c in r] for r in mixed] == [[17, 2], [1, 18]]  # (first fit, in order)
    built_in = sharing_rounds([get_family("myactuator").bind(i) for i in range(1, 33)])
    assert [len(r) for r in built_in] == [32]


def test_a_family_declares_the_ids_scan_probes(twin: ModuleType, monkeypatch: pytest.MonkeyPatch) -> None:
    assert default_ids("twin") == tuple(range(1, 33))  # (the toy allows 1-31: the twin declares 1-32)
    assert default_ids("myactuator") == DEFAULT_IDS
    assert default_ids("hollow") == tuple(i for i in DEFAULT_IDS if i in get_family("hollow").motor_ids)
    monkeypatch.setattr(twin, "CLI", dataclasses.replace(twin.CLI, scan_ids=(5, 40, 6)))
    assert default_ids("twin") == (5, 6)  # (those of them the family allows)


def _twins(*ids: int) -> Any:
    from cli._twin import TwinMotor

    return lambda family, probed, revision=None: [TwinMotor(i) for i in ids]


def test_a_family_whose_reply_ids_collide_scans_1_32_with_sim(
    twin: ModuleType, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    rows = run_json(capsys, ["scan", "--family", "twin", "--sim", "2", "--ids", "1-32"])
    assert [(r["id"], r["family"], r["errors"], r["state"]) for r in rows] == [
        (1, "twin", [], "DISABLED"),
        (2, "twin", [], "DISABLED"),
    ]
    # motor 17's request id is motor 1's reply id: both found, each in its own round
    monkeypatch.setattr(connect, "sim_devices", _twins(1, 17, 31))
    rows = run_json(capsys, ["scan", "--family", "twin", "--sim", "3"])  # (its declared ids: 1-32)
    assert [r["id"] for r in rows] == [1, 17, 31]
    monkeypatch.setattr(connect, "sim_devices", _twins())
    err = one_line(capsys, ["scan", "--family", "twin", "--sim", "1"], 1)
    assert "no twin motor answered on ids 1-32" in err


def test_a_family_whose_reply_ids_collide_scans_1_32_through_python_can_virtual(
    twin: ModuleType, capsys: pytest.CaptureFixture[str]
) -> None:
    devices = [twin.TwinMotor(i) for i in (1, 2, 17)]
    with served_on_virtual(devices) as channel:
        rows = run_json(capsys, ["scan", "--family", "twin", "-i", "virtual", "-c", channel, "--ids", "1-32"])
    assert [r["id"] for r in rows] == [1, 2, 17]
    assert all(d.counters["replied"] >= 1 for d in devices)


def test_scan_help_says_the_rule(capsys: pytest.CaptureFixture[str]) -> None:
    out, _ = run(capsys, ["scan", "--help"])
    text = " ".join(out.split())
    assert "probed in rounds" in text and "never probed at once" in text
    assert "or the ids the family's CLI part declares" in text


# ---- what a family's part supports ----


def test_a_part_says_what_it_supports(toy: ModuleType) -> None:
    from servobus_toy.cli import CLI as TOY_CLI

    assert TOY_CLI.supports("speed") and TOY_CLI.supports("stop") and TOY_CLI.supports("off")
    assert not TOY_CLI.supports("move") and not TOY_CLI.supports("mit")
    assert TOY_CLI.supports("status", get_family("toy"))  # (its reads derived from its declarations)
    assert TOY_CLI.operations(get_family("toy")) == ("status", "speed", "stop", "off", "reset")
    hollow = get_family("hollow").part("cli")
    assert not hollow.supports("status") and hollow.supports("move")
    assert get_family("myactuator").part("cli").supports("mit")
    assert CliFamily(why_not={"off": "no shutdown"}).operations() == ("status", "stop")
    assert not CliFamily(status=()).supports("status")


# ---- the demo: move, else mit, else a line naming both ----

#: MyActuator without its move: the demo drives its mit set-point
NO_MOVE = CliFamily(
    ops={k: v for k, v in get_family("myactuator").part("cli").ops.items() if k != "move"},
    why_not={"move": "taken away for the test"},
)
MITONLY = dataclasses.replace(
    get_family("myactuator"),
    name="mitonly",
    parts={"sim": get_family("myactuator").parts["sim"], "cli": f"{__name__}:NO_MOVE"},
)


@pytest.fixture
def mitonly(monkeypatch: pytest.MonkeyPatch) -> None:
    found = [EntryPoint("mitonly", f"{__name__}:MITONLY", ENTRY_POINT_GROUP)]
    monkeypatch.setattr(_plugins, "entry_points", lambda group: found if group == ENTRY_POINT_GROUP else [])


def test_the_demo_drives_a_family_without_move_through_mit(
    mitonly: None, capsys: pytest.CaptureFixture[str]
) -> None:
    chosen = parts("mitonly")
    assert chosen.uses == "mit"
    codec = get_family("mitonly").bind(1)
    setpoint = chosen.op.first(codec, chosen.values(45.0))[-1]
    assert isinstance(setpoint, ma.MotionCommand)
    assert math.isclose(setpoint.position_rad, math.pi / 4, abs_tol=1e-3)
    assert (setpoint.kp, setpoint.kd, setpoint.velocity_rad_s) == (MIT_KP, MIT_KD, 0.0)
    out, _ = run(capsys, ["demo", "--family", "mitonly", "--motors", "2", "--hz", "100", "--duration", "0.5"])
    assert "mitonly motors have no move: each follows its mit set-point (kp 20, kd 1, velocity 0)" in out
    summary = run_json(
        capsys, ["demo", "--family", "mitonly", "--motors", "2", "--hz", "100", "--duration", "0.5"]
    )
    assert summary["errors"] == 0 and summary["ticks"] > 0 and summary["pairs"] == 2 * summary["ticks"]


def test_the_demo_puts_on_a_bus_only_motors_that_can_share_it(twin: ModuleType) -> None:
    """Each simulated bus's ids: 1..N, unless some collide (the twin's 17 is 1's reply id)."""
    from servobus.cli._demo_parts import Parts

    chosen = parts("myactuator")
    assert chosen.ids(32) == list(range(1, 33))
    twins = Parts("twin", twin.SIM, chosen.op, chosen.values)
    assert twins.ids(3) == [1, 2, 3] and twins.ids(16) == list(range(1, 17))
    with pytest.raises(click.BadParameter, match="17 twin motors on one bus: at most 16 can share one"):
        twins.ids(17)


def test_the_demo_keeps_its_own_speed_for_a_move() -> None:
    chosen = parts("myactuator")
    assert chosen.uses == "move" and chosen.values(10.0)["max_speed_dps"] == MAX_SPEED_DPS


def test_a_family_with_neither_is_told_what_the_demo_needs(
    twin: ModuleType, capsys: pytest.CaptureFixture[str]
) -> None:
    err = one_line(capsys, ["demo", "--family", "twin", "--motors", "2", "--duration", "0.2"])
    assert "the demo moves motors with move, else mit (no mit: the toy protocol has no impedance mode)" in err
    assert err.rstrip().endswith(
        "twin motors have no move: the toy protocol has no position set-point; servobus speed, then stop"
    )
    with pytest.raises(click.BadParameter, match="the family's cli part has none"):
        no_reason = CliFamily()
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(twin, "CLI", no_reason)
            parts("twin")


# ---- move: the speed limit as the user gave it ----


def _values_sent(monkeypatch: pytest.MonkeyPatch) -> list[dict[str, Any]]:
    sent: list[dict[str, Any]] = []
    monkeypatch.setattr(setpoints, "_drive", lambda conn, name, values, **kw: sent.append(dict(values)))
    return sent


def test_move_passes_max_speed_dps_as_given(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Any
) -> None:
    sent = _values_sent(monkeypatch)
    limits = tmp_path / "limits.toml"
    limits.write_text("[all]\nspeed_dps = 360\n[motor.2]\nspeed_dps = 90\n")
    for extra in ([], ["--max-speed-dps", "60"], ["--limits", str(limits)], ["--no-speed-limit"]):
        run(capsys, ["move", "--sim", "2", "--angle-deg", "10", *extra])
    assert [v["max_speed_dps"] for v in sent] == [None, 60.0, 90.0, None]


@pytest.mark.parametrize(
    ("family", "relative"),
    [("myactuator", False), ("myactuator", True), ("lk", False), ("lk", True), ("hollow", False)],
)
def test_each_built_in_move_goes_without_a_speed_limit(
    capsys: pytest.CaptureFixture[str], family: str, relative: bool
) -> None:
    args = ["move", "--family", family, "--sim", "1", "--angle-deg", "20", "--duration", "3"]
    (row,) = run_json(capsys, [*args, *(["--relative"] if relative else [])])
    assert row["error"] is None and abs(row["angle_deg"] - 20) <= 1.0


class _Sniffer:
    """A passive node: every frame on the wire."""

    name = "sniffer"

    def __init__(self) -> None:
        self.seen: list[Frame] = []

    def receive(self, frame: Frame, now_s: float) -> list[Any]:
        self.seen.append(frame)
        return []

    def poll(self, now_s: float) -> list[Any]:
        return []

    def next_deadline_s(self) -> float | None:
        return None


def test_move_without_a_limit_sends_the_familys_no_limit_through_python_can_virtual(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """MyActuator's 0xA4 with maxSpeed 0 ("no limit", §4.21) without --max-speed-dps; 60 with it."""
    sniffer = _Sniffer()

    def max_speeds() -> set[int]:
        a4 = [f for f in sniffer.seen if f.arbitration_id == 0x141 and f.data[:1] == b"\xa4"]
        sniffer.seen.clear()
        return {int.from_bytes(bytes(f.data[2:4]), "little") for f in a4}

    with served_on_virtual([MyActuatorMotor(1), sniffer]) as channel:
        bus = ["-i", "virtual", "-c", channel, "--ids", "1", "--timeout-ms", "500"]
        run(capsys, ["move", *bus, "--angle-deg", "10", "--duration", "0.3"])
        assert max_speeds() == {0}
        run(capsys, ["move", *bus, "--angle-deg", "10", "--duration", "0.3", "--max-speed-dps", "60"])
        assert max_speeds() == {60}
