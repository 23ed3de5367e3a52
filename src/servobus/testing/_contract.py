"""The contract as a pytest class a family's tests subclass (see :mod:`servobus.testing`)."""

from __future__ import annotations

from typing import Any, ClassVar

import pytest

from servobus.protocols import Family, Reply
from servobus.testing import _checks as checks
from servobus.testing._checks import NO_OPTIONS, BindOptions
from servobus.testing._strategies import Strategies, strategies_of

__all__ = ["FamilyContract"]


class FamilyContract:
    """The family contract's tests: subclass it as ``TestMyFamily`` with ``family = FAMILY``.

    Attributes:
        family: the Family under test.
        strategies: message class -> a hypothesis strategy of its instances, for the classes whose
            declarations do not describe them (these win over the derived ones).
        unbuilt_ok: names of message classes the contract may leave without a strategy (the
            family's own tests check them); any other class without one fails
            :meth:`test_every_message_class_has_a_strategy`.
        max_examples: hypothesis examples per class in the round trips.
        bind_options: ``bind``'s keyword arguments, one mapping per binding to check besides every
            link and revision (``[{"model": "DM4310"}, {"model": "DM8009"}]``: every model); the
            default binds with the family's defaults. The request decoder is given the same ones.

    The tests take these through the fixtures ``contract_family``, ``contract_strategies``,
    ``contract_unbuilt_ok`` and ``contract_bind_options``, which return the attributes: a suite
    checking several families overrides the fixtures (parametrized) instead.
    """

    family: ClassVar[Family[Any]]
    strategies: ClassVar[Strategies] = {}
    unbuilt_ok: ClassVar[frozenset[str]] = frozenset()
    max_examples: ClassVar[int] = 20
    bind_options: ClassVar[BindOptions] = NO_OPTIONS

    @pytest.fixture
    def contract_family(self) -> Family[Any]:
        """The family under test (:attr:`family`)."""
        return self.family

    @pytest.fixture
    def contract_strategies(self) -> Strategies:
        """The strategies the family gives (:attr:`strategies`)."""
        return self.strategies

    @pytest.fixture
    def contract_unbuilt_ok(self) -> frozenset[str]:
        """The classes the contract may leave unbuilt (:attr:`unbuilt_ok`)."""
        return self.unbuilt_ok

    @pytest.fixture
    def contract_bind_options(self) -> BindOptions:
        """The bindings' options (:attr:`bind_options`)."""
        return self.bind_options

    def test_every_command_declares_its_reply_or_why_none_comes(self, contract_family: Family[Any]) -> None:
        checks.check_declarations(contract_family)

    def test_every_message_class_has_a_strategy(
        self,
        contract_family: Family[Any],
        contract_strategies: Strategies,
        contract_unbuilt_ok: frozenset[str],
    ) -> None:
        missing = set(checks.unbuilt(contract_family, contract_strategies)) - contract_unbuilt_ok
        assert not missing, (
            f"{contract_family.name}: no strategy for {sorted(missing)}: declare their fields, give "
            "them in `strategies`, or name them in `unbuilt_ok`"
        )

    def test_commands_encode_and_decode_back(
        self,
        contract_family: Family[Any],
        contract_strategies: Strategies,
        contract_bind_options: BindOptions,
    ) -> None:
        checked = checks.check_command_round_trips(
            contract_family,
            contract_strategies,
            max_examples=self.max_examples,
            bind_options=contract_bind_options,
        )
        assert checked, f"{contract_family.name}: no command was round-tripped"

    def test_replies_encode_and_decode_back(
        self,
        contract_family: Family[Any],
        contract_strategies: Strategies,
        contract_bind_options: BindOptions,
    ) -> None:
        checked = checks.check_reply_round_trips(
            contract_family,
            contract_strategies,
            max_examples=self.max_examples,
            bind_options=contract_bind_options,
        )
        built = strategies_of(contract_family, contract_strategies)
        drawn = [cls.__name__ for cls in built if issubclass(cls, Reply)]
        assert checked or not drawn, f"{contract_family.name}: no reply was round-tripped (of {drawn})"

    def test_the_bound_codec_follows_the_declarations(
        self,
        contract_family: Family[Any],
        contract_strategies: Strategies,
        contract_bind_options: BindOptions,
    ) -> None:
        checks.check_bound_codecs(contract_family, contract_strategies, bind_options=contract_bind_options)

    def test_every_binding_has_a_safe_command(
        self, contract_family: Family[Any], contract_bind_options: BindOptions
    ) -> None:
        checks.check_safe_commands(contract_family, bind_options=contract_bind_options)

    def test_a_few_motors_share_a_bus(
        self, contract_family: Family[Any], contract_bind_options: BindOptions
    ) -> None:
        checks.check_bus_of(contract_family, bind_options=contract_bind_options)

    def test_the_simulated_motor_answers_its_own_codec(
        self, contract_family: Family[Any], contract_strategies: Strategies
    ) -> None:
        if "sim" not in contract_family.parts:
            pytest.skip(f"{contract_family.name} has no sim part")
        assert checks.check_sim_answers(contract_family, contract_strategies), "no command was answered"

    def test_the_typed_motor_has_a_method_per_command(self, contract_family: Family[Any]) -> None:
        if contract_family.motor is None:
            pytest.skip(f"{contract_family.name} has no typed motor")
        motor = contract_family.motor()
        missing = [name for name in contract_family.methods() if name not in vars(motor)]
        assert not missing, f"{contract_family.name}: the typed motor has no {missing} (regenerate it)"

    def test_the_cli_part_is_a_cli_family(self, contract_family: Family[Any]) -> None:
        if not checks.check_cli_part(contract_family):
            pytest.skip(f"{contract_family.name} has no cli part")

    def test_the_dbc_builds_and_cantools_loads_it(self, contract_family: Family[Any]) -> None:
        pytest.importorskip("cantools")
        checks.check_dbc_part(contract_family)
