"""Host-side limits: a motor's envelope, declared once, checked on every command before its frame
leaves (ros2_control's joint limits, for a bus).

A :class:`Limits` holds what one motor may be told, in the host's units: a position range, the
largest speed, acceleration, current and torque, and a range for any other command field by its
name (a PID gain, a torque percentage). Every command's fields are read by their units, the suffix
of their names (``speed_dps``, ``velocity_rad_s``, ``position_rad``, ``current_a``, ...), so one
declaration covers every family and every command that sets the quantity, converted to the limit's
unit: ``MotionCommand.velocity_rad_s`` meets ``speed_dps`` in rad/s. A command beyond a limit is
refused (:class:`LimitExceeded`, a ValueError naming the command, the field, the value and the
limit) or, with ``clamp=True``, sent clamped to it. The Bus applies a motor's limits to every
request, tick, pipelined loop and broadcast, and counts both outcomes in ``metrics()``
(``limit_refused``, ``limit_clamped``).

Which fields meet which limit (a field's name ends with its unit):

- ``position_deg``: ``*_deg`` and ``*_rad`` fields, the target within [low, high] (see below);
- ``speed_dps``: ``*_dps``, ``*_rad_s`` and ``*_rpm``, at most either way; a bound left open
  (``max_speed_dps=None``, "no limit" on the wire) is beyond any limit;
- ``acceleration_dps_s``: ``*_dps_s`` and ``*_dps2``, at most; "no planning" (None) is beyond;
- ``current_a``: ``*_a``, at most either way (a tuple such as ``currents_a`` holds one value per
  motor: each, or the motor's own ``slot``);
- ``torque_nm``: ``*_nm``, at most either way;
- ``fields``: any field by ``"Class.field"`` or ``"field"`` (the class's key first), within [low, high].

A field the motor ignores as the command is set (``Command.inactive()``: a position with kp = 0)
is not checked, and a family's safe commands (stop, shutdown, brake) are never limited (the Bus
exempts them: :func:`safe_commands`). A command says how its position is meant
(``Command.POSITION``): ``"absolute"`` (the default) is
checked as it is; ``"relative"`` (an increment) from the motor's last known angle (its latest
status; refused, even with ``clamp``, before one is known); ``"single_turn"`` is refused whenever a
position range is declared, because where it ends depends on the turn the motor is in. Fields in
raw counts or percent meet no quantity limit: give them a ``fields`` range. A speed, current or
torque command (one without a position field) does not move a motor to a position, but once its
last reported angle is out of the range, one that drives it further out is sent as 0 (counted
``limit_clamped``, with ``clamp`` or without: refusing it would fail the whole tick, or a bridge's,
for where the motor is, which no caller could check beforehand); one that brings it back goes. A
single-turn angle (``Reply.SINGLE_TURN``) is never taken for the motor's position.

A file declares limits for the motors of a bus (:func:`load`, TOML)::

    clamp = false                 # refuse (default) or clamp what is beyond a limit

    [all]                         # every motor on the bus
    speed_dps = 720
    current_a = 8.0

    [motor.1]                     # motor 1 (whatever its family); these override [all]
    position_deg = [-90, 90]

    [motor."2-4"]
    position_deg = [0, 180]
    fields = { kp = [0, 50], "WritePidRam.value" = [0, 5] }
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from servobus.protocols import Command, Reply

__all__ = ["LimitBook", "LimitExceeded", "Limits", "angle_of", "load", "parse", "safe_commands"]

_DEG_PER_RAD = 180.0 / math.pi
#: what of a Limits meets a command class: (field, quantity, factor, kind, bound in the field's unit
#: or None for a position) per field, (field, range) per field range, the range's rule for speeds
_Compiled = tuple[
    tuple[tuple[str, str, float, str, float | None], ...], tuple[tuple[str, tuple[float, float]], ...], bool
]

#: a field's unit suffix -> (the quantity it meets, the factor to the limit's unit); longest first
_UNITS: tuple[tuple[str, str, float], ...] = (
    ("_dps_s", "acceleration_dps_s", 1.0),
    ("_dps2", "acceleration_dps_s", 1.0),
    ("_rad_s", "speed_dps", _DEG_PER_RAD),
    ("_dps", "speed_dps", 1.0),
    ("_rpm", "speed_dps", 6.0),
    ("_rad", "position_deg", _DEG_PER_RAD),
    ("_deg", "position_deg", 1.0),
    ("_nm", "torque_nm", 1.0),
    ("_a", "current_a", 1.0),
)
#: where a motor's last known angle is, in its replies: (field, factor to degrees)
_ANGLES = (("angle_deg", 1.0), ("position_deg", 1.0), ("position_rad", _DEG_PER_RAD))
_POSITIONS = ("absolute", "relative", "single_turn")


class LimitExceeded(ValueError):
    """A command beyond its motor's host-side limit: refused before its frame left.

    Attributes:
        field: the command field (``"SpeedControl.speed_dps"``).
        value: the value asked for, in the field's unit.
        limit: the limit it went beyond (``"speed_dps 720"``).
    """

    def __init__(self, message: str, field: str = "", value: object = None, limit: str = "") -> None:
        super().__init__(message)
        self.field, self.value, self.limit = field, value, limit


def _range(name: str, value: object) -> tuple[float, float]:
    if (
        not isinstance(value, tuple | list)
        or len(value) != 2
        or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)
    ):
        raise ValueError(f"{name}={value!r}: expected [low, high]")
    low, high = float(value[0]), float(value[1])
    if not (math.isfinite(low) and math.isfinite(high)) or low > high:
        raise ValueError(f"{name}=[{value[0]}, {value[1]}]: expected finite low <= high")
    return low, high


def _bound(name: str, value: object) -> float:
    if not isinstance(value, int | float) or isinstance(value, bool) or not value >= 0 or math.isinf(value):
        raise ValueError(f"{name}={value!r}: expected a finite number >= 0")
    return float(value)


@dataclass(frozen=True, slots=True, kw_only=True)
class Limits:
    """One motor's envelope (None: no limit on that quantity).

    Attributes:
        position_deg: the output angle range, (low, high), multi-turn, in degrees.
        speed_dps: the largest speed (and speed bound) a command may ask for, in deg/s.
        acceleration_dps_s: the largest acceleration, in deg/s².
        current_a: the largest current (torque-producing, q-axis), in A.
        torque_nm: the largest torque, in N·m.
        fields: a range for any command field, by ``"Class.field"`` or ``"field"`` (in the field's
            own unit: a gain, a percentage, raw counts).
        clamp: send a command beyond a limit clamped to it instead of refusing it.

    Raises:
        ValueError: a range with low above high, a negative or non-finite bound (named).
    """

    position_deg: tuple[float, float] | None = None
    speed_dps: float | None = None
    acceleration_dps_s: float | None = None
    current_a: float | None = None
    torque_nm: float | None = None
    fields: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    clamp: bool = False
    #: command class -> what of these limits meets it (made once per class: :meth:`_compile`)
    _compiled: dict[type, _Compiled] = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.position_deg is not None:
            object.__setattr__(self, "position_deg", _range("position_deg", self.position_deg))
        for name in ("speed_dps", "acceleration_dps_s", "current_a", "torque_nm"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, _bound(name, value))
        ranges = {str(k): _range(f"fields[{k!r}]", v) for k, v in dict(self.fields).items()}
        object.__setattr__(self, "fields", ranges)

    def merged(self, over: Limits) -> Limits:
        """These limits with ``over``'s set values (and its ``clamp``) taking their place."""
        changes: dict[str, Any] = {
            f.name: getattr(over, f.name)
            for f in dataclasses.fields(over)
            if f.init and f.name not in ("fields", "clamp") and getattr(over, f.name) is not None
        }
        return dataclasses.replace(self, **changes, fields={**self.fields, **over.fields}, clamp=over.clamp)

    def apply(self, command: Command, state: Reply | None = None, slot: int | None = None) -> Command:
        """``command`` if it is within these limits, else clamped to them (``clamp``).

        Args:
            command: the command about to be sent.
            state: the motor's latest status, for a relative position's target and the range's
                rule for speeds (None: unknown).
            slot: for a frame that carries one value per motor (a tuple field: LK's multi-motor
                torque, motors 1-4 in order), the index of this motor's value: only it is checked
                (None: every value).

        Raises:
            LimitExceeded: a field beyond its limit (without ``clamp``, or where no clamp is safe:
                a single-turn position under a position range, an increment from an unknown angle).
        """
        cls = type(command)
        compiled = self._compiled.get(cls)
        if compiled is None:
            compiled = self._compile(cls)
        checks, ranges, outward = compiled
        if not checks and not ranges:
            return command
        name = cls.__name__
        changes: dict[str, Any] = {}
        inactive = command.inactive() if cls in _INACTIVE else _NONE
        out = self._outside(state) if outward else 0
        for attribute, quantity, factor, kind, bound in checks:
            if attribute in inactive:
                continue
            value = getattr(command, attribute)
            if bound is None:  # (a position)
                new = self._position(command, name, attribute, value, factor, state)
            else:
                # (the common case first: a number within the limit, nothing made)
                if (value.__class__ is float or value.__class__ is int) and -bound <= value <= bound:
                    new = value
                else:
                    new = self._quantity(name, attribute, value, quantity, factor, kind, slot)
                # (driving a motor out of its range further out: sent as 0, never refused, see above)
                if (
                    out
                    and kind == _TARGET
                    and quantity in _DRIVING
                    and isinstance(new, int | float)
                    and new * out > 0
                ):
                    new = 0.0
            if new is not value:
                changes[attribute] = new
        for attribute, limit in ranges:
            if attribute in inactive:
                continue
            value = changes.get(attribute, getattr(command, attribute))
            new = self._within(name, attribute, value, limit, "fields", slot)
            if new is not value:
                changes[attribute] = new
        return dataclasses.replace(command, **changes) if changes else command  # type: ignore[type-var]

    def check(self, command: Command) -> None:
        """Raise LimitExceeded if ``command`` is beyond these limits, whatever ``clamp`` says: a
        setting is written as given or not at all (``servobus config set``/``restore``)."""
        if self.clamp:
            dataclasses.replace(self, clamp=False).check(command)
        else:
            self.apply(command)

    def _compile(self, cls: type) -> _Compiled:
        """What of these limits meets command class ``cls``: its fields a set limit meets, with the
        bound in the field's own unit (None for a position); its fields' ranges; whether the range's
        rule for speeds applies (a range is set, and ``cls`` has no position field)."""
        plan = _plan(cls)
        outward = self.position_deg is not None and not any(q == "position_deg" for _, q, _, _ in plan)
        checks = []
        for attribute, quantity, factor, kind in plan:
            limit = getattr(self, quantity)
            if limit is not None:
                bound = None if quantity == "position_deg" else limit / factor
                checks.append((attribute, quantity, factor, kind, bound))
            elif outward and kind == _TARGET and quantity in _DRIVING:  # (the range's rule alone)
                checks.append((attribute, quantity, factor, kind, math.inf))
        ranges = []
        for attribute in _field_names(cls) if self.fields else ():
            limit = self.fields.get(f"{cls.__name__}.{attribute}") or self.fields.get(attribute)
            if limit is not None:
                ranges.append((attribute, limit))
        compiled = self._compiled[cls] = (tuple(checks), tuple(ranges), outward)
        return compiled

    def _quantity(
        self, name: str, attribute: str, value: Any, quantity: str, factor: float, kind: str, slot: int | None
    ) -> Any:
        limit = getattr(self, quantity)
        if limit is None:  # (checked for the range's rule alone)
            return value
        if isinstance(value, tuple):  # one value per motor (LK's multi-motor torque)
            return _each(
                value, slot, lambda v: self._quantity(name, attribute, v, quantity, factor, kind, None)
            )
        said = f"{quantity} {limit:g}" + (f" ({limit / factor:.4g} in {attribute})" if factor != 1.0 else "")
        if value is None:  # a bound left open: "no limit" on the wire (or given another way: a raw limit)
            if kind != _OPEN:
                return value
            if self.clamp:
                return limit / factor
            raise self._beyond(name, attribute, "none (no limit)", said)
        if not isinstance(value, int | float) or isinstance(value, bool):
            return value
        if abs(value) * factor <= limit:
            return value
        if self.clamp:
            return math.copysign(limit / factor, value)
        raise self._beyond(name, attribute, f"{value:g}", said)

    def _outside(self, state: Reply | None) -> int:
        """Which way the motor's last reported angle is out of the position range: +1 above, -1
        below, 0 within it (or the range or angle not known)."""
        limit = self.position_deg
        angle = None if limit is None else angle_of(state)
        if limit is None or angle is None or limit[0] <= angle <= limit[1]:
            return 0
        return 1 if angle > limit[1] else -1

    def _position(
        self, command: Command, name: str, attribute: str, value: Any, factor: float, state: Reply | None
    ) -> Any:
        limit = self.position_deg
        if limit is None or not isinstance(value, int | float):
            return value
        kind = command.POSITION
        if kind == "absolute" and limit[0] <= value * factor <= limit[1]:  # (the common case)
            return value
        said = f"position_deg [{limit[0]:g}, {limit[1]:g}]"
        if kind == "single_turn":
            raise self._beyond(
                name, attribute, f"{value:g}", said,
                "a single-turn target's end depends on the turn the motor is in: use an absolute command",
            )  # fmt: skip
        if kind == "relative":
            now = angle_of(state)
            if now is None:
                raise self._beyond(
                    name,
                    attribute,
                    f"{value:g}",
                    said,
                    "its motor's angle is not known yet: read its status first",
                )
            target = now + value * factor
            if limit[0] <= target <= limit[1]:
                return value
            if self.clamp:
                return (min(max(target, limit[0]), limit[1]) - now) / factor
            raise self._beyond(name, attribute, f"{value:g} (to {target:g} deg from {now:g})", said)
        if factor != 1.0:
            said += f" ([{limit[0] / factor:.4g}, {limit[1] / factor:.4g}] in {attribute})"
        return self._within(name, attribute, value, (limit[0] / factor, limit[1] / factor), said)

    def _within(
        self,
        name: str,
        attribute: str,
        value: Any,
        limit: tuple[float, float],
        said: str,
        slot: int | None = None,
    ) -> Any:
        """``value`` within ``limit`` (``said``: the limit's name; ``"fields"`` for a field range;
        a tuple value: each of it, or its ``slot``'s)."""
        if isinstance(value, tuple):
            return _each(value, slot, lambda v: self._within(name, attribute, v, limit, said))
        if not isinstance(value, int | float) or isinstance(value, bool) or limit[0] <= value <= limit[1]:
            return value
        if not self.clamp:
            if said == "fields":
                said = f"fields {attribute} [{limit[0]:g}, {limit[1]:g}]"
            raise self._beyond(name, attribute, f"{value:g}", said)
        if isinstance(value, int):  # (an integer field stays one)
            return min(max(value, math.ceil(limit[0])), math.floor(limit[1]))
        return min(max(value, limit[0]), limit[1])

    def _beyond(self, name: str, attribute: str, value: str, limit: str, why: str = "") -> LimitExceeded:
        where = f"{name}.{attribute}"
        message = f"{where}={value} is beyond the host limit {limit}" + (f": {why}" if why else "")
        return LimitExceeded(message, where, value, limit)


