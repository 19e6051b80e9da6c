"""glsynth view: message checks, the camera JSON, pass images, picking, and the server over a
real websocket (the browser tests are in test_view_browser.py)."""

import contextlib
import dataclasses
import json
import os
import signal
import time
import types

import numpy as np
import pytest
import trimesh
from viewhelpers import SCENE_TOML

from glsynth.core.config import Config
from glsynth.core.errors import UserError
from glsynth.core.palette import COMPONENT_RGB
from glsynth.view.camera import camera_from_json, camera_json
from glsynth.view.protocol import (
    MAX_MESSAGE_BYTES,
    CameraRequest,
    SceneRequest,
    parse_message,
)
from glsynth.view.scene import SceneSettings
from glsynth.world.cameras import Camera, euler_xyz
from glsynth.world.environment import Part, PartKind

POSE = np.eye(4)
POSE[:3, :3] = euler_xyz(1.4, 0.1, 0.3)
POSE[:3, 3] = (10.0, -4.0, 6.0)


PREVIEW = SceneSettings("demo", 0, 0, quality="preview", config_toml=SCENE_TOML)
"""The in-process scene tests' scene: the viewer tests' one viaduct (tests/viewhelpers.py),
as their plumbing needs no more; nine openings a file."""


def camera_message(**change) -> str:
    message = {"type": "camera", "pose": POSE.tolist(), "focal_mm": 24.0, "moving": True}
    return json.dumps({**message, **change})


def test_a_camera_message_gives_its_pose_and_focal_length():
    request = parse_message(camera_message())
    assert isinstance(request, CameraRequest)
    assert np.array_equal(request.pose, POSE) and request.focal_mm == 24.0 and request.moving


@pytest.mark.parametrize("message, words", [
    ("not json", "not JSON"),
    (json.dumps({"type": "fly"}), "type is one of"),
    (json.dumps({"type": "save", "path": "/etc/passwd"}), "unknown field(s) ['path']"),
    (json.dumps({"type": "inspect", "x": 0.5}), "missing field(s) ['y']"),
    (json.dumps({"type": "inspect", "x": 1.5, "y": 0.5}), "x = 1.5: must be in [0, 1]"),
    (camera_message(focal_mm=1.0), "focal_mm = 1.0: must be in [4, 800]"),
    (camera_message(focal_mm=float("nan")), "must be a finite number"),
    (camera_message(pose=(2 * POSE).tolist()), "orthonormal"),
    (camera_message(pose=[[1, 2], [3, 4]]), "4 rows of 4"),
    (camera_message(moving="yes"), "moving = 'yes'"),
    (json.dumps({"type": "pass", "name": "normals"}), "pass 'normals': choose one of"),
    (json.dumps({"type": "scene", "seed": -1, "env": 0, "quality": None, "config_toml": None}),
     "seed = -1"),
    (json.dumps({"type": "scene", "seed": 0, "env": 0, "quality": "ultra", "config_toml": None}),
     "quality = 'ultra'"),
])
def test_a_bad_message_is_refused_with_the_field_named(message, words):
    with pytest.raises(UserError) as err:
        parse_message(message)
    assert words in str(err.value)


def test_an_oversized_message_is_refused_before_it_is_parsed():
    text = json.dumps({"type": "scene", "seed": 0, "env": 0, "quality": None,
                       "config_toml": "#" * MAX_MESSAGE_BYTES})
    with pytest.raises(UserError, match=f"at most {MAX_MESSAGE_BYTES}"):
        parse_message(text)


def test_a_scene_message_carries_config_text_not_a_path():
    request = parse_message(json.dumps({"type": "scene", "seed": 3, "env": 1, "quality": "fast",
                                        "config_toml": "[render]\nmsaa = 0\n"}))
    assert request == SceneRequest(3, 1, "fast", "[render]\nmsaa = 0\n")


