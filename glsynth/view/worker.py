"""The render thread: the one GL context of ``glsynth view`` and the queue in front of it.

Every page (client) has one slot for its next frame, in which the newest camera wins; a
moving camera's frame comes before any still, and a still whose client moves again while it
renders is interrupted (between passes and between bands of its colour pass: GL draws cannot
be cut) and never sent; a verdict's render stops likewise for any page's move. Scene changes
and relighting come first of all; when nothing else waits, the cracks of the parts no view
has shown yet are packed, a part at a time (so that a part's first view does not wait for
it), and then the sampled cameras' Section 3.4 verdicts are worked out one at a time.
Results go back through each client's ``send``, which must be safe to call from this thread.
"""

import ctypes
import gc
import itertools
import json
import os
import shutil
import tempfile
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

from glsynth.core.errors import UserError, shown
from glsynth.core.interrupts import RenderInterrupted
from glsynth.core.labels import Component, Damage
from glsynth.data.quality import QUALITY
from glsynth.render.gl.renderer import RenderOutput
from glsynth.render.view import write_render
from glsynth.view.camera import camera_json
from glsynth.view.frames import available_passes, encode, legend, pass_image
from glsynth.view.protocol import (
    CameraRequest,
    InspectRequest,
    LightingRequest,
    PassRequest,
    Request,
    SaveRequest,
    SceneRequest,
)
from glsynth.view.scene import Scene, SceneSettings, lighting_values, open_scene, scene_config
from glsynth.world.cameras import Camera

Send = Callable[[dict | bytes], None]
MOVING_WIDTHS = (192, 256, 320, 384, 480, 640)
"""The widths a moving camera's frames step through, to hold MOVING_FPS."""
MOVING_FPS = 12.0
VERDICT_AFTER_S = 2.0
"""Verdicts (full-size renders) start this long after the last move."""
STILL_BANDS = 4
"""Bands of rows of a full-size render's colour pass (its longest pass): a move waits for at
most about one piece; on a 1920x1080 still the bands' cost is within bench_view's noise
(docs/results.md, "The viewer")."""


@dataclass
class Client:
    send: Send
    pass_name: str = "color"
    camera: CameraRequest | None = None
    pending: CameraRequest | None = None
    """The frame to render next (the newest request wins)."""
    actions: deque = field(default_factory=deque)
    last: tuple[Camera, RenderOutput] | None = None
    """The last frame sent, for inspecting its pixels."""
    frames: int = 0
    passes: list[str] = field(default_factory=list)
    """The passes the page offers."""


@dataclass
class Pacer:
    """Measures moving frames and picks the width that holds MOVING_FPS."""

    step: int = 2
    seconds: float = 0.0

    def width(self) -> int:
        return MOVING_WIDTHS[self.step]

    def measured(self, seconds: float) -> None:
        self.seconds = seconds if not self.seconds else 0.7 * self.seconds + 0.3 * seconds
        budget = 1.0 / MOVING_FPS
        if self.seconds > budget and self.step > 0:
            self.step, self.seconds = self.step - 1, 0.0
        elif self.seconds < 0.45 * budget and self.step < len(MOVING_WIDTHS) - 1:
            self.step, self.seconds = self.step + 1, 0.0


