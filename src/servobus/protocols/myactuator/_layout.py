"""The 8-byte payload machinery of MyActuator messages (private): the shared layouts of
:mod:`servobus.protocols._layout`, with this family's titles and revisions.

A standard MyActuator payload is always 8 bytes, DATA[0] the command byte, fields little-endian at fixed
offsets, every other byte NULL (myactuator-v4.md §0; "Decoders should ignore them").
"""

from __future__ import annotations

from typing import ClassVar

from servobus.protocols._layout import (
    FLOAT32_MAX,
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
    check_fields,
    check_payload,
    construct,
)
from servobus.protocols._message import Command, Message, R
from servobus.protocols.myactuator.revision import ALL_REVISIONS, Revision, revision_names

__all__ = [
    "FLOAT32_MAX",
    "PAYLOAD_SIZE",
    "AsciiField",
    "BoolField",
    "EnumField",
    "FieldCodec",
    "Fixed",
    "FlagsField",
    "Float32Field",
    "LayoutMismatch",
    "MyActuatorCommand",
    "MyActuatorMessage",
    "OpenEnumField",
    "StepField",
    "check_fields",
    "check_payload",
    "construct",
]

PAYLOAD_SIZE = 8


class MyActuatorMessage(Message):
    """Base of this family's commands and replies: a title and the revisions the message exists in.

    ``TITLE`` names the command in error messages ("CAN-ID setting"); ``REVISIONS`` lists the protocol
    revisions that define it. :meth:`unavailable_reason` is the availability rule; messages whose
    availability depends on a field value (0x20 index 8, R2 replies of 0x72/0x73) refine it.
    """

    __slots__ = ()
    TITLE: ClassVar[str] = ""
    REVISIONS: ClassVar[frozenset[Revision]] = ALL_REVISIONS

    @property
    def code(self) -> int | None:
        """The command byte this message carries (DATA[0], or the command it answers)."""
        return self.CODE

    def unavailable_reason(self, revision: Revision) -> str | None:
        """Why this message does not exist in ``revision``, or None if it does."""
        return self.revision_reason(revision, self.code)

    @classmethod
    def revision_reason(cls, revision: Revision, code: int | None = None) -> str | None:
        """Why this class does not exist in ``revision``, or None if it does (class-level rule)."""
        if revision in cls.REVISIONS:
            return None
        code = cls.CODE if code is None else code
        prefix = f"0x{code:02X} " if code is not None else ""
        names = revision_names(cls.REVISIONS)
        return f"{prefix}{cls.TITLE} exists only in {names} (revision {revision.name} given)"


class Fixed(Layout, MyActuatorMessage):
    """A MyActuator payload of 8 bytes (:class:`~servobus.protocols._layout.Layout`)."""

    __slots__ = ()


class MyActuatorCommand(Fixed, Command[R]):
    """A MyActuator request with the standard 8-byte layout, generic in its reply:
    ``class ReadStatus2(MyActuatorCommand[StatusReply])``. Its declarations (``READ``, ``SLOW``, ...,
    see :class:`~servobus.protocols._message.Command`) are the only place the codec tables, the bound
    codec's rules and the simulator's dispatch learn them from."""

    __slots__ = ()