def safe_commands(codec: Any) -> frozenset[Command]:
    """``codec``'s safe commands (``safe_command`` of ``"stop"``, ``"shutdown"``, ``"brake"``, those
    its family or revision has): never limited, since stopping a motor is always allowed (and what a
    bridge lets any client send)."""
    made = set()
    for kind in ("stop", "shutdown", "brake"):
        try:
            made.add(codec.safe_command(kind))
        except ValueError:  # (a kind this family or revision has no command for)
            continue
    return frozenset(made)


def angle_of(state: Reply | None) -> float | None:
    """The output angle, in degrees, a motor's latest status reports (None: none does)."""
    if state is None or state.SINGLE_TURN:  # (an angle within the turn is not where the motor is)
        return None
    for name, factor in _ANGLES:
        value = getattr(state, name, None)
        if isinstance(value, int | float) and not isinstance(value, bool):
            return value * factor
    return None


_PLANS: dict[type, tuple[tuple[str, str, float, str], ...]] = {}


#: what a field is to its limit: a target (signed: a direction), a bound (at most; None: given
#: another way), a bound whose None is "no limit" (``max_*``; an acceleration's "no planning")
_TARGET, _BOUND, _OPEN = "target", "bound", "open"
_NONE: frozenset[str] = frozenset()
#: what drives a motor without a position: the range's rule for speeds meets these
_DRIVING = frozenset({"speed_dps", "current_a", "torque_nm"})
#: the command classes with fields their motor may ignore as set (``Command.inactive``)
_INACTIVE: set[type] = set()


