"""The Cycles twin: the colour of glsynth views path-traced by Blender Cycles, the paper's
renderer, from the same scene (glsynth/render/blender_job.py runs inside Blender).

What is shared: the uploaded parts with their dressed materials (the full-material glTF of
glsynth.render.gltf), the camera and sensor, the environment's Lighting (sun, sky, exposure)
and the tone map (glsynth.render.tonemap, applied here to Cycles' linear output). What Cycles
adds: global illumination, exact soft shadows, occlusion and the sky seen by every surface.
Labels and depth always come from the GL label pass, so a Cycles image and a glsynth image of
one view share their ground truth byte for byte. Cycles runs on the CPU with a seed per view
(Stream.CYCLES), so a view is reproduced exactly from its seeds.

Blender is optional: ``blender`` on PATH (Debian's package, 3.4) or a path given by the caller.
"""

import json
import shutil
import subprocess
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from glsynth.appearance.materials import Material
from glsynth.core.errors import UserError
from glsynth.core.fileio import atomic_write_bytes, atomic_write_json
from glsynth.core.seeding import Stream, make_seed
from glsynth.render.export import describe_lighting
from glsynth.render.gltf import gltf_binary
from glsynth.render.tonemap import tone_map
from glsynth.world.cameras import Camera
from glsynth.world.environment import Part
from glsynth.world.lighting import Lighting

JOB = Path(__file__).with_name("blender_job.py")
NO_BLENDER = ("Blender was not found: the Cycles renderer needs it. Install it (Debian: apt "
              "install blender python3-numpy), give its path with --blender, or use the GL "
              "renderer (--renderer gl)")


def find_blender(path: str | None = None) -> str | None:
    """The Blender executable: ``path`` if given (an error if it is not there), else PATH."""
    if path is None:
        return shutil.which("blender")
    found = shutil.which(path)
    if found is None:
        raise UserError(f"--blender {path!r}: no such executable; give the path of Blender, "
                        "or leave it out to use `blender` from PATH")
    return found


def require_blender(path: str | None = None) -> str:
    found = find_blender(path)
    if found is None:
        raise UserError(NO_BLENDER)
    return found


def camera_json(cam: Camera) -> dict:
    return {"pose": cam.pose.tolist(), "focal_mm": cam.focal_mm, "sensor_mm": cam.sensor_mm,
            "width": cam.width, "height": cam.height, "znear": cam.znear, "zfar": cam.zfar}


def cycles_seed(root_seed: int, env: int, item: int) -> int:
    """Cycles' seed (a non-negative int32) of one view: item = camera index, or 1,000,000 + N
    for plate N (env 0)."""
    return make_seed(root_seed, env, Stream.CYCLES, item) % (2 ** 31 - 1)


def read_raw(path: Path, size: Sequence[int]) -> np.ndarray:
    """A raw float32 RGBA image written bottom row first, top row first (H, W, 4)."""
    w, h = size
    return np.fromfile(path, np.float32).reshape(h, w, 4)[::-1].copy()


def run_job(blender: str, job: dict, work: Path, timeout_s: float) -> dict:
    """Run blender_job.py on ``job`` (written to work/job.json); its times and sizes."""
    atomic_write_json(work / "job.json", job)
    try:
        done = subprocess.run([blender, "-b", "--factory-startup", "--python-exit-code", "1",
                               "-P", str(JOB), "--", str(work / "job.json")],
                              capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired as err:
        raise UserError(f"Blender ran past its {timeout_s:.0f} s limit; give fewer samples "
                        "or a longer --timeout") from err
    if done.returncode != 0:
        tail = "\n".join((done.stdout + done.stderr).splitlines()[-15:])
        raise RuntimeError(f"Blender failed (exit {done.returncode}):\n{tail}")
    return json.loads((work / "blender_times.json").read_text())


@dataclass(frozen=True)
class CyclesResult:
    linear: list[np.ndarray]
    """Per camera, (H, W, 3) float32 linear radiance (before exposure)."""
    colour_s: list[float]
    import_s: float
    blender: str


def render_linear(parts: Sequence[Part], materials: dict[str, Material], lighting: Lighting,
                  cameras: Sequence[Camera], seeds: Sequence[int],
                  samples: int | Sequence[int], work: Path, blender: str,
                  timeout_s: float = 24 * 3600.0) -> CyclesResult:
    """Path-trace ``cameras`` of one scene at ``samples`` (one count, or one per camera);
    ``work`` is a scratch folder (its files are replaced). One Blender process imports the
    scene once for all cameras."""
    counts = [samples] * len(cameras) if isinstance(samples, int) else list(samples)
    if not cameras:
        return CyclesResult([], [], 0.0, "")
    work.mkdir(parents=True, exist_ok=True)
    glb = work / "scene.glb"
    atomic_write_bytes(glb, gltf_binary(parts, materials))
    job = {"mode": "twin", "glb": str(glb), "out": str(work), "samples": [int(n) for n in counts],
           "seeds": [int(s) for s in seeds], "cameras": [camera_json(c) for c in cameras],
           "lighting": describe_lighting(lighting)}
    times = run_job(blender, job, work, timeout_s)
    images = []
    for i, size in enumerate(times["sizes"]):
        path = work / f"cycles_{i}.f32"
        images.append(read_raw(path, size)[..., :3])
        path.unlink()
    return CyclesResult(images, times["colour_s"], times["import_s"], times["blender"])


def display(linear: np.ndarray, lighting: Lighting) -> np.ndarray:
    """Cycles' linear radiance through glsynth's exposure and tone map: uint8 sRGB."""
    return tone_map(linear, lighting.exposure)


def cycles_colour(view, placements: Sequence, work: Path, blender: str | None = None
                  ) -> list[np.ndarray]:
    """The Cycles twin's uint8 colour of views of an open EnvironmentView (its uploaded parts,
    dressing and lighting; [cycles] samples), one Blender process for all of them;
    ``work`` is removed afterwards."""
    env = view.environment
    parts = [p for p in env.parts if p.name in view.scene.parts]
    seeds = [cycles_seed(env.root_seed, env.env_index, p.index) for p in placements]
    try:
        result = render_linear(parts, view.dressing.materials, view.lighting,
                               [p.camera for p in placements], seeds,
                               view.config.cycles.samples, work, require_blender(blender))
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return [display(x, view.lighting) for x in result.linear]
