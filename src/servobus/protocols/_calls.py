"""The typed motor methods of a family, generated from its command declarations.

``await motor.read_status2()`` is a method of the family's typed calls class, one per command class,
its parameters the command's fields and its return type the command's declared reply
(``Command[StatusReply]``), so a type checker knows what comes back and refuses a misspelt name. The
class subclasses :class:`TypedCalls`, not the Bus's Motor: a family never imports the Bus. The Bus
composes the motor it hands out, ``type(name, (family.motor(), servobus.bus.Motor), {})``, so the
generated methods come first in the MRO and their ``self.request`` is the Bus's. The class is
written into ``protocols/<family>/_motor.py`` by ::

    python -m servobus.protocols._calls            # rewrite the built-in families' files
    python -m servobus.protocols._calls --check    # exit 1 if one is not current
    python -m servobus.protocols._calls my_family  # a plug-in family's package (its FAMILY)

and checked in; a test runs the check, so a command added without regenerating fails CI. The file is
generated rather than built at run time because a type checker reads files, not run-time classes.
"""

from __future__ import annotations

import argparse
import dataclasses
import enum
import importlib
import sys
import types
import typing
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from servobus.protocols._family import Family
from servobus.protocols._message import Command

__all__ = ["DEFAULT", "TypedCalls", "given", "given_model", "module_path", "render"]

if TYPE_CHECKING:
    # Type-only: to a type checker the typed calls are a Motor (user code passes them where a
    # servobus.Motor is expected). At run time this module never imports the Bus.
    from servobus.bus import Motor as _BusMotor

    class TypedCalls(_BusMotor):
        """The base of a family's generated typed calls, as a type checker sees it: a Motor."""

else:

    class TypedCalls:
        """The base of a family's generated typed calls (``protocols/<family>/_motor.py``'s ``Motor``).

        It adds nothing at run time: the Bus composes the class it hands out with its own Motor,
        ``type(name, (family.motor(), servobus.bus.Motor), {})``, which follows in the MRO and gives
        ``request`` and the rest, so the family's package never imports the Bus. A type checker sees
        it as a subclass of the Bus's Motor (above): ``bus.motor(FAMILY, id)`` is typed as the
        generated class, and user code passes it where a ``servobus.Motor`` is expected.
        """

        __slots__ = ()


DEFAULT: Any = object()
"""A generated method's default for a field whose own default a signature cannot spell (an
object): the field is then left out, and the command fills it in."""


def given(**fields: Any) -> dict[str, Any]:
    """The fields a generated method was given (those not left at :data:`DEFAULT`)."""
    return {name: value for name, value in fields.items() if value is not DEFAULT}


def given_model(motor: Any, model: Any) -> dict[str, Any]:
    """A command's ``model`` field in a generated method: ``model`` where given, else the motor's
    own (its bound codec's), so the command is checked against the ranges of the motor it goes to,
    and a value beyond them names that model; nothing where the codec has none (the command's default)."""
    if model is DEFAULT:
        model = getattr(motor.codec, "model", None)
    return {} if model is None else {"model": model}


_BUILTINS = {int, float, bool, str, bytes, type(None), object}
_NO_DEFAULT = dataclasses.MISSING
_LINE_LENGTH = 110  # pyproject.toml's, which ruff's import sorting keeps to even where E501 is off


class _Imports:
    """The modules a generated module imports; a name is written through its module
    (``commands.ReadStatus2``), so the imports stay one short line per package."""

    def __init__(self) -> None:
        self.modules: dict[str, set[str]] = {}  # parent package -> module names

    def name(self, obj: Any) -> str:
        """``obj``'s name in the generated module (``module.Name``, the module imported)."""
        parent, _, module = str(obj.__module__).rpartition(".")
        self.modules.setdefault(parent, set()).add(module)
        return f"{module}.{obj.__qualname__}"

    def lines(self) -> list[str]:
        """The import statements, sorted and wrapped the way ruff's isort writes them.

        Raises:
            ValueError: two imported modules have the same name (they would shadow each other).
        """
        names = [m for modules in self.modules.values() for m in modules]
        if len(names) != len(set(names)):
            raise ValueError(f"two imported modules share a name: {sorted(names)}")
        out = []
        for parent in sorted(self.modules, key=str.lower):
            modules = sorted(self.modules[parent], key=_isort_key)
            line = f"from {parent} import {', '.join(modules)}"
            if len(line) > _LINE_LENGTH:
                line = f"from {parent} import (\n" + "".join(f"    {m},\n" for m in modules) + ")"
            out.append(line)
        return out


def _isort_key(name: str) -> tuple[int, str]:
    """isort's order by type: CONSTANTS, then Classes, then the rest; case-insensitive within."""
    return (0 if name.isupper() else 1 if name[:1].isupper() else 2, name.lower())


def _annotation(tp: Any, imports: _Imports) -> str:
    """Source text for the type ``tp``."""
    if tp is None or tp is type(None):
        return "None"
    if tp is Any:
        return "Any"
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        return " | ".join(_annotation(arg, imports) for arg in typing.get_args(tp))
    if origin is typing.Literal:
        return f"Literal[{', '.join(repr(a) for a in typing.get_args(tp))}]"
    if origin is typing.ClassVar:
        raise TypeError("a ClassVar is not a field")
    if origin is not None:
        args = typing.get_args(tp)
        inner = ", ".join("..." if a is Ellipsis else _annotation(a, imports) for a in args)
        base = str(origin.__name__) if origin.__module__ == "builtins" else imports.name(origin)
        return f"{base}[{inner}]" if args else base
    if tp in _BUILTINS:
        return str(tp.__name__)
    if isinstance(tp, type):
        return imports.name(tp)
    raise TypeError(f"cannot write the annotation {tp!r}")


