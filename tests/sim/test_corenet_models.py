"""Which devices the C engine runs in C: the family models as they are, never a device that handles
frames its own way (a subclass or a patched class), whose receive() C would bypass."""

from __future__ import annotations

from typing import Any

import pytest

from servobus.frame import Frame
from servobus.protocols import myactuator as ma
from servobus.protocols.lk.sim.device import LkMotor
from servobus.protocols.myactuator.sim.device import MyActuatorMotor
from servobus.sim.corenet import CoreCanNetwork
from servobus.sim.device import Emission


class Recording(MyActuatorMotor):
    """A user's device: the model, and a log of every frame it is handed."""

    def __init__(self, motor_id: int) -> None:
        super().__init__(motor_id)
        self.seen: list[Frame] = []

    def receive(self, frame: Frame, now_s: float) -> list[Emission]:
        self.seen.append(frame)
        return super().receive(frame, now_s)


def _read_status(network: CoreCanNetwork, motor_id: int) -> list[tuple[float, Frame]]:
    network.send(ma.FAMILY.bind(motor_id).encode(ma.ReadStatus2()), network.now_s)
    return network.run_until_idle(0.01)


def test_the_models_run_in_c_and_an_overriding_subclass_in_python() -> None:
    network = CoreCanNetwork([MyActuatorMotor(1), Recording(2), LkMotor(3)])
    assert [bool(network._core[n]) for n in (1, 2, 3)] == [True, False, True]
    assert len(_read_status(network, 1)) == 1
    assert len(_read_status(network, 2)) == 1
    custom = network.devices["myactuator2"]
    assert isinstance(custom, Recording) and len(custom.seen) == 1  # its receive() saw the request


@pytest.mark.parametrize("method", ["receive", "poll"])
def test_a_model_whose_method_is_replaced_on_the_class_stays_in_python(
    monkeypatch: pytest.MonkeyPatch, method: str
) -> None:
    original = getattr(MyActuatorMotor, method)

    def wrapped(self: Any, *args: Any) -> Any:
        return original(self, *args)

    monkeypatch.setattr(MyActuatorMotor, method, wrapped)
    network = CoreCanNetwork([MyActuatorMotor(1)])
    assert not network._core[1]
    assert len(_read_status(network, 1)) == 1


def test_the_c_network_refuses_a_frame_the_wire_cannot_carry() -> None:
    """A CAN FD length between the eleven sizes has no wire time: refused, never queued."""
    from servobus.core._lib import ffi, lib

    net = ffi.new("sb_simnet *")
    assert lib.sb_simnet_init(net, 1_000_000.0, 5_000_000.0) == lib.SB_OK
    for length, status in ((9, lib.SB_E_ARG), (12, None), (13, lib.SB_E_ARG), (8, None)):
        got = lib.sb_simnet_send(net, 0, 1, lib.SB_FRAME_FD, bytes(64), length, 0.0, 0)
        assert got == status if status is not None else got >= 0, (length, got)