def _plan(cls: type) -> tuple[tuple[str, str, float, str], ...]:
    """The fields of command class ``cls`` a quantity limit meets: (field, quantity, factor to the
    limit's unit, what the field is: target, bound or open bound), once per class."""
    plan = _PLANS.get(cls)
    if plan is None:
        found = []
        for name in _field_names(cls):
            for suffix, quantity, factor in _UNITS:
                stem = name.removesuffix(suffix)
                if stem != name and stem:
                    if name.startswith("max_") or quantity == "acceleration_dps_s":
                        kind = _OPEN
                    else:
                        kind = _BOUND if "_limit" in name else _TARGET
                    found.append((name, quantity, factor, kind))
                    break
        position = getattr(cls, "POSITION", "absolute")
        if position not in _POSITIONS:
            raise ValueError(f"{cls.__name__}.POSITION={position!r}: one of {', '.join(_POSITIONS)}")
        if getattr(cls, "inactive", Command.inactive) is not Command.inactive:
            _INACTIVE.add(cls)
        plan = _PLANS[cls] = tuple(found)
    return plan


def _each(values: tuple[Any, ...], slot: int | None, check: Any) -> tuple[Any, ...]:
    """``check`` on each of ``values`` (or on the one at ``slot``); the same tuple when none changed."""
    new = tuple(check(v) if slot is None or i == slot else v for i, v in enumerate(values))
    return values if all(a is b for a, b in zip(new, values, strict=True)) else new


