"""Hot-path decoding for the bound codecs: build typed replies at struct speed (private).

The typed reply classes validate every field on construction (``__post_init__``), which is right for
objects users build and costs 3-20 µs a frame. A bound codec's hot decoders instead unpack with a
precomputed ``struct.Struct``, check only what the bytes can get wrong (a range the manual narrows,
an enum code), and build the reply through its slot descriptors, skipping ``__init__``.

One rule keeps them honest: **a fast decoder never decides an error.** Anything unusual (a range
check that fails, an unknown enum code, a wrong length) hands the bytes to the family's full decoder,
which either raises the ProtocolError users see everywhere else or returns the reply. The tests
compare the two paths on random bytes (tests/protocols/test_bound_fast.py).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

__all__ = ["Slow", "maker"]


class Slow(Exception):
    """Raised inside a fast decoder: let the full decoder handle these bytes."""


def maker(cls: type, names: tuple[str, ...] | None = None) -> Callable[..., Any]:
    """A function ``make(v1, v2, ...)`` returning a ``cls`` with those field values, unvalidated.

    The object is built as an instance of a twin class (the same bases and slots, no frozen
    ``__setattr__``), whose plain attribute stores are the fastest Python has, and then becomes a
    ``cls`` by ``__class__`` assignment, which CPython allows between classes of identical layout (and
    checks: a twin it refuses falls back to setting each slot through its descriptor).

    Args:
        cls: a slotted dataclass (frozen or not).
        names: the fields in argument order; default: every field in declaration order. Fields left
            out take their dataclass default.

    Raises:
        TypeError: ``cls`` is not a slotted dataclass, or a field left out has no default.
    """
    fields = {f.name: f for f in dataclasses.fields(cls)}
    if names is None:
        names = tuple(fields)
    defaults: dict[str, Any] = {}
    for name in fields:
        if type(getattr(cls, name, None)).__name__ != "member_descriptor":
            raise TypeError(f"{cls.__name__}.{name} is not a slot")
        if name not in names:
            default = fields[name].default
            if default is dataclasses.MISSING:
                raise TypeError(f"{cls.__name__}.{name} has no default and is not given")
            defaults[f"_d_{name}"] = default
    args = ", ".join(f"a{i}" for i in range(len(names)))
    values = {name: f"a{i}" for i, name in enumerate(names)} | {
        n: f"_d_{n}" for n in fields if n not in names
    }
    namespace: dict[str, Any] = {"_cls": cls, "_new": object.__new__, **defaults}
    make: Callable[..., Any] = _twin_maker(cls, args, values, namespace) or _descriptor_maker(
        cls, args, values, namespace
    )
    make.__qualname__ = f"make_{cls.__name__}"
    return make


def _twin_maker(cls: type, args: str, values: dict[str, str], namespace: dict[str, Any]) -> Any:
    twin = type(f"_{cls.__name__}Twin", cls.__bases__, {"__slots__": cls.__dict__.get("__slots__", ())})
    if any("__setattr__" in vars(base) for base in twin.__mro__[1:-1]):  # a frozen base would refuse
        return None
    # (made bare below: a __new__ of its own would be skipped)
    if getattr(twin, "__new__", None) is not object.__new__:
        return None
    namespace["_twin"] = twin
    # The stores written in make itself, on a bare twin (object.__new__, in C): one Python call per
    # object, not two (make, then an __init__).
    body = "".join(f"    o.{name} = {value}\n" for name, value in values.items())
    exec(f"def make({args}):\n    o = _new(_twin)\n{body}    o.__class__ = _cls\n    return o\n", namespace)
    make = namespace["make"]
    try:  # CPython checks the layouts on assignment: prove they match once, here
        probe: Any = object.__new__(twin)
        probe.__class__ = cls
    except TypeError:
        return None
    return make


def _descriptor_maker(cls: type, args: str, values: dict[str, str], namespace: dict[str, Any]) -> Any:
    setters = {f"_s_{name}": getattr(cls, name).__set__ for name in values}
    namespace.update(setters)
    body = "".join(f"    _s_{name}(o, {value})\n" for name, value in values.items())
    exec(f"def make({args}):\n    o = _new(_cls)\n{body}    return o\n", namespace)
    return namespace["make"]
