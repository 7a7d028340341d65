"""The panel's server: a Starlette app serving the page, its JSON calls and one websocket per page.

Every request passes :mod:`sashil.panel.guard`'s checks first (Host, token; Origin and the token
header on anything that changes state; the websocket's Origin and its token subprotocol before it
is accepted). No CORS header is ever sent.

One page controls at a time (the first to connect; it may hand control to the next page); every
page watches and every page may STOP. When the controlling page's connection drops during a run,
the run is stopped (``on_disconnect="stop"``, a dead-man: the rig is never left energised with the
controlling page gone); ``"keep"`` lets the run go on, and control passes to the next page.

A broadcaster task reads the bench once per display tick (:data:`FPS`) and queues the same binary
batch to every page; a page that cannot keep up loses batches, never slows the loop or the others.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import secrets
from collections.abc import AsyncIterator, Awaitable, Callable
from pathlib import Path
from typing import Any

from starlette.applications import Starlette
from starlette.concurrency import run_in_threadpool
from starlette.requests import Request
from starlette.responses import FileResponse, HTMLResponse, JSONResponse, PlainTextResponse, RedirectResponse, Response
from starlette.routing import Route, WebSocketRoute
from starlette.websockets import WebSocket, WebSocketDisconnect

from sashil.errors import SashilError
from sashil.panel import guard
from sashil.panel.bench import Bench
from sashil.panel.runs import RUN_FILES, list_runs, report_runs, run_file, run_traces

STATIC = Path(__file__).with_name("static")
#: display ticks per second: batches and status go out at this rate
FPS = 30.0
#: batches queued per page before the oldest are dropped (a slow page sees gaps, never lag)
QUEUE_DEPTH = 8
#: uvicorn's websocket implementation: the websockets library's sans-I/O protocol
WS_IMPL = "websockets-sansio"
#: the dead-man choices when the controlling page goes away during a run
ON_DISCONNECT = ("stop", "keep")
STATIC_FILES = {
    "panel.js": "text/javascript",
    "panel.css": "text/css",
    "uPlot.iife.min.js": "text/javascript",
    "uPlot.min.css": "text/css",
}


class Client:
    """One connected page: its id and the queue of messages waiting to be sent to it."""

    def __init__(self) -> None:
        self.id = secrets.token_hex(8)
        self.queue: asyncio.Queue[bytes | str] = asyncio.Queue(maxsize=QUEUE_DEPTH)
        self.dropped = 0

    def offer(self, message: bytes | str) -> None:
        """Queue ``message``; when the page is behind, the oldest queued message is dropped."""
        if self.queue.full():
            with contextlib.suppress(asyncio.QueueEmpty):
                self.queue.get_nowait()
                self.dropped += 1
        self.queue.put_nowait(message)


class Panel:
    """The state the routes share: the bench, the token, the pages and which one controls."""

    def __init__(
        self,
        bench: Bench,
        token: str,
        port: int,
        on_disconnect: str = "stop",
        names: tuple[str, ...] = guard.LOOPBACK_NAMES,
        scheme: str = "http",
    ):
        if on_disconnect not in ON_DISCONNECT:
            raise ValueError(f"on_disconnect: expected one of {ON_DISCONNECT}, got {on_disconnect!r}")
        self.bench, self.token, self.port, self.on_disconnect = bench, token, port, on_disconnect
        self.names, self.scheme = names, scheme
        self.clients: list[Client] = []
        self.controller: str | None = None
        self._event_seq = 0
        self._status_text = ""

    # -- the checks ---------------------------------------------------------------------------------
    def host_ok(self, host: str | None) -> bool:
        return guard.host_allowed(host, self.port, self.names)

    def origin_ok(self, origin: str | None) -> bool:
        return guard.origin_allowed(origin, self.port, self.names, self.scheme)

    def refusal(self, request: Request, *, changes: bool) -> Response | None:
        """A 403 for a request that fails the checks, else None."""
        if not self.host_ok(request.headers.get("host")):
            return PlainTextResponse("forbidden: unknown Host", status_code=403)
        cookie = request.cookies.get(guard.cookie_name(self.port))
        header = request.headers.get(guard.TOKEN_HEADER)
        if changes:
            if not self.origin_ok(request.headers.get("origin")):
                return PlainTextResponse("forbidden: foreign Origin", status_code=403)
            if not guard.same_token(header, self.token):
                return PlainTextResponse("forbidden: the token header is missing or wrong", status_code=403)
        elif not (guard.same_token(cookie, self.token) or guard.same_token(header, self.token)):
            return PlainTextResponse("forbidden: no token (open the URL sashil panel printed)", status_code=403)
        return None

    def controls(self, request: Request) -> bool:
        return self.controller is not None and request.headers.get("x-sashil-client") == self.controller

    # -- the pages ----------------------------------------------------------------------------------
    def roles(self) -> str:
        return json.dumps({"type": "control", "controller": self.controller, "pages": len(self.clients)})

    def join(self, client: Client) -> None:
        self.clients.append(client)
        if self.controller is None:
            self.controller = client.id
        self.broadcast(self.roles())

    def leave(self, client: Client) -> None:
        self.clients.remove(client)
        if self.controller == client.id:
            self.controller = self.clients[0].id if self.clients else None
            if self.on_disconnect == "stop" and self.bench.busy:
                self.bench.stop("STOP (the controlling page disconnected)")
        self.broadcast(self.roles())

    def hand_over(self, client_id: str) -> bool:
        """Give control to the next page after ``client_id`` (which must control)."""
        if client_id != self.controller or len(self.clients) < 2:
            return False
        ids = [c.id for c in self.clients]
        self.controller = ids[(ids.index(client_id) + 1) % len(ids)]
        self.broadcast(self.roles())
        return True

    def broadcast(self, message: bytes | str) -> None:
        for client in self.clients:
            client.offer(message)

    def tick(self) -> None:
        """One display tick: the status when it changed, new events, the new rows as one batch. The
        batch is read first and the status names the sub-run it belongs to, and is queued before
        it: a page starts a sub-run's traces afresh before its first rows arrive."""
        batch = self.bench.next_batch()
        status = json.dumps({"type": "status", **self.bench.status()})
        if status != self._status_text:
            self._status_text = status
            self.broadcast(status)
        events = self.bench.events_since(self._event_seq)
        if events:
            self._event_seq = events[-1]["seq"]
            self.broadcast(json.dumps({"type": "events", "events": events}))
        if batch is not None:
            self.broadcast(batch)


