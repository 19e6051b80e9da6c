"""Every reader of glsynth.data.readers and glsynth.core.reading (and the readers that go
through them: TOML configs, manifests, photos, --camera-json) against what stands in a file's
place: a FIFO, a folder, a symlink loop, /dev/zero, an oversize file, deep JSON, NaN. Each
gives one UserError line under 300 characters, never blocks, never lets another exception
through; the caches make a bad entry again with a warning. --camera-json is fuzzed with random
JSON of every type and depth (hypothesis). No GL: these run in seconds."""

import io
import json
import math
import os
import signal
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image

import glsynth.core.images
import glsynth.data.tokaido
import glsynth.view.camera
from glsynth.core import reading
from glsynth.core.config import load_config
from glsynth.core.errors import MAX_MESSAGE, UserError
from glsynth.core.images import read_photo
from glsynth.data import readers
from glsynth.data.tokaido import read_manifest
from glsynth.view.camera import read_camera_json

CONFIG = load_config("demo")


@pytest.fixture(autouse=True)
def never_hangs() -> Iterator[None]:
    """A reader that blocks (on a FIFO) fails the test after 10 s instead of hanging it."""
    def stop(*_: object) -> None:
        raise TimeoutError("a reader blocked")

    previous = signal.signal(signal.SIGALRM, stop)
    signal.alarm(10)
    yield
    signal.alarm(0)
    signal.signal(signal.SIGALRM, previous)


def _fifo(path: Path) -> Path:
    os.mkfifo(path)
    return path


def _folder(path: Path) -> Path:
    path.mkdir()
    (path / "inside").write_bytes(b"x")
    return path


def _loop(path: Path) -> Path:
    path.symlink_to(path)
    return path


def _dev_zero(path: Path) -> Path:
    path.symlink_to("/dev/zero")
    return path


def _missing(path: Path) -> Path:
    return path


SPECIAL: dict[str, Callable[[Path], Path]] = {
    "fifo": _fifo, "folder": _folder, "symlink loop": _loop, "/dev/zero": _dev_zero,
    "missing": _missing}

SIZE = (8, 6)
"""(width, height) the map readers are asked for."""

READERS: dict[str, Callable[[Path], object]] = {
    "read_json": lambda p: readers.read_json(p, {}, "fix it"),
    "read_npy": lambda p: reading.read_npy(p, "array", "fix it"),
    "read_float_map": lambda p: readers.read_float_map(p, "depth map", SIZE),
    "read_label_map": lambda p: readers.read_label_map(p, "component", SIZE),
    "read_depth_map": lambda p: readers.read_depth_map(p, SIZE),
    "read_crack_width_map": lambda p: readers.read_crack_width_map(p, SIZE),
    "read_rgb_image": lambda p: readers.read_rgb_image(p, "image", SIZE),
    "map_size": readers.map_size,
    "read_class_weights": lambda p: readers.read_class_weights(p, 3),
    "read_photo": read_photo,
    "load_config": lambda p: load_config("demo", p),
    "read_manifest": lambda p: read_manifest(p.parent, p.name),
    "read_camera_json": lambda p: read_camera_json(p, CONFIG),
}


def refused(read: Callable[[Path], object], path: Path, *needles: str) -> str:
    """The one UserError line ``read`` gives for ``path``."""
    with pytest.raises(UserError) as caught:
        read(path)
    message = str(caught.value)
    assert "\n" not in message and len(message) < MAX_MESSAGE, message
    for needle in needles:
        assert needle in message, message
    return message


@pytest.mark.parametrize("kind", SPECIAL)
@pytest.mark.parametrize("reader", READERS)
def test_a_special_file_is_refused_in_one_line(tmp_path, reader, kind):
    path = SPECIAL[kind](tmp_path / ("x" * 200 + ".file"))  # a long name, abbreviated
    needle = {"fifo": "not a regular file", "folder": "not a regular file",
              "/dev/zero": "not a regular file", "missing": "does not exist",
              "symlink loop": "cannot be opened"}[kind]
    refused(READERS[reader], path, needle, "...")


@pytest.mark.parametrize("reader", READERS)
def test_an_oversize_file_is_refused_before_it_is_read(tmp_path, reader, monkeypatch):
    for module in (reading, readers, glsynth.core.images, glsynth.data.tokaido,
                   glsynth.view.camera):
        for name in ("MAX_JSON_BYTES", "MAX_ARRAY_BYTES", "MAX_IMAGE_BYTES", "MAX_TOML_BYTES",
                     "MAX_MANIFEST_BYTES"):
            if hasattr(module, name):
                monkeypatch.setattr(module, name, 1000)
    path = tmp_path / "big"
    path.write_bytes(b"{" + b" " * 5000 + b"}")
    refused(READERS[reader], path, "5,002 bytes, more than the 1,000")


