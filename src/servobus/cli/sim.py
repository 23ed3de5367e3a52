"""``servobus sim``: the simulator's pty server, the click command :mod:`servobus.sim.command` defines.

The same command runs as ``python -m servobus.sim``, so the two never differ: the first line printed
is the pseudo-terminal to open; a bad argument is one line and exit 2; Ctrl-C, SIGTERM or SIGHUP stop
it (and remove its ``--link``).
"""

from __future__ import annotations

from servobus.sim.command import sim

__all__ = ["sim"]