class RenderWorker:
    """Owns the render thread; every public method is safe to call from any thread."""

    def __init__(self, settings: SceneSettings, out_dir: Path) -> None:
        self.out_dir = out_dir
        self.scene: Scene | None = None
        self.pacer = Pacer()
        self._clients: dict[int, Client] = {}
        self._ids = itertools.count(1)
        self._turn = 0
        self._wanted = settings
        """The settings last asked for (the preset stays the command line's)."""
        self._scene_request: tuple[SceneSettings, int | None] | None = (settings, None)
        self._lighting: tuple[dict[str, float], int] | None = None
        self._lock = threading.Condition()
        self._stopping = False
        self._last_move = 0.0
        self._cracks_waiting = False
        """Whether some part of the scene has cracks not packed yet."""
        self._thread = threading.Thread(target=self._run, name="glsynth-view-render",
                                        daemon=True)
        self._own_seed = settings.seed
        self._bank_dir = Path(tempfile.gettempdir()) / f"glsynth-view-bank-{os.getpid()}"
        """The damage bank of a seed a page chose (see _bank)."""
        self.loading: dict | None = None

    # --- called by the server ----------------------------------------------------------
    def start(self) -> None:
        self._thread.start()

    def stop(self, timeout: float = 30.0) -> None:
        with self._lock:
            self._stopping = True
            self._lock.notify_all()
        self._thread.join(timeout)

    def add_client(self, send: Send) -> int:
        with self._lock:
            cid = next(self._ids)
            self._clients[cid] = client = Client(send, passes=self._passes())
            hello = self.scene.summary() if self.scene is not None else None
        send({"type": "hello", "client": cid, "passes": client.passes,
              "qualities": list(QUALITY)})
        for message in (hello, self.loading):
            if message is not None:
                send(message)
        return cid

    def remove_client(self, cid: int) -> None:
        """A closed page: its pending frame and actions go with it."""
        with self._lock:
            self._clients.pop(cid, None)

    def submit(self, cid: int, request: Request) -> None:
        """Queue ``request`` of page ``cid``; a scene's config is checked first, here (a bad
        one raises UserError at once, rather than waiting behind a scene being opened)."""
        if isinstance(request, SceneRequest):
            with self._lock:
                wanted = replace(self._wanted, seed=request.seed, env=request.env,
                                 quality=request.quality, page_toml=request.config_toml,
                                 lighting=None)
            scene_config(wanted)
        with self._lock:
            client = self._clients.get(cid)
            if client is None:
                return
            if isinstance(request, CameraRequest):
                client.camera = client.pending = request
                if request.moving:
                    self._last_move = time.monotonic()
            elif isinstance(request, PassRequest):
                client.pass_name = request.name
                client.send({"type": "legend", "pass": request.name,
                             "legend": legend(request.name)})
                client.actions.append(request)
            elif isinstance(request, SceneRequest):
                self._wanted = wanted
                self._scene_request = (wanted, cid)
            elif isinstance(request, LightingRequest):
                self._lighting = (request.values, cid)
            else:
                client.actions.append(request)
            self._lock.notify_all()

    # --- the render thread -------------------------------------------------------------
    @staticmethod
    def _still(client: Client) -> CameraRequest | None:
        return replace(client.camera, moving=False) if client.camera else None

    def _passes(self) -> list[str]:
        last = next((c.last for c in self._clients.values() if c.last), None)
        return available_passes(last[1]) if last else available_passes(RenderOutput())

    def _broadcast(self, message: dict | bytes) -> None:
        with self._lock:
            clients = list(self._clients.values())
        for client in clients:
            client.send(message)

    def _next_job(self) -> Callable[[], None] | None:
        """The most urgent job, or None to stop; waits while there is none."""
        with self._lock:
            while not self._stopping:
                job = self._pick_job()
                if job is not None:
                    return job
                self._lock.wait(timeout=VERDICT_AFTER_S / 4)
        return None

    def _pick_job(self) -> Callable[[], None] | None:
        """Under the lock: scene, lighting, moving frames (clients in turn), actions, stills,
        one part's cracks, then one verdict."""
        if self._scene_request is not None:
            request, self._scene_request = self._scene_request, None
            return lambda: self._open(*request)
        if self.scene is None:
            return None
        if self._lighting is not None:
            lighting, self._lighting = self._lighting, None
            return lambda: self._relight(*lighting)
        ids = sorted(self._clients)
        self._turn += 1
        ids = ids[self._turn % len(ids):] + ids[:self._turn % len(ids)] if ids else ids
        for want in ("moving", "action", "still"):
            for cid in ids:
                job = self._client_job(cid, self._clients[cid], want)
                if job is not None:
                    return job
        if self._cracks_waiting:
            return self._pack_cracks
        # Verdicts wait for a pause in the moves: each is a full-size render.
        if self._clients and time.monotonic() - self._last_move > VERDICT_AFTER_S:
            todo = [i for i in range(len(self.scene.cameras)) if i not in self.scene.verdicts]
            return (lambda: self._verdict(todo[0])) if todo else None
        return None

    def _client_job(self, cid: int, client: Client, want: str) -> Callable[[], None] | None:
        pending = client.pending
        if want == "action" and client.actions:
            action = client.actions.popleft()
            return lambda: self._act(cid, client, action)
        if pending is not None and pending.moving == (want == "moving"):
            client.pending = None
            return lambda: self._frame(cid, client, pending)
        return None

    def _run(self) -> None:
        try:
            while (job := self._next_job()) is not None:
                try:
                    job()
                except Exception:  # a programming error: say so on every page, keep serving
                    traceback.print_exc()
                    self._broadcast({"type": "error", "message": "internal error in the "
                                     "render thread (the server's terminal has the traceback)"})
        finally:
            if self.scene is not None:
                self.scene.view.renderer.release()
            shutil.rmtree(self._bank_dir, ignore_errors=True)

    # --- jobs --------------------------------------------------------------------------
    def _error(self, cid: int | None, err: Exception) -> None:
        message = {"type": "error", "message": " ".join(str(err).split())}
        client = self._clients.get(cid) if cid is not None else None
        if client is not None:
            client.send(message)
        else:
            self._broadcast(message)

    def _progress(self, settings: SceneSettings) -> Callable[[str, float], None]:
        def report(stage: str, fraction: float) -> None:
            self.loading = {"type": "progress", "stage": stage, "fraction": fraction,
                            "seed": settings.seed, "env": settings.env}
            self._broadcast(self.loading)
        return report

    def _open(self, settings: SceneSettings, cid: int | None) -> None:
        """Open ``settings``' scene; a bad config changes nothing (the last good scene
        stays), and a failure after the old scene was let go opens the old one again."""
        previous = self.scene
        try:
            size = scene_config(settings).render
            if previous is not None:  # a size too large is refused while the scene stays
                previous.view.renderer.check_size(size.width, size.height)
        except UserError as err:
            self._error(cid, err)
            return
        renderer = previous.view.renderer if previous else None
        fallback = previous.settings if previous else None
        with self._lock:
            # The old environment goes before the new one is built: the process then peaks
            # at one environment's arrays, not two (pages see the progress meanwhile).
            self.scene = previous = None
            for client in self._clients.values():
                client.last = None
        return_free_memory()
        t0 = time.perf_counter()
        try:
            # Ctrl-C stops the opening at its next stage or part, not after it.
            scene = open_scene(settings, renderer, self._progress(settings),
                               self._bank(settings), interrupt=lambda: self._stopping)
        except RenderInterrupted:  # the server is stopping: there is nothing to show
            self.loading = None
            return
        except Exception as err:  # the last good scene opens again, as after a bad config
            self.loading = None
            if fallback is not None and fallback != settings:
                with self._lock:
                    self._scene_request = (fallback, None)
            if not isinstance(err, UserError):
                raise  # a programming error: _run prints its traceback on the pages' behalf
            self._error(cid, err)
            return
        with self._lock:
            self.scene, self.loading = scene, None
            self._cracks_waiting = True
            for client in self._clients.values():
                client.pending = client.pending or self._still(client)
        self._broadcast({**scene.summary(), "seconds": time.perf_counter() - t0})
        return_free_memory()

    def _bank(self, settings: SceneSettings) -> Path | None:
        """Where the damage bank of ``settings``' scene is cached: for the command line's seed
        the shared cache (as generate's run of that seed); for a seed a page chose, a folder
        of this server's, emptied before each opening and removed when it stops, so that a
        page stepping through seeds leaves at most one scene's bank on the disk."""
        if settings.seed == self._own_seed:
            return None
        shutil.rmtree(self._bank_dir, ignore_errors=True)
        return self._bank_dir

    def _pack_cracks(self) -> None:
        """One part's cracks (about 10 ms at the demo preset), in idle time."""
        self._cracks_waiting = self.scene.view.renderer.prepare_cracks(limit=1) > 0
        if not self._cracks_waiting:
            return_free_memory()  # packing's temporaries

    def _relight(self, values: dict[str, float], cid: int) -> None:
        try:
            self.scene.relight(values)
        except UserError as err:
            self._error(cid, err)
            return
        with self._lock:
            self.scene.verdicts.clear()  # the dark filter depends on the light
            for client in self._clients.values():
                client.pending = client.pending or self._still(client)
        self._broadcast({"type": "lighting", "lighting": lighting_values(self.scene.view.lighting)})

    def _camera(self, request: CameraRequest, width: int) -> Camera:
        """The requested view at ``width`` (the full size's aspect)."""
        full_w, full_h = self.scene.full_size
        width = min(width, full_w)
        r, sensor = self.scene.config.render, self.scene.config.cameras.sensor_mm
        return Camera(width, max(1, round(width * full_h / full_w)), request.focal_mm, sensor,
                      request.pose, r.znear_m, r.zfar_m)

    def _render(self, camera: Camera, interrupt: Callable[[], bool] | None = None
                ) -> RenderOutput:
        renderer = self.scene.view.renderer
        renderer.resize(camera.width, camera.height)
        return renderer.render(camera, interrupt=interrupt, bands=STILL_BANDS if interrupt
                               else 1)

    def _stale(self, cid: int, client: Client) -> bool:
        """Whether a still for ``client`` is no longer wanted: its page closed, or asked for
        another frame (a move, or a stop elsewhere) since the still was taken."""
        with self._lock:
            return cid not in self._clients or client.pending is not None

    def _moving(self) -> bool:
        """Whether some page waits for a moving frame."""
        with self._lock:
            return any(c.pending is not None and c.pending.moving
                       for c in self._clients.values())

    def _frame(self, cid: int, client: Client, request: CameraRequest) -> None:
        t0 = time.perf_counter()
        still = not request.moving
        camera = self._camera(request, self.scene.full_size[0] if still else self.pacer.width())
        try:
            output = self._render(camera, (lambda: self._stale(cid, client)) if still else None)
        except RenderInterrupted:
            return  # moved again (or closed): the move's frame comes next
        rendered = time.perf_counter() - t0
        if still and self._stale(cid, client):
            return  # moved during the read-back
        self._send_frame(cid, client, camera, output, still, t0, rendered)
        if not still:
            self.pacer.measured(time.perf_counter() - t0)

    def _repaint(self, cid: int, client: Client) -> None:
        """A new pass of the last full-size frame, without rendering it again."""
        with self._lock:
            last = client.last
            if last is None or last[0].width != self.scene.full_size[0]:
                client.pending = client.pending or self._still(client)
                return
        self._send_frame(cid, client, *last, True, time.perf_counter(), 0.0)

    def _send_frame(self, cid: int, client: Client, camera: Camera, output: RenderOutput,
                    still: bool, t0: float, rendered: float) -> None:
        """Encode the client's pass of ``output`` and send it with its header."""
        name = client.pass_name
        if available_passes(output) != client.passes:  # a renderer with more passes
            client.passes = available_passes(output)
            client.send({"type": "passes", "passes": client.passes, "current": name})
        if name not in client.passes:
            self._error(cid, ValueError(f"pass {name}: this renderer does not draw it"))
            name = client.pass_name = "color"
        data, mime = encode(pass_image(name, output, camera.fx), still)
        client.last = (camera, output)
        client.frames += 1
        header = {"type": "frame", "seq": client.frames, "still": still, "pass": name,
                  "mime": mime, "width": camera.width, "height": camera.height,
                  "focal_mm": camera.focal_mm, "render_ms": 1e3 * rendered,
                  "total_ms": 1e3 * (time.perf_counter() - t0)}
        client.send(pack_frame(header, data))

    def _act(self, cid: int, client: Client, action: Request) -> None:
        try:
            if isinstance(action, InspectRequest):
                client.send(self._inspect(client, action))
            elif isinstance(action, SaveRequest):
                client.send(self._save(client))
            elif isinstance(action, PassRequest):
                self._repaint(cid, client)
        except UserError as err:
            self._error(cid, err)

    def _inspect(self, client: Client, request: InspectRequest) -> dict:
        if client.last is None:
            raise UserError("inspect: no frame shown yet")
        camera, output = client.last
        col = min(int(request.x * camera.width), camera.width - 1)
        row = min(int(request.y * camera.height), camera.height - 1)
        hit = self.scene.picker.pick(camera, col, row)
        return {"type": "inspect", "col": col, "row": row,
                "component": Component(int(output.component[row, col])).name.lower(),
                "damage": Damage(int(output.damage[row, col])).name.lower(),
                "depth_m": float(output.depth[row, col]),
                "part": hit.part if hit else None,
                "part_depth_m": hit.depth_m if hit else None}

    def _save(self, client: Client) -> dict:
        """Render the client's camera at full size and write render's files into a new
        folder view_NNN under the output folder (the server makes every name)."""
        if client.camera is None:
            raise UserError("save view: no camera yet")
        camera = self._camera(client.camera, self.scene.full_size[0])
        # Photographed as render --camera-json photographs a camera given by hand (item 0);
        # the live frames stay the render's, at interactive speed.
        output = self.scene.view.photograph(self._render(camera), camera, 0)
        s = self.scene.settings
        try:  # the folder was checked at start; a disk may fill or a folder go since
            folder = new_folder(self.out_dir, "view")
            write_render(folder, camera, output, {
                "root_seed": s.seed, "env": s.env, "renderer": "gl", "preset": s.preset,
                "quality": s.quality, "lighting": lighting_values(self.scene.view.lighting)})
        except OSError as err:
            raise UserError(f"save view: cannot write into --out {shown(str(self.out_dir))} "
                            f"({err.strerror or type(err).__name__})") from None
        return {"type": "saved", "folder": folder.name, "camera": camera_json(camera)}

    def _verdict(self, index: int) -> None:
        scene = self.scene
        scene.view.renderer.resize(*scene.full_size)
        try:
            verdict = scene.verdict(index, self._moving, STILL_BANDS)
        except RenderInterrupted:
            return  # a page moved: the verdict is worked out again in the next pause
        with self._lock:
            if scene is not self.scene:
                return
            scene.verdicts[index] = verdict
        self._broadcast({"type": "verdict", "index": index, "verdict": verdict})


def return_free_memory() -> None:
    """Hand the heap that the last environment freed back to the system (glibc keeps it
    otherwise), so that the RSS of a long session follows what it holds."""
    gc.collect()
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass  # not glibc: nothing to trim


def pack_frame(header: dict, data: bytes) -> bytes:
    """One binary message: the header's length (4 bytes, big-endian), its JSON, the image."""
    head = json.dumps(header).encode()
    return len(head).to_bytes(4, "big") + head + data


def new_folder(root: Path, stem: str) -> Path:
    """A new folder root/stem_NNN, the first number not taken (made here, so two saves never
    share one)."""
    root.mkdir(parents=True, exist_ok=True)
    n = 0
    while True:
        folder = root / f"{stem}_{n:03d}"
        try:
            folder.mkdir()
            return folder
        except FileExistsError:
            n += 1
