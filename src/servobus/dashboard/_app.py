"""The dashboard's web app (Starlette, ASGI on anyio: asyncio and trio alike) and what it may command.

The page gets its data as server-sent events (one JSON update per period, the same text for every
page: :meth:`Board.update`) and draws it with uPlot, shipped in ``static/`` (no CDN: lab machines are
often offline). It may command nothing but the safe commands, stop and off, and only when the
Dashboard allows commands: a page can never leave a motor running, since all it can do is stop one.
"""

from __future__ import annotations

import json
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
        max_pages: the most pages streamed at once (each costs the event loop its writes; one more
            is answered 503).
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
        max_pages: int = 8,
    ) -> None:
        self.board = Board(update_hz=update_hz)
        self.allow_commands = allow_commands
        self.stop_timeout_s = stop_timeout_s
        self.on_stop = on_stop
        self._closing = anyio.Event()
        self.max_pages = max_pages
        self._pages = 0

    def tap(self, link: Any) -> TapLink:
        """:meth:`Board.tap`: give the result to the Bus for the raw frame view and the set-points."""
        return self.board.tap(link)

    def watch(self, bus: Any, *, name: str | None = None) -> None:
        """:meth:`Board.watch`."""
        self.board.watch(bus, name=name)

    def watch_loop(self, loop: Loop) -> None:
        """:meth:`Board.watch_loop`."""
        self.board.watch_loop(loop)

    def close(self) -> None:
        """End every page's stream of updates (before its server stops: a stream left open holds the
        server's shutdown for its graceful timeout). A page open after this gets no updates."""
        self._closing.set()

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
        if not isinstance(kind, str) or kind not in KINDS:
            raise ValueError(f"kind {kind!r}: expected one of {', '.join(KINDS)}")
        motors = self.board.motors() if keys is None else [self.board.find(k) for k in keys]
        commands = [(w, _codec(w.motor).safe_command(KINDS[kind])) for w in motors]
        if self.on_stop is not None:
            try:  # (the application stops giving them set-points; its failing must not cost the stop)
                self.on_stop(motors)
            except Exception:
                logger.exception("dashboard: on_stop failed; the stop is sent all the same")
        for loop in self.board.loops:  # what a loop was told to send next would follow the stop
            loop.drop(w.motor for w in motors if w.motor in loop.tracks)
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
        """The stops of one bus's motors, repeated until each acknowledged or ``stop_timeout_s``
        ended; what fails is reported, never raised (another bus's stops go on)."""
        bus = _bus_of(commands[0][0])
        if hasattr(bus, "engine"):
            from servobus.bus.safety import stop_motors

            try:
                outcome = await stop_motors(bus, {w.motor: c for w, c in commands}, self.stop_timeout_s)
                acknowledged = set(outcome.acknowledged)
            except Exception:  # (a closed Bus: nothing acknowledged)
                logger.exception("dashboard: the stop on %s failed", bus.name)
                acknowledged = set()
            for w, _ in commands:
                done["acknowledged" if w.motor in acknowledged else "not_acknowledged"].append(w.key)
            return
        async with anyio.create_task_group() as group:  # a bridge's motors: the bridge's Bus sends it
            for w, command in commands:
                group.start_soon(self._stop_remote, w, command, done)

    async def _stop_remote(self, w: Watched, command: Any, done: dict[str, list[str]]) -> None:
        """A bridge's motor's stop, asked again until the bridge says it was acknowledged or
        ``stop_timeout_s`` ended, and the network's allowance (the client's ``timeout_s``) after it (the
        bridge refuses one another client holds: not acknowledged)."""
        with anyio.move_on_after(self.stop_timeout_s + getattr(w.motor.bus, "timeout_s", 0.0)):
            while True:
                try:
                    await w.motor.request(command, timeout_s=self.stop_timeout_s)
                except ServobusError as exc:  # (lost on the way, or a timeout: again)
                    logger.debug("dashboard: %s: %s; again", w.key, exc)
                    await anyio.sleep(0.01)
                except Exception as exc:  # refused (another client holds it), or anything else
                    logger.warning("dashboard: %s: the stop was refused: %s", w.key, exc)
                    break
                else:
                    done["acknowledged"].append(w.key)
                    return
        done["not_acknowledged"].append(w.key)

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
        if self._pages >= self.max_pages:
            return JSONResponse({"error": f"{self.max_pages} pages are open already"}, status_code=503)
        board = self.board
        closing = self._closing

        async def updates() -> AsyncIterator[dict[str, str]]:
            self._pages += 1  # (counted once streaming: a page gone before costs nothing)
            try:
                while not closing.is_set():
                    yield {"event": "update", "data": board.update()}
                    with anyio.move_on_after(board.period_s):
                        await closing.wait()
            finally:
                self._pages -= 1

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
            body = await _json(request)
            motors, kind = body.get("motors"), body.get("kind", "stop")
            if motors != "all" and not (isinstance(motors, list) and all(isinstance(m, str) for m in motors)):
                raise ValueError('"motors": expected "all" or a list of motor keys')
            done = await self.stop(None if motors == "all" else motors, kind)
        except KeyError as exc:
            return JSONResponse({"error": f"no motor {exc.args[0]!r} on this dashboard"}, status_code=404)
        except _TooLarge as exc:
            return JSONResponse({"error": str(exc)}, status_code=413)
        except (ValueError, AttributeError) as exc:
            return JSONResponse({"error": str(exc)}, status_code=400)
        logger.info(
            "dashboard: %s sent to %s", kind, ", ".join(done["acknowledged"] + done["not_acknowledged"])
        )
        return JSONResponse(done)


#: the largest stop request read (a list of every motor's key fits many times over)
MAX_BODY = 16384


class _TooLarge(Exception):
    pass


async def _json(request: Request) -> Any:
    """The request's JSON body, read up to :data:`MAX_BODY` bytes (more is refused, not read).

    Raises:
        _TooLarge: a longer body.
        ValueError: not JSON.
    """
    body = b""
    async for chunk in request.stream():
        body += chunk
        if len(body) > MAX_BODY:
            raise _TooLarge(f"a stop request is at most {MAX_BODY} bytes")
    return json.loads(body)


def _bus_of(watched: Watched) -> Any:
    return watched.motor.bus


def _codec(motor: Any) -> Any:
    """The motor's codec (a bridge's motor: bound here in its family, revision and link)."""
    codec = getattr(motor, "codec", None)
    if codec is None:
        codec = motor.family.bind(motor.motor_id, revision=motor.revision, link=motor.link)
    return codec
