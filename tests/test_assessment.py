"""Condition assessment (paper Section 4.7): constructed maps with exact expected masks, areas
and counts; per-image failures; the CLI in oracle mode and with trained networks."""

import json

import numpy as np
import pytest

from glsynth.assess.condition import (
    AssessSettings,
    Maps,
    Photo,
    assess,
    assess_photos,
    assessment_picture,
)
from glsynth.cli import main


def constructed(depth_column: float = 2.0, focal_px: float | None = 600.0) -> Maps:
    """30x40 maps: left half a column (id 4), right half nonbridge above and slab below.
    Column rows 0-14 at depth_column, rows 15-29 at 50 m; slab at 3 m, nonbridge at 30 m.
    Damage: concrete on column rows 0-9 x cols 0-9 and rows 20-24 (far), rebar rows 0-4 x
    cols 10-14; concrete on nonbridge rows 0-4 x cols 30-34 and on slab rows 20-21 x 30-39."""
    component = np.full((30, 40), 1, np.uint8)
    component[:, :20] = 4
    component[15:, 20:] = 2
    depth = np.full((30, 40), 30.0, np.float32)
    depth[:15, :20] = depth_column
    depth[15:, :20] = 50.0
    depth[15:, 20:] = 3.0
    damage = np.ones((30, 40), np.uint8)
    damage[:10, :10] = 2
    damage[20:25, :10] = 2
    damage[:5, 10:15] = 3
    damage[:5, 30:35] = 2
    damage[20:22, 30:40] = 2
    return Maps(component, damage, depth, focal_px)


def test_known_focal_keeps_near_damage_on_bridge_components_exactly():
    maps = constructed()
    result = assess(maps)
    # 600 px / (100 * 2 m) = 3 px/cm and 600 / 300 = 2 px/cm pass; 50 m and 30 m do not.
    expected_reliable = np.zeros((30, 40), bool)
    expected_reliable[:15, :20] = True
    expected_reliable[15:, 20:] = True
    assert np.array_equal(result.reliable, expected_reliable)
    expected = np.zeros((30, 40), np.uint8)
    expected[:15, :20] = maps.damage[:15, :20]
    expected[15:, 20:] = maps.damage[15:, 20:]
    assert np.array_equal(result.damage, expected)
    column, slab = result.components["column"], result.components["slab"]
    assert column["pixels"] == 600 and column["pixels_in_rrdr"] == 300
    assert column["damaged_pixels"] == {"concrete": 100, "rebar": 25}
    assert column["damaged_fraction"] == {"concrete": 100 / 300, "rebar": 25 / 300}
    assert column["damaged_area_m2"]["concrete"] == pytest.approx(100 * (2 / 600) ** 2)
    assert column["area_m2_in_rrdr"] == pytest.approx(300 * (2 / 600) ** 2)
    assert slab["damaged_pixels"] == {"concrete": 20, "rebar": 0}
    assert slab["damaged_area_m2"]["concrete"] == pytest.approx(20 * (3 / 600) ** 2)
    assert "nonbridge" not in result.components
    # Far column damage (50 rows) and nonbridge damage (25) are dropped.
    assert result.totals["damage_outside_rrdr_or_bridge_pixels"] == 50 + 25


def test_unknown_focal_uses_the_depth_range():
    result = assess(constructed(depth_column=0.3, focal_px=None))
    assert not result.reliable[:15, :20].any()  # 0.3 m is nearer than 0.5 m
    assert result.reliable[15:, 20:].all()  # slab at 3 m
    assert not result.reliable[15:, :20].any()  # 50 m
    assert result.components["column"]["damaged_area_m2"] is None
    assert result.components["column"]["damaged_fraction"]["concrete"] is None
    assert result.components["slab"]["damaged_pixels"]["concrete"] == 20


