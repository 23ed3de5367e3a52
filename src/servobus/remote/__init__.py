"""Buses on other computers, through Zenoh: :class:`Bridge` serves local buses, :func:`connect`
reaches one from anywhere (``pip install 'servobus[remote]'``)."""

from servobus.remote.bridge import Bridge
from servobus.remote.client import BridgeLost, RemoteBus, RemoteError, RemoteMotor, RemoteStatus, connect

__all__ = ["Bridge", "BridgeLost", "RemoteBus", "RemoteError", "RemoteMotor", "RemoteStatus", "connect"]
