"""The web server of ``glsynth view``: the page (two files of this package) and one websocket
per open page, in front of one RenderWorker. Starlette routes, uvicorn serves, the
``websockets`` package frames (docs/design.md, "The viewer", says why these)."""

import asyncio
import contextlib
import socket
from collections.abc import Callable, Iterator
from importlib import resources
from pathlib import Path

import uvicorn
from starlette.applications import Starlette
from starlette.requests import Request as HttpRequest
from starlette.responses import HTMLResponse, Response
from starlette.routing import Route, WebSocketRoute
from starlette.websockets import WebSocket

from glsynth.core.errors import UserError, shown
from glsynth.view.protocol import MAX_MESSAGE_BYTES, parse_message
from glsynth.view.scene import SceneSettings
from glsynth.view.worker import RenderWorker

PAGE_FILES = {"/": ("index.html", "text/html"), "/viewer.js": ("viewer.js", "text/javascript")}
WS_MAX_BYTES = 4 * MAX_MESSAGE_BYTES
"""Larger messages close the connection; up to it, one over MAX_MESSAGE_BYTES is answered
with an error on the page."""


def _page_file(name: str) -> bytes:
    return resources.files("glsynth.view").joinpath("static", name).read_bytes()


async def _pump(ws: WebSocket, outbox: asyncio.Queue) -> None:
    """Send what the render thread queued for this page, in order; of the frames queued
    together only the newest goes (a slow connection shows the latest view, not a backlog)."""
    while True:
        batch = [await outbox.get()]
        while not outbox.empty():
            batch.append(outbox.get_nowait())
        newest = next((m for m in reversed(batch) if isinstance(m, bytes)), None)
        for message in batch:
            if message is newest:
                await ws.send_bytes(message)
            elif not isinstance(message, bytes):
                await ws.send_json(message)


def make_app(worker: RenderWorker) -> Starlette:
    """The page's files and its websocket, /ws."""
    files = {path: (_page_file(name), kind) for path, (name, kind) in PAGE_FILES.items()}

    async def page(request: HttpRequest) -> Response:
        body, kind = files[request.url.path]
        return HTMLResponse(body) if kind == "text/html" else Response(body, media_type=kind)

    async def session(ws: WebSocket) -> None:
        await ws.accept()
        loop, outbox = asyncio.get_running_loop(), asyncio.Queue()

        def send(message: dict | bytes) -> None:
            if not loop.is_closed():
                loop.call_soon_threadsafe(outbox.put_nowait, message)

        cid = worker.add_client(send)
        pump = asyncio.create_task(_pump(ws, outbox))
        try:
            while (message := await ws.receive())["type"] != "websocket.disconnect":
                text = message.get("text")
                try:
                    worker.submit(cid, parse_message(message.get("bytes", b"") if text is None
                                                     else text))
                except UserError as err:
                    send({"type": "error", "message": str(err)})
        finally:
            worker.remove_client(cid)
            pump.cancel()

    return Starlette(routes=[*(Route(path, page) for path in PAGE_FILES),
                             WebSocketRoute("/ws", session)])


def listen(host: str, port: int) -> socket.socket:
    """A socket bound to ``host``:``port`` and listening, or UserError (one line) saying why it
    cannot be."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
        sock.listen(128)  # pages that connect before uvicorn starts wait, not fail
    except OSError as err:
        sock.close()
        reason = err.strerror or " ".join(str(err).split())
        raise UserError(f"--host {shown(host, 60)} --port {port}: cannot listen there "
                        f"({reason}); give an address of this machine and a free port") from None
    return sock


class _Server(uvicorn.Server):
    """uvicorn's server, told of the Ctrl-C noted while glsynth view started (``noted``, from
    glsynth.core.interrupts.held_interrupt) as soon as it has taken the signals over: one
    that came before would otherwise be lost and the server run on. On the way out uvicorn
    gives the signals back and raises the one it caught, which the hold notes again."""

    def __init__(self, config: uvicorn.Config, noted: list[int]) -> None:
        super().__init__(config)
        self.noted = noted

    @contextlib.contextmanager
    def capture_signals(self) -> Iterator[None]:
        with super().capture_signals():
            for sig in self.noted:
                self.handle_exit(sig, None)
            self.noted.clear()
            yield


def serve(settings: SceneSettings, host: str, port: int, out_dir: Path,
          ready: Callable[[str], None], noted: list[int]) -> None:
    """Serve until interrupted, called inside held_interrupt() (``noted``: its list; the
    KeyboardInterrupt comes out of the hold after a clean shutdown). The port is bound before
    anything starts, so a taken one fails at once (UserError), and ``ready`` hears the page's
    address only once it is bound."""
    sock = listen(host, port)
    worker = RenderWorker(settings, out_dir)
    server = _Server(uvicorn.Config(
        make_app(worker), log_level="warning", ws_max_size=WS_MAX_BYTES,
        timeout_graceful_shutdown=3), noted)
    worker.start()
    try:
        bound = sock.getsockname()[1]
        ready(f"http://{'[' + host + ']' if sock.family == socket.AF_INET6 else host}:{bound}/")
        server.run(sockets=[sock])
    finally:
        worker.stop()
        sock.close()