def test_the_json_limit_is_64_mb_for_camera_json_too(tmp_path):
    path = tmp_path / "huge.json"
    with open(path, "wb") as f:
        f.truncate(70 * 2**20)  # sparse: 70 MB that take no disk
    refused(READERS["read_camera_json"], path, "73,400,320 bytes", "--camera-json")


@pytest.mark.parametrize("text, needle", [
    ("[" * 100_000 + "]" * 100_000, "nested too deeply"),
    ("[" * 40 + "]" * 40, "nests more than 32 levels"),
    ('{"a": NaN}', "NaN is not a finite number"),
    ('{"a": -Infinity}', "-Infinity is not a finite number"),
    ('{"a": 1e999}', "out of range"),
    ('{"a": ' + "9" * 5000 + "}", "an integer of 5000 digits"),
    ('{"a": 1', "not valid JSON"),
    ("\xff", "not valid JSON"),
])
@pytest.mark.parametrize("reader", ["read_json", "read_camera_json", "read_class_weights"])
def test_json_beyond_its_limits_is_refused(tmp_path, reader, text, needle):
    path = tmp_path / "doc.json"
    path.write_bytes(text.encode("utf-8", "surrogateescape") if text != "\xff" else b"\xff")
    refused(READERS[reader], path, needle)


def test_deep_toml_is_refused(tmp_path):
    path = tmp_path / "deep.toml"
    path.write_text("a = " + "[" * 100_000)
    refused(READERS["load_config"], path, "nests too deeply")


def _npy(path: Path, array: np.ndarray) -> Path:
    buffer = io.BytesIO()
    np.save(buffer, array)
    path.write_bytes(buffer.getvalue())
    return path


@pytest.mark.parametrize("values, needle", [
    (np.full((6, 8), np.nan, np.float32), "48 values that are not finite"),
    (np.full((6, 8), np.inf, np.float32), "48 values that are not finite"),
    (np.full((6, 8), -1, np.float32), "48 values that are not finite and >= 0"),
    (np.zeros((6, 8), np.float64), "float64"),
    (np.zeros((8, 6), np.float32), "(8, 6)"),
    (np.zeros((6, 8, 1), np.float32), "(6, 8, 1)"),
])
def test_a_float_map_holds_its_contract(tmp_path, values, needle):
    refused(READERS["read_float_map"], _npy(tmp_path / "m.npy", values), needle)


def test_a_float_map_that_keeps_it_is_read(tmp_path):
    values = np.arange(48, dtype=np.float32).reshape(6, 8)
    assert np.array_equal(READERS["read_float_map"](_npy(tmp_path / "m.npy", values)), values)


@pytest.mark.parametrize("data", [b"", b"\x93NUMPY", b"not an array",
                                  json.dumps({"a": 1}).encode()])
def test_a_damaged_npy_is_refused(tmp_path, data):
    path = tmp_path / "m.npy"
    path.write_bytes(data)
    refused(READERS["read_npy"], path, "is not a .npy array")


def test_a_pickled_npy_is_refused_unread(tmp_path):
    path = tmp_path / "m.npy"
    np.save(path, np.array([{"a": 1}], dtype=object), allow_pickle=True)
    refused(READERS["read_npy"], path, "is not a .npy array")


def test_an_rgb_image_of_another_mode_or_size_is_refused(tmp_path):
    Image.new("L", SIZE).save(tmp_path / "gray.png")
    Image.new("RGB", (9, 6)).save(tmp_path / "wide.png")
    refused(READERS["read_rgb_image"], tmp_path / "gray.png", "is a L image")
    refused(READERS["read_rgb_image"], tmp_path / "wide.png", "is 9x6; it must be 8x6")
    Image.new("RGB", SIZE, (1, 2, 3)).save(tmp_path / "ok.png")
    assert READERS["read_rgb_image"](tmp_path / "ok.png").shape == (6, 8, 3)


# --- markers and caches ----------------------------------------------------------------------

def test_a_marker_is_a_regular_file_and_anything_else_is_redone(tmp_path):
    assert not readers.is_marker(tmp_path / "none.done")
    (tmp_path / "file.done").write_bytes(b"")
    assert readers.is_marker(tmp_path / "file.done")
    for kind in ("folder", "fifo", "symlink loop"):
        path = SPECIAL[kind](tmp_path / f"{kind.replace(' ', '_')}.done")
        if kind == "folder":
            (path / "inside").unlink()
        with pytest.warns(UserWarning, match="is not a file; its unit is done again"):
            assert not readers.is_marker(path)
        assert not os.path.lexists(path)


def test_a_marker_folder_that_cannot_go_is_one_line(tmp_path):
    path = _folder(tmp_path / "full.done")
    with pytest.warns(UserWarning), pytest.raises(UserError, match="cannot be removed"):
        readers.is_marker(path)