def test_the_camera_json_round_trips_at_the_configs_size():
    config = Config()
    camera = Camera(config.render.width, config.render.height, 35.0, 36.0, POSE,
                    config.render.znear_m, config.render.zfar_m)
    again = camera_from_json(json.loads(json.dumps(camera_json(camera))), config)
    assert np.array_equal(again.pose, camera.pose) and again.focal_mm == camera.focal_mm
    assert (again.width, again.height, again.sensor_mm) == (camera.width, camera.height, 36.0)
    with pytest.raises(UserError, match="pose .4x4 world-from-camera. and focal_mm"):
        camera_from_json({"focal_mm": 35.0}, config)


def test_the_pacer_steps_down_when_slow_and_up_when_fast():
    from glsynth.view.worker import MOVING_FPS, Pacer

    pacer = Pacer()
    start = pacer.width()
    pacer.measured(2.0 / MOVING_FPS)
    assert pacer.width() < start
    for _ in range(3):
        pacer.measured(0.1 / MOVING_FPS)
    assert pacer.width() > start


def test_saves_go_to_new_numbered_folders_under_out(tmp_path):
    from glsynth.view.worker import new_folder

    (tmp_path / "view_000").mkdir()
    made = [new_folder(tmp_path, "view") for _ in range(2)]
    assert [m.name for m in made] == ["view_001", "view_002"]
    assert all(m.parent == tmp_path and m.is_dir() for m in made)


def test_the_picker_finds_the_nearest_part_and_its_axial_depth():
    from glsynth.view.pick import PartPicker

    def box(name, x):
        pose = np.eye(4)
        pose[:3, 3] = (x, 0.0, 0.0)
        return Part(name, PartKind.COLUMN, 0, trimesh.creation.box((1.0, 1.0, 1.0)), pose)

    # From the origin along world +x: camera x, y, z are world -y, +z, -x.
    pose = np.eye(4)
    pose[:3, :3] = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]]).T
    camera = Camera(101, 101, 36.0, 36.0, pose, 0.05, 100.0)
    hit = PartPicker([box("far", 10.0), box("near", 5.0)]).pick(camera, 50, 50)
    assert hit.part == "near" and hit.depth_m == pytest.approx(4.5, abs=1e-9)
    assert PartPicker([box("far", 10.0)]).pick(camera, 0, 0) is None


def test_the_component_pass_is_the_palette_and_crack_width_needs_its_map():
    from glsynth.view.frames import available_passes, legend, pass_image

    ids = np.array([[1, 4], [2, 6]], np.uint8)
    output = types.SimpleNamespace(component=ids, color=np.zeros((2, 2, 3), np.uint8))
    assert np.array_equal(pass_image("component", output, 10.0), COMPONENT_RGB[ids])
    assert "crack_width" not in available_passes(output)
    with pytest.raises(ValueError, match="no crack widths"):
        pass_image("crack_width", output, 10.0)
    output.crack_width = np.array([[0.0, 0.3], [2.5, 0.0]], np.float32)
    assert "crack_width" in available_passes(output)
    image = pass_image("crack_width", output, 10.0)
    assert image.shape == (2, 2, 3) and not np.array_equal(image[0, 1], image[1, 0])
    assert [s["value"] for s in legend("depth")["scale"]][:2] == [0.5, 1.0]
    assert legend("component")["swatches"][4] == {"label": "column", "rgb": [230, 25, 75]}


# --- the server, over a real websocket -------------------------------------------------------

SERVER_QUALITY = ("--quality", "preview")
"""The server's (and the render its saved view is checked against): a quarter of the image
size, small textures and damage maps (as in test_view_fuzz and test_view_bank)."""


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    from viewhelpers import ViewServer

    running = ViewServer(tmp_path_factory.mktemp("views"), *SERVER_QUALITY)
    try:
        yield running
    finally:
        assert running.stop() == 130


@contextlib.contextmanager
def _connect(server):
    """A page's websocket, once the scene is open, with the scene's summary."""
    from viewhelpers import receive
    from websockets.sync.client import connect

    with connect(server.ws_url, max_size=None, open_timeout=30) as ws:
        yield ws, receive(ws, "scene", timeout=180)


