"""Every file glsynth reads, corrupted, fed to the commands that read it (issue 30): the result
is exit 2 with one line naming the file, or a correct result; never a traceback or a silent
change. Photos of every kind a photographer gives go through predict on a real network.

The dataset is a hand-made Tokaido layout of 48x27 images (16x9 maps), made once per module,
and the runs are FCN58s with seeded weights written as `glsynth train` writes model.pt, so the
suite renders nothing and trains nothing; each fuzz test is bounded by FUZZ."""

import json
import shutil
import struct
import subprocess
import sys
import warnings
import zlib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image

from glsynth.cli import main
from glsynth.core.seeding import Stream, make_rng
from glsynth.data.tokaido import FrameRecord, frame_paths, manifest_text

torch = pytest.importorskip("torch")

FUZZ = settings()
"""The profile conftest loads: 25 examples a test in the full suite, 5 in the quick loop."""
IMAGE = (48, 27)
MAPS = (16, 9)
RUN_SIZE = (192, 108)


def _frame(root: Path, split: str, camera: int, rng: np.random.Generator) -> FrameRecord:
    paths = frame_paths(split, 0 if split == "train" else 1, camera)
    files = {k: root / v for k, v in paths.items()}
    for path in files.values():
        path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(rng.integers(0, 256, (*IMAGE[::-1], 3), np.uint8)).save(files["image"])
    Image.fromarray(rng.integers(0, 9, MAPS[::-1], np.uint8)).save(files["component"])
    Image.fromarray(rng.integers(0, 4, MAPS[::-1], np.uint8)).save(files["damage"])
    Image.fromarray(rng.integers(0, 65536, MAPS[::-1]).astype(np.uint16)).save(files["depth"])
    return FrameRecord(*(paths[k] for k in ("image", "component", "damage", "depth")), 35.0,
                       True, True)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    """Five training and two test frames with valid maps."""
    root = tmp_path_factory.mktemp("inputs") / "ds"
    rng = make_rng(3, 0, Stream.PLATES, 0)
    for split, n in (("train", 5), ("test", 2)):
        rows = [_frame(root, split, camera, rng) for camera in range(n)]
        (root / f"files_{split}.csv").write_text(manifest_text(rows))
    return root


def make_run(folder: Path, task: str) -> Path:
    """A run folder as `glsynth train` leaves one: model.pt (seeded FCN58) and settings.json."""
    from glsynth.model.fcn58 import FCN58
    from glsynth.model.runtime import save_torch
    from glsynth.model.settings import N_OUTPUTS

    torch.manual_seed(0)
    model = FCN58(N_OUTPUTS[task])
    folder.mkdir(parents=True)
    save_torch(folder / "model.pt", {"task": task, "out_channels": N_OUTPUTS[task],
                                     "image_size": RUN_SIZE, "mfb_weights": None,
                                     "state_dict": model.state_dict()})
    (folder / "settings.json").write_text(json.dumps({"task": task}))
    return folder


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    base = tmp_path_factory.mktemp("runs")
    return {task: make_run(base / task, task) for task in ("component", "depth")}


def run_cli(argv: list[str], capsys) -> tuple[int, str]:
    capsys.readouterr()
    code = main([str(a) for a in argv])
    return code, capsys.readouterr().err


def assert_one_line(code: int, err: str, names: str | None = None) -> None:
    """Exit 2, one line on stderr under 300 characters, no traceback; naming ``names``."""
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2, err
    assert len(lines) == 1 and lines[0].startswith("glsynth "), err
    assert len(lines[0]) < 300 and "Traceback" not in err, err
    if names is not None:
        assert names in lines[0], err


class Corrupted:
    """Replaces a file's bytes for one example and puts the original back."""

    def __init__(self, path: Path, data: bytes) -> None:
        self.path, self.data = path, data

    def __enter__(self) -> Path:
        self.original = self.path.read_bytes()
        self.path.write_bytes(self.data)
        return self.path

    def __exit__(self, *exc: object) -> None:
        self.path.write_bytes(self.original)


