"""Typed motor calls: each command is a method a type checker knows, returning its declared reply.

The methods are generated from the command declarations into ``protocols/<family>/_motor.py``
(``python -m servobus.protocols._calls``); these tests check that the files are current, that they
behave as the commands they send, and what ``mypy --strict`` sees in a user's file.
"""

from __future__ import annotations

import dataclasses
import inspect
import textwrap
from pathlib import Path

import mypy.api as mypy_api  # the test extra installs it: the typing promise is checked, never skipped
import pytest

from servobus.protocols import FAMILIES, get_family
from servobus.protocols._calls import module_path, render


@pytest.mark.parametrize("name", sorted(FAMILIES))
def test_the_generated_methods_are_current(name: str) -> None:
    family = get_family(name)
    path = module_path(FAMILIES[name].partition(":")[0])
    assert path.read_text() == render(family), f"run: python -m servobus.protocols._calls ({path.name})"


@pytest.mark.parametrize("name", sorted(FAMILIES))
def test_every_command_has_its_method_with_its_fields(name: str) -> None:
    family = get_family(name)
    motor_class = family.motor()
    for method, cls in family.methods().items():
        signature = inspect.signature(getattr(motor_class, method))
        fields = [f.name for f in dataclasses.fields(cls) if f.init]
        assert [p for p in signature.parameters if p not in ("self", "timeout_s", "retries")] == fields


USER_FILE = """
    from servobus import Bus
    from servobus.protocols import myactuator as ma
    from servobus.protocols import lk

    async def main(bus: Bus) -> None:
        motor = bus.motor(ma.FAMILY, 3)
        reveal_type(await motor.read_status2())
        reveal_type(await motor.request(ma.ReadStatus2()))
        reveal_type(await motor.speed_control(speed_dps=100.0))
        reveal_type(await motor.system_reset())
        other = bus.motor(lk.FAMILY, 9)
        reveal_type(other)
        await motor.read_statuss2()
        await motor.speed_control(speed_rpm=3.0)
        named = bus.motor("myactuator", 3)
        reveal_type(await named.read_status2())
"""


@pytest.fixture(scope="module")
def mypy_output(tmp_path_factory: pytest.TempPathFactory) -> list[str]:
    folder = tmp_path_factory.mktemp("user")
    path = folder / "user.py"
    path.write_text(textwrap.dedent(USER_FILE))
    stdout, stderr, _ = mypy_api.run(
        ["--strict", "--no-incremental", "--cache-dir", str(folder / ".cache"), str(path)]
    )
    assert not stderr, stderr
    return [line.split(": ", 1)[1] for line in stdout.splitlines() if line.startswith(str(path))]


def _reply_name(cls: type) -> str:
    return f"{cls.__module__}.{cls.__qualname__}"


def test_a_typed_motor_returns_each_command_s_declared_reply(mypy_output: list[str]) -> None:
    from servobus.protocols import myactuator as ma

    status = _reply_name(ma.ReadStatus2.REPLY)
    notes = [line for line in mypy_output if line.startswith("note: Revealed type")]
    assert notes[0] == f'note: Revealed type is "{status}"'
    assert notes[1] == f'note: Revealed type is "{status}"'
    assert notes[2] == f'note: Revealed type is "{_reply_name(ma.SpeedControl.REPLY)}"'
    assert notes[3] == 'note: Revealed type is "None"'
    assert notes[4] == 'note: Revealed type is "servobus.protocols.lk._motor.Motor"'
    assert notes[5] == 'note: Revealed type is "Any"'  # by name: the methods exist, untyped


def test_a_misspelt_command_or_field_is_a_type_error(mypy_output: list[str]) -> None:
    errors = [line for line in mypy_output if line.startswith("error:")]
    assert any('has no attribute "read_statuss2"' in e for e in errors), errors
    assert any('Unexpected keyword argument "speed_rpm"' in e for e in errors), errors
    assert len(errors) == 2, errors


def test_the_check_finds_a_stale_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from servobus.protocols import _calls

    stale = tmp_path / "_motor.py"
    stale.write_text("# an older version\n")
    monkeypatch.setattr(_calls, "module_path", lambda package: stale)
    assert _calls.main(["--check"]) == 1
    assert stale.read_text() == "# an older version\n"
    assert _calls.main([]) == 0 and _calls.main(["--check"]) == 1  # all three write the one path


def test_the_readme_s_bus_examples_pass_mypy_strict(tmp_path: Path) -> None:
    import re

    root = Path(__file__).resolve().parents[1]  # the quick start in the README, the rest in the Bus guide
    text = (root / "README.md").read_text() + (root / "docs" / "guides" / "bus.md").read_text()
    blocks = re.findall(r"<!-- (?:quickstart|service|signals):[^\n]*-->\n```python\n(.*?)```", text, re.S)
    assert len(blocks) == 4  # (the guide repeats the quick start)
    for index, code in enumerate(blocks):
        (tmp_path / f"block{index}.py").write_text(code)
    stdout, stderr, status = mypy_api.run(
        ["--strict", "--no-incremental", "--cache-dir", str(tmp_path / ".cache"), str(tmp_path)]
    )
    assert status == 0, stdout + stderr
