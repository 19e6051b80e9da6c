"""Bad input and faults: each gives exit code 2 and one line on stderr (no traceback), writes
nothing it should not, and never hangs. Programming errors keep their traceback."""

import json
import os
import signal
import struct
import subprocess
import sys
import time
import zlib
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from glsynth.cli import main
from glsynth.core.errors import UserError
from glsynth.core.fileio import atomic_write_bytes
from glsynth.core.runlock import RunLock


def one_line_error(capsys, *needles: str) -> str:
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    for needle in needles:
        assert needle in err, err
    return err


def run_cli(*args: str, env: dict | None = None, timeout: float = 240
            ) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "glsynth", *args], capture_output=True,
                          text=True, timeout=timeout, env={**os.environ, **(env or {})})


# --- one error path --------------------------------------------------------------------------
def test_a_programming_error_keeps_its_traceback(monkeypatch):
    import glsynth.cli as cli

    def broken(args):
        raise TypeError("a bug, not a user's mistake")

    monkeypatch.setattr(cli, "cmd_textures", broken)
    with pytest.raises(TypeError, match="a bug"):
        main(["textures", "--out", "unused"])


def test_debug_shows_the_traceback_of_a_user_error(tmp_path, capsys):
    args = ["export", "--seed", "0", "--env", "0", "--out", str(tmp_path / "x.txt")]
    assert main(args) == 2
    one_line_error(capsys, "glTF binary")
    with pytest.raises(UserError, match="glTF binary"):
        main(["--debug", *args])


def test_gl_unavailable_is_one_line(quick_config, tmp_path, capsys, monkeypatch):
    """(QUICK's small environment and textures: the context is asked for after the
    environment is built and dressed, 17 CPU-s of the demo's ten viaducts.)"""
    from glsynth.render.gl import context

    def missing(platform):
        raise OSError(f"lib{platform}.so: cannot open shared object file")

    monkeypatch.setattr(context, "_create", missing)
    code = main(["render", "--seed", "0", "--env", "0", "--camera", "0", "--config",
                 str(quick_config), "--out", str(tmp_path / "r")])
    assert code == 2
    one_line_error(capsys, "no OpenGL context", "libegl1", "libosmesa6")
    assert not (tmp_path / "r").exists()


# --- hangs -----------------------------------------------------------------------------------
@pytest.mark.parametrize("workers", ["1", "2"])
def test_workers_that_cannot_start_end_the_run(small_config, tmp_path, workers):
    """msaa 8 is more than llvmpipe has: every worker fails to start. The run ends with one
    line, promptly: 0.9 s with one worker and 2.3 s with two here, so 30 s leaves room for a
    loaded machine yet fails a run that starts workers again and again before it gives up. A
    pool that restarted them for ever would hang: the timeout stops that one."""
    config = tmp_path / "c.toml"
    text = Path(small_config).read_text().replace("msaa = 0", "msaa = 8")
    assert "msaa = 8" in text  # the small config's [render] section sets msaa
    config.write_text(text)
    t0 = time.monotonic()
    done = run_cli("generate", "--preset", "demo", "--config", str(config), "--seed", "0",
                   "--out", str(tmp_path / "ds"), "--workers", workers, timeout=180)
    assert done.returncode == 2, done.stderr
    lines = [ln for ln in done.stderr.splitlines() if "glsynth generate: error" in ln]
    assert len(lines) == 1 and "msaa = 8" in lines[0] and "Traceback" not in done.stderr
    assert time.monotonic() - t0 < 30, "the run started its workers again before giving up"
    assert not list((tmp_path / "ds").glob("img_syn_raw/*/*.png"))


# --- corrupt or mixed-up model files ---------------------------------------------------------
def _run_folder(tmp_path: Path, name: str, data: bytes | None = None, *,
                settings_task: str = "component", model_task: str = "component") -> Path:
    torch = pytest.importorskip("torch", reason="needs the [model] extra")
    from glsynth.model.fcn58 import FCN58
    from glsynth.model.runtime import save_torch
    from glsynth.model.settings import N_OUTPUTS

    run = tmp_path / name
    run.mkdir()
    (run / "settings.json").write_text(json.dumps({"task": settings_task}))
    if data is None:
        save_torch(run / "model.pt", {
            "task": model_task, "out_channels": N_OUTPUTS[model_task],
            "image_size": [192, 108], "target_size": [64, 36], "mfb_weights": None,
            "state_dict": FCN58(N_OUTPUTS[model_task]).state_dict()})
        assert torch.load(run / "model.pt", weights_only=True)["task"] == model_task
    else:
        (run / "model.pt").write_bytes(data)
    return run


def _photo(tmp_path: Path) -> Path:
    path = tmp_path / "photo.png"
    Image.fromarray(np.full((108, 192, 3), 128, np.uint8)).save(path)
    return path


