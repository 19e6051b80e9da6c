"""The input contract by kind, for what an independent probe still found after the readers
and the viewer's schema: folders held by another process above --out, symbolic-link loops as
--out, integers too large for a float, TOML nested past Python's stack, unbounded seeds and
sizes, marker rows that climb out of the dataset, and true crack widths beyond any crack."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from glsynth.cli import main
from glsynth.core.config import MAX_CRACK_WIDTH_MM, config_from_dict, parse_toml
from glsynth.core.errors import UserError
from glsynth.core.options import MAX_SIDE_PX, parse_size
from glsynth.data.dataset import _inside
from glsynth.data.readers import read_float_map
from glsynth.view.protocol import number_field

HOLD = ("import sys, time\n"
        "from glsynth.core.runlock import RunLock\n"
        "RunLock(sys.argv[1]).acquire()\n"
        "print('held', flush=True)\n"
        "time.sleep(120)\n")


@pytest.fixture
def held(tmp_path):
    """A folder whose run lock another process holds, as a running generate's is."""
    folder = tmp_path / "held"
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(folder)],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        yield folder
    finally:
        holder.kill()
        holder.wait()


def _one_line(capsys, needle: str) -> None:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and needle in err and len(err) < 300, err


@pytest.mark.parametrize("args", [
    ["textures", "--count", "1", "--size", "8", "--out", "{held}/sub"],
    ["histograms", "--seed", "0", "--count", "1", "--out", "{held}/h.png"],
    ["render", "--preset", "demo", "--seed", "0", "--env", "0", "--camera", "0", "--out",
     "{held}/sub"],
])
def test_no_command_writes_inside_a_folder_another_run_holds(held, capsys, args):
    before = sorted(p.name for p in held.iterdir())
    assert main([a.format(held=held) for a in args]) == 2
    _one_line(capsys, "which another glsynth run is writing")
    assert sorted(p.name for p in held.iterdir()) == before


def test_a_symbolic_link_loop_as_out_is_one_line(tmp_path, capsys):
    loop = tmp_path / "loop"
    loop.symlink_to(loop)
    assert main(["textures", "--count", "1", "--size", "8", "--out", str(loop)]) == 2
    _one_line(capsys, "loop of symbolic links")


def test_integers_too_large_for_a_float_are_refused_not_overflowed():
    huge = 10 ** 400
    with pytest.raises(UserError, match=r"x = .*: must be in \[0, 1\]"):
        number_field({"x": huge}, "x", 0.0, 1.0)
    with pytest.raises(UserError, match=r"render.znear_m = .*: must be in"):
        config_from_dict({"render": {"znear_m": huge}})
    with pytest.raises(UserError, match=r"render.width = .*: must be in"):
        config_from_dict(parse_toml(f"[render]\nwidth = {huge}\n", "config file"))


def test_toml_nested_past_the_stack_is_one_line():
    depth = 20_000
    with pytest.raises(UserError, match="config file nests too deeply"):
        parse_toml("width = " + "[" * depth + "]" * depth, "config file")


@pytest.mark.parametrize("value", [str(2 ** 63), "9" * 100])
def test_seeds_and_indices_are_bounded(tmp_path, capsys, value):
    with pytest.raises(SystemExit) as exit_:
        main(["histograms", "--seed", value, "--count", "1", "--out", str(tmp_path / "h.png")])
    assert exit_.value.code == 2 and not (tmp_path / "h.png").exists()
    assert "must be an integer in [0, 2**63 - 1]" in capsys.readouterr().err


def test_image_sizes_are_bounded():
    assert parse_size(f"{MAX_SIDE_PX}x96", 96) == (MAX_SIDE_PX, 96)
    with pytest.raises(UserError, match=f"each side must be at most {MAX_SIDE_PX} px"):
        parse_size("1000000x1000000", 96)


def test_marker_rows_stay_inside_the_dataset():
    assert _inside("img_syn_raw/train/image_0.png")
    for bad in ("../../../etc/passwd", "/etc/passwd", "", 3, "a/../../b"):
        assert not _inside(bad)


def test_true_crack_widths_are_bounded_by_the_widest_crack(tmp_path):
    widths = np.zeros((2, 3), np.float32)
    np.save(tmp_path / "ok.npy", widths + MAX_CRACK_WIDTH_MM)
    assert read_float_map(tmp_path / "ok.npy", "crack-width map", (3, 2),
                          high=MAX_CRACK_WIDTH_MM).max() == MAX_CRACK_WIDTH_MM
    widths[1, 2] = 1e30
    np.save(tmp_path / "wide.npy", widths)
    with pytest.raises(UserError, match="1 values that are not finite and in"):
        read_float_map(tmp_path / "wide.npy", "crack-width map", (3, 2),
                       high=MAX_CRACK_WIDTH_MM)
    assert read_float_map(tmp_path / "wide.npy", "depth map", (3, 2))[1, 2] == 1e30


def test_the_held_check_ignores_this_processs_own_locks(tmp_path):
    """A run may write below a folder it holds itself (its own sub-folders)."""
    from glsynth.core.runlock import RunLock, held_by_another

    with RunLock(tmp_path / "mine"):
        assert held_by_another(tmp_path / "mine" / "sub") is None
    assert held_by_another(Path(tmp_path)) is None


def test_a_bad_option_is_one_line_without_the_usage_block(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["render", "--preset", "demo", "--seed", "0", "--env", "0", "--camera", "9" * 50,
              "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and err.count("\n") == 1 and "usage" not in err
    assert err.startswith("glsynth render: error: argument --camera:")


def test_a_pose_with_an_integer_too_large_for_a_float_is_refused():
    from glsynth.view.protocol import rigid_pose

    with pytest.raises(UserError, match="4 rows of 4 finite numbers"):
        rigid_pose([[1, 0, 0, 10 ** 400], [0, 0, -1, -12], [0, 1, 0, 5], [0, 0, 0, 1]])
