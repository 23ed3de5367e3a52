"""The Damiao DM-J models: the ranges their MIT frames map onto 16/12-bit codes.

A frame's position, velocity and torque codes mean nothing without the motor's ``P_MAX``, ``V_MAX``
and ``T_MAX`` (the drive's "PMAX/VMAX/TMAX" settings, which the factory sets per model): the same
bytes are 10 N·m on a DM4310 and 200 N·m on a DM10010L. A bound codec is bound to one model
(``FAMILY.bind(1, model="DM4340")``) and every command and feedback of that motor is scaled by it.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["DEFAULT_MODEL", "KD_RANGE", "KP_RANGE", "MODELS", "DmModel", "find_model"]

#: The MIT gains' ranges: the same on every model.
KP_RANGE = (0.0, 500.0)
KD_RANGE = (0.0, 5.0)


@dataclass(frozen=True, slots=True)
class DmModel:
    """One DM-J model: the limits its MIT codes span.

    Attributes:
        name: the model's name (``"DM4310"``).
        p_max: position range is [-p_max, p_max] rad.
        v_max: velocity range is [-v_max, v_max] rad/s.
        t_max: torque range is [-t_max, t_max] N·m.
    """

    name: str
    p_max: float
    v_max: float
    t_max: float

    def __str__(self) -> str:
        return self.name


#: Every model, by name (the public driver's limit table).
MODELS: dict[str, DmModel] = {
    m.name: m
    for m in (
        DmModel("DM4310", 12.5, 30.0, 10.0),
        DmModel("DM4340", 12.5, 8.0, 28.0),
        DmModel("DM6006", 12.5, 45.0, 20.0),
        DmModel("DM8006", 12.5, 45.0, 40.0),
        DmModel("DM8009", 12.5, 45.0, 54.0),
        DmModel("DM10010L", 12.5, 25.0, 200.0),
    )
}
#: The model a codec is bound to when none is named.
DEFAULT_MODEL = MODELS["DM4310"]


def find_model(model: DmModel | str | None) -> DmModel:
    """``model`` itself, the model of that name (any case), or :data:`DEFAULT_MODEL` for None.

    Raises:
        ValueError: no model has that name (the message lists the known ones).
    """
    if model is None:
        return DEFAULT_MODEL
    if isinstance(model, DmModel):
        return model
    if isinstance(model, str):
        found = MODELS.get(model.upper())
        if found is not None:
            return found
    raise ValueError(f"dm has no model {model!r} (known: {', '.join(MODELS)})")
