"""Plug-in registries: protocol families and transports, built-in and from entry points."""

from __future__ import annotations

from importlib.metadata import EntryPoint

import pytest

from servobus import _plugins
from servobus.protocols import Family, get_family
from servobus.transports import CanTransport, available_transports, create_transport


@pytest.fixture
def plugins(monkeypatch: pytest.MonkeyPatch) -> dict[str, list[EntryPoint]]:
    """Entry points the registries will see, by group (empty until a test adds some)."""
    groups: dict[str, list[EntryPoint]] = {}
    monkeypatch.setattr(_plugins, "entry_points", lambda group: groups.get(group, []))
    return groups


def test_create_transport_builds_a_built_in_by_name() -> None:
    transport = create_transport("can", "virtual", "plugins", ignore_config=True)
    assert isinstance(transport, CanTransport) and transport.state.value == "closed"
    assert set(available_transports()) >= {"can", "rs485"}


@pytest.mark.usefixtures("plugins")
def test_an_unknown_name_lists_the_known_ones() -> None:
    known = r"\(known: can, rs485, sim, slcan\)"
    with pytest.raises(ValueError, match=rf"unknown transport 'carrier-pigeon' {known}"):
        create_transport("carrier-pigeon")
    with pytest.raises(ValueError, match="unknown protocol family 'acme'"):
        get_family("acme")


def test_plug_ins_register_through_entry_points(plugins: dict[str, list[EntryPoint]]) -> None:
    plugins["servobus.transports"] = [
        EntryPoint("mine", "servobus.transports.can:CanTransport", "servobus.transports")
    ]
    plugins["servobus.families"] = [EntryPoint("mine", "servobus.protocols.lk:FAMILY", "servobus.families")]
    assert isinstance(create_transport("mine", "virtual", "x", ignore_config=True), CanTransport)
    assert isinstance(get_family("mine"), Family)


def test_a_broken_plug_in_warns_and_the_built_ins_still_work(plugins: dict[str, list[EntryPoint]]) -> None:
    plugins["servobus.transports"] = [
        EntryPoint("broken", "no_such_module:Thing", "servobus.transports"),
        EntryPoint("can", "no_such_module:Shadow", "servobus.transports"),  # built-ins win a clash
        EntryPoint("wrong", "servobus.frame:Frame", "servobus.transports"),
    ]
    with pytest.warns(UserWarning, match="'broken'"), pytest.raises(ValueError, match="failed to load"):
        create_transport("broken")
    with pytest.raises(ValueError, match="not a servobus Transport"):
        create_transport("wrong")
    assert isinstance(create_transport("can", "virtual", "x", ignore_config=True), CanTransport)


def test_a_loaded_plug_in_is_read_again_from_its_module(plugins: dict[str, list[EntryPoint]]) -> None:
    import dataclasses

    from servobus.protocols import lk

    plugins["servobus.families"] = [EntryPoint("mine", "servobus.protocols.lk:FAMILY", "servobus.families")]
    assert get_family("mine") is lk.FAMILY
    original = lk.FAMILY
    try:
        lk.FAMILY = dataclasses.replace(original, description="rebound")
        assert get_family("mine").description == "rebound"  # the module's attribute, not a stale copy
    finally:
        lk.FAMILY = original
