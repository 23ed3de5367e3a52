"""``servobus.dbc`` (the path the docs showed) is a deprecated alias of the DBC contract
(``servobus.protocols.dbc``) and the exporter (``servobus.tools.dbc``), issue 38."""

from __future__ import annotations

import importlib
import sys

import pytest

import servobus.protocols.dbc as contract
import servobus.protocols.dbc_layouts as layouts
import servobus.tools.dbc as exporter


def test_importing_servobus_dbc_warns_and_gives_the_old_names() -> None:
    sys.modules.pop("servobus.dbc", None)
    with pytest.warns(DeprecationWarning, match=r"servobus\.protocols\.dbc.*servobus\.tools\.dbc"):
        alias = importlib.import_module("servobus.dbc")
    assert alias.DbcFamily is contract.DbcFamily
    assert alias.packed_signals is contract.packed_signals
    assert alias.plan is exporter.plan
    assert alias.dbc_text is exporter.dbc_text
    for name in alias.__all__:
        found = [getattr(m, name) for m in (contract, layouts, exporter) if hasattr(m, name)]
        assert found and getattr(alias, name) is found[0], name
    assert alias.message_fields is layouts.message_fields and alias.UNITS is layouts.UNITS


def test_servobus_cli_plugin_gives_the_cli_contract() -> None:
    from servobus.cli import plugin
    from servobus.protocols import cli

    assert plugin.CliFamily is cli.CliFamily
    assert set(plugin.__all__) == set(cli.__all__)
