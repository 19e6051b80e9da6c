"""Processes of a run (glsynth.core.children, glsynth.core.runlock): children die with a killed
driver, a new run names the processes of an earlier one that still hold its folder, forked
readers never keep a folder, and a bad Blender is one line before any work.

Every test that starts processes runs them in a session of their own and kills that whole
session in ``finally``, so a failing test leaves nothing running. Reads /proc (Linux)."""

import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from glsynth.cli import main
from glsynth.core.errors import UserError
from glsynth.core.runlock import WORKERS_LOCK, RunLock, lock_holders

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")

BLENDER = shutil.which("blender")
needs_blender = pytest.mark.skipif(
    BLENDER is None, reason="Blender is not installed (Debian package blender; "
                            "scripts/install.sh installs it): Blender's processes are not tested")
GONE_S = 5.0
"""How soon a killed driver's children must be gone (they take well under a second)."""


def _stat(pid: int) -> list[str] | None:
    """/proc/PID/stat after the command name: state, ppid, pgrp, ...; None if gone."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None


def _alive(pid: int) -> bool:
    fields = _stat(pid)
    return fields is not None and fields[0] not in ("Z", "X")


def _command(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


def _live(select: Callable[[list[str]], bool]) -> list[int]:
    pids = (int(p.name) for p in Path("/proc").iterdir() if p.name.isdigit())
    return [pid for pid in pids if (f := _stat(pid)) and f[0] not in ("Z", "X") and select(f)]


def _children(pid: int) -> list[int]:
    return _live(lambda fields: int(fields[1]) == pid)


def _wait(condition: Callable[[], object], timeout_s: float, step_s: float = 0.02) -> object:
    """The first true value of ``condition()`` within ``timeout_s``, else the last value."""
    deadline = time.monotonic() + timeout_s
    while not (value := condition()) and time.monotonic() < deadline:
        time.sleep(step_s)
    return value


@contextmanager
def _session(argv: list[str], **options) -> Iterator[subprocess.Popen]:
    """``argv`` in a new session; whatever of that session still lives is killed at the end."""
    process = subprocess.Popen(argv, start_new_session=True, **options)
    try:
        yield process
    finally:
        for pid in [process.pid, *_live(lambda fields: int(fields[3]) == process.pid)]:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        process.wait(timeout=30)


def _python(code: str) -> list[str]:
    return [sys.executable, "-c", code]


# --- the lock and its holders, without Blender or torch ---------------------------------------
def test_a_child_holds_the_worker_lock_and_dies_with_its_driver(tmp_path):
    out = tmp_path / "run"
    code = ("from glsynth.core.runlock import RunLock; from glsynth.core.children import "
            f"run_child; RunLock({str(out)!r}).acquire(); run_child(['sleep', '60'], 120)")
    with _session(_python(code)) as driver:
        sleeper = _wait(lambda: [p for p in _children(driver.pid)
                                 if _command(p).startswith("sleep")], 30)
        assert sleeper, "the child never started"
        assert sleeper[0] in {pid for pid, _ in lock_holders(out / WORKERS_LOCK)}
        with pytest.raises(UserError, match=rf"another glsynth run \(pid {driver.pid}\)"):
            RunLock(out).acquire()
        driver.kill()
        driver.wait(timeout=10)
        assert _wait(lambda: not _alive(sleeper[0]), GONE_S), "the child outlived its driver"
    with RunLock(out):  # nothing of the killed run holds the folder
        pass


@contextmanager
def _lock_holder(out: Path, then: str, worker: bool = False
                 ) -> Iterator[tuple[subprocess.Popen, int]]:
    """A process that takes ``out``'s lock (a worker's, or a driver's) and runs ``then``, which
    prints a pid; the process and that pid."""
    code = ("import os, subprocess, time; from glsynth.core.runlock import RunLock; "
            f"lock = RunLock({str(out)!r}, worker={worker}).acquire(); {then}")
    with _session(_python(code), stdout=subprocess.PIPE, text=True) as process:
        yield process, int(process.stdout.readline())


def test_a_new_run_names_the_earlier_runs_processes_that_hold_the_folder(tmp_path):
    out = tmp_path / "run"
    with _lock_holder(out, "print(os.getpid(), flush=True); time.sleep(60)", worker=True) \
            as (worker, _):
        with pytest.raises(UserError) as refused:
            RunLock(out).acquire()
    message = str(refused.value)
    assert "worker processes of an earlier run" in message and f"pid {worker.pid} (" in message
    assert sys.executable in message and len(message) < 300


def test_a_driver_that_ended_is_named_beside_the_processes_that_kept_its_lock(tmp_path):
    out = tmp_path / "run"
    with _lock_holder(out, "print(subprocess.Popen(['sleep', '60'], pass_fds=(lock._fd,)).pid)"
                      ) as (driver, sleeper):
        driver.wait(timeout=30)
        with pytest.raises(UserError) as refused:
            RunLock(out).acquire()
        os.kill(sleeper, signal.SIGKILL)
    message = str(refused.value)
    assert f"pid {driver.pid}, ended" in message and f"pid {sleeper} (sleep 60)" in message


def test_a_forked_child_does_not_keep_the_run_folder(tmp_path):
    """A data loader's workers are forked from the training driver; a kill of the driver must
    leave the folder free at once, while they still live."""
    out = tmp_path / "run"
    with _lock_holder(out, "pid = os.fork(); pid == 0 and (time.sleep(60), os._exit(0)); "
                           "print(pid, flush=True); time.sleep(60)") as (driver, child):
        with pytest.raises(UserError, match=f"pid {driver.pid}"):
            RunLock(out).acquire()  # the driver's lock stands while it lives
        driver.kill()
        driver.wait(timeout=10)
        assert _alive(child)
        with RunLock(out):
            pass


# --- Blender ----------------------------------------------------------------------------------
TWO_VIADUCTS = "[environment]\nn_viaducts = 2\ncutoff_factor = 1.0\n"
"""The driver and Blender are what these tests watch: a smaller environment builds sooner."""


def _render_args(tmp_path: Path, *extra: str) -> list[str]:
    config = tmp_path / "c.toml"
    config.write_text("[cameras]\nn_regular = 1\nn_closeup = 1\n[damage]\nresolution = 64\n"
                      "[materials]\ntexture_size = 32\nbuiltin_size = 64\n"
                      "images_per_category = 3\n[render]\nwidth = 64\nheight = 36\n"
                      + TWO_VIADUCTS)
    return ["render", "--preset", "demo", "--config", str(config), "--seed", "0", "--env", "0",
            "--camera", "0", "--renderer", "cycles", *extra, "--out", str(tmp_path / "out")]


@pytest.mark.slow
@needs_blender
def test_a_killed_cycles_driver_leaves_no_blender_and_a_rerun_works(tmp_path):
    argv = [sys.executable, "-m", "glsynth", *_render_args(tmp_path, "--samples", "1")]
    with _session(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL) as driver:
        blender = _wait(lambda: [p for p in _children(driver.pid)
                                 if "blender_job.py" in _command(p)], 180)
        assert blender, "Blender never started"
        driver.kill()
        driver.wait(timeout=10)
        assert _wait(lambda: not _alive(blender[0]), GONE_S), "Blender outlived its driver"
    again = subprocess.run(argv, capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr
    assert (tmp_path / "out" / "image.png").is_file()


def _silent_blender(folder: Path) -> Path:
    """A stand-in for Blender that says it is one, then sleeps in silence on every job (a real
    Blender that prints would die of SIGPIPE once its driver is gone, hiding an orphan),
    appending its pid to ``<fake>.pids``; once ``<fake>.rerun`` exists, jobs end at once
    without output."""
    folder.mkdir()
    fake = folder / "blender"
    fake.write_text('#!/bin/sh\n[ "$1" = --version ] && { echo "Blender 3.4.1"; exit 0; }\n'
                    '[ -e "$0.rerun" ] && exit 0\necho $$ >> "$0.pids"\nexec sleep 120\n')
    fake.chmod(0o755)
    return fake


@pytest.mark.slow  # generates a dataset, twice
@pytest.mark.parametrize("workers", [1, 2])
def test_a_killed_generate_driver_leaves_no_blender_and_its_rerun_is_accepted(tmp_path,
                                                                               workers):
    """With one worker the driver starts Blender; with two, a pool worker does."""
    fake = _silent_blender(tmp_path / "bin")
    config = tmp_path / "c.toml"
    config.write_text("[cameras]\nn_regular = 1\nn_closeup = 0\n[damage]\nresolution = 64\n"
                      "[materials]\ntexture_size = 32\nimages_per_category = 3\n[dataset]\n"
                      "n_environments = 1\nn_test_environments = 0\nn_plates = 1\n"
                      "n_test_plates = 0\n[render]\nmsaa = 0\nshadow_map_px = 512\n"
                      "sky_visibility_maps = 4\nsky_visibility_px = 256\n" + TWO_VIADUCTS)
    out = tmp_path / "out"
    argv = [sys.executable, "-m", "glsynth", "generate", "--preset", "demo", "--config",
            str(config), "--seed", "3", "--renderer", "cycles", "--samples", "1", "--out",
            str(out), "--workers", str(workers)]
    env = {**os.environ, "PATH": f"{fake.parent}{os.pathsep}{os.environ['PATH']}"}
    pids = Path(f"{fake}.pids")

    def started() -> list[int]:
        return [int(p) for p in pids.read_text().split()] if pids.exists() else []

    with _session(argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL) as driver:
        blender = _wait(started, 300)[0]
        parent = int(_stat(blender)[1])
        assert driver.pid in (parent, int(_stat(parent)[1]))
        assert blender in {pid for pid, _ in lock_holders(out / WORKERS_LOCK)}
        driver.kill()
        driver.wait(timeout=10)
        assert _wait(lambda: not any(_alive(p) for p in started()), GONE_S), \
            "Blender outlived its driver"
        Path(f"{fake}.rerun").touch()
        again = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=300)
    # Past the lock and up to Blender, which now ends without output.
    assert again.returncode == 2 and "wrote no blender_times.json" in again.stderr, again.stderr


@pytest.mark.parametrize("program", ["/bin/false", "/bin/true"])
def test_a_program_that_is_not_blender_is_one_line_before_any_work(tmp_path, capsys, program):
    t0 = time.perf_counter()
    assert main(_render_args(tmp_path, "--blender", program)) == 2
    assert time.perf_counter() - t0 < 5  # no environment built, no GL context
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and len(err) < 300, err
    assert f"--blender '{program}'" in err and "is not Blender" in err
    assert not (tmp_path / "out").exists()


def test_a_blender_that_writes_nothing_is_one_line(tmp_path, capsys):
    fake = tmp_path / "blender"
    fake.write_text('#!/bin/sh\n[ "$1" = --version ] && echo "Blender 3.4.1"\nexit 0\n')
    fake.chmod(0o755)
    assert main(_render_args(tmp_path, "--blender", str(fake))) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and len(err) < 300, err
    assert f"Blender ({fake}) exited 0 but wrote no blender_times.json" in err


RENDER = ["render", "--renderer", "cycles", "--seed", "0", "--env", "0", "--camera", "0"]
GENERATE = ["generate", "--renderer", "cycles", "--seed", "0"]
BENCH = ["bench", "quality"]


@pytest.mark.parametrize("command, suggested, not_suggested", [
    (RENDER, ["give its path with --blender", "or use --renderer gl"], "put `blender`"),
    (GENERATE, ["put `blender` on PATH", "or use --renderer gl"], "--blender"),
    (BENCH, ["give its path with --blender", "or use --reference glsynth"], "--renderer"),
])
def test_without_blender_the_message_suggests_what_the_command_accepts(
        tmp_path, capsys, monkeypatch, command, suggested, not_suggested):
    monkeypatch.setenv("PATH", "/nonexistent")
    assert main([*command, "--preset", "demo", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Blender was not found" in err, err
    assert all(s in err for s in suggested) and not_suggested not in err, err
    assert not (tmp_path / "out").exists()


# --- training ---------------------------------------------------------------------------------
def test_training_resumes_at_once_after_a_kill(tiny_dataset, tmp_path):
    """The data loader's forked workers neither keep the run folder nor outlive the driver."""
    pytest.importorskip("torch", reason="needs the [model] extra")
    argv = [sys.executable, "-m", "glsynth", "train", "--task", "component", "--data",
            str(tiny_dataset), "--out", str(tmp_path / "run"), "--image-size", "192x108",
            "--batch-size", "2", "--schedule", "1e-3:1", "--loader-workers", "2", "--seed", "1"]
    with _session(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL) as driver:
        def loader_workers() -> list[int]:
            found = [p for p in _children(driver.pid) if "-m glsynth train" in _command(p)]
            return found if len(found) == 2 else []

        loaders = _wait(loader_workers, 300)
        assert loaders, "the data loader's workers never started"
        driver.kill()
        driver.wait(timeout=10)
        with _session(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                      text=True) as resumed:
            _, err = resumed.communicate(timeout=600)
        assert resumed.returncode == 0 and "in use" not in err, err
        assert not any(_alive(p) for p in loaders), "a loader worker outlived its driver"
