"""Check, then lock, then write: every command that writes an --out folder (render, render
--camera-json, fly, generate, assess) refuses an --out held by another run's lock, an --out
that is a file and one that cannot be made, each with one line under 300 characters and exit
2, leaving no folder behind; a plan or a config refused inside the lock leaves none either;
and work a user sizes is bounded before it starts. Frames of 160x90."""

import json
import os
import shutil
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from glsynth.cli import main
from glsynth.core.errors import MAX_MESSAGE
from glsynth.core.runlock import DRIVER_LOCK, WORKERS_LOCK, RunLock

SMALL = """[render]
width = 160
height = 90
msaa = 0
shadow_map_px = 256
sky_visibility_px = 128
[damage]
resolution = 64
[materials]
texture_size = 64
builtin_size = 64
[flight]
max_frames = 1
"""
LOCKS = {DRIVER_LOCK, WORKERS_LOCK}


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("cfg") / "small.toml"
    path.write_text(SMALL)
    return path


@pytest.fixture(scope="module")
def rendered(small, tmp_path_factory) -> Path:
    """One render of camera 0: the input of assess --oracle and render --camera-json."""
    out = tmp_path_factory.mktemp("render") / "camera0"
    assert main(["render", "--config", str(small), "--seed", "0", "--env", "0", "--camera",
                 "0", "--out", str(out)]) == 0
    return out


TOKAIDO = """[dataset]
n_environments = 2
n_test_environments = 1
n_plates = 3
n_test_plates = 1
plates_per_task = 2
[cameras]
n_regular = 3
n_closeup = 2
[damage]
resolution = 64
[materials]
texture_size = 32
builtin_size = 64
images_per_category = 3
"""
"""generate writes the Tokaido layout, at 1920x1080 only (conftest's small dataset)."""


@pytest.fixture(scope="module")
def inputs(small, rendered, tmp_path_factory) -> dict[str, Path]:
    tokaido = tmp_path_factory.mktemp("cfg") / "tokaido.toml"
    tokaido.write_text(TOKAIDO)
    return {"small": small, "tokaido": tokaido, "rendered": rendered}


COMMANDS: dict[str, Callable[[dict[str, Path], Path], list[str]]] = {
    "render": lambda i, out: ["render", "--config", str(i["small"]), "--seed", "0", "--env",
                              "0", "--camera", "0", "--out", str(out)],
    "render --camera-json": lambda i, out: [
        "render", "--config", str(i["small"]), "--seed", "0", "--env", "0", "--camera-json",
        str(i["rendered"] / "camera.json"), "--out", str(out)],
    "fly": lambda i, out: ["fly", "--config", str(i["small"]), "--seed", "0", "--env", "0",
                           "--plan", "orbit", "--out", str(out)],
    "generate": lambda i, out: ["generate", "--config", str(i["tokaido"]), "--seed", "0",
                                "--out", str(out)],
    "assess": lambda i, out: ["assess", "--oracle", str(i["rendered"]), "--out", str(out)],
}


def one_line(capsys, *needles: str) -> str:
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    assert len(err) < MAX_MESSAGE, err
    for needle in needles:
        assert needle in err, err
    return err


