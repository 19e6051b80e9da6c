"""Quality presets and the speed-against-accuracy bench (glsynth bench quality)."""

import json

import pytest

from glsynth.cli import main
from glsynth.core.config import Config
from glsynth.measure.quality import QUALITY, apply_quality


def test_presets_set_every_knob():
    for name, q in QUALITY.items():
        c = apply_quality(Config(), name)
        assert (c.render.width, c.render.height) == (round(1920 * q.render_scale),
                                                     round(1080 * q.render_scale))
        assert c.render.msaa == q.msaa and c.materials.texture_size == q.texture_size
        assert c.damage.resolution == q.damage_resolution and c.damage.octaves == q.octaves
        assert c.environment.cylinder_segments == q.cylinder_segments
        assert c.render.shadow_map_px == q.shadow_map_px
    default = apply_quality(Config(), "default")
    assert default == Config()
    with pytest.raises(ValueError, match="choose one of"):
        apply_quality(Config(), "ultra")


def test_bench_quality_on_real_renders(tmp_path, capsys):
    config = tmp_path / "c.toml"
    config.write_text("[cameras]\nn_regular = 2\nn_closeup = 2\n")
    out = tmp_path / "q"
    assert main(["bench", "quality", "--preset", "demo", "--config", str(config), "--cameras",
                 "2", "--presets", "preview,fast,reference", "--out", str(out)]) == 0
    result = json.loads((out / "quality.json").read_text())
    rows = result["presets"]
    ref, preview = rows["reference"], rows["preview"]
    assert ref["psnr_db"] == 99.0 and ref["ssim"] == pytest.approx(1.0)
    assert ref["component_agreement"] == ref["damage_agreement"] == 1.0
    assert ref["damaged_area_error_pp"] == 0.0 and ref["depth_median_rel_error"] == 0.0
    assert preview["psnr_db"] < 99.0 and 0.5 < preview["component_agreement"] < 1.0
    assert preview["render_s"] < ref["render_s"]
    assert (out / "quality.png").is_file()
    # The ray cast agrees with the reference render but for edge pixels; preview less so.
    truth = ref["vs_raycast"]
    assert truth["component_agreement"] > 0.999 and truth["damage_agreement"] > 0.999
    assert truth["depth_median_rel_error"] < 1e-5
    assert preview["vs_raycast"]["component_agreement"] < truth["component_agreement"]
    assert "Embree ray cast" in (out / "quality.md").read_text()
    assert "| preview | 480x270 |" in (out / "quality.md").read_text()
