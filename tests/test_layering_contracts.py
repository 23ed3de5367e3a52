"""The contracts a family implements live in the protocols layer (issue 38): the layering table puts
a family's cli, dbc and _motor parts in the family layer, and the one type-only import up the layers
(the typed calls are a Motor to a type checker) stays type-only."""

from __future__ import annotations

import test_layering as lay
from servobus.protocols import FAMILIES


def test_a_family_s_parts_are_in_the_family_layer() -> None:
    for family in FAMILIES:
        for part in ("cli", "dbc", "_motor", "bound", "codec"):
            assert lay.layer_of(f"servobus.protocols.{family}.{part}") == "family", (family, part)


def test_the_contracts_are_in_the_protocols_layer() -> None:
    for module in ("cli", "dbc", "dbc_layouts", "_calls"):
        assert lay.layer_of(f"servobus.protocols.{module}") == "protocols", module


def test_a_family_importing_the_cli_or_the_bus_is_a_violation() -> None:
    source = "from servobus.cli import plugin\nfrom servobus.bus import Motor\nimport servobus.dbc\n"
    assert lay.import_violations(source, "servobus.protocols.lk.cli") == [
        "1: family imports servobus.cli.plugin (app)",
        "2: family imports servobus.bus (bus)",
        "3: family imports servobus.dbc (app)",
    ]


def test_type_only_imports_stay_type_only() -> None:
    """An allowed type-only import outside ``if TYPE_CHECKING:`` is a violation again."""
    module = "servobus.protocols._calls"
    typed = "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from servobus.bus import Motor\n"
    assert lay.import_violations(typed, module) == []
    assert lay.import_violations("from servobus.bus import Motor\n", module) == [
        "1: protocols imports servobus.bus (bus)"
    ]
    branch = "if TYPE_CHECKING:\n    pass\nelse:\n    from servobus.bus import Motor\n"
    assert lay.import_violations(branch, module) == ["4: protocols imports servobus.bus (bus)"]
    for module, allowed in lay.TYPE_ONLY.items():
        path = lay.SRC.parent.joinpath(*module.split(".")).with_suffix(".py")
        if not path.exists():  # a package: its __init__
            path = lay.SRC.parent.joinpath(*module.split("."), "__init__.py")
        source = path.read_text()
        lines = lay.type_checking_lines(source)
        for line, name in lay.imported_modules(source, module):
            if name in allowed:
                assert line in lines, f"{module}:{line} imports {name} outside TYPE_CHECKING"
