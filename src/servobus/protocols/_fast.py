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
    setters: dict[str, Any] = {}
    defaults: dict[str, Any] = {}
    for name in fields:
        descriptor: Any = getattr(cls, name, None)
        if type(descriptor).__name__ != "member_descriptor":
            raise TypeError(f"{cls.__name__}.{name} is not a slot")
        setters[f"_s_{name}"] = descriptor.__set__
        if name not in names:
            default = fields[name].default
            if default is dataclasses.MISSING:
                raise TypeError(f"{cls.__name__}.{name} has no default and is not given")
            defaults[f"_d_{name}"] = default
    args = ", ".join(f"a{i}" for i in range(len(names)))
    body = [f"_s_{name}(o, a{i})" for i, name in enumerate(names)]
    body += [f"_s_{name}(o, _d_{name})" for name in fields if name not in names]
    keywords = ", ".join(f"{k}={k}" for k in (*setters, *defaults))
    source = (
        f"def make({args}{', ' if args else ''}*, _new=_new, _cls=_cls, {keywords}):\n"
        f"    o = _new(_cls)\n" + "".join(f"    {line}\n" for line in body) + "    return o\n"
    )
    namespace: dict[str, Any] = {"_new": object.__new__, "_cls": cls, **setters, **defaults}
    exec(source, namespace)
    make: Callable[..., Any] = namespace["make"]
    make.__qualname__ = f"make_{cls.__name__}"
    return make
