"""What a protocol family's simulator part declares: the contract behind ``FAMILY.part("sim")``.

The simulator's command line (``python -m servobus.sim``, ``servobus sim``), the CLI's ``--sim N``
and ``servobus demo`` never name a family: they ask its :class:`SimFamily`, which each family's
package exposes as ``SIM`` (``servobus.protocols.<family>.sim:SIM`` for the built-ins, any
``"module:attribute"`` in ``Family.parts["sim"]`` for a plug-in family). It says:

* **which media it serves** (:attr:`SimFamily.media`): ``"can"`` (classic CAN: the SLCAN adapter
  of ``servobus sim --slcan``, the in-process bus of ``--sim N``), ``"canfd"`` (``--fd``) and
  ``"rs485"`` (the family's serial line, ``servobus sim --rs485``);
* **which optional flags it takes** (:attr:`SimFamily.options`): ``"baud"`` (``--baud``: the RS485
  line's rate, one of its :class:`~servobus.protocols.SerialLine`'s ``bauds``) and ``"modbus"``
  (``--modbus``: the RS485 line in Modbus RTU mode);
* **its checks** (:meth:`SimFamily.check`): each refusal is one line naming the flag, raised as
  ``ValueError`` before anything is opened (the command line prints it and exits 2);
* **its motor ids** (:meth:`SimFamily.motor_ids`; the family's ``motor_ids`` unless a mode narrows
  them);
* **its devices** (:meth:`SimFamily.devices`): the simulated devices for ids, a revision and the
  options, as a :class:`Setup`.

A minimal plug-in (see ``tests/plugins`` for a whole one)::

    class ToySim(SimFamily):
        def devices(self, ids, revision, options):
            return Setup(can_devices=[ToyMotor(i) for i in ids])

    SIM = ToySim(family="toy", media=("can",), turnaround_s=100e-6)

Sans-IO: nothing here opens, awaits or reads a clock; the attachments (:mod:`servobus.sim.attach`)
serve what a :class:`Setup` holds.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from enum import Enum
from typing import Any

from servobus.protocols import Family, SerialLine, get_family
from servobus.sim.device import Device, SerialDevice

__all__ = ["MEDIA", "OPTIONS", "Setup", "SimFamily", "SimOptions", "offered_by"]

MEDIA = ("can", "canfd", "rs485")
"""What a simulator part may serve: classic CAN, CAN FD, the family's RS485 line."""
OPTIONS = ("baud", "modbus")
"""The optional flags a simulator part may take."""


@dataclass(frozen=True, slots=True, kw_only=True)
class SimOptions:
    """What the user asked the simulator for, in the terms of the command line's flags.

    Attributes:
        rs485: serve the family's RS485 line (``--rs485``), not CAN.
        fd: CAN FD (``--fd``).
        modbus: the RS485 line in Modbus RTU mode (``--modbus``).
        baud: the RS485 line's rate (``--baud``); None: the part's default.
    """

    rs485: bool = False
    fd: bool = False
    modbus: bool = False
    baud: int | None = None

    @property
    def medium(self) -> str:
        """``"rs485"``, ``"canfd"`` or ``"can"``."""
        return "rs485" if self.rs485 else "canfd" if self.fd else "can"


@dataclass(frozen=True, slots=True)
class Setup:
    """What to serve: CAN devices (behind SLCAN, or on the in-process bus) or serial devices (on an
    RS485 line at ``baud``)."""

    can_devices: Sequence[Device] = ()
    serial_devices: Sequence[SerialDevice] = ()
    baud: int = 0

    def __post_init__(self) -> None:
        if self.can_devices and self.serial_devices:
            raise ValueError("a Setup serves CAN devices or serial devices, not both")
        if self.serial_devices and self.baud <= 0:
            raise ValueError(f"baud={self.baud}: serial devices need the line's rate")


