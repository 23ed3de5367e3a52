"""Checks every family's codec tests share (style.md: "any bytes -> reply or ProtocolError").

Used from tests/protocols/<family>/: keep each family's tests about its own bytes, and the shape of
the contract in one place.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from hypothesis import strategies as st

from servobus.errors import ProtocolError
from servobus.protocols import Message

# 0..8 bytes with any DATA[0]: classic CAN payloads, including the empty and truncated ones.
can_payloads = st.binary(min_size=0, max_size=8)
# Any standard identifier: the ones a family owns and the ones it must reject.
standard_ids = st.integers(min_value=0, max_value=0x7FF)


def decodes_or_protocol_error(decode: Callable[..., Message], *args: Any, **kwargs: Any) -> Message | None:
    """Call ``decode``; return its message, or None if it raised ProtocolError.

    Any other exception propagates and fails the calling test. A returned message must be a
    Message whose encode() does not raise (the simulator re-encodes what it decodes).
    """
    try:
        message = decode(*args, **kwargs)
    except ProtocolError as exc:
        assert str(exc), "ProtocolError without a message"
        return None
    assert isinstance(message, Message), f"{decode.__name__} returned {type(message).__name__}"
    message.encode()
    return message


def assert_quantised(decoded: float, given: float, resolution: float, *, field: str) -> None:
    """``decoded`` is ``given`` rounded to a multiple of ``resolution`` (half a step at most away)."""
    tolerance = resolution / 2 + 1e-9 * max(1.0, abs(given))
    assert math.isclose(decoded, given, abs_tol=tolerance), (
        f"{field}: {given!r} decoded as {decoded!r}, more than half of {resolution!r} away"
    )
