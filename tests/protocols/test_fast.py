"""protocols/_fast.py: ``maker`` builds genuine, frozen instances of the class it was made for."""

from __future__ import annotations

import dataclasses

import pytest

from servobus.protocols import myactuator as ma
from servobus.protocols._fast import maker


def test_made_object_is_the_class_itself_frozen_and_equal() -> None:
    make = maker(ma.StatusReply, ("command", "temperature_c", "current_a", "speed_dps", "angle_deg"))
    made = make(ma.StatusCommand.TORQUE_CONTROL, 50, 1.0, 500.0, 45.0)
    built = ma.StatusReply(
        command=ma.StatusCommand.TORQUE_CONTROL,
        temperature_c=50,
        current_a=1.0,
        speed_dps=500.0,
        angle_deg=45.0,
    )
    assert type(made) is ma.StatusReply
    assert made == built and hash(made) == hash(built) and repr(made) == repr(built)
    with pytest.raises(dataclasses.FrozenInstanceError):
        made.current_a = 2.0  # type: ignore[misc]


def test_fields_left_out_take_their_default() -> None:
    made = maker(ma.StatusReply, ("temperature_c", "current_a", "speed_dps", "angle_deg"))(1, 0.5, 2.0, 3.0)
    assert made.command is ma.StatusCommand.READ_STATUS_2


@dataclasses.dataclass(frozen=True, slots=True)
class _Base:
    a: int


@dataclasses.dataclass(frozen=True, slots=True)
class _Child(_Base):
    b: int


def test_a_frozen_base_class_still_gets_a_working_maker() -> None:
    made = maker(_Child)(1, 2)  # the twin would inherit _Base's refusing __setattr__: descriptors instead
    assert type(made) is _Child and made == _Child(a=1, b=2)


def test_a_field_without_default_must_be_given() -> None:
    with pytest.raises(TypeError, match="no default"):
        maker(_Child, ("a",))