def _camera(pose, focal_mm, moving=False) -> str:
    return json.dumps({"type": "camera", "pose": pose, "focal_mm": focal_mm, "moving": moving})


def test_a_bad_message_gets_an_error_and_the_server_keeps_rendering(server):
    from viewhelpers import receive

    with _connect(server) as (ws, scene):
        ws.send("{\"type\": \"camera\", \"pose\": 3}")
        assert "missing field(s) ['focal_mm', 'moving']" in receive(ws, "error")["message"]
        ws.send(_camera(scene["cameras"][1]["pose"], scene["cameras"][1]["focal_mm"], True))
        header, image = receive(ws, "frame")
        assert not header["still"] and header["width"] < scene["size"][0] and image


def test_two_pages_keep_their_own_cameras(server):
    from viewhelpers import receive

    with _connect(server) as (a, scene), _connect(server) as (b, _):
        a.send(_camera(scene["cameras"][0]["pose"], 20.0))
        b.send(_camera(scene["cameras"][0]["pose"], 60.0))
        assert receive(a, "frame")[0]["focal_mm"] == 20.0
        assert receive(b, "frame")[0]["focal_mm"] == 60.0


def test_save_view_writes_renders_files_and_its_camera_renders_the_same(server, tmp_path):
    import cv2
    from viewhelpers import receive, render_camera_json

    with _connect(server) as (ws, scene):
        ws.send(_camera(scene["cameras"][2]["pose"], scene["cameras"][2]["focal_mm"]))
        receive(ws, "frame")
        ws.send(json.dumps({"type": "save"}))
        saved = receive(ws, "saved")
    folder = server.out / saved["folder"]
    assert folder.parent == server.out
    assert sorted(p.name for p in folder.iterdir()) == ["camera.json", "component.png",
                                                        "crack_width.npy", "damage.png",
                                                        "depth.npy", "image.png"]
    again = render_camera_json(json.loads((folder / "camera.json").read_text()), tmp_path,
                               True, *SERVER_QUALITY)
    for name in ("image.png", "component.png", "damage.png"):
        assert np.array_equal(cv2.imread(str(folder / name)), cv2.imread(str(again / name))), name
    for name in ("depth.npy", "crack_width.npy"):
        assert np.array_equal(np.load(folder / name), np.load(again / name)), name


def test_ctrl_c_stops_the_server_with_130(tmp_path):
    from viewhelpers import ViewServer

    assert ViewServer(tmp_path).stop() == 130


def test_ctrl_c_while_the_viewer_starts_stops_it_with_130(tmp_path):
    """Ctrl-C 0.3 s after the start, while the command line still loads (glsynth.core.
    interrupts: lost there, the server ran on)."""
    from viewhelpers import view_process

    proc = view_process(tmp_path / "views")
    time.sleep(0.3)
    proc.send_signal(signal.SIGINT)
    try:
        assert proc.wait(30) == 130, proc.stdout.read()
    finally:
        proc.kill()
        proc.communicate()


def test_a_ctrl_c_noted_before_the_server_took_the_signals_stops_it_at_once(tmp_path):
    """The hand-over to uvicorn, in this process: a server started with a Ctrl-C already noted
    stops by itself and the hold raises it (a second SIGINT after 20 s stands in for a hang)."""
    import threading

    import uvicorn
    from starlette.applications import Starlette

    from glsynth.core.interrupts import held_interrupt
    from glsynth.view.server import _Server, listen

    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    backstop = threading.Timer(20.0, os.kill, (os.getpid(), signal.SIGINT))
    sock = listen("127.0.0.1", 0)
    try:
        started = time.monotonic()
        with pytest.raises(KeyboardInterrupt), held_interrupt() as noted:
            signal.raise_signal(signal.SIGINT)
            backstop.start()
            _Server(uvicorn.Config(Starlette(), log_level="warning"), noted).run(sockets=[sock])
        assert time.monotonic() - started < 10
    finally:
        backstop.cancel()
        sock.close()
        signal.signal(signal.SIGINT, previous)