@pytest.mark.parametrize("focal", [600.0, None])
def test_zero_and_non_finite_depth_are_never_reliable(focal):
    maps = constructed(focal_px=focal)
    depth = np.zeros_like(maps.depth_m)
    depth[0, 0], depth[0, 1] = np.nan, np.inf
    result = assess(Maps(maps.component, maps.damage, depth, focal))
    assert not result.reliable.any() and result.totals["assessed_pixels"] == 0
    for entry in result.components.values():
        assert entry["damaged_pixels"] == {"concrete": 0, "rebar": 0}
        if focal is not None:
            assert entry["area_m2_in_rrdr"] == 0.0


def test_no_bridge_pixels_and_all_damage_outside_the_rrdr():
    maps = constructed()
    nonbridge = Maps(np.ones_like(maps.component), maps.damage, maps.depth_m, 600.0)
    result = assess(nonbridge)
    assert result.components == {} and result.totals["assessed_pixels"] == 0
    far = Maps(maps.component, maps.damage, np.full_like(maps.depth_m, 100.0), 600.0)
    result = assess(far)
    assert result.totals["damaged_pixels"] == {"concrete": 0, "rebar": 0}
    assert result.totals["damage_outside_rrdr_or_bridge_pixels"] == int((maps.damage >= 2).sum())


def test_settings_and_sizes_are_checked():
    with pytest.raises(ValueError, match="--min-px-per-cm 0"):
        AssessSettings(min_px_per_cm=0)
    with pytest.raises(ValueError, match="NEAR < FAR"):
        AssessSettings(depth_range_m=(20, 0.5))
    maps = constructed()
    with pytest.raises(ValueError, match="of one size"):
        Maps(maps.component, maps.damage[:-1], maps.depth_m, None)


def test_picture_greys_out_far_and_nonbridge_regions():
    maps = constructed()
    rgb = np.full((30, 40, 3), 200, np.uint8)
    picture = assessment_picture(rgb, maps.component, assess(maps))
    grey = round(200 * 0.45 + 90)
    assert (picture[15:, :20] == grey).all() and (picture[:15, 20:] == grey).all()
    assert tuple(picture[0, 0]) != (grey,) * 3 and picture[0, 0, 0] > picture[0, 0, 2]


def test_a_batch_goes_on_past_bad_images_and_handles_different_sizes(tmp_path):
    def good(shape):
        def load():
            maps = constructed()
            return np.zeros((*shape, 3), np.uint8), maps
        return load

    def mismatched():
        maps = constructed()
        return np.zeros((90, 120, 3), np.uint8), Maps(maps.component, maps.damage[:, :-1],
                                                      maps.depth_m, None)

    def corrupt():
        from glsynth.core.images import read_photo

        path = tmp_path / "corrupt.png"
        path.write_bytes(b"not a png")
        return read_photo(path), constructed()

    photos = [Photo("a", good((90, 120))), Photo("bad", mismatched), Photo("b", good((61, 77))),
              Photo("corrupt", corrupt)]
    summary = assess_photos(photos, tmp_path / "out", AssessSettings())
    assert summary["assessed"] == ["a", "b"]
    assert [f["image"] for f in summary["failed"]] == ["bad", "corrupt"]
    assert "of one size" in summary["failed"][0]["error"]
    assert "not a readable image" in summary["failed"][1]["error"]
    report = json.loads((tmp_path / "out" / "b.json").read_text())
    assert report["components"]["column"]["damaged_pixels"] == {"concrete": 100, "rebar": 25}
    from PIL import Image

    assert Image.open(tmp_path / "out" / "b_assessment.png").size == (77, 61)
    assert summary["components"]["column"]["damaged_pixels"]["concrete"] == 200


