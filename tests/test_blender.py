"""glsynth bench blender: the comparison itself, the report when Blender is absent, bad input,
and, where Blender is installed (scripts/install.sh installs it when it can), a real Cycles run."""

import json
import shutil

import numpy as np
import pytest

from glsynth.cli import main
from glsynth.measure.blender_bench import compare_labels_depth, read_pass


def test_compare_counts_blender_sky_as_nonbridge_and_depth_where_both_hit():
    component = np.array([[1, 4], [4, 2]], np.uint8)
    depth = np.array([[2000.0, 10.0], [20.0, 5.0]], np.float32)
    theirs = np.array([[0.0, 4.0], [3.9999, 3.0]], np.float32)  # 0: Blender's empty world
    their_depth = np.array([[1e10, 10.001], [20.0, 5.0]], np.float32)
    scores = compare_labels_depth(component, depth, theirs, their_depth, zfar=2000.0)
    assert scores["component_agreement"] == 0.75
    assert scores["pixels_hit_by_both"] == 3
    assert scores["depth_median_rel_diff"] == pytest.approx(0.0)
    assert scores["depth_p99_rel_diff"] == pytest.approx(1e-4 * 0.98, rel=0.05)


def test_raw_passes_are_read_top_row_first(tmp_path):
    rgba = np.zeros((2, 3, 4), np.float32)
    rgba[0, :, 0] = [1, 2, 3]  # Blender's first row is the bottom one
    (tmp_path / "p.f32").write_bytes(rgba.tobytes())
    assert read_pass(tmp_path / "p.f32", [3, 2]).tolist() == [[0, 0, 0], [1, 2, 3]]


def test_without_blender_it_says_so_and_measures_nothing(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    out = tmp_path / "b"
    assert main(["bench", "blender", "--out", str(out)]) == 0
    assert "Blender is not installed" in capsys.readouterr().err
    assert not out.exists()


def test_bad_blender_path_camera_and_samples_are_clear_errors(tmp_path, capsys):
    assert main(["bench", "blender", "--blender", str(tmp_path / "nope"), "--out",
                 str(tmp_path)]) == 2
    assert "--blender" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["bench", "blender", "--samples", "0", "--out", str(tmp_path)])
    assert "give integers >= 1, comma-separated" in capsys.readouterr().err
    if shutil.which("blender"):
        assert main(["bench", "blender", "--camera", "99", "--out", str(tmp_path)]) == 2
        assert "cameras 0 to 11" in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("blender") is None, reason="Blender is not installed")
def test_cycles_sees_the_same_components_and_depth(tmp_path):
    config = tmp_path / "small.toml"
    # Small textures and damage maps and two viaducts: what Blender is handed to load, not
    # what the agreement reads (components and depth).
    config.write_text("[render]\nwidth = 192\nheight = 108\n[damage]\nresolution = 64\n"
                      "[materials]\ntexture_size = 32\nimages_per_category = 3\n"
                      "[environment]\nn_viaducts = 2\ncutoff_factor = 1.0\n")
    out = tmp_path / "b"
    assert main(["bench", "blender", "--config", str(config), "--camera", "3", "--samples",
                 "1", "--out", str(out)]) == 0
    result = json.loads((out / "blender.json").read_text())
    agreement = result["agreement"]
    assert agreement["component_agreement"] > 0.99
    assert agreement["pixels_hit_by_both"] > 0.5 * 192 * 108
    assert agreement["depth_median_rel_diff"] < 1e-4
    assert result["cycles"]["colour_s"]["1"] > 0 and (out / "blender_1spp.png").is_file()
    assert "Cycles colour, 1 samples" in (out / "blender.md").read_text()
