"""The Cycles twin: the colour of glsynth views path-traced by Blender Cycles, the paper's
renderer, from the same scene (glsynth/render/blender_job.py runs inside Blender).

What is shared: the uploaded parts with their dressed materials (the full-material glTF of
glsynth.render.gltf), the camera and sensor, the environment's Lighting (sun, sky, exposure)
and the tone map (glsynth.render.tonemap, applied here to Cycles' linear output). What Cycles
adds: global illumination, exact soft shadows, occlusion and the sky seen by every surface.
A part's cracks (Material.cracks) are baked into a coverage texture with texels fine enough
for the cameras (glsynth.render.crack_texture) and darken its surface by the GL crack pass's
contrast. Labels and depth always come from the GL label pass, so a Cycles image and a glsynth
image of one view share their ground truth byte for byte. Cycles runs on the CPU with a seed
per view (Stream.CYCLES), so a view is reproduced exactly from its seeds.

Blender is optional: ``blender`` on PATH (Debian's package, 3.4) or a path given by the caller.
"""

import functools
import json
import re
import shutil
import subprocess
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from glsynth.appearance.materials import Material
from glsynth.core.children import run_child
from glsynth.core.errors import UserError
from glsynth.core.fileio import atomic_write_bytes, atomic_write_json, png_bytes
from glsynth.core.seeding import Stream, make_seed
from glsynth.render.crack_texture import (
    BLOCK,
    LOOKUP_TOLERANCE_M,
    bake_for_views,
    encode,
    framed,
)
from glsynth.render.cracks_index import crack_contrast
from glsynth.render.export import describe_lighting
from glsynth.render.gltf import gltf_binary
from glsynth.render.tonemap import tone_map
from glsynth.world.cameras import Camera
from glsynth.world.environment import Part
from glsynth.world.lighting import Lighting

JOB = Path(__file__).with_name("blender_job.py")
CHECK_TIMEOUT_S = 60.0
"""How long ``blender --version`` may take (0.2 s for Debian's Blender 3.4)."""


def find_blender(path: str | None = None) -> str | None:
    """The Blender executable: ``path`` if given (an error if it is not there or not Blender),
    else ``blender`` from PATH, if any."""
    if path is None:
        found = shutil.which("blender")
        return None if found is None else check_blender(
            found, "`blender` on PATH", "put Blender 3.4 or later first on PATH")
    found = shutil.which(path)
    if found is None:
        raise UserError(f"--blender {path!r}: no such executable; give the path of Blender, "
                        "or leave it out to use `blender` from PATH")
    return check_blender(found, f"--blender {path!r}", "give the path of Blender 3.4 or later")


@functools.cache
def check_blender(executable: str, named: str, fix: str) -> str:
    """``executable`` if ``executable --version`` says it is Blender: checked once a process,
    before any work, so a wrong program fails in a second with one line."""
    try:
        done = run_child([executable, "--version"], CHECK_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        raise UserError(f"{named} ({executable}): `--version` ran past {CHECK_TIMEOUT_S:.0f} "
                        f"s, so it is not Blender; {fix}") from None
    except OSError as err:
        raise UserError(f"{named} ({executable}) does not run ({err.strerror}); {fix}") from None
    if done.returncode != 0 or not re.search(r"^Blender \d", done.stdout, re.MULTILINE):
        said = " ".join(done.stdout.split()[:4])[:40] or "nothing"
        raise UserError(f"{named} ({executable}) is not Blender: `--version` exited "
                        f"{done.returncode} and printed {said!r}; {fix}")
    return executable


def require_blender(path: str | None = None, *, option: bool = False,
                    instead: str = "--renderer gl") -> str:
    """The Blender executable (see find_blender), or an error saying how to give it: with
    ``--blender`` if the command has that ``option``, else on PATH, or ``instead``, the
    command's way to do without it."""
    found = find_blender(path)
    if found is None:
        where = "give its path with --blender" if option else "put `blender` on PATH"
        raise UserError("Blender was not found on PATH: the Cycles renderer needs it. Install "
                        f"it (Debian: apt install blender python3-numpy) and {where}, or use "
                        f"{instead}")
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
    times = work / "blender_times.json"
    times.unlink(missing_ok=True)  # a stale one must not pass for this job's
    try:
        done = run_child([blender, "-b", "--factory-startup", "--python-exit-code", "1",
                          "-P", str(JOB), "--", str(work / "job.json")], timeout_s)
    except subprocess.TimeoutExpired as err:
        raise UserError(f"Blender ran past its {timeout_s:.0f} s limit; give fewer samples "
                        "or a longer --timeout") from err
    if done.returncode != 0:
        tail = "\n".join((done.stdout + done.stderr).splitlines()[-15:])
        raise RuntimeError(f"Blender failed (exit {done.returncode}):\n{tail}")
    if not times.exists():
        raise UserError(f"Blender ({blender}) exited 0 but wrote no {times.name}: it did not "
                        "run glsynth's job script. Check that it is Blender 3.4 or later with "
                        "its Python (`blender -b --python-expr 'import bpy'`)")
    return json.loads(times.read_text())


def crack_jobs(parts: Sequence[Part], materials: dict[str, Material],
               cameras: Sequence[Camera], work: Path) -> list[dict]:
    """The job's cracks: per part with cracks, its crack texture for ``cameras`` (images
    written to ``work``) and where it lies on the part."""
    shown = {p.name: framed(materials[p.name].cracks, p.pose, cameras) for p in parts
             if materials[p.name].cracks is not None}
    cracked = [p for p in parts if p.name in shown and len(shown[p.name].points)]
    textures = bake_for_views([(shown[p.name], p.mesh, p.pose) for p in cracked], cameras)
    jobs = []
    for i, (part, texture) in enumerate(zip(cracked, textures)):
        images = {"indirection": encode(texture.indirection, 1), "atlas": encode(texture.atlas)}
        for name, rgb in images.items():
            atomic_write_bytes(work / f"cracks_{i}_{name}.png", png_bytes(rgb))
        jobs.append({
            "part": part.name, "pose": part.pose.tolist(),
            "contrast": crack_contrast(materials[part.name].cracks),
            "tolerance_m": LOOKUP_TOLERANCE_M, "block_m": BLOCK * texture.texel_m,
            **{name: str(work / f"cracks_{i}_{name}.png") for name in images},
            "indirection_size": list(texture.indirection.shape[::-1]),
            "atlas_blocks": texture.atlas.shape[0] // BLOCK,
            "planes": [{"normal": g.normal.tolist(), "offset": g.offset,
                        "u_axis": g.u_axis.tolist(), "v_axis": g.v_axis.tolist(),
                        "corner": g.corner.tolist(), "blocks": list(g.blocks),
                        "column": g.column} for g in texture.planes]})
    return jobs


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
           "lighting": describe_lighting(lighting),
           "cracks": crack_jobs(parts, materials, cameras, work)}
    times = run_job(blender, job, work, timeout_s)
    for member in job["cracks"]:
        Path(member["indirection"]).unlink()
        Path(member["atlas"]).unlink()
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
