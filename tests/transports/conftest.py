"""Fixtures the transport tests share."""

from __future__ import annotations

import itertools

import pytest

_channels = itertools.count()


@pytest.fixture
def channel() -> str:
    """A python-can ``virtual`` channel no other test uses."""
    return f"can-test-{next(_channels)}"
