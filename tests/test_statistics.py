"""glsynth stats: a dataset's statistics beside the paper's, from files or from the generator."""

import json

import numpy as np
import pytest
from PIL import Image

from glsynth.cli import main
from glsynth.data.statistics import dataset_statistics, read_image_counts, read_removals
from glsynth.data.tokaido import DEPTH_MAX_CODE


def write_dataset(root):
    """Two views and one plate, every pixel chosen by hand (360 x 640 maps of black 1920 x 1080
    images: maps are a third of their image)."""
    comp_a = np.full((360, 640), 1, np.uint8)
    comp_a[:180] = 6  # rail: 115,200 px
    comp_a[180:, :320] = 7  # sleeper: 57,600 px; nonbridge the other 57,600
    dmg_a = np.full((360, 640), 1, np.uint8)
    dmg_a[:10, :10] = 2  # 100 concrete
    dmg_a[10:12, :10] = 3  # 20 rebar
    comp_b = np.full((360, 640), 4, np.uint8)  # column only (a close-up)
    dmg_b = np.zeros((360, 640), np.uint8)  # unlabelled: damage outside the RRDR
    plate = np.full((360, 640), 2, np.uint8)
    plate[:, 320:] = 1  # half concrete damage
    depth_a = np.full((360, 640), DEPTH_MAX_CODE, np.uint16)  # sky ...
    depth_a[180:] = 0  # ... and 0.5 m
    depth_b = np.full((360, 640), 2222, np.uint16)  # 0.5 + 29.5 * 2222 / 65535 = 1.5 m
    files = {"img_syn_raw/train/image_case0_frame0_Scene.png": np.zeros((1080, 1920, 3), np.uint8),
             "img_syn_raw/test/image_case1_frame7_Scene.png": np.zeros((1080, 1920, 3), np.uint8),
             "synthetic/train/labcmp/image_case0_frame0.bmp": comp_a,
             "synthetic/train/labdmg/image_case0_frame0.bmp": dmg_a,
             "synthetic/train/depth/image_case0_frame0.png": depth_a,
             "synthetic/test/labcmp/image_case1_frame7.bmp": comp_b,
             "synthetic/test/labdmg/image_case1_frame7.bmp": dmg_b,
             "synthetic/test/depth/image_case1_frame7.png": depth_b,
             "images_puretex/image_0.png": np.zeros((1080, 1920, 3), np.uint8),
             "synthetic_puretex/labdmg/image_0.bmp": plate}
    for rel, array in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        Image.fromarray(array).save(root / rel)
    a = "img_syn_raw/train/image_case0_frame0_Scene.png"
    b = "img_syn_raw/test/image_case1_frame7_Scene.png"
    (root / "files_train.csv").write_text(
        f"{a},synthetic/train/labcmp/image_case0_frame0.bmp,synthetic/train/labdmg/"
        "image_case0_frame0.bmp,synthetic/train/depth/image_case0_frame0.png,20.0,True,True\n")
    (root / "files_test.csv").write_text(
        f"{b},synthetic/test/labcmp/image_case1_frame7.bmp,synthetic/test/labdmg/"
        "image_case1_frame7.bmp,synthetic/test/depth/image_case1_frame7.png,52.5,False,False\n")
    (root / "files_puretex_train.csv").write_text(
        "images_puretex/image_0.png,synthetic_puretex/labdmg/image_0.bmp\n")
    (root / "files_puretex_test.csv").write_text("")


def test_stats_of_a_hand_built_dataset_are_the_counts_built_in(tmp_path, capsys):
    write_dataset(tmp_path / "ds")
    assert main(["stats", str(tmp_path / "ds"), "--out", str(tmp_path / "s")]) == 0
    stats = json.loads((tmp_path / "s" / "stats.json").read_text())
    n = 360 * 640
    assert stats["images"] == {"regular": 1, "closeup": 1, "plate": 1}
    assert "keep_rate" not in stats  # no progress markers: released-layout rows only
    assert stats["views_showing"]["rail"] == 0.5 and stats["views_showing"]["sleeper"] == 0.5
    assert stats["views_showing"]["column"] == 0.5 and stats["views_showing"]["slab"] == 0.0
    assert stats["views_showing_by_kind"]["regular"]["rail"] == 1.0
    assert stats["views_showing_by_kind"]["closeup"]["rail"] == 0.0
    assert stats["views_showing_by_kind"]["closeup"]["column"] == 1.0
    assert stats["component_pixel_share"]["rail"] == pytest.approx(115_200 / (2 * n))
    assert stats["component_pixel_share"]["column"] == pytest.approx(0.5)
    # Damage task: view a (flagged) and the plate; view b is not flagged.
    labelled = n + n
    assert stats["damage_share"]["concrete"] == pytest.approx((100 + n / 2) / labelled)
    assert stats["damage_share"]["rebar"] == pytest.approx(20 / labelled)
    assert stats["damage_images"] == {"frames": 1, "plates": 1, "total": 2}
    depth = stats["depth_histogram"]
    assert depth["sky_pixels"] == n // 2 and depth["pixels"][0] == n // 2 + n
    assert sum(depth["pixels"]) == n // 2 + n
    assert stats["focal_histogram"]["images"] == [0, 1, 0, 0, 0, 0, 0, 1]
    table = capsys.readouterr().out
    assert "| keep rate: regular | 86.5 % | no metadata |" in table
    assert "| views showing rail (all / regular / close-up) | not given | 50.0 % / 100.0 % / " \
           "0.0 % |" in table
    assert (tmp_path / "s" / "stats.png").stat().st_size > 10_000


def test_removals_by_kind_come_from_the_run_markers(tmp_path):
    (tmp_path / "progress").mkdir()
    for env, removed in ((0, {"regular": {"dark": 1}, "closeup": {"too_close": 2}}),
                         (1, {"regular": {"dark": 2, "single_component": 1}, "closeup": {}})):
        (tmp_path / "progress" / f"env_{env:06d}.json").write_text(
            json.dumps({"removed": removed}))
    removals = read_removals(tmp_path)
    assert removals == {"regular": {"dark": 3, "single_component": 1},
                        "closeup": {"too_close": 2}}
    older = tmp_path / "older"
    (older / "progress").mkdir(parents=True)
    (older / "progress" / "env_000000.json").write_text(json.dumps({"removed": {"dark": 1}}))
    assert read_removals(older) is None  # no camera kind recorded: no keep rates
    write_dataset(tmp_path)
    stats = dataset_statistics(read_image_counts(tmp_path), removals)
    assert stats["keep_rate"] == {"regular": 1 / 5, "closeup": 1 / 3}


def test_the_generate_report_and_glsynth_stats_agree(tiny_dataset):
    """The report's statistics come from the maps as written; glsynth stats reads them back."""
    report = json.loads((tiny_dataset / "report.json").read_text())["statistics"]
    again = dataset_statistics(read_image_counts(tiny_dataset), read_removals(tiny_dataset))
    assert json.loads(json.dumps(again)) == report
