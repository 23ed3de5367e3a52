"""The dashboard's web app (Starlette, ASGI on anyio: asyncio and trio alike) and what it may command.

The page gets its data as server-sent events (one JSON update per period, the same text for every
page: :meth:`Board.update`) and draws it with uPlot, shipped in ``static/`` (no CDN: lab machines are
often offline). It may command nothing but the safe commands, stop and off, and only when the
Dashboard allows commands: a page can never leave a motor running, since all it can do is stop one.
"""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator, Callable, Sequence
from pathlib import Path
from typing import Any

import anyio
from sse_starlette.sse import EventSourceResponse
from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import FileResponse, JSONResponse, Response
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles

from servobus._version import __version__
from servobus.dashboard._board import Board, Watched
from servobus.errors import ServobusError
from servobus.loop import Loop
from servobus.tools.recording import TapLink

__all__ = ["KINDS", "Dashboard"]

logger = logging.getLogger("servobus.dashboard")

STATIC = Path(__file__).parent / "static"
#: the page's buttons and the codec's safe command each sends (``BoundCodec.safe_command``)
KINDS = {"stop": "stop", "off": "shutdown"}
#: the ASGI scope key an authenticating middleware sets False for a user who may only read
MAY_COMMAND = "servobus.may_command"


class Dashboard:
    """A live view of buses, their motors and a loop, served as a web page (:meth:`app`).

    Args:
        allow_commands: the page's stop and off buttons work (default: read-only, they are refused).
        update_hz: the most updates per second each page gets (made once for all pages).
        stop_timeout_s: how long a stop is repeated until the motor acknowledges it.
        on_stop: called with the motors a page is about to stop (before their stop leaves), so the
            application stops commanding them: a control loop that went on would undo the stop.

    Example (a service that runs a Bus mounts the page on its own server)::

        dash = Dashboard()
        async with Bus(dash.tap(CanTransport("socketcan", "can0"))) as bus:
            dash.watch(bus)
            app.mount("/dashboard", dash.app())
    """

    def __init__(
        self,
        *,
        allow_commands: bool = False,
        update_hz: float = 30.0,
        stop_timeout_s: float = 0.5,
        on_stop: Callable[[Sequence[Watched]], object] | None = None,
    ) -> None:
        self.board = Board(update_hz=update_hz)
        self.allow_commands = allow_commands
        self.stop_timeout_s = stop_timeout_s
        self.on_stop = on_stop
        self.closed = False

    def close(self) -> None:
        """End the pages' update streams (within an update period): a server stopped after it stops at
        once, with no stream to cut (hypercorn cancelling one printed a traceback)."""
        self.closed = True

    def tap(self, link: Any) -> TapLink:
        """:meth:`Board.tap`: give the result to the Bus for the raw frame view and the set-points."""
        return self.board.tap(link)

    def watch(self, bus: Any, *, name: str | None = None) -> None:
        """:meth:`Board.watch`."""
        self.board.watch(bus, name=name)

    def watch_loop(self, loop: Loop) -> None:
        """:meth:`Board.watch_loop`."""
        self.board.watch_loop(loop)

    async def stop(self, keys: Sequence[str] | None, kind: str = "stop") -> dict[str, list[str]]:
        """Send ``kind``'s safe command (``"stop"`` or ``"off"``) to the motors ``keys`` (all: None),
        again until each acknowledged it or ``stop_timeout_s`` ended; shielded from cancellation (a
        page that goes away does not cut its stop short).

        Returns:
            ``{"acknowledged": [...], "not_acknowledged": [...]}``, by key.

        Raises:
            KeyError: a key of no motor on the board.
            ValueError: an unknown kind, or a motor whose family has no such command.
        """
        if kind not in KINDS:
            raise ValueError(f"kind {kind!r}: expected one of {', '.join(KINDS)}")
        motors = self.board.motors() if keys is None else [self.board.find(k) for k in keys]
        commands = [(w, _codec(w.motor).safe_command(KINDS[kind])) for w in motors]
        if self.on_stop is not None:
            self.on_stop(motors)
        done: dict[str, list[str]] = {"acknowledged": [], "not_acknowledged": []}
        with anyio.CancelScope(shield=True):
            by_bus: dict[int, list[tuple[Watched, Any]]] = {}
            for w, command in commands:
                by_bus.setdefault(id(_bus_of(w)), []).append((w, command))
            async with anyio.create_task_group() as group:
                for mine in by_bus.values():
                    group.start_soon(self._stop_on, mine, done)
        return done

    async def _stop_on(self, commands: list[tuple[Watched, Any]], done: dict[str, list[str]]) -> None:
        bus = _bus_of(commands[0][0])
        if hasattr(bus, "engine"):
            from servobus.bus.safety import stop_motors

            outcome = await stop_motors(bus, {w.motor: c for w, c in commands}, self.stop_timeout_s)
            for w, _ in commands:
                done["acknowledged" if w.motor in outcome.acknowledged else "not_acknowledged"].append(w.key)
            return
        for w, command in commands:  # a bridge's motor: the bridge's Bus sends it
            try:
                with anyio.fail_after(self.stop_timeout_s):
                    await w.motor.request(command)
            except (ServobusError, TimeoutError) as exc:
                logger.warning("dashboard: %s: %s", w.key, exc)
                done["not_acknowledged"].append(w.key)
            else:
                done["acknowledged"].append(w.key)

    def app(self) -> Starlette:
        """The page and its API as an ASGI app, to serve (:func:`servobus.dashboard.serve`) or to
        mount on a server of one's own (Starlette ``Mount``, FastAPI ``app.mount``)."""
        return Starlette(
            routes=[
                Route("/", self._index),
                Route("/api/info", self._info),
                Route("/api/snapshot", self._snapshot),
                Route("/api/events", self._events),
                Route("/api/stop", self._stop, methods=["POST"]),
                Mount("/static", StaticFiles(directory=STATIC), name="static"),
            ]
        )

    async def _index(self, request: Request) -> Response:
        if not request.url.path.endswith("/"):  # (mounted: the page's relative links need the slash)
            return Response(status_code=307, headers={"location": request.url.path + "/"})
        return FileResponse(STATIC / "index.html", headers={"cache-control": "no-store"})

    async def _info(self, request: Request) -> Response:
        return JSONResponse(
            {
                "version": __version__,
                "commands": self._may_command(request),
                "update_hz": round(1.0 / self.board.period_s, 3),
            }
        )

    async def _snapshot(self, request: Request) -> Response:
        return Response(self.board.update(), media_type="application/json")

    async def _events(self, request: Request) -> Response:
        board = self.board

        async def updates() -> AsyncIterator[dict[str, str]]:
            while not self.closed:
                yield {"event": "update", "data": board.update()}
                await anyio.sleep(board.period_s)

        return EventSourceResponse(updates(), ping=15, headers={"cache-control": "no-store"})

    def _may_command(self, request: Request) -> bool:
        return self.allow_commands and request.scope.get(MAY_COMMAND, True) is not False

    async def _stop(self, request: Request) -> Response:
        if not self._may_command(request):
            why = "user may only read" if self.allow_commands else "start it with --allow-commands"
            return JSONResponse({"error": f"the dashboard is read-only: {why}"}, status_code=403)
        # JSON only: a cross-site form cannot send it (it would need a CORS preflight, never allowed)
        if request.headers.get("content-type", "").split(";")[0].strip() != "application/json":
            return JSONResponse({"error": "send JSON (application/json)"}, status_code=415)
        try:
            body = await request.json()
            motors, kind = body.get("motors"), body.get("kind", "stop")
            if motors != "all" and not (isinstance(motors, list) and all(isinstance(m, str) for m in motors)):
                raise ValueError('"motors": expected "all" or a list of motor keys')
            done = await self.stop(None if motors == "all" else motors, kind)
        except KeyError as exc:
            return JSONResponse({"error": f"no motor {exc.args[0]!r} on this dashboard"}, status_code=404)
        except (ValueError, AttributeError) as exc:
            return JSONResponse({"error": str(exc)}, status_code=400)
        logger.info(
            "dashboard: %s sent to %s", kind, ", ".join(done["acknowledged"] + done["not_acknowledged"])
        )
        return JSONResponse(done)


def _bus_of(watched: Watched) -> Any:
    return watched.motor.bus


def _codec(motor: Any) -> Any:
    """The motor's codec (a bridge's motor: bound here in its family, revision and link)."""
    codec = getattr(motor, "codec", None)
    if codec is None:
        codec = motor.family.bind(motor.motor_id, revision=motor.revision, link=motor.link)
    return codec