def test_ctrl_c_while_the_viewer_makes_the_texture_repository_stops_it_between_images(
        tmp_path):
    """On a fresh cache the render thread first makes the built-in repository (72 images,
    10 CPU-s): Ctrl-C once the first image is written ends the server within seconds, the
    repository left unfinished (it carries on at the next start)."""
    from viewhelpers import view_process

    cache = tmp_path / "cache"
    proc = view_process(tmp_path / "views", env={**os.environ, "GLSYNTH_CACHE": str(cache)})
    try:
        assert "open http" in proc.stdout.readline()
        deadline = time.monotonic() + 60
        while not list(cache.glob("textures-*/*/*.png")) and time.monotonic() < deadline:
            time.sleep(0.05)
        proc.send_signal(signal.SIGINT)
        started = time.monotonic()
        assert proc.wait(30) == 130, proc.stdout.read()
        assert time.monotonic() - started < 10
    finally:
        proc.kill()
        proc.communicate()
    made = len(list(cache.glob("textures-*/*/*.png")))
    assert 1 <= made < 72


def test_render_refuses_a_bad_camera_json_in_one_line_before_any_work(tmp_path, capsys):
    from glsynth.cli import main

    bad = tmp_path / "camera.json"
    bad.write_text(json.dumps({"pose": (3 * POSE).tolist(), "focal_mm": 24.0}))
    code = main(["render", "--preset", "demo", "--seed", "0", "--env", "0", "--camera-json",
                 str(bad), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "orthonormal" in err
    assert not (tmp_path / "out").exists()


def test_view_refuses_a_cycles_config_before_it_serves(tmp_path, capsys):
    from glsynth.cli import main

    config = tmp_path / "cycles.toml"
    config.write_text('[render]\nrenderer = "cycles"\n')
    code = main(["view", "--config", str(config), "--port", "0", "--out", str(tmp_path)])
    assert code == 2 and "renderer" in capsys.readouterr().err


def test_relighting_draws_what_opening_under_that_light_draws():
    """Scene.relight (Renderer.relight, no upload) against a scene opened afresh under the
    same fixed lighting: the same bytes."""
    from glsynth.view.scene import open_scene

    settings = PREVIEW
    values = {"sun_elevation_deg": 35.0, "sun_azimuth_deg": 80.0, "turbidity": 5.0,
              "exposure": 1.5}
    relit = open_scene(settings, None, lambda *_: None)
    with relit.view.renderer:
        relit.relight(values)
        _, colour = relit.view.render(1)
        assert relit.view.lighting.sun_azimuth_deg == 80.0
        fresh = open_scene(dataclasses.replace(PREVIEW, lighting=values),
                           relit.view.renderer, lambda *_: None)
        _, expected = fresh.view.render(1)
        assert np.array_equal(colour.color, expected.color)


def test_the_queue_keeps_the_newest_request_moves_first_and_forgets_closed_pages(tmp_path):
    """The render thread's choice of job, without GL: each page's newest camera wins, moving
    frames go before stills, cracks are packed ahead of use only when no frame waits, and a
    closed page's pending frame is dropped."""
    from glsynth.view.scene import SceneSettings
    from glsynth.view.worker import RenderWorker

    worker = RenderWorker(SceneSettings("demo", 0, 0), tmp_path)
    worker._scene_request = None  # as if the scene were open
    worker.scene = types.SimpleNamespace(cameras=[], verdicts={}, summary=lambda: {})
    done = []
    worker._frame = lambda cid, client, request: done.append((cid, request.focal_mm))
    still, moving = worker.add_client(lambda m: None), worker.add_client(lambda m: None)
    worker.submit(still, parse_message(camera_message(focal_mm=30.0, moving=False)))
    for focal in (40.0, 41.0, 42.0):
        worker.submit(moving, parse_message(camera_message(focal_mm=focal)))
    worker._cracks_waiting = True  # a part whose cracks no view has packed yet

    def pack_cracks() -> None:
        done.append("cracks")
        worker._cracks_waiting = False

    worker._pack_cracks = pack_cracks
    while (job := worker._pick_job()) is not None:
        job()
    assert done == [(moving, 42.0), (still, 30.0), "cracks"]
    worker.submit(moving, parse_message(camera_message(focal_mm=50.0)))
    worker.remove_client(moving)
    assert worker._pick_job() is None


def test_a_banded_interruptible_render_is_the_same_bytes_and_stops_at_a_checkpoint():
    """Renderer.render with ``interrupt`` and the colour pass in bands: the same bytes as one
    go; an interrupt raises RenderInterrupted at the next checkpoint, and leaves no state
    (scissor, depth mask) that changes the next render."""
    from glsynth.core.interrupts import RenderInterrupted
    from glsynth.view.scene import open_scene

    scene = open_scene(PREVIEW, None, lambda *_: None)
    with scene.view.renderer as renderer:
        camera = scene.cameras[1].camera
        whole = renderer.render(camera)
        asked = []

        def never() -> bool:
            asked.append(1)
            return False

        banded = renderer.render(camera, interrupt=never, bands=5)
        assert len(asked) == 2 + 5  # after sky visibility and labels, then each band
        stop_at = iter([False, False, False, True])
        with pytest.raises(RenderInterrupted):
            renderer.render(camera, interrupt=lambda: next(stop_at), bands=5)
        again = renderer.render(camera)
        for name in ("color", "component", "damage", "depth", "crack_width"):
            assert np.array_equal(getattr(banded, name), getattr(whole, name)), name
            assert np.array_equal(getattr(again, name), getattr(whole, name)), name
        assert len(np.unique(whole.color.reshape(-1, 3), axis=0)) > 1000


@pytest.fixture
def preview_worker(tmp_path):
    """A render worker with the demo's environment 0 open at preview quality, its jobs run by
    the test. The renderer it holds at the end is released however the test ends, so a
    failing test leaks no GL context."""
    from glsynth.view.worker import RenderWorker

    worker = RenderWorker(PREVIEW, tmp_path)
    worker._pick_job()()  # opens the scene
    yield worker
    if worker.scene is not None:
        with worker.scene.view.renderer:  # leaving the block releases the context
            pass


def test_a_move_interrupts_a_still_in_flight_and_the_stale_still_is_never_sent(preview_worker):
    """The render thread's jobs run here, on a real scene: a move that arrives while a still
    renders (after its label pass) stops it before its colour pass, the next job sends the
    move's small frame, and no full-size frame follows; a still left alone is sent."""
    from glsynth.view.worker import STILL_BANDS

    worker = preview_worker
    sent = []
    cid = worker.add_client(sent.append)
    renderer, placement = worker.scene.view.renderer, worker.scene.cameras[1]
    label_pass, draw_colors = renderer._label_pass, renderer._draw_colors
    bands, during_labels = [], []
    renderer._draw_colors = lambda *a: (bands.append(1), draw_colors(*a))

    def label_then_maybe_move(*args) -> None:
        label_pass(*args)
        for message in during_labels:
            worker.submit(cid, parse_message(message))
        during_labels.clear()

    renderer._label_pass = label_then_maybe_move
    pose, focal = placement.camera.pose.tolist(), placement.camera.focal_mm

    def frames() -> list[dict]:
        heads = [json.loads(m[4:4 + int.from_bytes(m[:4], "big")]) for m in sent
                 if isinstance(m, bytes)]
        sent.clear()
        return heads

    worker.submit(cid, parse_message(camera_message(pose=pose, focal_mm=focal, moving=False)))
    during_labels.append(camera_message(pose=pose, focal_mm=focal + 1, moving=True))
    worker._pick_job()()  # the still: interrupted
    assert frames() == [] and bands == []
    worker._pick_job()()  # the move
    moved = frames()
    assert [(f["still"], f["focal_mm"]) for f in moved] == [(False, focal + 1)]
    assert moved[0]["width"] < worker.scene.full_size[0]
    while (job := worker._pick_job()) is not None:  # the idle work: no stale still
        job()
    assert frames() == [] and worker._cracks_waiting is False
    bands.clear()
    worker.submit(cid, parse_message(camera_message(pose=pose, focal_mm=focal, moving=False)))
    worker._pick_job()()
    assert [(f["still"], f["width"]) for f in frames()] == [(True, worker.scene.full_size[0])]
    assert len(bands) == STILL_BANDS
    # A page that moves and stops elsewhere within one still: the first still is dropped and
    # only the second pose's is sent.
    worker.submit(cid, parse_message(camera_message(pose=pose, focal_mm=focal, moving=False)))
    during_labels.append(camera_message(pose=pose, focal_mm=focal + 2, moving=False))
    worker._pick_job()()
    assert frames() == []
    worker._pick_job()()
    assert [(f["still"], f["focal_mm"]) for f in frames()] == [(True, focal + 2)]


def test_a_switch_lets_the_old_environment_go_before_it_builds_the_new_one(preview_worker,
                                                                          monkeypatch):
    """When the new environment's building starts, nothing holds the old one (its arrays
    are freed first: one environment at a time, not two, at the peak); then the new scene
    serves, on the same GL context."""
    import gc
    import weakref

    import glsynth.view.worker as worker_module

    worker = preview_worker
    old_view, renderer = weakref.ref(worker.scene.view), worker.scene.view.renderer
    seen = []

    def open_scene(*args, **kwargs):
        gc.collect()
        seen.append(old_view() is None)
        return real_open(*args, **kwargs)

    real_open = worker_module.open_scene
    monkeypatch.setattr(worker_module, "open_scene", open_scene)
    worker.submit(worker.add_client(lambda m: None), SceneRequest(0, 1, "preview", None))
    worker._pick_job()()
    assert seen == [True]
    assert worker.scene.settings.env == 1 and worker.scene.view.renderer is renderer


def test_a_failed_opening_releases_its_context(monkeypatch):
    """An opening that fails after the old scene was let go releases the renderer it was
    given (before, the worker's retry made a second context and the first was never freed);
    the next opening makes a context afresh and serves."""
    import glsynth.view.scene as scene_module
    from glsynth.render.gl.renderer import Renderer
    from glsynth.view.scene import open_scene

    settings = PREVIEW
    scene = open_scene(settings, None, lambda *_: None)
    renderer, released = scene.view.renderer, []
    monkeypatch.setattr(renderer, "release", lambda: (released.append(True),
                                                      Renderer.release(renderer)))

    def failing(*args, **kwargs):
        raise UserError("environment.n_viaducts = 0: a bad opening")

    real = scene_module.EnvironmentView.open
    monkeypatch.setattr(scene_module.EnvironmentView, "open", failing)
    with pytest.raises(UserError, match="bad opening"):
        open_scene(dataclasses.replace(settings, env=1), renderer, lambda *_: None)
    assert released == [True]
    monkeypatch.setattr(scene_module.EnvironmentView, "open", real)
    again = open_scene(dataclasses.replace(settings, env=1), None, lambda *_: None)
    with again.view.renderer:
        assert again.view.renderer is not renderer and again.settings.env == 1


def test_a_programming_error_in_a_switch_reopens_the_last_scene(preview_worker, monkeypatch):
    """A switch that fails with a programming error keeps its traceback (the render thread
    prints it) but leaves no page waiting on a progress bar: loading clears and the last good
    scene is asked for again. The failure is inside the opening, which releases the context
    it was given (test_a_failed_opening_releases_its_context)."""
    import glsynth.view.scene as scene_module

    worker = preview_worker
    real_open = scene_module.EnvironmentView.open

    def broken(config, seed, env, *args, **kwargs):
        if env == 1:
            raise RuntimeError("a bug")
        return real_open(config, seed, env, *args, **kwargs)

    monkeypatch.setattr(scene_module.EnvironmentView, "open", broken)
    worker.submit(worker.add_client(lambda m: None), SceneRequest(0, 1, "preview", None))
    with pytest.raises(RuntimeError, match="a bug"):
        worker._pick_job()()
    assert worker.loading is None and worker.scene is None
    worker._pick_job()()  # the fallback
    assert worker.scene is not None and worker.scene.settings.env == 0
