"""servobus.testing, the family contract as a suite a family's package runs: it runs from an
out-of-tree package's own test file, it fails a family that breaks the contract, the project's suite
runs it over another installed family, and servobus itself never imports pytest or hypothesis."""

from __future__ import annotations

import dataclasses
import math
import os
import re
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import Any, ClassVar

import pytest
from hypothesis import given, settings

from _toy import another_family
from servobus.testing import (
    FamilyContract,
    bindings,
    check_bound_codecs,
    check_command_round_trips,
    check_declarations,
    check_reply_round_trips,
    check_sim_answers,
    message_strategy,
    unbuilt,
)

ROOT = Path(__file__).resolve().parents[1]
CONTRACT_TESTS = sorted(name for name in dir(FamilyContract) if name.startswith("test_"))

#: a family package's whole contract test: the file the "Writing a family" page shows
PACKAGE_TEST = """\
from servobus.testing import FamilyContract

from servobus_aaa import FAMILY


class TestAaaFamily(FamilyContract):
    family = FAMILY
"""


def _pytest(args: list[str], *, cwd: Path, path: list[Path]) -> subprocess.CompletedProcess[str]:
    pythonpath = os.pathsep.join([*map(str, path), os.environ.get("PYTHONPATH", "")])
    return subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=240,
        env={**os.environ, "PYTHONPATH": pythonpath},
        check=False,
    )


def _passed(result: subprocess.CompletedProcess[str]) -> int:
    found = re.search(r"(\d+) passed", result.stdout)
    return int(found.group(1)) if found else 0