def make_app(panel: Panel) -> Starlette:
    """The panel's ASGI app: the page, what it reads, what changes the bench, and the socket."""
    routes = [
        *_page_routes(panel),
        *_read_routes(panel),
        *_run_routes(panel),
        *_tool_routes(panel),
        WebSocketRoute("/ws", _socket(panel)),
    ]
    return Starlette(routes=routes, lifespan=_lifespan(panel))


Handler = Callable[[Request], Awaitable[Response]]


def _guarded(panel: Panel, changes: bool, control: bool = False) -> Callable[[Handler], Handler]:
    """A handler behind the panel's checks (:meth:`Panel.refusal`); ``control``: only the page in
    control may call it."""

    def wrap(handler: Handler) -> Handler:
        async def checked(request: Request) -> Response:
            refused = panel.refusal(request, changes=changes)
            if refused is not None:
                return refused
            if control and not panel.controls(request):
                return JSONResponse({"error": "this page watches: another page has control"}, status_code=409)
            return await handler(request)

        return checked

    return wrap


async def _body(request: Request) -> dict[str, Any]:
    """The request's JSON object, or an empty one."""
    try:
        data = await request.json()
    except ValueError:
        return {}
    return data if isinstance(data, dict) else {}


def _refused(err: SashilError) -> Response:
    return JSONResponse({"error": str(err)}, status_code=400)


