"""The host-side limits (:mod:`servobus.limits`) as the simulated drives' own envelope.

A real drive has its own limits (its maximum current, speed and acceleration settings), whatever
the host sends; :func:`bound` gives the simulated motors the ones a limits file declares, so a
simulator served to other tools (``servobus sim --limits FILE``), and a command's or a bridge's
``--sim`` bus given ``--limits``, move within the same envelope whoever commands them. Only what a
drive enforces is taken: ``current_a`` (and ``torque_nm`` through the motor's torque constant),
``speed_dps`` and ``acceleration_dps_s``. A drive has no position range, nor field ranges: those
are the host's.

Sans-IO: it changes the devices' plants before they are served.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from typing import Any

from servobus.limits import LimitBook

__all__ = ["bound"]


def bound(devices: Iterable[Any], book: LimitBook) -> int:
    """Give each device with a ``motor_id`` and a ``plant`` its limits from ``book`` (the tighter of
    its own and the book's); returns how many devices were bounded."""
    count = 0
    for device in devices:
        plant = getattr(device, "plant", None)
        motor_id = getattr(device, "motor_id", None)
        limits = book.of(motor_id) if isinstance(motor_id, int) else None
        if plant is None or limits is None:
            continue
        params = plant.params
        changes: dict[str, float] = {}
        currents = [params.max_current_a]
        if limits.current_a is not None:
            currents.append(limits.current_a)
        if limits.torque_nm is not None:
            currents.append(limits.torque_nm / params.torque_constant_nm_per_a)
        if min(currents) < params.max_current_a:
            changes["max_current_a"] = min(currents)
        if limits.speed_dps is not None:
            changes["speed_limit_dps"] = min(limits.speed_dps, params.speed_limit_dps)
            if limits.speed_dps < params.max_speed_dps:  # (the position loop's)
                changes["max_speed_dps"] = max(limits.speed_dps, 1e-9)
        accel = limits.acceleration_dps_s
        if accel is not None and accel < params.max_acceleration_dps2:
            changes["max_acceleration_dps2"] = max(accel, 1e-9)
        if not changes:
            continue
        plant.params = dataclasses.replace(params, **changes)
        if "max_acceleration_dps2" in changes:
            plant.acceleration_dps2 = min(plant.acceleration_dps2, changes["max_acceleration_dps2"])
        count += 1
    return count
