"""``python -m servobus.sim``: the ``servobus sim`` command (:mod:`servobus.sim.command`) under Python's name.

Simulated motors on a pseudo-terminal, for any tool to talk to: the first line printed is the path
a host should open; it serves until interrupted (Ctrl-C, SIGTERM or SIGHUP)::

    python -m servobus.sim --family myactuator --motors 4 --slcan
    python -m servobus.sim --family lk --motors 8 --revision V2_35 --link /tmp/can0

A bad argument prints one line (``servobus.sim: error: ...``) to stderr and exits with status 2.
"""

from __future__ import annotations

import sys

from servobus.sim.command import main

if __name__ == "__main__":
    sys.exit(main())