def _page_routes(panel: Panel) -> list[Route]:
    """The page (its token taken from the URL into a cookie) and its static files."""

    async def index(request: Request) -> Response:
        if not panel.host_ok(request.headers.get("host")):
            return PlainTextResponse("forbidden: unknown Host", status_code=403)
        given = request.query_params.get("token")
        if given is not None:
            if not guard.same_token(given, panel.token):
                return PlainTextResponse("forbidden: wrong token", status_code=403)
            response: Response = RedirectResponse("/", status_code=303)  # the token leaves the URL bar
            response.set_cookie(
                guard.cookie_name(panel.port),
                panel.token,
                httponly=True,
                samesite="strict",
                secure=panel.scheme == "https",
            )
            return response
        refused = panel.refusal(request, changes=False)
        if refused is not None:
            return refused
        page = (STATIC / "index.html").read_text(encoding="utf-8").replace("{{TOKEN}}", panel.token)
        return HTMLResponse(page, headers={"Cache-Control": "no-store", "X-Frame-Options": "DENY"})

    @_guarded(panel, changes=False)
    async def static(request: Request) -> Response:
        name = request.path_params["name"]
        if name not in STATIC_FILES:  # a fixed list: no path from the request reaches the disk
            return PlainTextResponse("not found", status_code=404)
        return FileResponse(STATIC / name, media_type=STATIC_FILES[name])

    return [Route("/", index), Route("/static/{name}", static)]


def _read_routes(panel: Panel) -> list[Route]:
    """What a page reads: the laws, the bench's status, the run folders and their files."""

    @_guarded(panel, changes=False)
    async def laws(request: Request) -> Response:
        return JSONResponse(panel.bench.law_table())

    @_guarded(panel, changes=False)
    async def runs(request: Request) -> Response:
        return JSONResponse(await run_in_threadpool(list_runs, panel.bench.runs_dir))

    @_guarded(panel, changes=False)
    async def run_item(request: Request) -> Response:
        name, item = request.path_params["name"], request.path_params["item"]
        if item == "traces":
            batch = await run_in_threadpool(run_traces, panel.bench.runs_dir, name)
            if batch is None:
                return PlainTextResponse("not found", status_code=404)
            return Response(batch, media_type="application/octet-stream")
        path = run_file(panel.bench.runs_dir, name, item)
        if path is None:
            return PlainTextResponse("not found", status_code=404)
        return FileResponse(path, media_type=RUN_FILES[item], headers={"Cache-Control": "no-store"})

    @_guarded(panel, changes=False)
    async def status(request: Request) -> Response:
        return JSONResponse(panel.bench.status())

    return [
        Route("/api/laws", laws),
        Route("/api/status", status),
        Route("/api/runs", runs),
        Route("/api/runs/{name}/{item}", run_item),
    ]


def _run_routes(panel: Panel) -> list[Route]:
    """What changes the run: start, stop, tune and restore."""

    @_guarded(panel, changes=True, control=True)
    async def start(request: Request) -> Response:
        choice = await _body(request)
        try:
            run = await run_in_threadpool(panel.bench.start, choice)
        except SashilError as err:
            return _refused(err)
        return JSONResponse({"run_id": run.run_id, "folder": run.folder})

    @_guarded(panel, changes=True)
    async def stop(request: Request) -> Response:
        return JSONResponse({"stopping": panel.bench.stop("STOP (panel)")})

    @_guarded(panel, changes=True, control=True)
    async def tune(request: Request) -> Response:
        data = await _body(request)
        values = data.get("set")
        if not isinstance(values, dict):
            return JSONResponse({"error": "expected {'set': {param: value}}"}, status_code=400)
        try:
            events = await run_in_threadpool(panel.bench.tune, values, data.get("ramp_s"))
        except SashilError as err:
            return _refused(err)
        return JSONResponse({"events": events})

    @_guarded(panel, changes=True, control=True)
    async def restore(request: Request) -> Response:
        try:
            events = await run_in_threadpool(panel.bench.restore)
        except SashilError as err:
            return _refused(err)
        return JSONResponse({"events": events})

    return [
        Route("/api/start", start, methods=["POST"]),
        Route("/api/stop", stop, methods=["POST"]),
        Route("/api/tune", tune, methods=["POST"]),
        Route("/api/restore", restore, methods=["POST"]),
    ]


