"""A resumed glsynth fly reads its finished frames back like dataset maps: a frame whose files
break their contract (an all-NaN or wrong-shape depth, a damaged image, a camera.json that is
not the plan's, a marker that is a folder) is rendered again with a warning, and the flight
ends with the bytes of an uninterrupted one; finished frames are never rendered again; a
damaged run file is one line. The COLMAP model's observations sit at pixel centres + 0.5.
Twelve frames of 160x90 in an environment of two viaducts (each resume builds it again: with
ten, 3.3 CPU-s a resume); every kind of damage is done to a frame of its own and one resume
mends them all."""

import hashlib
import io
import json
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from glsynth.cli import main
from glsynth.core.errors import MAX_MESSAGE

SMALL = """[render]
width = 160
height = 90
msaa = 0
shadow_map_px = 256
sky_visibility_px = 128
[damage]
resolution = 64
model = "paper"
[materials]
texture_size = 64
builtin_size = 64
[environment]
n_viaducts = 2
cutoff_factor = 1.0
[flight]
max_frames = 12
point_stride_px = 3
"""


def _fly(cfg: Path, out: Path) -> list[str]:
    return ["fly", "--seed", "0", "--env", "0", "--plan", "orbit", "--config", str(cfg),
            "--out", str(out)]


def _digests(out: Path) -> dict[str, str]:
    return {str(p.relative_to(out)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(out.rglob("*")) if p.is_file() and not p.name.startswith(".")}


@pytest.fixture(scope="module")
def whole(tmp_path_factory) -> tuple[Path, Path, dict[str, str]]:
    folder = tmp_path_factory.mktemp("resume")
    cfg = folder / "small.toml"
    cfg.write_text(SMALL)
    out = folder / "whole"
    assert main(_fly(cfg, out)) == 0
    return cfg, out, _digests(out)


def _copy(whole: tuple, tmp_path: Path) -> Path:
    out = tmp_path / "flight"
    shutil.copytree(whole[1], out)
    (out / "flight.json").unlink()  # as a run killed before its exports
    return out


def test_a_resume_renders_only_the_frames_without_a_marker(whole, tmp_path, capsys):
    cfg, _, digests = whole
    out = _copy(whole, tmp_path)
    capsys.readouterr()
    assert main(_fly(cfg, out)) == 0
    assert "(0 rendered now)" in capsys.readouterr().out
    assert _digests(out) == digests
    (out / "flight.json").unlink()
    (out / "progress" / "frame_0001.done").unlink()
    assert main(_fly(cfg, out)) == 0
    assert "(1 rendered now" in capsys.readouterr().out
    assert _digests(out) == digests


def _npy(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, array)
    return buffer.getvalue()


def _depth(value: float, shape: tuple[int, int] = (90, 160)) -> Callable[[Path], None]:
    return lambda folder: (folder / "depth.npy").write_bytes(
        _npy(np.full(shape, value, np.float32)))


def _camera_moved(folder: Path) -> None:
    info = json.loads((folder / "camera.json").read_text())
    info["pose"][0][3] += 1.0
    (folder / "camera.json").write_text(json.dumps(info))


def _marker_folder(folder: Path) -> None:
    marker = folder.parent.parent / "progress" / f"{folder.name}.done"
    marker.unlink()
    marker.mkdir()


DAMAGE: dict[str, Callable[[Path], None]] = {
    "all-NaN depth": _depth(np.nan),
    "infinite depth": _depth(np.inf),
    "depth of another shape": _depth(1.0, (45, 80)),
    "truncated depth": lambda f: (f / "depth.npy").write_bytes(b"\x93NUMPY\x01\x00"),
    "truncated camera.json": lambda f: (f / "camera.json").write_text('{"K": [[1'),
    "deep camera.json": lambda f: (f / "camera.json").write_text("[" * 10000 + "]" * 10000),
    "camera.json of another pose": _camera_moved,
    "truncated image": lambda f: (f / "image.png").write_bytes(
        (f / "image.png").read_bytes()[:200]),
    "image that is a folder": lambda f: ((f / "image.png").unlink(), (f / "image.png").mkdir()),
    "label map of another size": lambda f: (f / "component.png").write_bytes(_small_png()),
    "marker that is a folder": _marker_folder,
}


def _small_png() -> bytes:
    from glsynth.core.fileio import png_bytes

    return png_bytes(np.ones((45, 80), np.uint8))


def test_damaged_frames_are_rendered_again_to_the_same_bytes(whole, tmp_path, capsys):
    """Each kind of DAMAGE done to a frame of its own (frames 1 to 11), then one resume: each
    such frame is rendered again, with a one-line warning naming it, and the others not."""
    cfg, _, digests = whole
    out = _copy(whole, tmp_path)
    damaged = {f"frame_{k:04d}": kind for k, kind in enumerate(DAMAGE, start=1)}
    for frame, kind in damaged.items():
        DAMAGE[kind](out / "frames" / frame)
    capsys.readouterr()
    assert main(_fly(cfg, out)) == 0
    captured = capsys.readouterr()
    assert f"({len(DAMAGE)} rendered now" in captured.out
    warnings = captured.err.strip().splitlines()
    for frame, kind in damaged.items():
        lines = [w for w in warnings if frame in w]
        assert len(lines) == 1 and len(lines[0]) < MAX_MESSAGE, (kind, lines)
    assert len(warnings) == len(DAMAGE) and "Traceback" not in captured.err
    assert _digests(out) == digests


@pytest.mark.parametrize("text", ['{"root_seed": 0', "[" * 10000, '{"root_seed": NaN}'])
def test_a_damaged_run_file_is_one_line(whole, tmp_path, capsys, text):
    cfg = whole[0]
    out = _copy(whole, tmp_path)
    (out / "flight_run.json").write_text(text)
    capsys.readouterr()
    assert main(_fly(cfg, out)) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and len(err) < MAX_MESSAGE, err
    assert "flight run file" in err and "move the folder aside" in err


def test_a_damaged_summary_is_made_again(whole, tmp_path, capsys):
    cfg, _, digests = whole
    out = _copy(whole, tmp_path)
    (out / "flight.json").write_text('{"plan": "orbit", "frames": Infinity}')
    capsys.readouterr()
    assert main(_fly(cfg, out)) == 0
    assert "flight summary" in capsys.readouterr().err
    assert _digests(out) == digests


def test_colmap_observations_sit_at_pixel_centres(whole):
    """images.txt's POINTS2D are where COLMAP's camera model puts each point: the projection
    in glsynth's convention (pixel centres at integers) shifted by +0.5."""
    pycolmap = pytest.importorskip("pycolmap", reason="pycolmap is not installed")
    model = pycolmap.Reconstruction(str(whole[1] / "sparse" / "0"))
    checked = 0
    for image in model.images.values():
        camera = model.cameras[image.camera_id]
        for point in image.points2D:
            if not point.has_point3D():
                continue
            xyz = model.points3D[point.point3D_id].xyz
            uv = camera.img_from_cam(np.array([image.cam_from_world() * xyz]))[0]
            assert np.abs(uv - point.xy).max() < 1e-4, (uv, point.xy)
            checked += 1
    assert checked > 100