def png(array: np.ndarray, mode: str | None = None) -> bytes:
    import io

    buffer = io.BytesIO()
    Image.fromarray(array, mode).save(buffer, format="TIFF" if array.dtype.kind in "fi"
                                      and array.dtype.itemsize == 4 else "PNG")
    return buffer.getvalue()


def bomb_png(width: int, height: int) -> bytes:
    """A valid PNG header that claims width x height pixels (with a right CRC)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data)))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b""))
            + chunk(b"IEND", b""))


# A label map broken one way per example: size, mode/dtype, ids, garbage, truncation, bomb.
def _bad_label(kind: st.SearchStrategy) -> st.SearchStrategy:
    size = st.tuples(st.integers(1, 40), st.integers(1, 40)).filter(lambda s: s != MAPS).map(
        lambda s: png(np.ones(s[::-1], np.uint8)))
    rgb = st.just(png(np.ones((*MAPS[::-1], 3), np.uint8)))
    wide = st.sampled_from([np.float32, np.int32, np.uint16]).map(
        lambda t: png(np.ones(MAPS[::-1], t)))
    ids = kind.map(lambda top: png(np.full(MAPS[::-1], top, np.uint8)))
    garbage = st.binary(max_size=300)
    truncated = st.integers(0, 60).map(lambda n: png(np.ones(MAPS[::-1], np.uint8))[:n])
    return st.one_of(size, rgb, wide, ids, garbage, truncated, st.just(bomb_png(40000, 40000)))


BAD_COMPONENT = _bad_label(st.integers(9, 255))
BAD_DEPTH = st.one_of(
    st.just(png(np.ones(MAPS[::-1], np.uint8))),  # 8-bit depth
    st.just(png(np.ones((*MAPS[::-1], 3), np.uint8))),
    st.tuples(st.integers(1, 40), st.integers(1, 40)).filter(lambda s: s != MAPS).map(
        lambda s: png(np.ones(s[::-1], np.uint16))),
    st.binary(max_size=300))


def _stats_and_evaluate_refuse(path: Path, data: bytes, dataset: Path, run: Path,
                               out: Path, capsys) -> None:
    """With ``path`` holding ``data``, stats and evaluate each print one line naming it, or,
    where the damage left the map whole (a PNG cut after its last pixel), succeed."""
    with Corrupted(path, data):
        for argv in (["stats", dataset, "--out", out / "s"],
                     ["evaluate", "--run", run, "--data", dataset, "--out", out / "e"]):
            code, err = run_cli(argv, capsys)
            if code == 0:
                _assert_whole_map(path)
            else:
                assert_one_line(code, err, names=str(path))


def _assert_whole_map(path: Path) -> None:
    """The map as Pillow decodes it meets its kind's contract: what was read was valid."""
    with Image.open(path) as im:
        ids = np.asarray(im)
        mode = im.mode
    assert ids.shape == MAPS[::-1]
    if "depth" in path.parts:
        assert mode.startswith("I;16")
    else:
        assert mode in ("L", "P") and ids.max() <= 8


@FUZZ
@given(data=BAD_COMPONENT)
def test_bad_component_maps_are_one_line_in_stats_and_evaluate(dataset, runs, tmp_path, capsys,
                                                              data):
    _stats_and_evaluate_refuse(dataset / frame_paths("test", 1, 1)["component"], data,
                               dataset, runs["component"], tmp_path, capsys)


@FUZZ
@given(data=BAD_DEPTH)
def test_bad_depth_maps_are_one_line_in_stats_and_evaluate(dataset, runs, tmp_path, capsys,
                                                          data):
    _stats_and_evaluate_refuse(dataset / frame_paths("test", 1, 0)["depth"], data, dataset,
                               runs["depth"], tmp_path, capsys)


@settings(FUZZ, max_examples=8)
@given(data=BAD_COMPONENT)
def test_bad_component_maps_stop_train_with_one_line(dataset, tmp_path_factory, capsys, data):
    label = dataset / frame_paths("train", 0, 2)["component"]
    out = tmp_path_factory.mktemp("t") / "run"
    with Corrupted(label, data):
        assert_one_line(*run_cli(["train", "--task", "component", "--data", dataset, "--out",
                                  out, "--image-size", "192x108", "--schedule", "1e-3:1",
                                  "--loader-workers", "0", "--val-count", "0"], capsys),
                        names=str(label))


