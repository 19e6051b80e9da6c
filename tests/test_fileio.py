"""File output: the PNG encoder's round trip, the background writer's ordering, bound and
failures, and a rendered view's files (write_render)."""

import io
import threading
import time
import zlib
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from glsynth.core import fileio
from glsynth.core.errors import UserError
from glsynth.core.fileio import BackgroundWriter, image_bytes
from glsynth.render import view as render_view
from glsynth.render.gl.renderer import RenderOutput
from glsynth.render.view import write_render
from glsynth.world.cameras import Camera


@pytest.mark.parametrize("shape, dtype", [((7, 5, 3), np.uint8), ((7, 5), np.uint8),
                                          ((7, 5), np.uint16)])
def test_png_decodes_to_the_same_array_in_rgb_order(shape, dtype):
    top = int(np.iinfo(dtype).max)
    array = ((np.arange(np.prod(shape)) * 7919) % (top + 1)).astype(dtype).reshape(shape)
    array.flat[0] = top  # the extremes: white and black
    array.flat[-1] = 0
    decoded = np.asarray(Image.open(io.BytesIO(image_bytes(array, "PNG"))))
    assert decoded.dtype == dtype and np.array_equal(decoded, array)


def test_bmp_stays_an_8_bit_image():
    ids = np.array([[1, 2], [3, 4]], np.uint8)
    image = Image.open(io.BytesIO(image_bytes(ids, "BMP")))
    assert image.format == "BMP" and np.array_equal(np.asarray(image), ids)


def test_jobs_run_in_order_and_leaving_waits_for_all():
    done = []
    with BackgroundWriter(pending=3) as writer:
        for i in range(6):
            writer.submit(lambda k: (time.sleep(0.01), done.append(k)), i)
    assert done == list(range(6))


def test_at_most_pending_jobs_wait():
    release, waiting = threading.Event(), []
    with BackgroundWriter(pending=2) as writer:
        writer.submit(release.wait)
        writer.submit(lambda: None)
        blocked = threading.Thread(target=writer.submit, args=(lambda: None,))
        blocked.start()
        blocked.join(0.3)
        waiting.append(blocked.is_alive())  # a third job waits for the first to finish
        release.set()
        blocked.join(5)
    assert waiting == [True] and not blocked.is_alive()


def test_a_failed_write_is_raised_by_the_next_submit_and_stops_later_ones():
    done = []

    def fail() -> None:
        raise UserError("cannot write 'x.png': No space left on device")

    with pytest.raises(UserError, match="x.png"):
        with BackgroundWriter() as writer:
            writer.submit(fail)
            time.sleep(0.2)
            writer.submit(done.append, 1)
    assert done == []


def test_a_failed_write_is_raised_on_leaving():
    def fail() -> None:
        raise UserError("cannot write 'y.png'")

    with pytest.raises(UserError, match="y.png"):
        with BackgroundWriter() as writer:
            writer.submit(fail)


def test_an_error_in_the_block_wins_and_the_jobs_still_finish():
    done = []
    with pytest.raises(KeyError):
        with BackgroundWriter() as writer:
            writer.submit(lambda: (time.sleep(0.1), done.append(1)))
            raise KeyError("render failed")
    assert done == [1]


def test_pending_must_be_positive():
    with pytest.raises(ValueError, match="pending = 0"):
        BackgroundWriter(pending=0)


def test_png_rows_use_the_up_filter():
    """Every row of a PNG carries filter type 2 (Up): image_bytes asks for that one filter
    rather than the best of five per row (half the CPU; docs/results.md)."""
    array = ((np.arange(37 * 23 * 3) * 7919) % 256).astype(np.uint8).reshape(37, 23, 3)
    data = image_bytes(array, "PNG")
    chunks, at = b"", 8
    while at < len(data):
        length = int.from_bytes(data[at:at + 4], "big")
        if data[at + 4:at + 8] == b"IDAT":
            chunks += data[at + 8:at + 8 + length]
        at += 12 + length
    rows = zlib.decompress(chunks)
    stride = 1 + 23 * 3
    assert len(rows) == 37 * stride and set(rows[::stride]) == {2}


def _small_render() -> tuple[Camera, RenderOutput]:
    """A free camera and an 8 x 6 view of every pass."""
    output = RenderOutput(color=(np.arange(144) * 7919 % 256).astype(np.uint8).reshape(6, 8, 3),
                          component=np.full((6, 8), 2, np.uint8),
                          damage=np.zeros((6, 8), np.uint8),
                          depth=np.full((6, 8), 3.5, np.float32),
                          crack_width=np.zeros((6, 8), np.float32))
    return Camera(8, 6, 35.0, 36.0, np.eye(4), 0.05, 100.0), output


def test_a_view_is_written_whole_with_its_colour_from_a_second_thread(tmp_path, monkeypatch):
    writers: dict[str, str] = {}
    original = fileio.atomic_write_bytes

    def recording(path: Path, data: bytes) -> None:
        writers[Path(path).name] = threading.current_thread().name
        original(path, data)

    monkeypatch.setattr(render_view, "atomic_write_bytes", recording)
    monkeypatch.setattr(fileio, "atomic_write_bytes", recording)  # the background writer's
    camera, output = _small_render()
    write_render(tmp_path / "view", camera, output, {"root_seed": 1})
    main = threading.current_thread().name
    assert writers.pop("image.png") != main
    assert set(writers.values()) == {main}  # the labels and depth, here
    names = sorted(p.name for p in (tmp_path / "view").iterdir())
    assert names == ["camera.json", "component.png", "crack_width.npy", "damage.png",
                     "depth.npy", "image.png"]
    assert np.array_equal(np.asarray(Image.open(tmp_path / "view" / "image.png")), output.color)


def test_a_failed_colour_write_is_raised_and_no_camera_json_follows(tmp_path):
    """The colour's PNG is written on a second thread: its failure still stops the view
    before camera.json, the last file, is written."""
    camera, output = _small_render()
    (tmp_path / "view" / "image.png").mkdir(parents=True)  # a folder where the file goes
    with pytest.raises(UserError, match="image.png"):
        write_render(tmp_path / "view", camera, output, {"root_seed": 1})
    assert not (tmp_path / "view" / "camera.json").exists()
    assert (tmp_path / "view" / "depth.npy").exists()  # the other files were written whole
