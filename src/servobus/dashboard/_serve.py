"""Serving the dashboard: hypercorn (asyncio and trio) on a socket bound here, loopback by default.

Beyond this host only with users (HTTP Basic, a ``user:password`` file like the bridge's) or when
told ``insecure``, as the bridge does; on loopback, requests must name this host (a page of another
site that rebinds its name to 127.0.0.1 is refused).
"""

from __future__ import annotations

import base64
import binascii
import contextlib
import functools
import hashlib
import hmac
import ipaddress
import logging
import os
import socket
from collections.abc import AsyncIterator, Awaitable, Callable, Collection, Iterable, Mapping, MutableMapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import anyio
import sniffio

from servobus.dashboard._app import MAY_COMMAND, Dashboard

__all__ = ["DEFAULT_PORT", "Access", "InsecureListen", "listening_socket", "serve", "serving", "url_of"]

DEFAULT_PORT = 8765
#: how long the server has to close its connections once told to stop (then it is cancelled)
SHUTDOWN_S = 3.0
LOOPBACK_NAMES = ("127.0.0.1", "localhost", "[::1]", "::1")

Scope = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[MutableMapping[str, Any]]]
Send = Callable[[MutableMapping[str, Any]], Awaitable[None]]
App = Callable[[Scope, Receive, Send], Awaitable[None]]


class InsecureListen(ValueError):
    """The dashboard was asked to listen beyond this host without users (and not ``insecure``)."""


@dataclass(frozen=True, slots=True)
class Access:
    """Who may open the page (HTTP Basic): ``users`` by name with their password; ``commanders``, the
    names among them who may press stop (the others only read)."""

    users: Mapping[str, str]
    commanders: Collection[str] = ()

    def __post_init__(self) -> None:
        if not self.users:
            raise ValueError("no users: a users file needs one user:password a line")
        unknown = sorted(set(self.commanders) - set(self.users))
        if unknown:
            raise ValueError(f"--commander {', '.join(unknown)}: not in the users file")

    @classmethod
    def from_file(cls, path: Path, commanders: Collection[str] = ()) -> Access:
        """``user:password`` lines (the bridge's ``--users`` file); blank lines and ``#`` comments
        skipped.

        Raises:
            ValueError: a line that is not ``user:password``, or a commander not in the file.
        """
        users: dict[str, str] = {}
        for number, line in enumerate(path.read_text().splitlines(), 1):
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            user, sep, password = line.partition(":")
            if not sep or not user or not password:
                raise ValueError(f"{path}:{number}: expected user:password")
            users[user] = password
        return cls(users, frozenset(commanders))

    def check(self, header: str | None) -> str | None:
        """The user an ``Authorization`` header names with the right password, else None."""
        scheme, _, given = (header or "").strip().partition(" ")
        if scheme.lower() != "basic":
            return None
        try:
            user, _, password = base64.b64decode(given.strip(), validate=True).decode().partition(":")
        except (binascii.Error, UnicodeDecodeError):
            return None
        known = self.users.get(user)
        # compared whatever the user, digests of equal length: the answer's timing tells neither
        # whether the user exists nor how long the password is
        same = hmac.compare_digest(_digest(known or ""), _digest(password))
        return user if same and known is not None else None


def _digest(text: str) -> bytes:
    return hashlib.sha256(text.encode()).digest()