def test_valid_edge_maps_give_the_counts_of_their_pixels(dataset, tmp_path, capsys):
    """A palette (mode P) label map with the top id is valid: stats counts it."""
    import io

    from glsynth.data.statistics import read_image_counts

    label = dataset / frame_paths("test", 1, 1)["component"]
    ids = np.full(MAPS[::-1], 8, np.uint8)
    im = Image.fromarray(ids, "P")
    im.putpalette([v for i in range(256) for v in (i, 255 - i, i // 2)])
    buffer = io.BytesIO()
    im.save(buffer, format="BMP")
    with Corrupted(label, buffer.getvalue()):
        assert Image.open(label).mode == "P"
        assert run_cli(["stats", dataset, "--out", tmp_path], capsys)[0] == 0
        counts = read_image_counts(dataset)
    assert counts[-1].component[8] == ids.size


# --- manifests -------------------------------------------------------------------------------
ROW = ",".join(frame_paths("test", 1, 0).values()) + ",35.0,True,True\n"
BAD_MANIFESTS = st.one_of(
    st.binary(min_size=1, max_size=200).map(lambda b: b"\xff\xfe" + b),  # not UTF-8
    st.integers(1025, 200_000).map(lambda n: ("a" * n + ROW[ROW.index(","):]).encode()),
    st.integers(0, 12).filter(lambda n: n not in (0, 2, 7)).map(
        lambda n: (",".join(["x"] * n) + "\n").encode()),
    st.sampled_from([b'"unterminated,a,b\n' * 2 + b'"', ROW.replace("35.0", "nan").encode(),
                     ROW.replace("True", "yes", 1).encode(), b"../x,a,b,c,1,True,True\n",
                     ROW.replace("img_syn_raw", "img\x00raw").encode(),
                     ("/" + ROW).encode()]))


@FUZZ
@given(data=BAD_MANIFESTS)
def test_bad_manifests_are_one_line_in_every_command_that_reads_them(dataset, runs, tmp_path,
                                                                    capsys, data):
    manifest = dataset / "files_test.csv"
    with Corrupted(manifest, data):
        for argv in (["stats", dataset, "--out", tmp_path / "s"],
                     ["evaluate", "--run", runs["component"], "--data", dataset, "--out",
                      tmp_path / "e"],
                     ["assess", "--oracle", dataset, "--out", tmp_path / "a"]):
            assert_one_line(*run_cli(argv, capsys), names=str(manifest))


# --- JSON documents --------------------------------------------------------------------------
JSON_GARBAGE = st.one_of(
    st.binary(max_size=200),
    st.recursive(st.none() | st.booleans() | st.integers() | st.text(max_size=20),
                 lambda inner: st.lists(inner, max_size=3) | st.dictionaries(
                     st.text(max_size=8), inner, max_size=3), max_leaves=8).map(
        lambda v: json.dumps(v).encode()))


@FUZZ
@given(data=JSON_GARBAGE)
def test_bad_run_settings_are_one_line_for_train_and_predict(dataset, runs, tmp_path_factory,
                                                            capsys, data):
    run = tmp_path_factory.mktemp("r") / "run"
    run.mkdir()
    (run / "settings.json").write_bytes(data)
    code, err = run_cli(["train", "--task", "component", "--data", dataset, "--out", run,
                         "--schedule", "1e-3:1"], capsys)
    assert_one_line(code, err, names=str(run / "settings.json"))
    shutil.copy(runs["component"] / "model.pt", run / "model.pt")
    photo = dataset / frame_paths("test", 1, 0)["image"]
    code, err = run_cli(["predict", "--run", run, photo, "--out", run / "p"], capsys)
    assert_one_line(code, err, names=str(run / "settings.json"))
    assert not (run / "p").exists()


TRAIN_ONE_STEP = ["--task", "component", "--image-size", "192x108", "--schedule", "1e-3:1",
                  "--loader-workers", "0", "--val-count", "0", "--time-budget-min", "1e-9"]


@pytest.fixture(scope="module")
def trained(dataset, tmp_path_factory) -> Path:
    """A run folder after one training step, with its class_weights.json."""
    run = tmp_path_factory.mktemp("trained") / "run"
    assert main(["train", *TRAIN_ONE_STEP, "--data", str(dataset), "--out", str(run)]) == 0
    assert (run / "class_weights.json").is_file()
    return run


@settings(FUZZ, max_examples=10)
@given(data=st.one_of(JSON_GARBAGE, st.sampled_from([
    b'{"weights": [1, 2]}', b'{"weights": [1e999, 1, 1, 1, 1, 1, 1, 1, 1]}',
    b'{"weights": [-1, 1, 1, 1, 1, 1, 1, 1, 1]}', b'{"weights": "x"}'])))
def test_bad_class_weights_are_one_line_on_resume(dataset, trained, tmp_path_factory, capsys,
                                                  data):
    run = tmp_path_factory.mktemp("w") / "run"
    shutil.copytree(trained, run)
    (run / "class_weights.json").write_bytes(data)
    assert_one_line(*run_cli(["train", *TRAIN_ONE_STEP, "--data", dataset, "--out", run],
                             capsys), names=str(run / "class_weights.json"))


@FUZZ
@given(data=JSON_GARBAGE)
def test_a_bad_run_file_is_one_line_before_generate_renders(small_config, tmp_path_factory,
                                                           capsys, data):
    out = tmp_path_factory.mktemp("g") / "ds"
    out.mkdir()
    (out / "glsynth_run.json").write_bytes(data)
    code, err = run_cli(["generate", "--preset", "demo", "--config", small_config, "--seed",
                         "5", "--out", out], capsys)
    assert_one_line(code, err, names=str(out / "glsynth_run.json"))
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == \
        ["glsynth_run.json"]


@FUZZ
@given(data=JSON_GARBAGE)
def test_a_corrupt_progress_marker_is_redone_with_a_warning(tmp_path_factory, data):
    from glsynth.core.config import load_config
    from glsynth.data.dataset import pending_tasks, plan

    config = load_config("demo")
    out = tmp_path_factory.mktemp("m")
    task = plan(config)[0]
    (out / task.marker).parent.mkdir()
    (out / task.marker).write_bytes(data)
    with pytest.warns(UserWarning, match=task.marker):
        assert pending_tasks(config, out)[0] == task
    assert not (out / task.marker).exists()


@FUZZ
@given(data=JSON_GARBAGE)
def test_a_corrupt_marker_in_a_dataset_is_one_line_for_stats(dataset, tmp_path, capsys, data):
    marker = dataset / "progress" / "env_000000.json"
    marker.parent.mkdir(exist_ok=True)
    marker.write_bytes(b"{}")
    try:
        with Corrupted(marker, data):
            code, err = run_cli(["stats", dataset, "--out", tmp_path], capsys)
    finally:
        shutil.rmtree(marker.parent)
    if code == 0:  # only a marker with a table of removals passes
        parsed = _json_or_none(data)
        assert isinstance(parsed, dict) and isinstance(parsed.get("removed"), dict), data
    else:
        assert_one_line(code, err, names=str(marker))


def _json_or_none(data: bytes) -> object:
    try:
        return json.loads(data)
    except ValueError:
        return None


# --- training cache --------------------------------------------------------------------------
@FUZZ
@given(data=st.one_of(
    st.binary(max_size=300),
    st.sampled_from(["float64", "wrong shape", "foreign", "npy"])))
def test_bad_cache_entries_are_made_again_with_a_warning(dataset, tmp_path_factory, data):
    from glsynth.model.data import InputCache, load_image

    from glsynth.data.readers import cache_entry_bytes

    cache = InputCache(dataset, (24, 12), base=tmp_path_factory.mktemp("cache"))
    image = dataset / frame_paths("train", 0, 0)["image"]
    expected = load_image(image, (24, 12))
    assert torch.equal(cache.load(image), expected)
    entry = next(cache.dir.rglob("*.npz"))
    ok = np.load(entry)["rgb"]
    if data == "float64":
        data = cache_entry_bytes(ok.astype(np.float64), str(np.load(entry)["key"]))
    elif data == "wrong shape":
        data = cache_entry_bytes(ok[:5], str(np.load(entry)["key"]))
    elif data == "foreign":
        data = cache_entry_bytes(ok[::-1], "another image")
    elif data == "npy":
        data = b"\x93NUMPY" + bytes(40)
    entry.write_bytes(data)
    with pytest.warns(UserWarning, match="remaking"):
        assert torch.equal(cache.load(image), expected)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert torch.equal(cache.load(image), expected)  # made again, valid now


# --- TOML ------------------------------------------------------------------------------------
@FUZZ
@given(data=st.one_of(
    st.binary(max_size=200),
    st.dictionaries(st.text(min_size=1, max_size=2000), st.integers(), min_size=1,
                    max_size=50).map(
        lambda d: ("[render]\n" + "".join(f"{json.dumps(k)} = {v}\n" for k, v in d.items())
                   ).encode()),
    st.text(min_size=1, max_size=5000).map(lambda s: f"[{json.dumps(s)}]\n".encode())))
def test_bad_config_files_are_one_short_line(tmp_path, capsys, data):
    config = tmp_path / "c.toml"
    config.write_bytes(data)
    assert_one_line(*run_cli(["preview", "--config", config, "--seed", "0", "--env", "0",
                              "--cameras", "100000", "--out", tmp_path / "p.png"], capsys))
    assert not (tmp_path / "p.png").exists()


# --- arguments -------------------------------------------------------------------------------
@pytest.mark.parametrize("extra", [
    ["--data", "/nonexistent"], ["--device", "bogus"], ["--device", "cuda:99"],
    ["--schedule", "nan:1"], ["--schedule", "inf:1"], ["--weight-decay", "inf"],
    ["--weight-decay", "nan"], ["--time-budget-min", "nan"]])
def test_train_writes_nothing_on_bad_arguments(dataset, tmp_path, capsys, extra):
    argv = ["train", "--task", "component", "--data", dataset, "--out", tmp_path / "t1", *extra]
    assert_one_line(*run_cli(argv, capsys))
    assert not (tmp_path / "t1").exists()


@pytest.mark.parametrize("argv", [
    ["assess", "--oracle", "{data}", "--sensor-mm", "0"],
    ["assess", "--oracle", "{data}", "--sensor-mm", "nan"],
    ["assess", "--oracle", "{data}", "--focal-mm", "-1"],
    ["preview", "--seed", "0", "--env", "0", "--cameras", "100000"],
    ["generate", "--seed", "0", "--engine", "ray", "--address", "not an address"],
    ["generate", "--seed", "0", "--engine", "ray", "--address", "host:99999"]])
def test_unchecked_values_are_one_line_before_any_write(dataset, tmp_path, capsys, argv):
    argv = [a.replace("{data}", str(dataset)) for a in argv] + ["--out", tmp_path / "o"]
    assert_one_line(*run_cli(argv, capsys))
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("size", ["0", "3", "8193", "100000"])
def test_textures_size_is_bounded(tmp_path, capsys, size):
    code, err = run_cli(["textures", "--out", tmp_path / "t", "--size", size], capsys)
    assert_one_line(code, err, names="4 to 8192")
    assert not (tmp_path / "t").exists()


@pytest.mark.parametrize("size", [4, 5, 9, 15])
def test_the_smallest_textures_are_made(tmp_path, size):
    """Every category draws at the smallest sizes allowed (scenes hung at 5-9 px)."""
    assert main(["textures", "--out", str(tmp_path), "--count", "1", "--size", str(size)]) == 0
    assert len(list(tmp_path.glob("*/*.png"))) == 6


def test_a_render_size_beyond_the_gl_is_one_line_with_the_limit():
    from glsynth.core.config import RenderConfig
    from glsynth.core.errors import UserError
    from glsynth.render.gl.renderer import Renderer

    with pytest.raises(UserError, match=r"\[render\] 16000x9000 at msaa = 4"):
        Renderer(RenderConfig(width=16000, height=9000, msaa=4))


def test_a_worker_traceback_stays_out_of_the_line(dataset, tmp_path, capsys):
    """A missing training image read by a DataLoader worker process: one line naming it."""
    image = dataset / frame_paths("train", 0, 3)["image"]
    saved = image.read_bytes()
    image.unlink()
    try:
        code, err = run_cli(["train", "--task", "component", "--data", dataset, "--out",
                             tmp_path / "run", "--image-size", "192x108", "--schedule", "1e-3:1",
                             "--loader-workers", "1", "--val-count", "0"], capsys)
    finally:
        image.write_bytes(saved)
    assert_one_line(code, err, names=str(image))


def test_a_warning_is_one_line(dataset, tmp_path, capsys, monkeypatch):
    """A warning while a command runs (a unit or cache entry redone) is one line."""
    import warnings

    import glsynth.data.statistics as statistics

    counts = statistics.read_image_counts

    def warn_then_count(root):
        warnings.warn("training cache: remaking 'x.npz' (not a zip file)", stacklevel=1)
        return counts(root)

    monkeypatch.setattr(statistics, "read_image_counts", warn_then_count)
    assert run_cli(["stats", dataset, "--out", tmp_path], capsys) == (
        0, "glsynth stats: warning: training cache: remaking 'x.npz' (not a zip file)\n")


def test_a_data_loader_workers_error_is_its_own_message():
    from torch._utils import ExceptionWrapper

    from glsynth.cli import one_line
    from glsynth.core.errors import UserError

    try:
        raise UserError("'x.png' does not exist; check the path")
    except UserError:
        wrapped = ExceptionWrapper(where="in DataLoader worker process 0")
    with pytest.raises(UserError) as caught:
        wrapped.reraise()
    assert "Traceback" in str(caught.value)
    assert one_line(caught.value) == "'x.png' does not exist; check the path"


# --- photos ----------------------------------------------------------------------------------
def _photo_kinds(rgb: np.ndarray) -> dict[str, tuple[bytes, np.ndarray]]:
    """Each kind's file bytes and the 8-bit RGB read_photo promises for it."""
    import io

    def save(im: Image.Image, format: str = "PNG", **kw) -> bytes:
        buffer = io.BytesIO()
        im.save(buffer, format=format, **kw)
        return buffer.getvalue()

    gray = rgb[..., 0]
    gray16 = gray.astype(np.uint16) * 257 + 100
    import cv2

    rgb16 = rgb.astype(np.uint16) * 257 + 100
    ok, rgb16_png = cv2.imencode(".png", cv2.cvtColor(rgb16, cv2.COLOR_RGB2BGR))
    unit = (gray.astype(np.float32) / 255)
    rgba = np.dstack([rgb, np.full(gray.shape, 7, np.uint8)])
    palette = Image.fromarray(rgb).quantize(64)
    exif = Image.Exif()
    exif[0x0112] = 6  # rotate 90 degrees clockwise to view
    rep = np.repeat
    return {
        "rgb8": (save(Image.fromarray(rgb)), rgb),
        "gray8": (save(Image.fromarray(gray)), rep(gray[..., None], 3, 2)),
        "gray16": (save(Image.fromarray(gray16)), rep(
            ((gray16.astype(np.uint32) * 2 + 257) // 514).astype(np.uint8)[..., None], 3, 2)),
        "rgb16": (rgb16_png.tobytes(), ((rgb16.astype(np.uint32) * 2 + 257) // 514
                                        ).astype(np.uint8)),
        "rgba": (save(Image.fromarray(rgba)), rgb),
        "palette": (save(palette), np.asarray(palette.convert("RGB"))),
        "float": (save(Image.fromarray(unit), "TIFF"), rep(
            np.round(unit * 255).astype(np.uint8)[..., None], 3, 2)),
        "exif": (save(Image.fromarray(rgb), "PNG", exif=exif), np.rot90(rgb, -1)),
    }


def test_every_photo_kind_is_predicted_as_its_stated_conversion(runs, tmp_path, capsys):
    from glsynth.core.images import read_photo

    rgb = make_rng(1, 0, Stream.PLATES, 0).integers(0, 256, (40, 64, 3), np.uint8)
    rgb[:, :32] //= 3  # structure the network sees
    for name, (data, expected) in _photo_kinds(rgb).items():
        path = tmp_path / "in" / f"{name}.img"
        path.parent.mkdir(exist_ok=True)
        path.write_bytes(data)
        np.testing.assert_array_equal(read_photo(path), expected, err_msg=name)
        reference = tmp_path / "ref" / f"{name}.png"
        reference.parent.mkdir(exist_ok=True)
        Image.fromarray(expected).save(reference)
        for src, out in ((path, tmp_path / "out"), (reference, tmp_path / "refout")):
            assert run_cli(["predict", "--run", runs["component"], src, "--out", out],
                           capsys)[0] == 0, name
        got = np.asarray(Image.open(tmp_path / "out" / f"{name}_component_overlay.png"))
        want = np.asarray(Image.open(tmp_path / "refout" / f"{name}_component_overlay.png"))
        assert got.shape == (*expected.shape[:2], 3), name  # portrait stays portrait
        np.testing.assert_array_equal(got, want, err_msg=name)


@pytest.mark.parametrize("kind", ["cmyk", "int32", "float_out_of_range", "garbage", "bomb"])
def test_photo_kinds_glsynth_refuses_are_one_line(runs, tmp_path, capsys, kind):
    path = tmp_path / "photo.img"
    if kind == "cmyk":
        Image.new("CMYK", (8, 8)).save(path, format="JPEG")
    elif kind == "int32":
        Image.fromarray(np.ones((8, 8), np.int32)).save(path, format="TIFF")
    elif kind == "float_out_of_range":
        Image.fromarray(np.full((8, 8), 2.5, np.float32)).save(path, format="TIFF")
    elif kind == "garbage":
        path.write_bytes(b"\x89PNG\r\n\x1a\n garbage")
    else:
        path.write_bytes(bomb_png(40000, 40000))
    for argv in (["predict", "--run", runs["component"], path, "--out", tmp_path / "o"],):
        assert_one_line(*run_cli(argv, capsys), names=str(path))
    assert not (tmp_path / "o").exists()


def test_photos_with_one_file_name_keep_their_own_outputs(dataset, runs, tmp_path, capsys):
    photos = []
    for folder, camera in (("a", 0), ("b", 1), ("c", 2)):
        photo = tmp_path / folder / "ok.png"
        photo.parent.mkdir()
        shutil.copy(dataset / frame_paths("train", 0, camera)["image"], photo)
        photos.append(photo)
    single = tmp_path / "ok_1.png"  # an input whose stem is a renamed one's
    shutil.copy(photos[0], single)
    assert run_cli(["predict", "--run", runs["component"], *photos, single, "--out",
                    tmp_path / "out"], capsys)[0] == 0
    written = sorted(p.name for p in (tmp_path / "out").glob("*_overlay.png"))
    assert len(written) == 4, written
    for stem, photo in zip(("ok_0", "ok_5", "ok_2"), photos):  # ok_1 is the single's stem
        alone = tmp_path / f"alone_{stem}"
        assert run_cli(["predict", "--run", runs["component"], photo, "--out", alone],
                       capsys)[0] == 0
        assert (tmp_path / "out" / f"{stem}_component.png").read_bytes() == \
            (alone / "ok_component.png").read_bytes()


# --- as the user runs it ---------------------------------------------------------------------
@pytest.mark.parametrize("case", ["label", "manifest", "train"])
def test_subprocess_errors_are_one_line(dataset, tmp_path, case):
    label = dataset / frame_paths("test", 1, 1)["component"]
    manifest = dataset / "files_test.csv"
    argv = {"label": ["stats", dataset, "--out", tmp_path / "s"],
            "manifest": ["stats", dataset, "--out", tmp_path / "s"],
            "train": ["train", "--task", "component", "--data", "/nonexistent", "--out",
                      tmp_path / "t1"]}[case]
    target = {"label": (label, png(np.ones((*MAPS[::-1], 3), np.uint8))),
              "manifest": (manifest, b"\xff" * 70_000), "train": None}[case]
    command = [sys.executable, "-m", "glsynth", *map(str, argv)]
    if target is None:
        done = subprocess.run(command, capture_output=True, text=True)
    else:
        with Corrupted(*target):
            done = subprocess.run(command, capture_output=True, text=True)
    assert_one_line(done.returncode, done.stderr)
    assert not (tmp_path / "t1").exists()