def test_servobus_never_imports_pytest_or_hypothesis_until_servobus_testing_is_imported() -> None:
    code = (
        "import sys, servobus, servobus.protocols, servobus.sim, servobus.tools.dbc, servobus.cli\n"
        "from servobus.protocols import FAMILIES, get_family\n"
        "[get_family(n).part(p) for n in FAMILIES for p in get_family(n).parts]\n"
        "print(sorted(m for m in ('pytest', 'hypothesis') if m in sys.modules))\n"
        "import servobus.testing\n"
        "print(sorted(m for m in ('pytest', 'hypothesis') if m in sys.modules))\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == ["[]", "['hypothesis', 'pytest']"]


def test_a_family_package_runs_the_whole_contract_with_one_class(tmp_path: Path) -> None:
    """An out-of-tree package (a copy of the toy family, installed as ``aaa``) with the one test file
    the docs show: every test of the contract runs and passes, outside servobus' own suite."""
    site = another_family(tmp_path / "site", "aaa")
    tests = tmp_path / "package" / "tests"
    tests.mkdir(parents=True)
    (tests / "test_contract.py").write_text(PACKAGE_TEST)
    # (servobus as this interpreter has it installed: a clean install's src/ has no compiled core)
    result = _pytest(["-rA", "tests"], cwd=tests.parent, path=[site])
    assert result.returncode == 0, result.stdout + result.stderr
    ran = re.findall(r"PASSED \S+::TestAaaFamily::(test_\w+)", result.stdout)
    assert sorted(ran) == CONTRACT_TESTS


def test_the_project_suite_runs_the_contract_over_another_installed_family(tmp_path: Path) -> None:
    """A distribution the suite was never told of, registering ``aaa``, is checked by
    tests/protocols/test_family_contract.py because it is installed (found by its entry point)."""
    site = another_family(tmp_path / "site", "aaa")
    result = _pytest(
        ["tests/protocols/test_family_contract.py", "-k", "aaa or the_suite_checks"],
        cwd=ROOT,
        path=[site],
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert _passed(result) == len(CONTRACT_TESTS) + 2  # the contract, the parts, the list of families


def test_the_tests_that_list_families_pass_with_another_family_installed(tmp_path: Path) -> None:
    """The tests that name the installed families (an unknown family's error, the "use --family X"
    hints) mean the built-ins are among them, not that they are all: with a plug-in that sorts first
    and offers CAN FD and RS485 installed, they still pass."""
    site = another_family(tmp_path / "site", "aaa", media=("can", "canfd", "rs485"))
    result = _pytest(
        [
            "tests/sim/test_family.py",
            "tests/test_plugin_family.py",
            "-k",
            "offer or refuses_what or unknown or registers",
        ],
        cwd=ROOT,
        path=[site],
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert _passed(result) == 7


# ---- the contract fails a family that breaks it ----


def _toy_with(toy: ModuleType, **changes: Any) -> Any:
    return dataclasses.replace(toy.FAMILY, package=None, **changes)


def test_a_command_class_that_is_not_slotted_is_refused(toy: ModuleType) -> None:
    @dataclasses.dataclass(frozen=True)
    class Unslotted(toy.messages.ToyCommand[toy.StateReply]):  # type: ignore[name-defined,misc]
        CODE: ClassVar[int] = 0x55

    with pytest.raises(AssertionError, match="Unslotted is no frozen slotted dataclass"):
        check_declarations(_toy_with(toy, commands=(*toy.FAMILY.commands, Unslotted)))


def test_a_bound_codec_that_retries_a_write_is_refused(toy: ModuleType) -> None:
    from servobus_toy.codec import ToyCodec, bind

    class Retrying(ToyCodec):
        def retry_safe(self, command: Any) -> bool:
            return True

    def lying_bind(motor_id: int, **options: Any) -> ToyCodec:
        codec = bind(motor_id, **options)
        return Retrying(codec.motor_id, codec.revision)

    with pytest.raises(AssertionError, match="SetSpeed: retry_safe is not READ"):
        check_bound_codecs(_toy_with(toy, bind=lying_bind))


def test_a_request_decoder_that_loses_a_value_is_refused(toy: ModuleType) -> None:
    def rounding(can_id: int, data: bytes, **options: Any) -> Any:
        command = toy.FAMILY.decode_request(can_id, data, **options)
        if isinstance(command, toy.SetSpeed):
            return toy.SetSpeed(speed_dps=round(command.speed_dps))
        return command

    with pytest.raises(AssertionError, match=r"SetSpeed\(speed_dps=.*\) does not decode back"):
        check_command_round_trips(_toy_with(toy, decode_request=rounding), max_examples=50)


def test_a_reply_the_codec_does_not_take_is_refused(toy: ModuleType) -> None:
    from servobus_toy.codec import ToyCodec, bind

    class Deaf(ToyCodec):
        def classify(self, frame: Any) -> Any:
            return super().classify(dataclasses.replace(frame, arbitration_id=0x7FF))

    def deaf_bind(motor_id: int, **options: Any) -> ToyCodec:
        codec = bind(motor_id, **options)
        return Deaf(codec.motor_id, codec.revision)

    with pytest.raises(AssertionError, match="does not decode back: no codec takes it"):
        check_reply_round_trips(_toy_with(toy, bind=deaf_bind))


def test_a_simulated_motor_that_does_not_answer_is_refused(
    toy: ModuleType, monkeypatch: pytest.MonkeyPatch
) -> None:
    from servobus_toy.device import ToyMotor

    assert check_sim_answers(toy.FAMILY) == 4  # the commands that get a reply
    monkeypatch.setattr(ToyMotor, "receive", lambda self, frame, now_s: [])
    answer = r"the simulated motor's answer to ReadState.*none with the reply key"
    with pytest.raises(AssertionError, match=answer):
        check_sim_answers(toy.FAMILY)


class TestAFamilyWithAClassWithoutStrategy(FamilyContract):
    """A class the declarations do not describe fails the contract unless the family gives its
    strategy (or names it in ``unbuilt_ok``)."""

    @pytest.fixture
    def contract_family(self, toy: ModuleType) -> Any:
        @dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
        class Calibrate(toy.messages.ToyCommand[toy.StateReply]):  # type: ignore[name-defined,misc]
            CODE: ClassVar[int] = 0x40
            model: str  # required, and no declared field says what it holds

        return _toy_with(toy, commands=(*toy.FAMILY.commands, Calibrate))

    def test_every_message_class_has_a_strategy(self, contract_family: Any, **_: Any) -> None:  # type: ignore[override]
        assert unbuilt(contract_family) == ["Calibrate"]
        with pytest.raises(AssertionError, match=r"no strategy for \['Calibrate'\]"):
            super().test_every_message_class_has_a_strategy(contract_family, {}, frozenset())
        super().test_every_message_class_has_a_strategy(contract_family, {}, frozenset({"Calibrate"}))

    def test_the_simulated_motor_answers_its_own_codec(self, **_: Any) -> None:  # type: ignore[override]
        pytest.skip("the toy's simulated motor has no Calibrate")

    def test_the_typed_motor_has_a_method_per_command(self, **_: Any) -> None:  # type: ignore[override]
        pytest.skip("the typed motor is generated without Calibrate")


def test_bind_options_bind_each_model_and_reach_the_request_decoder(toy: ModuleType) -> None:
    from servobus_toy.codec import bind

    seen: set[str] = set()

    def bind_model(motor_id: int, *, model: str = "small", **options: Any) -> Any:
        if model not in ("small", "large"):
            raise ValueError(f"no model {model!r}")
        seen.add(f"bind {model}")
        return bind(motor_id, **options)

    def decode_model(can_id: int, data: bytes, *, model: str = "small", **options: Any) -> Any:
        seen.add(f"decode {model}")
        return toy.FAMILY.decode_request(can_id, data, **options)

    family = _toy_with(toy, bind=bind_model, decode_request=decode_model)
    options = [{"model": "large"}, {"model": "huge"}]  # huge: refused, skipped
    assert len(list(bindings(family, options=options))) == 1
    check_command_round_trips(family, bind_options=options, max_examples=2)
    assert seen == {"bind large", "decode large"}


# ---- the strategies ----


def test_the_derived_values_are_within_the_declared_limits_and_on_their_resolution(toy: ModuleType) -> None:
    strategy = message_strategy(toy.SetSpeed)
    assert strategy is not None

    @settings(max_examples=200, deadline=None, database=None)
    @given(strategy)
    def each(command: Any) -> None:
        assert -1000.0 <= command.speed_dps <= 1000.0
        counts = command.speed_dps * 100
        assert math.isclose(counts, round(counts), abs_tol=1e-6)

    each()


def test_a_class_without_declared_fields_for_its_required_values_has_no_derived_strategy() -> None:
    from servobus.protocols import lk

    assert message_strategy(lk.SpeedControl) is None  # its motor type: a model, not a declared field
    assert message_strategy(lk.ReadStatus1) is not None