def guarded(app: App, *, access: Access | None, loopback: str | None) -> App:
    """``app`` behind the listening rules: users' passwords (when ``access``), and when listening
    on the loopback address ``loopback``, a Host header naming this host (that address,
    ``localhost`` or ``127.0.0.1``): a page of another site whose name was rebound to this host
    names its own."""
    names = {*LOOPBACK_NAMES, loopback, f"[{loopback}]"} if loopback else set()

    async def guard(scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await app(scope, receive, send)
            return
        headers = {k.decode("latin-1"): v.decode("latin-1") for k, v in scope.get("headers", ())}
        if names and _host_name(headers.get("host", "")) not in names:
            await _refuse(send, 421, "this dashboard answers to 127.0.0.1 and localhost only")
            return
        if access is not None:
            user = access.check(headers.get("authorization"))
            if user is None:
                await _refuse(send, 401, "log in", {"www-authenticate": 'Basic realm="servobus dashboard"'})
                return
            scope[MAY_COMMAND] = user in access.commanders
        await app(scope, receive, send)

    return guard


def _host_name(host: str) -> str:
    if host.startswith("["):
        return host.split("]")[0] + "]"
    return host.rsplit(":", 1)[0] if host.count(":") == 1 else host


async def _refuse(send: Send, status: int, text: str, headers: Mapping[str, str] | None = None) -> None:
    raw = [(b"content-type", b"text/plain; charset=utf-8")]
    raw += [(k.encode(), v.encode()) for k, v in (headers or {}).items()]
    await send({"type": "http.response.start", "status": status, "headers": raw})
    await send({"type": "http.response.body", "body": text.encode() + b"\n"})


def is_loopback(host: str) -> bool:
    """``host`` is this host only (``localhost``, 127.0.0.0/8, ::1)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def listening_socket(
    host: str = "127.0.0.1", port: int = DEFAULT_PORT, *, access: Access | None = None, insecure: bool = False
) -> socket.socket:
    """A socket listening on ``host:port`` (port 0: any free one), refused beyond this host without
    ``access`` unless ``insecure``.

    Raises:
        InsecureListen: beyond loopback, no access and not insecure.
        OSError: the address is taken or not this host's.
    """
    if not is_loopback(host) and access is None and not insecure:
        raise InsecureListen(
            f"refusing to listen on {host} without users: anyone who reaches it would see the motors"
            " (give --users, or --insecure)"
        )
    family = socket.AF_INET6 if ":" in host.strip("[]") else socket.AF_INET
    return socket.create_server((host.strip("[]"), port), family=family, backlog=64)


async def serve(
    app: App,
    sock: socket.socket,
    *,
    access: Access | None = None,
    certfile: Path | None = None,
    keyfile: Path | None = None,
    stopped: anyio.Event | None = None,
) -> None:
    """Serve ``app`` on ``sock`` (:func:`listening_socket`) until ``stopped`` is set or the caller
    is cancelled, on the running event loop (asyncio or trio); it closes its connections first
    (an open page's stream within ``config.graceful_timeout``, 1 s)."""
    from hypercorn.config import Config

    host = sock.getsockname()[0]
    config = Config()
    config.bind = [f"fd://{os.dup(sock.fileno())}"]  # (hypercorn closes what it serves: its own copy)
    config.certfile = str(certfile) if certfile else None
    config.keyfile = str(keyfile) if keyfile else None
    config.accesslog = None
    config.errorlog = logging.getLogger("servobus.dashboard.http")
    config.graceful_timeout = 1.0
    wrapped = guarded(app, access=access, loopback=host if is_loopback(host) else None)
    if sniffio.current_async_library() == "trio":
        from hypercorn.trio import serve as run
    else:
        from hypercorn.asyncio import serve as run  # type: ignore[assignment]

    # hypercorn's asyncio server does not survive being cancelled (its shutdown raises
    # InvalidStateError); it is told to stop instead, and given SHUTDOWN_S to do so, shielded.
    shutdown = anyio.Event()
    server = anyio.CancelScope(shield=True)

    async def hypercorn() -> None:
        with server:
            await run(wrapped, config, shutdown_trigger=shutdown.wait)  # type: ignore[arg-type]

    async with anyio.create_task_group() as group:
        group.start_soon(hypercorn)
        try:
            await (stopped or anyio.Event()).wait()
        finally:
            shutdown.set()
            server.deadline = anyio.current_time() + SHUTDOWN_S


@contextlib.asynccontextmanager
async def serving(
    app: App | Dashboard,
    sock: socket.socket,
    *,
    access: Access | None = None,
    certfile: Path | None = None,
    keyfile: Path | None = None,
    closing: Iterable[Dashboard] = (),
) -> AsyncIterator[str]:
    """Serve ``app`` (a Dashboard's page, or an application that mounts one) on ``sock`` while
    inside the block, in a task of its own on this event loop; yields the page's address. On the way
    out, the pages' streams of the Dashboard (and of ``closing``) end first, then the server stops.

    Example::

        with listening_socket("127.0.0.1", 0) as sock:
            async with serving(dash, sock) as url:
                print(url)  # the page is served while the block runs
    """
    dashboards = [*closing]
    if isinstance(app, Dashboard):
        dashboards.append(app)
        app = app.app()
    stopped = anyio.Event()
    async with anyio.create_task_group() as group:
        group.start_soon(
            functools.partial(
                serve, app, sock, access=access, certfile=certfile, keyfile=keyfile, stopped=stopped
            )
        )
        try:
            yield url_of(sock, tls=certfile is not None)
        finally:
            for dash in dashboards:
                dash.close()  # (their streams end within an update: the server has none to cut)
            stopped.set()


def url_of(sock: socket.socket, *, tls: bool = False) -> str:
    """The page's address on ``sock``."""
    host, port = sock.getsockname()[:2]
    shown = f"[{host}]" if ":" in host else host
    return f"{'https' if tls else 'http'}://{shown}:{port}/"