@pytest.mark.parametrize("kind", ["fifo", "folder", "symlink loop", "truncated", "foreign"])
def test_a_bad_training_cache_entry_is_made_again(tmp_path, kind):
    path = tmp_path / "entry.npz"
    if kind == "truncated":
        path.write_bytes(readers.cache_entry_bytes(np.zeros((2, 2, 3), np.uint8), "k")[:50])
    elif kind == "foreign":
        path.write_bytes(readers.cache_entry_bytes(np.zeros((2, 2, 3), np.uint8), "other"))
    else:
        SPECIAL[kind](path)
    with pytest.warns(UserWarning, match="training cache: remaking"):
        assert readers.read_cache_entry(path, "k", (2, 2, 3)) is None
    assert not os.path.lexists(path)
    path.write_bytes(readers.cache_entry_bytes(np.ones((2, 2, 3), np.uint8), "k"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert readers.read_cache_entry(path, "k", (2, 2, 3)).sum() == 12


@pytest.fixture
def repository(tmp_path, monkeypatch):
    from glsynth.appearance.repository import TextureRepository, generate_repository

    monkeypatch.setenv("GLSYNTH_CACHE", str(tmp_path / "cache"))
    return TextureRepository(generate_repository(tmp_path / "repo", 0, 1, 64), 32)


@pytest.mark.parametrize("kind", ["fifo", "folder", "symlink loop", "truncated"])
def test_a_bad_decoded_image_entry_is_decoded_again(repository, tmp_path, kind):
    good = repository.image("concrete", 0)
    entry, = (tmp_path / "cache" / "decoded").iterdir()
    entry.unlink()
    if kind == "truncated":
        entry.write_bytes(b"\x93NUMPY")
    else:
        SPECIAL[kind](entry)
    repository._cache.clear()
    with pytest.warns(UserWarning, match="decoding .* again"):
        assert np.array_equal(repository.image("concrete", 0), good)
    assert entry.is_file()


@pytest.mark.parametrize("in_the_way", ["the cache", "its decoded folder"])
def test_a_cache_that_is_a_file_is_blamed_on_glsynth_cache(tmp_path, monkeypatch, in_the_way):
    from glsynth.appearance.repository import TextureRepository, generate_repository

    root = generate_repository(tmp_path / "repo", 0, 1, 64)
    cache = tmp_path / "cache"
    if in_the_way == "the cache":
        cache.write_text("")
    else:
        cache.mkdir()
        (cache / "decoded").write_text("")
    monkeypatch.setenv("GLSYNTH_CACHE", str(cache))
    with pytest.raises(UserError) as caught:
        TextureRepository(root, 32).image("concrete", 0)
    message = str(caught.value)
    assert message.startswith("$GLSYNTH_CACHE: cannot make") and "--out" not in message


@pytest.mark.parametrize("kind", ["fifo", "folder", "truncated", "bad meta"])
def test_a_bad_damage_bank_entry_is_made_again(tmp_path, kind):
    from glsynth.appearance.damage_bank import DamageBank
    from glsynth.appearance.repository import TextureRepository, generate_repository
    from glsynth.core.config import DamageConfig

    repository = TextureRepository(generate_repository(tmp_path / "repo", 0, 1, 64), 32)
    bank = DamageBank(DamageConfig(resolution=64), 0, tmp_path / "bank")
    made = bank.entry("slight", 0, repository)
    path = bank._path("slight", 0)
    if kind == "truncated":
        path.write_bytes(path.read_bytes()[:100])
    elif kind == "bad meta":
        with np.load(path) as data:
            arrays = dict(data)
        arrays["meta"] = np.frombuffer(b'{"threshold": NaN}', np.uint8)
        np.savez(path, **arrays)
    else:
        path.unlink()
        SPECIAL[kind](path)
    with pytest.warns(UserWarning, match="damage bank: making .* again"):
        params, images = bank.record("slight", 0, repository)
    assert (params, images) == (made.params, made.images)
    again = bank.entry("slight", 0, repository)
    assert np.array_equal(again.maps.mask, made.maps.mask)


# --- --camera-json with any JSON -------------------------------------------------------------

JSON = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False)
    | st.text(max_size=20),
    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=8), inner,
                                                                  max_size=5),
    max_leaves=40)


def _camera_like(value: object) -> object:
    """Half the time, the value where a camera's pose or focal length goes."""
    return {"pose": value, "focal_mm": 24.0} if isinstance(value, list) else \
        {"pose": np.eye(4).tolist(), "focal_mm": value}


@settings(max_examples=300, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(value=JSON, wrap=st.booleans(), depth=st.integers(0, 60))
def test_camera_json_of_any_shape_is_a_camera_or_one_line(tmp_path, value, wrap, depth):
    document = _camera_like(value) if wrap else value
    for _ in range(depth):
        document = [document]
    path = tmp_path / "camera.json"
    path.write_text(json.dumps(document))
    try:
        camera = read_camera_json(path, CONFIG)
    except UserError as err:
        assert "\n" not in str(err) and len(str(err)) < MAX_MESSAGE, str(err)
        assert str(err).startswith("--camera-json")
        return
    assert np.isfinite(camera.pose).all() and math.isfinite(camera.focal_mm)
