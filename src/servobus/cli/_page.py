"""The page of ``servobus dashboard`` and ``servobus demo --dashboard``: what both commands share (the
extra's one-line refusal, ``HOST:PORT``), and the demo's page (:class:`DemoPage`)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import TYPE_CHECKING

import click

if TYPE_CHECKING:
    import socket

    from servobus.dashboard import Dashboard

__all__ = ["EXTRA", "DemoPage", "dashboard_extra", "parse_listen"]


#: the ``dashboard`` extra's packages (a module missing from anywhere else is not the extra's fault)
EXTRA = frozenset({"starlette", "hypercorn", "sse_starlette"})


@contextlib.contextmanager
def dashboard_extra() -> Iterator[None]:
    """Turn a missing ``dashboard`` extra into one line saying what to install (exit 1)."""
    try:
        yield
    except ModuleNotFoundError as exc:
        missing = (exc.name or "").split(".")[0]
        if missing not in EXTRA:
            raise
        raise click.ClickException(
            f"the dashboard needs {missing}: pip install 'servobus[dashboard]'"
        ) from None


def parse_listen(text: str) -> tuple[str, int]:
    """``HOST:PORT`` (``[::1]:8765`` for IPv6; port 0: any free port).

    Raises:
        click.BadParameter: not a host and port.
    """
    host, sep, port = text.rpartition(":")
    if not sep or not host or not port.isdigit() or int(port) > 65535:
        raise click.BadParameter(f"{text!r}: expected HOST:PORT, e.g. 127.0.0.1:8765", param_hint="--listen")
    return host.strip("[]"), int(port)


class DemoPage:
    """``--dashboard``: the page's listening socket, and the read-only Dashboard of the demo's buses
    and loop (made here, before the event loop: a missing extra or a bad address is refused first)."""

    def __init__(self, sock: socket.socket, dash: Dashboard) -> None:
        self.sock, self.dash = sock, dash

    @classmethod
    def listen(cls, text: str) -> DemoPage:
        """Listening on ``text`` (``HOST:PORT``) of this host.

        Raises:
            click.BadParameter: not a host and port, or not this host (exit 2).
            click.ClickException: the extra is missing, or the address is taken (exit 1).
        """
        with dashboard_extra():
            from servobus.dashboard import Dashboard, InsecureListen, listening_socket
        try:
            host, port = parse_listen(text)
        except click.BadParameter as exc:
            exc.param_hint = "--dashboard"
            raise
        try:
            sock = listening_socket(host, port)
        except InsecureListen:
            raise click.BadParameter(
                f"{host}: the demo serves its page on this host only (127.0.0.1, localhost, ::1); to "
                "serve one beyond it, with users: servobus dashboard --sim N --listen HOST:PORT --users FILE",
                param_hint="--dashboard",
            ) from None
        except OSError as exc:
            raise click.ClickException(f"--dashboard {text}: {exc.strerror or exc}") from None
        return cls(sock, Dashboard())

    def announce(self, buses: int, *, err: bool) -> None:
        from servobus.dashboard import url_of

        where = f"{buses} simulated bus" + ("es" if buses > 1 else "")
        click.echo(
            f"servobus dashboard: {url_of(self.sock)} (the demo's {where} and its loop; read-only)", err=err
        )

    def serving(self) -> contextlib.AbstractAsyncContextManager[str]:
        """The page served while inside (:func:`servobus.dashboard.serving`)."""
        from servobus.dashboard import serving

        return serving(self.dash, self.sock)
