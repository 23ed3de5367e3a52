"""Field scales the core tests share: the manuals' ranges for the frames the core packs.

The family codecs (servobus.protocols) will own these per revision and motor model; until they land,
the core's tests take them from here.
"""

from __future__ import annotations

from servobus.core import FieldScale

# MyActuator motion mode, V4.3 ranges (myactuator-v4.md §5.5, [002]).
MIT_V43 = [
    FieldScale.linear("position_rad", -12.5, 12.5, 16),
    FieldScale.linear("velocity_rad_s", -45.0, 45.0, 12),
    FieldScale.linear("kp", 0.0, 500.0, 12),
    FieldScale.linear("kd", 0.0, 5.0, 12),
    FieldScale.linear("torque_ff_nm", -24.0, 24.0, 12),
]