@pytest.mark.parametrize("kind", ["truncated", "empty", "random", "wrong keys"])
def test_a_damaged_model_file_is_one_line(tmp_path, capsys, kind):
    torch = pytest.importorskip("torch", reason="needs the [model] extra")
    import io

    good = io.BytesIO()
    torch.save({"state_dict": {}}, good)
    data = {"truncated": good.getvalue()[:40], "empty": b"",
            "random": np.arange(512, dtype=np.uint8).tobytes(),
            "wrong keys": good.getvalue()}[kind]
    run = _run_folder(tmp_path, "run", data)
    photo = _photo(tmp_path)
    for args in (["predict", "--run", str(run), str(photo), "--out", str(tmp_path / "p")],
                 ["assess", "--runs", f"component={run},damage={run},depth={run}",
                  str(photo), "--out", str(tmp_path / "a")]):
        assert main(args) == 2
        err = one_line_error(capsys, "model.pt")
        assert "weights_only" not in err
    assert not (tmp_path / "p").exists()


def test_a_model_for_another_task_than_its_settings_is_refused(tmp_path, capsys):
    run = _run_folder(tmp_path, "mixed", settings_task="component", model_task="damage")
    assert main(["predict", "--run", str(run), str(_photo(tmp_path)), "--out",
                 str(tmp_path / "p")]) == 2
    one_line_error(capsys, "damage network", "settings.json says component")
    assert not (tmp_path / "p").exists()


# --- images that cannot be read --------------------------------------------------------------
def _png_header_only(path: Path, width: int, height: int) -> None:
    """A PNG whose header claims width x height (no pixel data is needed to be refused)."""
    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(
            ">I", zlib.crc32(kind + body))
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IEND", b""))


def test_a_decompression_bomb_in_the_repository_is_skipped_with_its_name(tmp_path):
    from glsynth.appearance.repository import TextureRepository, generate_repository

    root = generate_repository(tmp_path / "repo", 0, 2, 16)
    bomb = root / "steel" / "steel_0000.png"
    _png_header_only(bomb, 14_000, 14_000)  # 196 megapixels
    repo = TextureRepository(root, 16)
    with pytest.warns(UserWarning, match="steel_0000.png.*DecompressionBomb"):
        image = repo.image("steel", 0)
    assert image.shape == (16, 16, 3)  # the next readable image of the category


# --- one writer per output folder ------------------------------------------------------------
def test_a_second_writer_is_refused_with_the_holders_pid(small_config, tmp_path, capsys):
    out = tmp_path / "ds"
    with RunLock(out):
        code = main(["generate", "--preset", "demo", "--config", str(small_config), "--seed",
                     "0", "--out", str(out)])
        assert code == 2
        one_line_error(capsys, "in use by another glsynth run", f"pid {os.getpid()}")
        assert sorted(p.name for p in out.iterdir()) == [".glsynth.lock",
                                                          ".glsynth.workers.lock"]


def test_a_run_cannot_start_while_an_earlier_runs_workers_live(tmp_path):
    out = tmp_path / "ds"
    with (RunLock(out, worker=True),
          pytest.raises(UserError, match="worker processes of an earlier run")):
        RunLock(out).acquire()
    with RunLock(out):  # once they are gone, the folder is free
        pass