def _tree(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


@pytest.mark.parametrize("command", COMMANDS)
def test_an_out_held_by_another_run_is_refused_untouched(inputs, tmp_path, capsys, command):
    out = tmp_path / "held"
    with RunLock(out):
        before = _tree(out)
        assert main(COMMANDS[command](inputs, out)) == 2
        assert _tree(out) == before == LOCKS
    one_line(capsys, "is in use by another glsynth run", "pid")


@pytest.mark.parametrize("command", COMMANDS)
def test_an_out_that_is_a_file_is_refused_untouched(inputs, tmp_path, capsys, command):
    out = tmp_path / "a_file"
    out.write_bytes(b"mine")
    assert main(COMMANDS[command](inputs, out)) == 2
    one_line(capsys, "is a file; give a folder")
    assert out.read_bytes() == b"mine" and set(os.listdir(tmp_path)) == {"a_file"}


@pytest.mark.parametrize("where", ["under a file", "in /proc"])
@pytest.mark.parametrize("command", COMMANDS)
def test_an_out_that_cannot_be_made_is_one_line(inputs, tmp_path, capsys, command, where):
    (tmp_path / "f").write_bytes(b"")
    out = tmp_path / "f" / "out" if where == "under a file" else Path("/proc/glsynth-out")
    assert main(COMMANDS[command](inputs, out)) == 2
    one_line(capsys, "cannot create the folder or its lock file" if where == "under a file"
             else "is in the kernel's /proc, /sys or /dev")
    assert set(os.listdir(tmp_path)) == {"f"} and not out.exists()


@pytest.mark.parametrize("where", ["a file", "in /proc"])
def test_fly_refuses_a_wrong_out_before_it_builds_the_environment(inputs, tmp_path, capsys,
                                                                   monkeypatch, where):
    """A flight checks its plan before it takes the lock (so a refused plan leaves no folder),
    and that builds the environment (15 s for the paper's): --out is checked first. (A held
    --out is refused before any command runs: test_an_out_held_by_another_run_...)"""
    from glsynth.data import flight

    def built(*_args: object) -> None:
        raise AssertionError("the environment was built before --out was checked")

    monkeypatch.setattr(flight, "build_environment", built)
    out = tmp_path / "a_file" if where == "a file" else Path("/proc/glsynth-out")
    if where == "a file":
        out.write_bytes(b"mine")
    assert main(COMMANDS["fly"](inputs, out)) == 2
    one_line(capsys, "is a file" if where == "a file" else "/proc, /sys or /dev")


def test_a_long_out_is_abbreviated_in_the_line(inputs, tmp_path, capsys):
    out = tmp_path / ("deep" * 40) / ("x" * 200)
    out.parent.mkdir()
    out.write_bytes(b"")
    assert main(COMMANDS["render"](inputs, out)) == 2
    assert "..." in one_line(capsys, "is a file; give a folder")


def test_a_refused_config_inside_the_lock_leaves_no_folder(small, tmp_path, capsys):
    """The texture repository is read after the lock is taken: its refusal removes the
    folder the run made (and only that: a folder given leaves as it was)."""
    cfg = tmp_path / "c.toml"
    cfg.write_text(SMALL.replace("[materials]\n", "[materials]\nrepository = "
                                 f"{str(tmp_path / 'none')!r}\n"))
    out = tmp_path / "render"
    assert main(COMMANDS["render"]({"small": cfg}, out)) == 2
    one_line(capsys, "texture repository")
    assert not out.exists()
    out.mkdir()
    assert main(COMMANDS["render"]({"small": cfg}, out)) == 2
    assert out.is_dir() and _tree(out) <= LOCKS


def test_a_refused_plan_leaves_no_folder(small, tmp_path, capsys):
    cfg = tmp_path / "collide.toml"
    cfg.write_text(SMALL + "standoff_m = 0.4\n")
    out = tmp_path / "flight"
    assert main(COMMANDS["fly"]({"small": cfg}, out)) == 2
    one_line(capsys, "waypoint 0 is 0.")
    assert not out.exists()


@pytest.mark.parametrize("plan, needle", [
    ('plan = "underdeck"', "lower forward_overlap_pct or shorten the path"),
    ('plan = "facade"\nlength_m = 0.0', "lower side_overlap_pct"),
    ('plan = "orbit"\nheights_m = [' + ", ".join(["2.0"] * 20) + "]",
     "lower forward_overlap_pct")])
def test_a_plan_of_millions_of_frames_is_refused_at_once(small, tmp_path, capsys, plan, needle):
    """Micrometre spacing (a stand-off of 10 um): the frames are counted, not built (such a
    plan had taken 95 s and 0.7 GB for max_frames = 2 before it was cut)."""
    cfg = tmp_path / "dense.toml"
    cfg.write_text(SMALL.replace("max_frames = 1", f"max_frames = 2\n{plan}\nstandoff_m = "
                                 "0.00001\nspeed_mps = 0.000001\nframe_rate_hz = 1000.0"))
    out = tmp_path / "flight"
    t0 = time.perf_counter()
    assert main(["fly", "--config", str(cfg), "--seed", "0", "--env", "0", "--out",
                 str(out)]) == 2
    assert time.perf_counter() - t0 < 20
    one_line(capsys, "more than the 100,000 a plan may have", needle)
    assert not out.exists()


@pytest.mark.parametrize("in_the_way", ["the cache", "its decoded folder"])
def test_a_cache_in_the_way_is_blamed_on_glsynth_cache(small, tmp_path, capsys, monkeypatch,
                                                       in_the_way):
    cache = tmp_path / "cache"
    if in_the_way == "the cache":
        cache.write_bytes(b"")
    else:  # the small config's repository (three 64 px images a category) is made first
        cache.mkdir()
        (cache / "decoded").write_bytes(b"")
    monkeypatch.setenv("GLSYNTH_CACHE", str(cache))
    out = tmp_path / "render"
    assert main(COMMANDS["render"]({"small": small}, out)) == 2
    err = one_line(capsys, "glsynth render: error: $GLSYNTH_CACHE: cannot make")
    assert "--out" not in err and not out.exists()


@pytest.mark.parametrize("value", [np.inf, np.nan])
def test_assess_refuses_true_crack_widths_that_are_not_finite(rendered, tmp_path, capsys,
                                                              value):
    """An oracle's ground truth must hold its contract: an infinite crack width had made
    every width error None and the run succeed."""
    data = tmp_path / "render"
    shutil.copytree(rendered, data)
    widths = np.load(data / "crack_width.npy")
    widths[0, 0] = value
    np.save(data / "crack_width.npy", widths)
    out = tmp_path / "assessed"
    assert main(["assess", "--oracle", str(data), "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and len(err[0]) < MAX_MESSAGE, err
    assert "crack-width map" in err[0] and "1 values that are not finite" in err[0]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["assessed"] == [] and len(summary["failed"]) == 1
