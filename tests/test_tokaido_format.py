import re

import numpy as np
import pytest

from glsynth.core.config import RenderConfig
from glsynth.core.filters import mask_damage, pixels_per_cm, removal_reason, rrdr
from glsynth.core.labels import Damage
from glsynth.data.tokaido import (
    IMAGE_SIZE,
    LABEL_STRIDE,
    FrameRecord,
    PuretexRecord,
    decode_depth,
    downsample_labels,
    encode_depth,
    frame_paths,
    manifest_text,
    read_manifest,
)


def test_the_default_render_size_is_the_tokaido_image_size():
    # core/ cannot import the data layer's constant, so the config's default restates it:
    # this keeps the two from drifting apart.
    assert (RenderConfig().width, RenderConfig().height) == IMAGE_SIZE
    assert [side // LABEL_STRIDE for side in IMAGE_SIZE] == [640, 360]


def test_paths_match_the_released_layout_and_loader_conventions():
    p = frame_paths("train", 12, 7)
    assert p["image"] == "img_syn_raw/train/image_case12_frame7_Scene.png"
    assert p["component"] == "synthetic/train/labcmp/image_case12_frame7.bmp"
    # The entrants' loaders: environment from the name, label by replacing _Scene.png.
    name = p["image"].split("/")[-1]
    assert int(re.sub("[^0-9]", "", name.split("_")[1])) == 12
    assert name.replace("_Scene.png", ".bmp") == p["damage"].split("/")[-1]
    assert name.replace("_Scene.png", ".png") == p["depth"].split("/")[-1]
    with pytest.raises(ValueError, match="split"):
        frame_paths("val", 0, 0)


def test_depth_encoding_round_trip_and_clipping():
    depth = np.array([0.0, 0.5, 0.50001, 5.0, 29.9999, 30.0, 100.0, 2000.0, np.nan])
    code = encode_depth(depth)
    assert code.dtype == np.uint16
    assert list(code[[0, 1, 5, 6, 7, 8]]) == [0, 0, 65535, 65535, 65535, 65535]
    inside = (depth >= 0.5) & (depth <= 30.0)
    err = np.abs(decode_depth(code)[inside] - depth[inside])
    assert err.max() <= 29.5 / 65535 / 2 + 1e-6  # half a code step
    assert decode_depth(np.array([0, 65535])).tolist() == [0.5, 30.0]


def test_label_downsampling_is_nearest_at_block_centres():
    labels = np.arange(1080 * 1920, dtype=np.int64).reshape(1080, 1920) % 9
    small = downsample_labels(labels.astype(np.uint8))
    assert small.shape == (360, 640)
    assert np.array_equal(small, labels[1::3, 1::3])
    with pytest.raises(ValueError, match="multiples of 3"):
        downsample_labels(np.zeros((10, 10), np.uint8))


def listed(split: str, env: int, camera: int) -> list[str]:
    """The four paths of a frame that its manifest row lists (not its crack-width map)."""
    paths = frame_paths(split, env, camera)
    return [paths[k] for k in ("image", "component", "damage", "depth")]


def test_manifest_round_trip_with_backslashes(tmp_path):
    rows = [FrameRecord(*listed("test", 180, 3), 27.5, True, False),
            FrameRecord(*listed("test", 181, 60), None, False, True)]
    (tmp_path / "files_test.csv").write_text(manifest_text(rows))
    assert read_manifest(tmp_path, "files_test.csv") == rows
    text = manifest_text(rows).replace("/", "\\")
    (tmp_path / "files_train.csv").write_text(text)
    assert read_manifest(tmp_path, "files_train.csv") == rows
    pure = [PuretexRecord("images_puretex/image_3.png", "synthetic_puretex/labdmg/image_3.bmp")]
    (tmp_path / "files_puretex_train.csv").write_text(manifest_text(pure))
    assert read_manifest(tmp_path, "files_puretex_train.csv") == pure
    first = (tmp_path / "files_test.csv").read_text().splitlines()[0].split(",")
    assert len(first) == 7 and first[5:] == ["True", "False"]  # no header row


@pytest.mark.parametrize("line, message", [
    ("../../etc/passwd,b,c,d,1,True,True", "escapes the dataset root"),
    ("/etc/passwd,b,c,d,1,True,True", "must be relative"),
    ("C:\\x.png,b,c,d,1,True,True", "must be relative"),
    ("a,b,c,d,1,yes,True", "flag 'yes' must be 'True' or 'False'"),
    ("a,b,c", "3 columns"),
])
def test_bad_manifests_are_rejected(tmp_path, line, message):
    (tmp_path / "files_train.csv").write_text(line + "\n")
    with pytest.raises(ValueError, match=message):
        read_manifest(tmp_path, "files_train.csv")


def test_missing_manifest(tmp_path):
    with pytest.raises(ValueError, match="does not exist"):
        read_manifest(tmp_path, "files_train.csv")


def test_each_filter_trips_on_a_case_built_for_it():
    h, w = 6, 8
    bright = np.full((h, w, 3), 120, np.uint8)
    two = np.ones((h, w), np.uint8)
    two[:, :4] = 4
    far = np.full((h, w), 10.0, np.float32)
    assert removal_reason(bright, two, far) is None
    assert removal_reason(np.full((h, w, 3), 29, np.uint8), two, far) == "dark"
    assert removal_reason(np.full((h, w, 3), 30, np.uint8), two, far) is None
    assert removal_reason(bright, np.full((h, w), 4, np.uint8), far) == "single_component"
    close = far.copy()
    close[2, 3] = 0.5  # "not larger than 50 cm"
    assert removal_reason(bright, two, close) == "too_close"
    close[2, 3] = 0.5001
    assert removal_reason(bright, two, close) is None


def test_rrdr_maths_at_the_extremes():
    f_px = 55.0 / 36.0 * 1920  # 2933 px
    depth = np.array([0.0, -1.0, np.inf, np.nan, 1e-9, 0.5, 19.5, 19.6, 1e6])
    ppc = pixels_per_cm(depth, f_px)
    assert np.all(np.isfinite(ppc)) and ppc[0] == ppc[1] == ppc[2] == ppc[3] == 0.0
    limit = f_px / 150.0  # 1.5 px/cm
    reliable = rrdr(depth, f_px)
    assert reliable.tolist() == [False, False, False, False, True, True, 19.5 <= limit,
                                 19.6 <= limit, False]
    assert rrdr(np.array([limit]), f_px)[0]
    unknown = rrdr(depth, None)
    assert unknown.tolist() == [False, False, False, False, False, True, True, True, False]
    with pytest.raises(ValueError, match="focal_px"):
        rrdr(depth, 0.0)


def test_damage_outside_the_rrdr_becomes_unlabelled():
    damage = np.array([[1, 2, 3], [2, 1, 3]], np.uint8)
    reliable = np.array([[True, False, True], [False, False, False]])
    assert mask_damage(damage, reliable).tolist() == [[1, 0, 3], [0, 1, 0]]
    assert mask_damage(damage, np.zeros_like(reliable)).tolist() == [[1, 0, 0], [0, 1, 0]]
    clean = mask_damage(np.ones((2, 3), np.uint8), np.ones_like(reliable))
    assert np.all(clean == Damage.NO_DAMAGE)
    with pytest.raises(ValueError, match="differ in size"):
        mask_damage(damage, reliable[:, :2])