def test_a_killed_holder_leaves_no_stale_lock(tmp_path):
    out = tmp_path / "ds"
    holder = subprocess.Popen([sys.executable, "-c", (
        "import sys, time; from glsynth.core.runlock import RunLock; "
        f"RunLock({str(out)!r}).acquire(); print('held', flush=True); time.sleep(60)")],
        stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(UserError, match=f"pid {holder.pid}"):
            RunLock(out).acquire()
    finally:
        os.kill(holder.pid, signal.SIGKILL)
        holder.wait()
    with RunLock(out):
        pass


def test_training_runs_take_the_same_lock(tmp_path, capsys):
    pytest.importorskip("torch", reason="needs the [model] extra")
    run, data = tmp_path / "run", tmp_path / "data"
    data.mkdir()  # a manifest is all train reads before it takes the lock
    (data / "files_train.csv").write_text("a_Scene.png,a.bmp,b.bmp,d.png,20.0,True,True\n")
    with RunLock(run):
        assert main(["train", "--task", "component", "--data", str(data),
                     "--out", str(run)]) == 2
        one_line_error(capsys, "in use by another glsynth run")


# --- validation before work ------------------------------------------------------------------
@pytest.mark.parametrize("cameras", [["100"], ["0", "5000"]])
def test_camera_indices_are_checked_before_any_work(tmp_path, capsys, cameras):
    t0 = time.perf_counter()
    code = main(["render", "--preset", "paper", "--seed", "0", "--env", "0", "--camera",
                 *cameras, "--out", str(tmp_path / "r")])
    assert code == 2 and time.perf_counter() - t0 < 5  # the environment is never built
    one_line_error(capsys, f"--camera {cameras[-1]}", "cameras 0 to 99")
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("focal, shown", [("nan", "'nan'"), ("abc", "'abc'"), ("-3", "'-3'")])
def test_a_bad_manifest_focal_length_names_file_and_line(tmp_path, capsys, focal, shown):
    from glsynth.data.tokaido import read_manifest

    rows = ["a_Scene.png,a.bmp,b.bmp,d.png,20.0,True,False",
            f"b_Scene.png,a.bmp,b.bmp,d.png,{focal},True,False"]
    (tmp_path / "files_test.csv").write_text("\n".join(rows) + "\n")
    with pytest.raises(UserError, match=rf"files_test.csv' line 2: focal length {shown}"):
        read_manifest(tmp_path, "files_test.csv")
    assert main(["assess", "--oracle", str(tmp_path), "--out", str(tmp_path / "a")]) == 2
    one_line_error(capsys, "line 2", "focal length")


def test_a_wrong_config_type_names_the_field(tmp_path, capsys):
    config = tmp_path / "c.toml"
    config.write_text('[lighting]\nsky_rgb = "abc"\n')
    assert main(["export", "--seed", "0", "--env", "0", "--config", str(config), "--out",
                 str(tmp_path / "s.glb")]) == 2
    one_line_error(capsys, "lighting.sky_rgb = 'abc'", "3 numbers in [0.0, 1.0]")


def test_a_config_that_is_not_utf8_names_the_file(tmp_path, capsys):
    config = tmp_path / "c.toml"
    config.write_bytes(b"[lighting]\n# caf\xe9\nexposure = 1.0\n")
    assert main(["export", "--seed", "0", "--env", "0", "--config", str(config), "--out",
                 str(tmp_path / "s.glb")]) == 2
    one_line_error(capsys, str(config), "not UTF-8")
    assert not (tmp_path / "s.glb").exists()


def test_a_write_error_names_the_file_not_its_temporary(tmp_path, monkeypatch):
    real_open = os.open

    def refuse(path, flags, mode=0o777, **kw):
        if str(path).endswith(".tmp"):
            raise PermissionError(13, "Permission denied", str(path))
        return real_open(path, flags, mode, **kw)

    monkeypatch.setattr(os, "open", refuse)
    target = tmp_path / "image.png"
    with pytest.raises(UserError) as info:
        atomic_write_bytes(target, b"x")
    message = str(info.value)
    assert repr(str(target)) in message and ".tmp" not in message
    assert "permissions" in message and "again to resume" in message
    assert list(tmp_path.iterdir()) == []


def _children(pid: int) -> list[int]:
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            found.append(int(stat.parent.name))
    return found


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc (Linux)")
def test_workers_end_with_a_killed_driver(quick_config, tmp_path):
    """After SIGKILL of the driver its workers stop at once (they would otherwise go on
    writing while a resumed run starts)."""
    out = tmp_path / "ds"
    driver = subprocess.Popen([sys.executable, "-m", "glsynth", "generate", "--preset",
                               "demo", "--config", str(quick_config), "--seed", "3", "--out",
                               str(out), "--workers", "2"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 180
    workers: list[int] = []
    while time.time() < deadline and not list(out.glob("img_syn_raw/*/*.png")):
        time.sleep(0.05)
    workers = [p for p in _children(driver.pid)
               if b"multiprocessing" in Path(f"/proc/{p}/cmdline").read_bytes()]
    assert workers, "no worker process while the run was writing"
    os.kill(driver.pid, signal.SIGKILL)
    driver.wait()
    deadline = time.time() + 10
    while time.time() < deadline and any(Path(f"/proc/{p}").exists() for p in workers):
        time.sleep(0.05)
    assert not any(Path(f"/proc/{p}").exists() and
                   Path(f"/proc/{p}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
                   for p in workers)
    assert main(["generate", "--preset", "demo", "--config", str(quick_config), "--seed", "3",
                 "--out", str(out)]) == 0  # the folder is free again and the run resumes


def test_two_runs_started_together_leave_one_writer(quick_config, tmp_path):
    out = tmp_path / "ds"
    cmd = [sys.executable, "-m", "glsynth", "generate", "--preset", "demo", "--config",
           str(quick_config), "--seed", "4", "--out", str(out)]
    runs = [subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
            for _ in range(2)]
    try:
        deadline = time.time() + 120
        while time.time() < deadline and all(r.poll() is None for r in runs):
            time.sleep(0.05)
        losers = [r for r in runs if r.poll() is not None]
        assert len(losers) == 1, "both runs are writing, or both ended"
        assert losers[0].returncode == 2
        assert "is in use by another glsynth run (pid" in losers[0].stderr.read()
    finally:
        for r in runs:
            if r.poll() is None:
                r.kill()
            r.wait()


def test_written_files_get_the_usual_mode(tmp_path):
    mask = os.umask(0o022)
    try:
        atomic_write_bytes(tmp_path / "a.txt", b"x")
        assert (tmp_path / "a.txt").stat().st_mode & 0o777 == 0o644
        os.umask(0o002)
        atomic_write_bytes(tmp_path / "b.txt", b"x")
        assert (tmp_path / "b.txt").stat().st_mode & 0o777 == 0o664
    finally:
        os.umask(mask)