def test_oracle_cli_on_generated_data(tiny_dataset, tmp_path):
    from PIL import Image

    from glsynth.data.tokaido import read_manifest

    out = tmp_path / "oracle"
    assert main(["assess", "--oracle", str(tiny_dataset), "--out", str(out)]) == 0
    rows = read_manifest(tiny_dataset, "files_test.csv")
    summary = json.loads((out / "summary.json").read_text())
    assert len(summary["assessed"]) == len(rows) and summary["failed"] == []
    pixels = 0
    for row in rows:
        stem = row.image.split("/")[-1].removesuffix("_Scene.png")
        report = json.loads((out / f"{stem}.json").read_text())
        truth = np.asarray(Image.open(tiny_dataset / row.damage))
        comp = np.asarray(Image.open(tiny_dataset / row.component))
        kept = sum(sum(e["damaged_pixels"].values()) for e in report["components"].values())
        on_bridge = int(((truth >= 2) & (comp >= 2)).sum())
        # Ground-truth labels are already RRDR-masked at full size; the oracle's RRDR from the
        # decoded 640x360 depth can differ only on the 1.5 px/cm boundary.
        assert kept <= on_bridge and kept >= 0.98 * on_bridge
        assert Image.open(out / f"{stem}_assessment.png").size == (1920, 1080)
        # The demo preset's cracks come from mechanics, with crack-width maps: wherever a
        # measured skeleton pixel has a true width, the error against it is reported.
        truth = report["cracks"]["truth"]
        assert report["cracks"]["measured"]
        compared = truth["all"]["pixels"]
        pixels += compared
        if compared:
            assert np.isfinite(truth["all"]["median_abs_error_mm"])
        assert Image.open(out / f"{stem}_cracks.png").size == (1920, 1080)
    assert summary["cracks"]["truth"]["all"]["pixels"] == pixels


# --- with trained networks -------------------------------------------------------------------
@pytest.fixture(scope="module")
def runs(tiny_run):
    """The networks test_model trains too (conftest's tiny_run): component for two epochs,
    damage and depth for one, all at 192x108."""
    return ",".join(f"{t}={tiny_run(t)}" for t in ("component", "damage", "depth"))


def test_assess_cli_with_networks(tiny_dataset, runs, tmp_path, capsys):
    from glsynth.data.tokaido import read_manifest

    image = tiny_dataset / read_manifest(tiny_dataset, "files_test.csv")[0].image
    corrupt = tmp_path / "corrupt.jpg"
    corrupt.write_bytes(b"\xff\xd8 broken")
    out = tmp_path / "photos"
    assert main(["assess", "--runs", runs, str(image), str(corrupt), "--focal-mm", "24",
                 "--out", str(out)]) == 1
    summary = json.loads((out / "summary.json").read_text())
    assert summary["assessed"] == [image.stem] and summary["failed"][0]["image"] == "corrupt"
    report = json.loads((out / f"{image.stem}.json").read_text())
    assert report["maps_size"] == [64, 36] and report["focal_px"] == pytest.approx(24 / 36 * 1920)
    assert report["cracks"]["measured"] and report["cracks"]["truth"] is None
    capsys.readouterr()
    out = tmp_path / "eval"
    assert main(["assess", "--runs", runs, "--data", str(tiny_dataset), "--out", str(out)]) == 0
    evaluation = json.loads((out / "evaluation" / "rrdr_evaluation.json").read_text())
    assert evaluation["images"] > 0 and "concrete" in evaluation["after"]["per_class"]
    assert (out / "evaluation" / "fig18_iou_vs_pixel_ratio.png").is_file()
    assert "before P/R/IoU" in capsys.readouterr().out


def test_assess_refuses_missing_or_mismatched_runs(runs, tmp_path, capsys):
    assert main(["assess", "--runs", runs.replace("depth=", "depth=/nope/"), "x.png",
                 "--out", str(tmp_path)]) == 2
    assert "has no model.pt" in capsys.readouterr().err
    swapped = runs.replace("component=", "tmp=").replace("damage=", "component=").replace(
        "tmp=", "damage=")
    assert main(["assess", "--runs", swapped, "x.png", "--out", str(tmp_path)]) == 2
    assert "was trained for" in capsys.readouterr().err
    assert main(["assess", "--runs", "component=a", "x.png", "--out", str(tmp_path)]) == 2
    assert "missing damage, depth" in capsys.readouterr().err
