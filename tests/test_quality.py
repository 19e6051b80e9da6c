"""Quality presets and the speed-against-accuracy bench (glsynth bench quality)."""

import json

import numpy as np
import pytest

from glsynth.cli import main
from glsynth.core.config import Config
from glsynth.core.labels import Component
from glsynth.data.quality import QUALITY, apply_quality
from glsynth.data.tokaido import IMAGE_SIZE
from glsynth.measure.quality_bench import colour_scores, label_scores
from glsynth.render.gl.renderer import RenderOutput


def test_colour_and_label_scores_by_hand():
    zfar = 100.0
    color = np.full((8, 12, 3), 100, np.uint8)  # SSIM needs 7x7 windows
    ids = np.ones((8, 12), np.uint8)
    depth = np.full((8, 12), 10.0, np.float32)
    reference = RenderOutput(color, ids, ids, depth)
    same = colour_scores(color, color, ids)
    assert same["psnr_db"] == 99.0 and same["ssim"] == pytest.approx(1.0)
    assert same["ciede2000"] == 0.0
    # No column, slab or beam pixel: those regions have no score.
    assert same["ciede2000_columns"] is None and same["ciede2000_deck_underside"] is None
    brighter = color.copy()
    brighter[0, 0] = 110  # squared error 3 x 100 over 96 pixels x 3 channels
    component = ids.copy()
    component[0, 0] = int(Component.COLUMN)
    scores = colour_scores(brighter, color, component)
    assert scores["psnr_db"] == pytest.approx(10 * np.log10(255**2 / (300 / 288)))
    # Only the changed pixel differs: the column region's error is its error, the mean 1/96 of it.
    assert scores["ciede2000_columns"] > 0
    assert scores["ciede2000"] == pytest.approx(scores["ciede2000_columns"] / 96)
    damage = ids.copy()
    damage[:4, :6] = 2  # 24 of 96 pixels damaged
    component = ids.copy()
    component[7] = 4  # 12 of 96 pixels differ
    far = depth.copy()
    far[:2] = 11.0  # 24 pixels 10 % too far
    far[2:4] = 12.0  # 24 pixels 20 % too far: sorted, the 48th and 49th of 96 are 0 and 0.1
    labels = label_scores(RenderOutput(brighter, component, damage, far), reference, zfar)
    assert labels["component_agreement"] == 0.875 and labels["damage_agreement"] == 0.75
    assert labels["damaged_area_error_pp"] == pytest.approx(25.0)
    assert labels["depth_median_rel_error"] == pytest.approx(0.05)
    half = RenderOutput(color[::2, ::2], ids[::2, ::2], ids[::2, ::2], depth[::2, ::2])
    assert label_scores(half, reference, zfar)["component_agreement"] == 1.0  # nearest


def test_presets_set_every_knob():
    for name, q in QUALITY.items():
        c = apply_quality(Config(), name)
        assert (c.render.width, c.render.height) == tuple(round(side * q.render_scale)
                                                          for side in IMAGE_SIZE)
        assert c.render.msaa == q.msaa and c.materials.texture_size == q.texture_size
        assert c.damage.resolution == q.damage_resolution and c.damage.octaves == q.octaves
        assert c.environment.cylinder_segments == q.cylinder_segments
        assert c.render.shadow_map_px == q.shadow_map_px
        assert (c.render.sky_visibility_maps, c.render.ao) == (q.sky_visibility_maps, q.ao)
    default = apply_quality(Config(), "default")
    assert default == Config()
    with pytest.raises(ValueError, match="choose one of"):
        apply_quality(Config(), "ultra")


@pytest.mark.slow  # a whole benchmark: three presets opened, rendered and ray-cast
def test_bench_quality_on_real_renders(tmp_path, capsys):
    config = tmp_path / "c.toml"
    # The paper's damage: the ray cast has no cracks (their labels are checked against numpy
    # in test_crack_render), so under mechanics its damage agreement would measure them.
    config.write_text("[cameras]\nn_regular = 2\nn_closeup = 2\n[damage]\nmodel = \"paper\"\n"
                      "[environment]\nn_viaducts = 3\ncutoff_factor = 1.5\n")
    out = tmp_path / "q"
    assert main(["bench", "quality", "--preset", "demo", "--config", str(config), "--cameras",
                 "2", "--presets", "preview,fast,reference", "--reference", "glsynth",
                 "--out", str(out)]) == 0
    result = json.loads((out / "quality.json").read_text())
    rows = result["presets"]
    ref, preview, fast = rows["reference"], rows["preview"], rows["fast"]
    # preview renders the same scene at a quarter of the size without MSAA and without sun
    # shadows: far from the reference (12 dB, CIEDE2000 17.6 measured); fast keeps shadows
    # (26 dB, 4.5).
    assert 8.0 < preview["psnr_db"] < fast["psnr_db"] < 99.0 and 0.3 < preview["ssim"] < 1.0
    assert 0 < fast["ciede2000"] < preview["ciede2000"]
    assert preview["time_per_sample_s"] > 0 and ref["time_per_sample_s"] > 0
    assert (out / "quality.png").is_file()
    # The ray cast agrees with the reference render but for edge pixels; preview less so.
    truth = ref["vs_raycast"]
    assert truth["component_agreement"] > 0.999 and truth["damage_agreement"] > 0.999
    assert truth["depth_median_rel_error"] < 1e-5
    assert preview["vs_raycast"]["component_agreement"] < truth["component_agreement"]
    assert "Embree ray cast" in (out / "quality.md").read_text()
    assert "| glsynth preview | 480x270 |" in (out / "quality.md").read_text()
