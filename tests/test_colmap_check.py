"""COLMAP itself on a small flight (glsynth.measure.colmap_check, the check bench_flight runs
at 960x540): a 38-frame ring (70 % forward overlap) around a column at 2 m, 640x360, 50 mm,
in a two-viaduct environment. The issue's goals, held here at this size: triangulated points
within 10 mm (median) of the true surfaces, 95 % of the frames registered by the mapper, under
0.5 degrees of rotation error (median). docs/results.md has what it measured."""

import pytest

from glsynth.cli import main
from glsynth.core.config import load_config
from glsynth.core.errors import UserError
from glsynth.measure import colmap_check
from glsynth.world.environment import build_environment

# The ring checks the poses' conventions against COLMAP's own reconstruction: the pinhole
# render (the camera model's noise, blur and JPEG are tested in test_camera_model), round the
# bare concrete column (the demo preset jackets it in steel, class 8, which gives COLMAP too
# few features).
RING = """[render]
width = 640
height = 360
[environment]
n_viaducts = 2
cutoff_factor = 1.0
jacket_probability = 0.0
brace_probability = 0.0
downpipe_probability = 0.0
trough_probability = 0.0
sign_probability = 0.0
[flight]
heights_m = [2.0]
focal_mm = 50.0
forward_overlap_pct = 70.0
[sensor]
enabled = false
"""


@pytest.mark.slow
def test_colmap_reconstructs_a_small_orbit(tmp_path):
    pytest.importorskip("pycolmap", reason="pycolmap is not installed (the [flights] extra): "
                        "COLMAP's reconstruction is not checked")
    cfg = tmp_path / "ring.toml"
    cfg.write_text(RING)
    out = tmp_path / "flight"
    assert main(["fly", "--preset", "demo", "--seed", "0", "--env", "0", "--config", str(cfg),
                 "--out", str(out)]) == 0
    env = build_environment(load_config("demo", cfg), 0, 0)
    checked = colmap_check.reconstruct(env, out, tmp_path / "colmap")
    tri, mapper = checked["triangulation_with_true_poses"], checked["mapper"]
    assert tri["points"] > 1000 and tri["median_distance_mm"] <= 10.0, tri
    assert tri["share_by_component"]["column"] > 0.5, tri
    assert mapper["registered_share"] >= 0.95 and mapper["models"] == 1, mapper
    assert mapper["median_rotation_error_deg"] < 0.5, mapper


def test_without_pycolmap_the_check_says_so_in_one_line(tmp_path, monkeypatch, env0):
    monkeypatch.setattr(colmap_check, "pycolmap", None)
    with pytest.raises(UserError, match=r"needs pycolmap: pip install -e \.\[flights\]$"):
        colmap_check.reconstruct(env0, tmp_path, tmp_path / "colmap")
