"""A live view of buses, their motors and a running loop, in a browser (``servobus dashboard``).

* :class:`Dashboard`: what is shown (:meth:`~Dashboard.watch` a Bus or a bridge's bus,
  :meth:`~Dashboard.watch_loop` a :class:`servobus.Loop`, :meth:`~Dashboard.tap` a link for the raw
  frames) and the page itself as an ASGI app (:meth:`~Dashboard.app`), to serve or to mount on a
  server of one's own.
* :func:`serving` (a block) and :func:`serve` (a task): hypercorn on the running event loop
  (asyncio or trio), on a socket that :func:`listening_socket` binds (loopback unless users are
  given or ``insecure``).

Needs the ``dashboard`` extra: ``pip install 'servobus[dashboard]'``.
"""

from servobus.dashboard._app import KINDS, Dashboard
from servobus.dashboard._board import Board, Watched
from servobus.dashboard._serve import (
    DEFAULT_PORT,
    Access,
    InsecureListen,
    listening_socket,
    serve,
    serving,
    url_of,
)

__all__ = [
    "DEFAULT_PORT",
    "KINDS",
    "Access",
    "Board",
    "Dashboard",
    "InsecureListen",
    "Watched",
    "listening_socket",
    "serve",
    "serving",
    "url_of",
]
