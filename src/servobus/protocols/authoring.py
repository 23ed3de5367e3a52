"""What a protocol family is written with: the public names for a family's author.

A family (built in, or a third party's package registered under the ``servobus.families`` entry
point) declares its commands and replies on these bases and field kinds, implements the bound-codec
contract on :class:`CodecBase`, and describes itself with a :class:`Family`. Payloads with a command
byte and whole-byte fields are :class:`Layout` classes; bit-packed ones (MIT-style set-points and
feedback, ``FF x 7 + code`` special commands, scales from the motor's model) are :class:`BitLayout`
classes (:mod:`servobus.protocols.bits`); ``tests/plugins``
holds a complete example (a toy family in its own package). Typed motor methods for it are generated with
``python -m servobus.protocols._calls <package>``.
"""

from __future__ import annotations

from servobus.protocols._bound import (
    EXTENDED,
    KIND_NOT_OURS,
    KIND_REPLY,
    KIND_REPORT,
    KIND_STREAM,
    BoundCodec,
    Broadcast,
    CodecBase,
    FrameKind,
    Framing,
    StreamDeframer,
    check_bus,
    echo_key,
    frame_key,
    id_key,
    motor_ids_of,
)
from servobus.protocols._family import Family, SerialLine, command_classes, method_name
from servobus.protocols._fields import IntField, ScaledField, check_choice, check_range, round_half_away
from servobus.protocols._layout import (
    AsciiField,
    BoolField,
    EnumField,
    FieldCodec,
    FlagsField,
    Float32Field,
    Layout,
    LayoutMismatch,
    OpenEnumField,
    StepField,
)
from servobus.protocols._message import Command, Message, R, Reply, construct, decode_by_code, require_length
from servobus.protocols.bits import (
    BitField,
    BitLayout,
    Bits,
    Choice,
    Code,
    Const,
    Flag,
    Linear,
    OffsetBinary,
    Scale,
    Signed,
    claimant,
    field_names,
    le,
)

__all__ = [
    "EXTENDED",
    "KIND_NOT_OURS",
    "KIND_REPLY",
    "KIND_REPORT",
    "KIND_STREAM",
    "AsciiField",
    "BitField",
    "BitLayout",
    "Bits",
    "BoolField",
    "BoundCodec",
    "Broadcast",
    "Choice",
    "Code",
    "CodecBase",
    "Command",
    "Const",
    "EnumField",
    "Family",
    "FieldCodec",
    "Flag",
    "FlagsField",
    "Float32Field",
    "FrameKind",
    "Framing",
    "IntField",
    "Layout",
    "LayoutMismatch",
    "Linear",
    "Message",
    "OffsetBinary",
    "OpenEnumField",
    "R",
    "Reply",
    "Scale",
    "ScaledField",
    "SerialLine",
    "Signed",
    "StepField",
    "StreamDeframer",
    "check_bus",
    "check_choice",
    "check_range",
    "claimant",
    "command_classes",
    "construct",
    "decode_by_code",
    "echo_key",
    "field_names",
    "frame_key",
    "id_key",
    "le",
    "method_name",
    "motor_ids_of",
    "require_length",
    "round_half_away",
]
