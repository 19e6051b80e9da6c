import argparse
import json
import subprocess
import sys

import pytest
from PIL import Image

from glsynth.cli import main, non_negative_int, positive_int, positive_int_list

SMALL_TEXTURES = ("[materials]\ntexture_size = 64\nbuiltin_size = 64\nimages_per_category = 3\n"
                  "[damage]\nresolution = 64\n")
"""Textures and damage maps small enough that an export builds and dresses a whole environment
in a few CPU-seconds (the demo's own: 13 CPU-s, most of it the texture repository's first
generation)."""


def test_export_end_to_end(tmp_path, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text(SMALL_TEXTURES)
    out = tmp_path / "deep" / "scene.glb"
    assert main(["export", "--seed", "4", "--env", "2", "--config", str(cfg), "--out",
                 str(out)]) == 0
    assert out.stat().st_size > 100_000
    info = json.loads((tmp_path / "deep" / "scene.json").read_text())
    assert info["root_seed"] == 4 and info["env"] == 2
    assert "parts" in capsys.readouterr().out


def test_export_is_byte_identical_for_the_same_seed(tmp_path):
    """Of a two-viaduct environment (test_export_end_to_end exports a whole one)."""
    cfg = tmp_path / "c.toml"
    cfg.write_text(SMALL_TEXTURES + "[environment]\nn_viaducts = 2\ncutoff_factor = 1.0\n")
    a, b = tmp_path / "a" / "scene.glb", tmp_path / "b" / "scene.glb"
    for out in (a, b):
        assert main(["export", "--seed", "1", "--env", "0", "--config", str(cfg),
                     "--out", str(out)]) == 0
    assert len(json.loads((a.parent / "scene.json").read_text())["viaducts"]) == 2
    assert a.read_bytes() == b.read_bytes()
    assert (a.parent / "scene.json").read_bytes() == (b.parent / "scene.json").read_bytes()


def test_bad_config_value_is_a_clear_error(tmp_path, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text("[environment]\nmax_slope = 0.5\n")
    code = main(["export", "--seed", "0", "--env", "0", "--config", str(cfg),
                 "--out", str(tmp_path / "s.glb")])
    err = capsys.readouterr().err
    assert code == 2 and "environment.max_slope = 0.5" in err and "(0.0, 0.2]" in err


def test_unwritable_output_is_a_clear_error(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    cfg = tmp_path / "c.toml"  # the export is built before its folder is made
    cfg.write_text(SMALL_TEXTURES + "[environment]\nn_viaducts = 2\ncutoff_factor = 1.0\n")
    code = main(["export", "--seed", "0", "--env", "0", "--config", str(cfg), "--out",
                 str(blocker / "s.glb")])
    assert code == 2 and "Choose a writable --out" in capsys.readouterr().err


def test_histograms_png(tmp_path):
    out = tmp_path / "fig7.png"
    assert main(["histograms", "--seed", "0", "--count", "20", "--out", str(out)]) == 0
    assert Image.open(out).size[0] > 500


def test_console_script_entry_point(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "glsynth", "export", "--seed", "-1",
                           "--env", "0", "--out", str(tmp_path / "s.glb")],
                          capture_output=True, text=True)
    assert proc.returncode == 2 and "must be an integer in [0, 2**63 - 1]" in proc.stderr


def test_textures_command(tmp_path):
    out = tmp_path / "repo"
    assert main(["textures", "--out", str(out), "--count", "1", "--size", "16"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["concrete", "ground", "painted", "scene",
                                                      "steel", "wood"]


COMMANDS = [["export"], ["histograms"], ["render"], ["preview"], ["generate"], ["stats"],
            ["train"], ["evaluate"], ["predict"], ["assess"], ["bench", "quality"],
            ["bench", "blender"], ["bench", "sim2real"], ["textures"]]


@pytest.mark.parametrize("command", COMMANDS, ids=" ".join)
def test_every_command_builds_its_options(command, capsys):
    with pytest.raises(SystemExit) as done:
        main([*command, "--help"])
    assert done.value.code == 0
    assert capsys.readouterr().out.startswith(f"usage: glsynth {' '.join(command)} ")


def test_integer_options_take_what_their_names_say():
    assert non_negative_int("0") == 0 and positive_int("1") == 1
    assert positive_int_list("1,16,64") == [1, 16, 64]
    for parse, text, message in ((non_negative_int, "-1", r"must be an integer in \[0, 2\*\*63"),
                                 (positive_int, "0", r"must be an integer in \[1, 2\*\*63"),
                                 (positive_int_list, "1,0", "give integers >= 1"),
                                 (positive_int_list, "1,,2", "give integers >= 1"),
                                 (positive_int_list, "", "give integers >= 1")):
        with pytest.raises(argparse.ArgumentTypeError, match=message):
            parse(text)
    with pytest.raises(ValueError):  # argparse: "invalid non_negative_int value: 'x'"
        non_negative_int("x")
