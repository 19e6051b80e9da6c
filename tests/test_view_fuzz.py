"""glsynth view against a hostile page: any JSON value, any text or bytes, of any type, depth
and size, gets an error reply on a connection that stays open, and never a traceback; a
config upload cannot reach the server's files or grow its disk caches; a frame too large for
the memory is refused before it is allocated; a mirrored camera is refused; ``--out`` and
``--host`` are checked before the port is bound."""

import dataclasses
import json
import re
import socket
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from glsynth.core.config import Config
from glsynth.core.errors import UserError
from glsynth.view.protocol import MAX_DEPTH, MAX_MESSAGE_BYTES, SCHEMA, parse_message

PROBE = json.dumps({"type": "pass", "name": "color"})
"""A valid message the server answers at once (with the pass's legend)."""
FUZZ = settings(max_examples=40, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(),
    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(), inner, max_size=5),
    max_leaves=20)
"""Any JSON value, NaN and infinities included (json.dumps writes them as Python's json
reads them)."""

field_names = st.sampled_from(sorted({k for fields in SCHEMA.values() for k in fields})) \
    | st.text(max_size=8)
messages = st.builds(
    lambda kind, fields: {"type": kind, **fields},
    st.sampled_from(sorted(SCHEMA)) | json_values,
    st.dictionaries(field_names, json_values, max_size=6))
"""Objects shaped like messages: a type (known or any value) and fields of any value, so
that the checks of each type's fields are reached, not only the first one."""


# --- a live server ----------------------------------------------------------------------------

@pytest.fixture(scope="module")
def server(tmp_path_factory):
    from viewhelpers import ViewServer

    # The smallest quality: the scene it opens meanwhile is the quickest to build.
    running = ViewServer(tmp_path_factory.mktemp("views"), "--quality", "preview")
    try:
        yield running
    finally:
        code = running.stop()
        rest = running.proc.stdout.read()
        assert code == 130 and "Traceback" not in rest, rest
        assert not list(Path(tempfile.gettempdir()).glob(f"glsynth-view-bank-{running.proc.pid}"))


@pytest.fixture(scope="module")
def page(server):
    from websockets.sync.client import connect

    with connect(server.ws_url, max_size=None, open_timeout=30) as ws:
        yield ws


def answers(ws, message: str | bytes) -> list[dict]:
    """What the server sends back to ``message``: the text messages before the answer to a
    probe sent after it (which shows the connection still open and serving)."""
    ws.send(message)
    ws.send(PROBE)
    got = []
    while True:
        reply = ws.recv(timeout=60)
        if isinstance(reply, str):
            got.append(json.loads(reply))
            if got[-1]["type"] == "legend":
                return got


def refused(ws, message: str | bytes) -> str:
    """The one error line the server answers ``message`` with."""
    errors = [m["message"] for m in answers(ws, message) if m["type"] == "error"]
    assert len(errors) == 1, errors
    assert "\n" not in errors[0] and len(errors[0]) < 300, errors[0]
    return errors[0]


def invalid(text: str) -> bool:
    """Whether the protocol refuses ``text`` (a valid message is not a probe of refusal);
    anything but UserError fails the test here already."""
    try:
        parse_message(text)
    except UserError:
        return True
    return False


@FUZZ
@given(value=json_values | messages)
def test_any_json_value_gets_an_error_and_the_connection_stays_open(page, value):
    text = json.dumps(value)
    assume(invalid(text))
    refused(page, text)