def _default(value: Any, imports: _Imports) -> str | None:
    """Source text for a field's default value, or None where it cannot be written (an object):
    the method then leaves the field out unless it is given, and the class fills its default."""
    if isinstance(value, enum.Enum):
        return f"{imports.name(type(value))}.{value.name}"
    if value is None or isinstance(value, bool | int | float | str | bytes):
        return repr(value)
    if isinstance(value, tuple) and all(isinstance(v, int | float | str) for v in value):
        return repr(value)
    return None


def _parameters(cls: type[Command], imports: _Imports) -> tuple[list[str], list[str]]:
    """The method's parameters (fields in declaration order; keyword-only once a field without a
    default follows one with a default) and the command's keyword arguments."""
    hints = typing.get_type_hints(cls)
    params: list[str] = []
    args: list[str] = []
    keyword_only = False
    seen_default = False
    for f in dataclasses.fields(cls):  # type: ignore[arg-type]
        if not f.init:
            continue
        text = f"{f.name}: {_annotation(hints[f.name], imports)}"
        arg = f"{f.name}={f.name}"
        if f.default is not _NO_DEFAULT or f.default_factory is not _NO_DEFAULT:
            written = _default(f.default, imports) if f.default is not _NO_DEFAULT else None
            if written is None:
                written, arg = "DEFAULT", f"**given({f.name}={f.name})"
                if f.name == "model":  # (the motor's model where none is given: given_model)
                    arg = "**given_model(self, model)"
            text += f" = {written}"
            seen_default = True
        elif seen_default and not keyword_only:
            params.append("*")
            keyword_only = True
        params.append(text)
        args.append(arg)
    if not keyword_only:
        params.append("*")
    return params, args


def _summary(cls: type) -> str:
    doc = (cls.__doc__ or "").strip().splitlines()
    line = doc[0].strip() if doc else cls.__name__
    return line.replace('"""', "'''").replace("\\", "\\\\")


def _helpers_module(family: Family[Any]) -> str:
    """Where a generated module imports its helpers from: a plug-in family's from the one public
    module it is written with (servobus.authoring), a built-in's from the protocols layer's own."""
    package = getattr(family, "package", None) or ""
    return "servobus.protocols._calls" if package.startswith("servobus.") else "servobus.authoring"


def _helpers(methods: str) -> str:
    """The names of this module the generated ``methods`` use."""
    names = [n for n in ("given", "given_model") if f"**{n}(" in methods]
    return ", ".join(["DEFAULT", "TypedCalls", *names] if names else ["TypedCalls"])


def render(family: Family[Any]) -> str:
    """The source of ``family``'s typed Motor subclass."""
    imports = _Imports()
    methods: list[str] = []
    for name, cls in family.methods().items():  # declaration order: reads and writes mixed
        params, args = _parameters(cls, imports)
        reply = _annotation(cls.REPLY, imports)
        command = imports.name(cls)
        signature = ", ".join(["self", *params, "timeout_s: float | None = None", "retries: int = 0"])
        # One line a method (its docstring is the command's, set by the Bus (bus._motor_class)): the
        # methods differ only by name and types, and a block of them would read as repeated code.
        methods.append(
            f"    # {_summary(cls)}\n"
            f"    async def {name}({signature}) -> {reply}: return await self.request("
            f"{command}({', '.join(args)}), timeout_s=timeout_s, retries=retries)\n"
        )
    head = [
        f'"""The typed methods of a {family.name} motor, one per command class. Generated by\n'
        '``python -m servobus.protocols._calls`` from the command declarations: do not edit."""\n',
        "# ruff: noqa: E501",
        "",
        "from __future__ import annotations",
        "",
        "from typing import Any, Literal  # noqa: F401",
        "",
        f"from {_helpers_module(family)} import " + _helpers("".join(methods)),
        *imports.lines(),
        "",
        '__all__ = ["Motor"]',
        "",
        "",
        "class Motor(TypedCalls):",
        f'    """A {family.name} motor on a Bus (``bus.motor(FAMILY, id)``): a typed method per command'
        '\n    (the Bus\'s Motor, which the Bus composes after this class, sends them)."""',
        "",
    ]
    return "\n".join(head) + "\n" + "".join(methods)


def module_path(package: str) -> Path:
    """Where the generated module of the family package ``package`` lives (beside its ``__init__``)."""
    module = importlib.import_module(package)
    assert module.__file__ is not None
    return Path(module.__file__).parent / "_motor.py"


def main(argv: Sequence[str] | None = None) -> int:
    from servobus.protocols import FAMILIES, get_family

    parser = argparse.ArgumentParser(
        prog="python -m servobus.protocols._calls", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--check", action="store_true", help="exit 1 if a generated file is not current")
    parser.add_argument(
        "packages", nargs="*", help="a plug-in family's package (its FAMILY); default: the built-in families"
    )
    args = parser.parse_args(argv)
    if args.packages:
        targets = [(importlib.import_module(p).FAMILY, p) for p in args.packages]
    else:
        targets = [(get_family(name), target.partition(":")[0]) for name, target in FAMILIES.items()]
    stale = []
    for family, package in targets:
        path = module_path(package)
        text = render(family)
        if path.exists() and path.read_text() == text:
            continue
        stale.append(path)
        if not args.check:
            path.write_text(text)
    for path in stale:
        print(f"{'not current' if args.check else 'written'}: {path}", file=sys.stderr)
    return 1 if stale and args.check else 0


if __name__ == "__main__":
    sys.exit(main())
