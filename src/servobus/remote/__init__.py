"""Buses on other computers, through Zenoh: :class:`Bridge` serves local buses, :func:`connect`
reaches one from anywhere (``pip install 'servobus[remote]'``)."""

try:
    import zenoh  # noqa: F401  (the optional dependency, named in the error below)
except ImportError as exc:  # pragma: no cover - exercised only without the extra
    raise ImportError("servobus.remote needs eclipse-zenoh: pip install 'servobus[remote]'") from exc

from servobus.remote.bridge import Bridge
from servobus.remote.client import BridgeLost, RemoteBus, RemoteError, RemoteMotor, RemoteStatus, connect

__all__ = ["Bridge", "BridgeLost", "RemoteBus", "RemoteError", "RemoteMotor", "RemoteStatus", "connect"]
