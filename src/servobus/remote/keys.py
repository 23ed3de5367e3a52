"""The key expressions a bridge serves, in one place (node N, bus B, motor M, its decimal id):

| key | what | who may use it |
|---|---|---|
| ``servobus/N/_alive`` | the bridge's liveliness token | readers |
| ``servobus/N/_clients/<id>`` | a commanding client's liveliness token | commanders |
| ``servobus/N/B/info`` | queryable: the bus's motors, families, limits (JSON) | readers |
| ``servobus/N/B/metrics`` | queryable: the Bus's and the bridge's counters (JSON) | readers |
| ``servobus/N/B/M/state`` | published: latest reply, online flag, fault (binary) | readers |
| ``servobus/N/B/M/read`` | queryable: one read-only command (``READ``) | readers |
| ``servobus/N/B/M/request`` | queryable: one command of any kind | commanders |
| ``servobus/N/B/M/setpoint`` | subscribed: a motor's set-point | commanders |
| ``servobus/N/B/setpoints`` | subscribed: a batch of set-points of one bus | commanders |

Names are checked here so that a node, bus or client id can never be a wildcard or a path.
"""

from __future__ import annotations

import re

__all__ = ["ROOT", "Keys", "check_name"]

ROOT = "servobus"

_MOTOR = re.compile(r"0|[1-9][0-9]{0,4}")  # one spelling per id: no "03", no other digit scripts
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}")


def check_name(what: str, name: str) -> str:
    """``name`` if it is a valid node, bus or client name (letters, digits, ``_.-``, not starting
    with ``_``, which the bridge's own keys use), else ValueError naming ``what``."""
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise ValueError(
            f"{what} {name!r} is not a valid name: 1-64 letters, digits, '_', '.', '-', "
            "starting with a letter or digit"
        )
    return name


class Keys:
    """The keys of one node (a bridge), built once; the motor's are built per call."""

    __slots__ = ("_prefix", "alive", "clients", "node")

    def __init__(self, node: str) -> None:
        self.node = check_name("node", node)
        self._prefix = f"{ROOT}/{node}"
        self.alive = f"{self._prefix}/_alive"
        self.clients = f"{self._prefix}/_clients/*"

    def client(self, client_id: str) -> str:
        return f"{self._prefix}/_clients/{check_name('client id', client_id)}"

    def bus(self, bus: str, leaf: str) -> str:
        """``servobus/N/B/<leaf>`` (``info``, ``metrics``, ``setpoints``)."""
        return f"{self._prefix}/{bus}/{leaf}"

    def motor(self, bus: str, motor_id: int | str, leaf: str) -> str:
        """``servobus/N/B/M/<leaf>`` (``state``, ``read``, ``request``, ``setpoint``); ``*`` for M
        gives the expression that matches every motor of the bus."""
        return f"{self._prefix}/{bus}/{motor_id}/{leaf}"

    def parse_motor(self, key: str) -> tuple[str, int, str]:
        """``(bus, motor_id, leaf)`` of a motor key of this node.

        Raises:
            ValueError: not a motor key of this node.
        """
        parts = str(key).split("/")
        if len(parts) != 5 or parts[0] != ROOT or parts[1] != self.node or not _MOTOR.fullmatch(parts[3]):
            raise ValueError(f"{key!r} is not a motor key of node {self.node!r}")
        return parts[2], int(parts[3]), parts[4]
