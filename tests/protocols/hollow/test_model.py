"""Model scaling parameters and the per-model packer cache."""

from __future__ import annotations

import pytest

from servobus.core import HOLLOW_EXT_REPLY, HOLLOW_FD_COMMAND, HOLLOW_FD_REPLY, HOLLOW_SETPOINT, MIT_REPLY
from servobus.protocols.hollow import DEFAULT_MODEL, MODEL_3507, MODELS, HollowModel
from servobus.protocols.hollow.model import packers


def test_defaults_are_the_manuals_worked_example_scales() -> None:
    # hollow.md §4.3 / §4.6 / A8 / A30 / §7.4.
    assert (
        HollowModel(pmax_turns=1.0, speed_full_scale_rad_s=200.0, current_full_scale_a=4.0, pole_pairs=14)
        == DEFAULT_MODEL
    )
    assert DEFAULT_MODEL.position_full_scale_deg == 360.0
    assert MODELS == {"default": DEFAULT_MODEL, "3507": MODEL_3507}
    assert MODEL_3507.speed_full_scale_rad_s == 58.639


def test_packers_are_built_once_per_model() -> None:
    first = packers(DEFAULT_MODEL)
    assert packers(HollowModel()) is first  # equal models share the cache entry
    assert packers(MODEL_3507) is not first
    layouts = [
        p.layout
        for p in (first.setpoint, first.normal_reply, first.extended_reply, first.fd_command, first.fd_reply)
    ]
    assert layouts == [HOLLOW_SETPOINT, MIT_REPLY, HOLLOW_EXT_REPLY, HOLLOW_FD_COMMAND, HOLLOW_FD_REPLY]


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("pmax_turns", 0.0, r"pmax_turns=0\.0 is outside \(0, inf\)"),
        ("speed_full_scale_rad_s", -1.0, r"speed_full_scale_rad_s=-1\.0 is outside"),
        ("current_full_scale_a", float("nan"), "current_full_scale_a=nan is not a finite number"),
        ("pole_pairs", 0, r"pole_pairs=0 is outside \[1, inf\)"),
        ("pole_pairs", 1.5, "pole_pairs=1.5 is not an integer"),
    ],
)
def test_model_validation(field: str, value: object, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        HollowModel(**{field: value})  # type: ignore[arg-type]
