"""The family contract as a test suite: what a protocol family's own package runs against its
``FAMILY`` (and what servobus runs over every installed family).

Import it only from tests: it imports pytest and hypothesis (``pip install 'servobus[testing]'``;
the DBC check needs cantools, ``servobus[dbc]``). Nothing else in servobus imports it.

A family's package runs the whole contract with one test file, its ``tests/test_contract.py``::

    from servobus.testing import FamilyContract

    from my_family import FAMILY


    class TestMyFamily(FamilyContract):
        family = FAMILY

pytest collects the ``test_*`` methods of the subclass. Each checks one part of the contract:

* the declarations: every command declares its reply (``Command[R]``) or why none comes
  (``NO_REPLY``); commands and replies are frozen slotted dataclasses; ``READ``, ``SLOW``, ... are
  bools; one motor method name per command;
* encode/decode round trips, with hypothesis: values drawn from each class's declared field limits
  (:func:`message_strategy`), every command encodes and ``FAMILY.decode_request`` gives back an
  equal command, every reply's bytes decode back to an equal reply through the bound codec;
* the bound codec (:class:`~servobus.protocols.BoundCodec`) on every link and revision it binds:
  requests on the motor's own or shared identifiers, ``retry_safe`` is ``READ``, a reply key
  exactly when a reply is declared, safe commands that encode, a few motors passing ``check_bus``;
* the ``sim`` part, if any: a simulated motor answers each command that expects a reply with a
  frame the bound codec takes as that reply;
* the ``cli`` part, if any, is a :class:`servobus.protocols.cli.CliFamily` offering or refusing
  every CLI operation; the ``dbc`` part, if any, is a :class:`servobus.protocols.dbc.DbcFamily`,
  and the family's DBC builds and loads in cantools.

A class whose required fields the declarations do not describe (a field kind the rules do not
know, a required field no declared field covers: a motor model) gets its strategy from the family;
it must draw values the decoder gives back unchanged (a bit field scaled over ``[lo, hi]`` in
``bits`` bits: ``lo + k * (hi - lo) / (2**bits - 1)``)::

    from hypothesis import strategies as st

    def grid(lo: float, hi: float, bits: int) -> st.SearchStrategy[float]:
        top = (1 << bits) - 1
        return st.integers(0, top).map(lambda k: lo + k * (hi - lo) / top)

    class TestMyFamily(FamilyContract):
        family = FAMILY
        strategies = {Mit: st.builds(Mit, position_rad=grid(-12.5, 12.5, 16))}
        unbuilt_ok = frozenset({"Calibrate"})  # checked by the package's own tests instead
        bind_options = [{"model": "DM4310"}, {"model": "DM8009"}]  # bind (and decode) each model
        max_examples = 50

Every check is also a plain function (``check_declarations(FAMILY)``, ...), for a test runner other
than pytest or a test of one part.
"""

from __future__ import annotations

from servobus.testing._checks import (
    NO_OPTIONS,
    BindOptions,
    bindings,
    check_bound_codecs,
    check_bus_of,
    check_cli_part,
    check_command_round_trips,
    check_dbc_part,
    check_declarations,
    check_reply_round_trips,
    check_safe_commands,
    check_sim_answers,
    unbuilt,
)
from servobus.testing._contract import FamilyContract
from servobus.testing._strategies import (
    Strategies,
    field_strategy,
    message_classes,
    message_strategy,
    strategies_of,
)

__all__ = [
    "NO_OPTIONS",
    "BindOptions",
    "FamilyContract",
    "Strategies",
    "bindings",
    "check_bound_codecs",
    "check_bus_of",
    "check_cli_part",
    "check_command_round_trips",
    "check_dbc_part",
    "check_declarations",
    "check_reply_round_trips",
    "check_safe_commands",
    "check_sim_answers",
    "field_strategy",
    "message_classes",
    "message_strategy",
    "strategies_of",
    "unbuilt",
]