@FUZZ
@given(depth=st.integers(MAX_DEPTH + 1, MAX_MESSAGE_BYTES // 2), bracket=st.sampled_from("[{"))
def test_json_of_any_depth_gets_an_error_not_a_recursion_error(page, depth, bracket):
    closing = {"[": "]", "{": "}"}[bracket]
    opening = bracket if bracket == "[" else '{"a":'
    text = json.dumps({"type": "pass", "name": "x"})[:-1] + ', "deep": ' \
        + opening * depth + "1" + closing * depth + "}"
    if len(text) <= MAX_MESSAGE_BYTES:
        assert "nest deeper than" in refused(page, text)
    else:
        assert "at most" in refused(page, text)


@FUZZ
@given(payload=st.binary(max_size=64) | st.text(max_size=64))
def test_any_bytes_or_text_gets_an_error(page, payload):
    assume(isinstance(payload, bytes) or invalid(payload))
    refused(page, payload)


def test_a_message_over_the_size_limit_gets_an_error(page):
    assert "at most" in refused(page, " " * (MAX_MESSAGE_BYTES + 1))


def test_a_message_over_the_websocket_limit_closes_that_connection_alone(server, page):
    """Beyond WS_MAX_BYTES the websocket library closes the connection (1009, "message too
    big") rather than buffer it; other pages and new connections are served."""
    from websockets.exceptions import ConnectionClosed
    from websockets.sync.client import connect

    from glsynth.view.server import WS_MAX_BYTES

    with connect(server.ws_url, max_size=None, open_timeout=30) as ws:
        ws.send(" " * (WS_MAX_BYTES + 1))
        with pytest.raises(ConnectionClosed) as closed:
            while True:
                ws.recv(timeout=60)
    assert closed.value.rcvd.code == 1009
    refused(page, "{}")


def _scene_message(config_toml: str) -> str:
    return json.dumps({"type": "scene", "seed": 0, "env": 0, "quality": "fast",
                       "config_toml": config_toml})


def test_a_page_config_naming_a_path_or_a_cache_is_refused_by_the_server(page, tmp_path):
    (tmp_path / "concrete").mkdir()
    path = refused(page, _scene_message(f'[materials]\nrepository = "{tmp_path}"\n'))
    assert path.startswith("[materials] repository: a page may not set a path"), path
    cache = refused(page, _scene_message("[materials]\nimages_per_category = 10000\n"))
    assert cache.startswith("[materials] images_per_category = 10000: a page may not change")


# --- what a page's config may change -----------------------------------------------------------

def _other_value(value: object) -> object | None:
    """A different value of the same TOML kind, or None where there is none to try."""
    if isinstance(value, bool):
        return not value
    if isinstance(value, int):
        return value + 1
    if isinstance(value, float):
        return value * 0.9 + 0.05
    if isinstance(value, str):
        return value + "x"
    if isinstance(value, tuple) and value and all(isinstance(v, float) for v in value):
        return [v * 0.9 + 0.05 for v in value]
    return None


def _every_field(config: Config) -> list[tuple[str, str, object]]:
    return [(s.name, f.name, getattr(getattr(config, s.name), f.name))
            for s in dataclasses.fields(config) for f in dataclasses.fields(getattr(config,
                                                                                    s.name))]


@pytest.mark.parametrize("quality", [None, "fast"])
def test_no_single_config_change_lets_a_page_reach_a_path_or_a_new_cache_entry(quality):
    """Every field of every section, set to another value by a page: the viewer refuses it,
    or opens a config that reads the server's own files and caches (glsynth.appearance.caches)
    and changes no free-text field."""
    from glsynth.appearance.caches import disk_caches
    from glsynth.view.scene import SceneSettings, scene_config

    base = scene_config(SceneSettings("demo", 0, 0, quality))
    tried = refusals = 0
    for section, name, value in _every_field(base):
        other = _other_value(value)
        if other is None:
            continue
        tried += 1
        toml = f"[{section}]\n{name} = {json.dumps(other)}\n"
        try:
            config = scene_config(SceneSettings("demo", 0, 0, quality, page_toml=toml))
        except UserError as err:
            refusals += "a page may not" in str(err)
            continue
        assert disk_caches(config) == disk_caches(base), (section, name)
        assert not isinstance(value, str) or getattr(getattr(config, section), name) == value
    assert tried > 100 and refusals >= 5


@pytest.mark.parametrize("toml, words", [
    ('[materials]\nrepository = "/etc"\n', "[materials] repository: a page may not set a path"),
    ("[materials]\nrepository_seed = 7\n", "[materials] repository_seed = 7: a page may not "
                                           "change what the server caches"),
    ("[materials]\nbuiltin_size = 8192\n", "[materials] builtin_size = 8192: a page may not"),
    ("[damage]\nbank_size = 5\n", "[damage] bank_size = 5: a page may not"),
    ("[damage]\nbank_size = 5\n[lighting]\nexposure = 1.0\n", "[damage] bank_size = 5"),
])
def test_a_page_config_is_refused_naming_the_field(toml, words):
    from glsynth.view.scene import SceneSettings, scene_config

    with pytest.raises(UserError) as err:
        scene_config(SceneSettings("demo", 0, 0, "fast", page_toml=toml))
    assert str(err.value).startswith(words)


def test_the_servers_own_config_may_name_a_path_a_page_may_change_the_light(tmp_path):
    from glsynth.view.scene import SceneSettings, scene_config

    own = f'[materials]\nrepository = "{tmp_path}"\n'
    config = scene_config(SceneSettings("demo", 0, 0, "fast", config_toml=own,
                                        page_toml="[lighting]\nexposure = 1.5\n"))
    assert config.materials.repository == str(tmp_path) and config.lighting.exposure == 1.5


# --- frames and cameras ------------------------------------------------------------------------

def _rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096 / 2**20


def test_a_frame_larger_than_free_memory_or_the_gl_is_refused_before_allocation(monkeypatch):
    import glsynth.render.gl.renderer as gl_renderer
    from glsynth.core.config import RenderConfig

    small = RenderConfig(width=320, height=180, msaa=0, shadow_map_px=0, sky_visibility_maps=0)
    with gl_renderer.Renderer(small) as renderer:
        side = renderer.ctx.info["GL_MAX_RENDERBUFFER_SIZE"]
        with pytest.raises(UserError, match=f"at most {side} px"):
            renderer.resize(side + 1, 8)
        monkeypatch.setattr(gl_renderer, "available_bytes", lambda: 256 * 2**20)
        before = _rss_mb()
        with pytest.raises(UserError, match=r"8192x8192: its render targets take [\d.]+ GiB"):
            renderer.resize(8192, 8192)
        assert renderer.size == (320, 180) and _rss_mb() - before < 64
        renderer.resize(640, 360)  # within the 256 MiB: allowed
        # A new renderer makes its context and compiles its programs (llvmpipe's JIT: 100-300
        # MB, more in a process that has rendered much) before it can measure its targets; the
        # promise is that the 8192x8192 targets themselves are never allocated.
        before = _rss_mb()
        with pytest.raises(UserError, match="render targets take") as refused:
            gl_renderer.Renderer(dataclasses.replace(small, width=8192, height=8192))
        need_mb = float(re.search(r"take ([\d.]+) GiB", str(refused.value))[1]) * 1024
        assert _rss_mb() - before < need_mb / 4


def _rotation(quaternion: list[float]) -> np.ndarray:
    w, x, y, z = np.array(quaternion) / np.linalg.norm(quaternion)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


quaternions = st.lists(st.floats(-1, 1), min_size=4, max_size=4).filter(
    lambda q: np.linalg.norm(q) > 0.1)


@settings(max_examples=50, deadline=None, derandomize=True)
@given(quaternion=quaternions, mirror=st.integers(0, 2))
def test_a_mirrored_camera_is_refused_and_a_rotation_is_not(quaternion, mirror):
    """A rotation times a reflection is orthonormal too: only its determinant (-1) tells it."""
    pose = np.eye(4)
    pose[:3, :3] = _rotation(quaternion)
    message = {"type": "camera", "pose": pose.tolist(), "focal_mm": 24.0, "moving": True}
    assert np.array_equal(parse_message(json.dumps(message)).pose, pose)
    pose[:3, mirror] *= -1
    with pytest.raises(UserError, match="right-handed"):
        parse_message(json.dumps({**message, "pose": pose.tolist()}))


# --- --out and --host, before anything is bound -----------------------------------------------

def _view(capsys, out: str, *extra: str) -> str:
    from glsynth.cli import main

    code = main(["view", "--preset", "demo", "--port", "0", "--out", out, *extra])
    captured = capsys.readouterr()
    assert code == 2 and "open http" not in captured.out and not captured.out
    assert captured.err.count("\n") == 1 and len(captured.err) < 300, captured.err
    assert "listening" not in captured.err
    return captured.err


def test_view_refuses_an_out_that_is_a_file(tmp_path, capsys):
    (tmp_path / "file").write_text("x")
    assert "is a file" in _view(capsys, str(tmp_path / "file"))


def test_view_refuses_an_out_another_run_holds(tmp_path, capsys):
    from glsynth.core.runlock import RunLock

    with RunLock(tmp_path / "held"):
        assert "is in use by another glsynth run" in _view(capsys, str(tmp_path / "held"))


def test_view_refuses_an_out_it_cannot_write_or_in_proc_with_the_path_cut(tmp_path, capsys):
    (tmp_path / "file").write_text("x")
    deep = tmp_path / "file" / ("long" * 60) / ("path" * 60)
    assert "cannot create the folder" in _view(capsys, str(deep))
    assert "/proc" in _view(capsys, "/proc/self/views")


def test_view_reports_an_address_it_cannot_bind_without_a_listening_line(tmp_path, capsys):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = str(taken.getsockname()[1])
        err = _view(capsys, str(tmp_path / "a"), "--port", port)
    assert f"--port {port}: cannot listen there" in err
    # TEST-NET-1 (RFC 5737): an address no machine of ours has.
    assert "cannot listen there" in _view(capsys, str(tmp_path / "b"), "--host", "192.0.2.1")

