"""A running ``glsynth view`` for the viewer's server and browser tests."""

import json
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

VIEW_ARGS = ["--preset", "demo", "--quality", "fast", "--seed", "0", "--env", "0"]
"""The scene of every viewer test: `glsynth render` with the same arguments draws it too."""
SCENE_TOML = "[environment]\njacket_probability = 0.0\nn_viaducts = 1\ncutoff_factor = 0.5\n"
"""... with bare columns (the demo preset jackets most of environment 0's viaducts, and the
browser tests click a column) and one viaduct (the least the config allows; one viaduct needs
cutoff_factor <= 0.5): each server and render opens the scene anew, and ten took 6 s an
opening, two 1.1 s, one 0.8 s."""


def scene_args(folder: Path, extra_toml: str = "") -> list[str]:
    """VIEW_ARGS and a --config of SCENE_TOML (and ``extra_toml``) written into ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "scene.toml").write_text(SCENE_TOML + extra_toml)
    return [*VIEW_ARGS, "--config", str(folder / "scene.toml")]


def _ctrl_c_as_at_a_terminal() -> None:
    """The server's SIGINT as a terminal's Ctrl-C reaches it: a test run started as a
    background job ignores SIGINT, and its children would inherit that and exit 0."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def view_process(out: Path, *extra: str, env: dict | None = None) -> subprocess.Popen:
    """``glsynth view`` of the tests' scene started, saving into ``out``, its output piped
    (``env``: the child's environment, default this one's)."""
    scene = scene_args(out.with_name(out.name + "_scene"))
    return subprocess.Popen(
        [sys.executable, "-m", "glsynth", "view", *scene, "--port", "0", "--out", str(out),
         *extra], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env,
        preexec_fn=_ctrl_c_as_at_a_terminal)


class ViewServer:
    """``glsynth view`` in a child process on a free port; ``stop()`` sends Ctrl-C."""

    def __init__(self, out: Path, *extra: str, env: dict | None = None) -> None:
        self.out = out
        self.proc = view_process(out, *extra, env=env)
        line = self.proc.stdout.readline()
        found = re.search(r"(http://\S+/)", line)
        if not found:
            self.proc.kill()
            raise AssertionError(f"glsynth view did not start: {line}{self.proc.stdout.read()}")
        self.url = found.group(1)
        self.ws_url = self.url.replace("http://", "ws://") + "ws"

    def stop(self, timeout: float = 60.0) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
        try:
            return self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
            raise


def receive(ws, want: str, timeout: float = 120.0) -> dict | tuple[dict, bytes]:
    """The next message of type ``want`` (a frame comes as (header, image bytes)); others
    are skipped."""
    deadline = time.monotonic() + timeout
    while True:
        message = ws.recv(timeout=max(0.1, deadline - time.monotonic()))
        if isinstance(message, bytes):
            n = int.from_bytes(message[:4], "big")
            header = json.loads(message[4:4 + n])
            if want == "frame":
                return header, message[4 + n:]
        elif json.loads(message)["type"] == want:
            return json.loads(message)


def render_camera_json(camera: dict, folder: Path, photo: bool = True,
                       *extra: str) -> Path:
    """`glsynth render --camera-json` of ``camera`` into ``folder``, with the viewer tests'
    scene; ``photo`` False: the render before the camera model ([sensor] off), which is what
    the viewer's live frames show. ``extra``: more arguments (a server's own, such as
    ``--quality preview``)."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "camera_in.json").write_text(json.dumps(camera))
    args = scene_args(folder, "" if photo else "[sensor]\nenabled = false\n")
    subprocess.run([sys.executable, "-m", "glsynth", "render", *args,
                    "--camera-json", str(folder / "camera_in.json"), "--out", str(folder),
                    *extra],
                   check=True, capture_output=True, timeout=300)
    return folder