@dataclass(frozen=True, slots=True, kw_only=True)
class SimFamily:
    """A family's simulator part (its ``SIM``): subclass it, implement :meth:`devices`.

    Attributes:
        family: the family's registry name (``get_family(family)`` is the family itself).
        media: what it can serve, of :data:`MEDIA` (``"can"``, ``"canfd"``, ``"rs485"``).
        options: the optional flags it takes, of :data:`OPTIONS` (``"baud"``, ``"modbus"``).
        turnaround_s: its devices' time from a request to its reply (a host plans by it:
            ``servobus demo`` spreads motors over buses with it).
        default_baud: the RS485 line's rate when ``--baud`` is not given (0: the first of the
            serial line's ``bauds``).
        refusals: a reason for a medium or an option it lacks, keyed like them, said in place of
            the generic one: ``{"rs485": "neither LK manual defines an RS485 framing"}``.

    Overridable:
        :meth:`check` (extend it: add rules, then ``super().check(options)``), :meth:`motor_ids`
        and :meth:`motor_ids_note` (a mode that narrows the ids), :meth:`serial_line` (which of
        the family's serial lines the options select); :meth:`devices` must be implemented.
    """

    family: str
    media: tuple[str, ...] = ("can",)
    options: tuple[str, ...] = ()
    turnaround_s: float = 0.0
    default_baud: int = 0
    refusals: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        unknown = [m for m in self.media if m not in MEDIA] + [o for o in self.options if o not in OPTIONS]
        if unknown:
            raise ValueError(
                f"{self.family} sim: unknown media or options {unknown} (known: {MEDIA}, {OPTIONS})"
            )
        if self.turnaround_s < 0:
            raise ValueError(f"{self.family} sim: turnaround_s={self.turnaround_s} must be >= 0")

    # ----------------------------------------------------------------- what to override

    def devices(self, ids: Sequence[int], revision: Enum, options: SimOptions) -> Setup:
        """The simulated devices with ``ids``, speaking ``revision``, as ``options`` ask (checked
        by :meth:`check` first).

        Raises:
            ValueError: a device refused its settings (one line).
        """
        raise NotImplementedError(f"{type(self).__name__}.devices")

    def check(self, options: SimOptions) -> None:
        """Refuse what this part cannot serve, before anything is built or opened.

        The generic rules, from :attr:`media`, :attr:`options` and the family's serial lines: a
        medium or flag it lacks (with :attr:`refusals`' reason where there is one), ``--baud`` or
        ``--modbus`` without ``--rs485``, ``--fd`` with ``--rs485``, a rate the serial line does
        not run at. A subclass adds its own rules before calling this.

        Raises:
            ValueError: one line, starting with the flag it refuses (``--fd: ...``).
        """
        name = self.family
        if options.rs485 and "rs485" not in self.media:
            why = self.refusals.get("rs485", f"the simulated {name} devices have no RS485 line")
            raise ValueError(f"--rs485: {why}; use --slcan")
        if options.modbus and "modbus" not in self.options:
            why = self.refusals.get("modbus", f"the simulated {name} devices speak no Modbus RTU")
            raise ValueError(f"--modbus: {why}{_elsewhere('modbus')}")
        if options.fd and "canfd" not in self.media:
            why = self.refusals.get("canfd", f"the simulated {name} motors speak classic CAN only")
            raise ValueError(f"--fd: {why}{_elsewhere('canfd')}")
        if options.baud is not None:
            if not options.rs485:
                raise ValueError(f"--baud {options.baud}: the rate of an RS485 line; it needs --rs485")
            if "baud" not in self.options:
                why = self.refusals.get("baud", f"the {name} RS485 line has one rate")
                raise ValueError(f"--baud {options.baud}: {why}; drop --baud")
        if options.modbus and not options.rs485:
            raise ValueError("--modbus: a mode of the RS485 line; it needs --rs485")
        if options.fd and options.rs485:
            raise ValueError("--fd: a CAN mode; --rs485 serves the serial line; drop --fd")
        if options.baud is not None:
            bauds = self.serial_line(options).bauds
            if options.baud not in bauds:
                rates = ", ".join(str(b) for b in bauds)
                raise ValueError(f"--baud {options.baud}: the {name} RS485 line runs at one of {rates}")

    def motor_ids(self, options: SimOptions) -> range:
        """The ids a simulated device may have with ``options`` (default: the family's)."""
        return self.protocol().motor_ids

    def motor_ids_note(self, options: SimOptions) -> str:
        """Said after the id range when an id is refused: why ``options`` narrowed it ("" if not)."""
        return ""

    def serial_line(self, options: SimOptions) -> SerialLine:
        """The family's serial line that ``options`` select (default: its first).

        Raises:
            ValueError: the family declares no serial line.
        """
        lines = self.protocol().serial
        if not lines:
            raise ValueError(f"--rs485: the {self.family} family declares no serial line (Family.serial)")
        return lines[0]

    # ----------------------------------------------------------------- derived

    def protocol(self) -> Family:
        """The family this part simulates."""
        return get_family(self.family)

    def baud(self, options: SimOptions) -> int:
        """The RS485 line's rate for ``options``: ``--baud``, else :attr:`default_baud`, else the
        serial line's default."""
        if options.baud is not None:
            return options.baud
        return self.default_baud or self.serial_line(options).bauds[0]


def offered_by(what: str) -> list[str]:
    """The families whose simulator part serves the medium or takes the option ``what``, by name
    (for "use --family X" hints). Imports every family's part: for error messages only; a part
    that fails to load is left out."""
    from servobus.protocols import available_families

    found = []
    for name in available_families():
        try:
            sim: Any = get_family(name).part("sim")
        except (LookupError, ValueError, ImportError):
            continue
        if isinstance(sim, SimFamily) and (what in sim.media or what in sim.options):
            found.append(name)
    return found


def _elsewhere(what: str) -> str:
    names = offered_by(what)
    label = {"canfd": "CAN FD", "modbus": "Modbus RTU"}.get(what, what)
    return f" ({label}: {', '.join(f'--family {n}' for n in names)})" if names else ""