def _tool_routes(panel: Panel) -> list[Route]:
    """The bench's other actions: save the tuned config, hand control over, the doctor, a report."""

    @_guarded(panel, changes=True)
    async def save(request: Request) -> Response:
        try:
            text = panel.bench.saved_config()
        except SashilError as err:
            return _refused(err)
        name = f"{panel.bench.run.law or 'panel'}-tuned.yaml"
        return PlainTextResponse(
            text, media_type="application/x-yaml", headers={"Content-Disposition": f'attachment; filename="{name}"'}
        )

    @_guarded(panel, changes=True, control=True)
    async def doctor(request: Request) -> Response:
        data = await _body(request)
        driver, port = data.get("driver") or None, data.get("port") or None
        if not all(value is None or isinstance(value, str) for value in (driver, port)):
            return JSONResponse({"error": "doctor: driver and port are strings"}, status_code=400)
        try:
            return JSONResponse(await run_in_threadpool(panel.bench.doctor, driver, port))
        except SashilError as err:
            return _refused(err)

    @_guarded(panel, changes=True)
    async def report(request: Request) -> Response:
        names = (await _body(request)).get("runs")
        if panel.bench.busy:  # a report's plotting would compete with the loop for the CPU
            return JSONResponse({"error": "report: the rig is running: report when it is idle"}, status_code=400)
        try:
            text = await run_in_threadpool(report_runs, panel.bench.runs_dir, names if isinstance(names, list) else [])
        except SashilError as err:
            return _refused(err)
        return PlainTextResponse(text)

    @_guarded(panel, changes=True)
    async def hand_over(request: Request) -> Response:
        return JSONResponse({"handed_over": panel.hand_over(request.headers.get("x-sashil-client", ""))})

    return [
        Route("/api/save", save, methods=["POST"]),
        Route("/api/hand-over", hand_over, methods=["POST"]),
        Route("/api/doctor", doctor, methods=["POST"]),
        Route("/api/report", report, methods=["POST"]),
    ]


def _socket(panel: Panel) -> Callable[[WebSocket], Awaitable[None]]:
    """The page's websocket: its checks before anything is read, then the panel's messages out and
    STOP words in."""

    async def socket(websocket: WebSocket) -> None:
        headers = websocket.headers
        if not (
            panel.host_ok(headers.get("host"))
            and panel.origin_ok(headers.get("origin"))
            and guard.same_token(guard.subprotocol_token(headers), panel.token)
        ):
            await websocket.close(code=1008)  # refused before anything is read
            return
        await websocket.accept(subprotocol=guard.SUBPROTOCOL)
        client = Client()
        panel.join(client)
        await websocket.send_text(json.dumps({"type": "hello", "client": client.id, **panel.bench.status()}))
        client.offer(panel.roles())

        async def send() -> None:
            while True:
                message = await client.queue.get()
                if isinstance(message, bytes):
                    await websocket.send_bytes(message)
                else:
                    await websocket.send_text(message)

        sender = asyncio.create_task(send())
        try:
            while True:
                text = await websocket.receive_text()
                with contextlib.suppress(ValueError):
                    if json.loads(text).get("stop"):
                        panel.bench.stop("STOP (panel)")
        except (WebSocketDisconnect, RuntimeError):
            pass
        finally:
            sender.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await sender
            panel.leave(client)

    return socket


def _lifespan(panel: Panel) -> Callable[[Starlette], contextlib.AbstractAsyncContextManager[None]]:
    """The server's lifespan: the display ticks, the loop server started ahead (it ends with the
    process), and at the end the bench stopped and joined."""

    @contextlib.asynccontextmanager
    async def lifespan(app: Starlette) -> AsyncIterator[None]:
        async def broadcaster() -> None:
            while True:
                panel.tick()
                await asyncio.sleep(1.0 / FPS)

        from sashil.runtime.loop_process import start_ahead

        start_ahead()  # the loop server imports and warms up before the first click
        task = asyncio.create_task(broadcaster())
        try:
            yield
        finally:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
            panel.bench.stop("STOP (the panel server is shutting down)")
            await run_in_threadpool(panel.bench.join)

    return lifespan