_NAMES: dict[type, tuple[str, ...]] = {}


def _field_names(cls: type) -> tuple[str, ...]:
    names = _NAMES.get(cls)
    if names is None:
        names = _NAMES[cls] = (
            tuple(f.name for f in dataclasses.fields(cls)) if dataclasses.is_dataclass(cls) else ()
        )
    return names


@dataclass(frozen=True, slots=True)
class LimitBook:
    """The limits of a bus's motors, by id: ``all`` for every motor, ``motors`` over it.

    Attributes:
        all: the limits of every motor (None: none).
        motors: motor id -> its own limits, merged over ``all``.
    """

    all: Limits | None = None
    motors: Mapping[int, Limits] = field(default_factory=dict)

    def of(self, motor_id: int) -> Limits | None:
        """Motor ``motor_id``'s limits: its own over ``all`` (None: it has none)."""
        own = self.motors.get(motor_id)
        if own is None:
            return self.all
        return own if self.all is None else self.all.merged(own)


_KEYS = frozenset({"position_deg", "speed_dps", "acceleration_dps_s", "current_a", "torque_nm", "fields"})


def parse(text: str, *, source: str = "limits") -> LimitBook:
    """A :class:`LimitBook` from TOML text (the module's docstring shows the format).

    Raises:
        ValueError: bad TOML, an unknown key or section, a bad value or id range (one line, with
            ``source`` and the key).
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{source}: not TOML: {exc}") from None
    unknown = set(data) - {"clamp", "all", "motor"}
    if unknown:
        raise ValueError(f"{source}: unknown key {sorted(unknown)[0]!r} (clamp, [all], [motor.ID])")
    clamp = data.get("clamp", False)
    if not isinstance(clamp, bool):
        raise ValueError(f"{source}: clamp={clamp!r}: true or false")
    every = _limits(data["all"], clamp, f"{source} [all]") if "all" in data else None
    motors: dict[int, Limits] = {}
    sections = data.get("motor", {})
    if not isinstance(sections, dict):
        raise ValueError(f"{source}: motor: expected [motor.ID] sections")
    for ids, values in sections.items():
        limits = _limits(values, clamp, f"{source} [motor.{ids}]")
        for motor_id in _ids(ids, f"{source} [motor.{ids}]"):
            motors[motor_id] = limits
    return LimitBook(every, motors)


def load(path: str | Path) -> LimitBook:
    """:func:`parse` of the file at ``path``.

    Raises:
        OSError: the file cannot be read. ValueError: as :func:`parse`.
    """
    path = Path(path)
    return parse(path.read_text(encoding="utf-8"), source=str(path))


def _limits(values: object, clamp: bool, where: str) -> Limits:
    if not isinstance(values, dict):
        raise ValueError(f"{where}: expected a table of limits")
    unknown = set(values) - _KEYS
    if unknown:
        raise ValueError(f"{where}: unknown limit {sorted(unknown)[0]!r} (one of {', '.join(sorted(_KEYS))})")
    try:
        return Limits(**values, clamp=clamp)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None


def _ids(text: str, where: str) -> range:
    first, sep, last = text.partition("-")
    try:
        low = int(first)
        high = int(last) if sep else low
    except ValueError:
        raise ValueError(f"{where}: a motor id or a range like 2-4") from None
    if not 0 <= low <= high <= 0x7FF:
        raise ValueError(f"{where}: ids between 0 and 2047, low to high")
    return range(low, high + 1)
