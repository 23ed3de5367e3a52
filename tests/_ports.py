"""Loopback addresses for the tests that listen: a free TCP port, and a Zenoh endpoint on one."""

from __future__ import annotations

import socket


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on now."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def loopback_endpoint() -> str:
    """A Zenoh endpoint on a free loopback port (``tcp/127.0.0.1:PORT``)."""
    return f"tcp/127.0.0.1:{free_port()}"
