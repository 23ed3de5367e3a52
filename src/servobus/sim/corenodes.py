"""The devices on a :class:`~servobus.sim.corenet.CoreCanNetwork`, by their node in the C network.

Node 0 is the host; every device gets a node when it is added. A device with a C path (its
family's ``CORE_FAMILY`` and ``core_*`` methods, and ``receive``/``poll`` its model's own) gets its
C twin there; any other device stays in Python and C hands it its frames and polls as events. What C
needs to know of a Python device (the identifiers it listens to, its next deadline) is written into
its node after every call into it and whenever it says it changed; a core device pushes its whole
state itself. A device that listens to more identifiers than C holds gets every frame from C, and
the network drops the others in Python (:attr:`CoreNodes.filter`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Hashable
from typing import Any, cast

from servobus.core._lib import lib
from servobus.sim.device import Device, Listener
from servobus.sim.network import HOST

__all__ = ["CoreNodes", "handles_frames_as_its_model"]

_INF = math.inf
_MAX_LISTEN = lib.SB_SIM_MAX_LISTEN


def handles_frames_as_its_model(device: object) -> bool:
    """The device's ``receive`` and ``poll`` are its family model's own, which the C path reproduces.

    A subclass of the model that overrides either (a user's custom device), or one replaced on the
    class (a test that records every frame a motor receives), wants to see the frames itself: C
    would bypass it, so such a device stays in Python. Told apart by where the methods were written:
    in the package that also writes ``core_attach``, under the name of the class that holds them.
    """
    cls = type(device)
    attach = next((k for k in cls.__mro__ if "core_attach" in vars(k)), None)
    if attach is None:
        return False
    package = attach.__module__.rpartition(".")[0]
    for name in ("receive", "poll"):
        owner = next((k for k in cls.__mro__ if name in vars(k)), None)
        method = vars(owner).get(name) if owner is not None else None
        if (
            owner is None
            or owner.__module__.rpartition(".")[0] != package
            or getattr(method, "__qualname__", None) != f"{owner.__qualname__}.{name}"
        ):
            return False
    return True


class CoreNodes:
    """Which device is on which node of ``net`` (a ``sb_simnet *``), and what C knows of each.

    Args:
        net: the C network.
        make_link: ``make_link(node, name)`` gives a listening device's account with the network.
    """

    def __init__(self, net: Any, make_link: Callable[[int, str], Any]) -> None:
        self._net = net
        self._make_link = make_link
        self.devices: dict[str, Device] = {}
        self.names: list[str | None] = [None] * lib.SB_NET_NODES
        self.names[0] = HOST
        self.node_of: dict[str, int] = {}
        self.by_node: list[Device | None] = [None] * lib.SB_NET_NODES
        self.core: list[bool] = [False] * lib.SB_NET_NODES  # the device has a C path
        self.filter: dict[int, frozenset[int]] = {}  # listeners with more identifiers than C holds
        self.listeners: dict[str, Listener] = {}
        self.unlinked: list[tuple[int, Device]] = []  # asked for their deadline before every run
        self.dirty: list[str] = []  # listening devices that said they changed
        self._first: dict[str, tuple[int, float, int]] = {}  # a removed node's first (joined, seq)

    def add(self, device: Device) -> None:
        """Give ``device`` a node (and its C twin if it has a C path).

        Raises:
            ValueError: another device has the same name, the device is on another network, or the
                network is full.
        """
        name, net = device.name, self._net
        if name in self.devices or name == HOST:
            raise ValueError(f"a device named {name!r} is already on this bus")
        linked = all(hasattr(device, method) for method in ("listen_ids", "attach", "settle"))
        core = linked and hasattr(device, "CORE_FAMILY") and handles_frames_as_its_model(device)
        has_first, first_joined, first_seq = self._first.pop(name, (0, 0.0, 0))
        kind = lib.SB_NODE_CORE if core else lib.SB_NODE_PYTHON
        node = lib.sb_simnet_add(net, kind, linked, has_first, first_joined, first_seq)
        if node < 0:
            self._first[name] = (has_first, first_joined, first_seq)
            raise ValueError(
                f"no room for {name!r}: a simulated CAN network holds {lib.SB_NET_NODES - 1} devices"
            )
        try:
            if linked:
                link = self._make_link(node, name)
                if core:
                    cast(Any, device).core_attach(net.motors + node, link)
                else:
                    cast(Listener, device).attach(link)
                self.listeners[name] = cast(Listener, device)
                self.dirty.append(name)
            else:
                net.motors[node].listen_all = 1
                lib.sb_simnet_touch(net, node)
                self.unlinked.append((node, device))
        except BaseException:
            lib.sb_simnet_remove(net, node)
            self._first[name] = (has_first, first_joined, first_seq)
            raise
        self.devices[name] = device
        self.names[node] = name
        self.node_of[name] = node
        self.by_node[node] = device
        self.core[node] = core

    def remove(self, name: str) -> Device:
        """Take the device off its node (settled up first).

        Raises:
            KeyError: no device of that name.
            RuntimeError: called from inside the network's own run (a device's receive or poll).
        """
        net = self._net
        if net.phase != 0:  # C refuses while a step is half done: refuse before anything changes
            raise RuntimeError(f"cannot remove {name!r} while the network is handing it a frame or a poll")
        device = self.devices.pop(name)
        node = self.node_of.pop(name)
        if self.listeners.pop(name, None) is not None:
            if self.core[node]:
                cast(Any, device).core_detach()  # settles up first
            else:
                cast(Listener, device).attach(None)  # settles up first
            self.filter.pop(node, None)
        else:
            self.unlinked.remove((node, device))
        state = net.nodes[node]
        self._first[name] = (int(state.has_first), float(state.first_joined_s), int(state.first_seq))
        if lib.sb_simnet_remove(net, node) != lib.SB_OK:  # (checked above: cannot happen)
            raise RuntimeError(f"the simulated network refused to remove {name!r}")
        self.by_node[node] = None
        self.core[node] = False
        return device

    def source_node(self, source: Hashable) -> int | None:
        """The node of an arbitration source (the host or a device name), None if none."""
        if source == HOST:
            return 0
        return self.node_of.get(source) if isinstance(source, str) else None

    def called(self, node: int, device: Device) -> None:
        """After a call into a device: its deadline (and a core device's state) into C again."""
        if self.core[node]:
            cast(Any, device).core_push()
        else:
            deadline = device.next_deadline_s()
            self._net.motors[node].py_deadline_s = _INF if deadline is None else deadline
        lib.sb_simnet_touch(self._net, node)

    def refresh(self) -> None:
        """Ask the devices that said they changed for their identifiers and deadline again, and the
        unlinked devices for their deadline (SimCanNetwork asks those at every event)."""
        net = self._net
        if self.dirty:
            names, self.dirty[:] = set(self.dirty), []
            for name in names:
                node = self.node_of.get(name)
                device = self.listeners.get(name)
                if node is None or device is None:
                    continue
                self._write_listen(node, device.listen_ids())
                self.called(node, device)
        for node, unlinked in self.unlinked:
            deadline = unlinked.next_deadline_s()
            net.motors[node].py_deadline_s = _INF if deadline is None else deadline
            lib.sb_simnet_touch(net, node)

    def _write_listen(self, node: int, ids: Collection[int] | None) -> None:
        motor = self._net.motors[node]
        self.filter.pop(node, None)
        if ids is None or len(ids) > _MAX_LISTEN:
            if ids is not None:
                self.filter[node] = frozenset(ids)
            motor.listen_all = 1
            motor.n_listen = 0
            return
        ordered = sorted(ids)
        motor.listen_all = 0
        motor.n_listen = len(ordered)
        motor.listen[0 : len(ordered)] = ordered
