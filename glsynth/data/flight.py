"""glsynth fly: render an inspection flight ([flight]; glsynth.world.flights) and export it.

Layout of the output folder:

    frames/frame_NNNN/   image.png component.png damage.png depth.npy camera.json (as render)
    progress/frame_NNNN.done   a frame's marker, written after its files
    sparse/0/            COLMAP text model (cameras.txt, images.txt, points3D.txt)
    transforms.json      nerfstudio / instant-ngp
    points.ply           labelled point cloud
    environment.glb, scene.json   the environment (glsynth export, dressed as the flight saw it)
    flight.json          the flight's plan and counts, written last
    flight_run.json      the run's identity (seed, environment, settings)

The environment is built and uploaded once, culled to what the flight's cameras can see. A
killed run resumes at the first frame without a marker; the exports are made from the frames'
files, so a resumed flight writes the same bytes as an uninterrupted one.
"""

import hashlib
import json
import os
import shutil
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from glsynth.appearance.materials import srgb_decode
from glsynth.core.config import Config, MaterialsConfig, config_to_dict
from glsynth.core.errors import UserError, named
from glsynth.core.fileio import atomic_write_bytes, atomic_write_json, jsonable
from glsynth.core.runlock import DRIVER_LOCK, WORKERS_LOCK
from glsynth.data.flight_export import (
    Frame,
    ply_bytes,
    sample_points,
    visibility,
    write_colmap,
    write_transforms,
)
from glsynth.data.readers import (
    is_marker,
    read_float_map,
    read_json,
    read_label_map,
    read_rgb_image,
)
from glsynth.render.export import export_environment
from glsynth.render.gl.renderer import RenderOutput
from glsynth.render.view import EnvironmentView, free_camera_json, write_render
from glsynth.world.cameras import Camera
from glsynth.world.environment import build_environment
from glsynth.world.flights import FlightPlan, plan_flight, ring_overlap_pct, sensor_height_mm
from glsynth.world.lens import Lens, resample, source_camera, source_pixels
from glsynth.world.lighting import LUMINANCE, Lighting

RUN_FILE = "flight_run.json"
MID_GREY = 0.18
"""The linear luminance a metered flight's median pixel gets (18 % grey, as light meters
aim)."""
METERED_FRAMES = 4


def frame_name(index: int) -> str:
    return f"frame_{index:04d}"


def _prepare(out: Path, config: Config, root_seed: int, env: int) -> None:
    """Create or reopen ``out``; refuse a folder that holds another run or other files."""
    settings = {"root_seed": root_seed, "env": env, "config": config_to_dict(config)}
    digest = hashlib.sha256(json.dumps(settings, sort_keys=True, default=str).encode())
    identity = {"root_seed": root_seed, "env": env, "config_sha256": digest.hexdigest()}
    run_file = out / RUN_FILE
    if os.path.lexists(run_file):
        recorded = read_json(run_file, {}, "move the folder aside and fly into a new one",
                             "flight run file")
        if recorded != identity:
            raise UserError(f"--out {named(out)} holds a flight with other settings; use a new "
                            "folder, or the same preset, config, seed and env to resume it")
        for stale in out.rglob(".*.tmp"):  # interrupted atomic writes of a killed run
            stale.unlink()
    elif any(p.name not in (DRIVER_LOCK, WORKERS_LOCK) for p in out.iterdir()):
        raise UserError(f"--out {named(out)} is not empty and holds no glsynth flight; use a "
                        "new or empty folder")
    atomic_write_json(run_file, identity)


def flight_materials(materials: MaterialsConfig) -> MaterialsConfig:
    """[materials] as a flight draws them: concrete detail "flights" turns it on."""
    if materials.concrete_detail == "flights":
        return replace(materials, concrete_detail="on")
    return materials


def _frame_meta(lens: Lens, plan: FlightPlan, index: int, meta: dict) -> dict:
    """What a frame's camera.json holds beside the camera itself."""
    return {"kind": "flight", "lens": {"model": lens.model, "k1": lens.k1, "k2": lens.k2},
            "frame": index, "time_s": float(plan.times_s[index]), "plan": plan.plan, **meta}


def _distorted(output: RenderOutput, where: np.ndarray | None) -> RenderOutput:
    """A source render resampled through the lens (glsynth.world.lens); as it is without."""
    if where is None:
        return output
    return RenderOutput(color=resample(output.color, where, nearest=False),
                        component=resample(output.component, where, nearest=True),
                        damage=resample(output.damage, where, nearest=True),
                        depth=resample(output.depth, where, nearest=True),
                        crack_width=resample(output.crack_width, where, nearest=True))


FRAME_FIX = "it is rendered again on resume"


def _read_frame(out: Path, index: int, camera: Camera, lens: Lens, info: dict) -> Frame:
    """Frame ``index`` as written, each file checked against its contract (glsynth.data.
    readers) and its camera.json against ``info``, what the plan writes there."""
    folder = out / "frames" / frame_name(index)
    written = read_json(folder / "camera.json", {}, FRAME_FIX, "frame camera")
    if written != json.loads(json.dumps(jsonable(info))):
        raise UserError(f"frame camera {named(folder / 'camera.json')} is not the camera this "
                        f"flight plans for frame {index}; {FRAME_FIX}")
    size = (camera.width, camera.height)
    return Frame(f"frames/{frame_name(index)}/image.png", camera, lens, info["time_s"],
                 read_rgb_image(folder / "image.png", "frame image", size),
                 read_label_map(folder / "component.png", "component", size),
                 read_label_map(folder / "damage.png", "damage", size),
                 read_float_map(folder / "depth.npy", "frame depth map", size, FRAME_FIX))


def exposed(view: EnvironmentView, cameras: list[Camera], mode: str) -> Lighting:
    """The flight's lighting, its renderer relit by it. "metered": the camera exposes once
    for the whole flight, as a drone's does with its exposure locked: the scene's exposure
    times MID_GREY over the median luminance of METERED_FRAMES frames spread along the path
    (rendered at the scene's exposure); "scene": the environment's [lighting] exposure."""
    if mode == "scene" or not cameras:
        return view.lighting
    picks = sorted({round(i * (len(cameras) - 1) / max(1, METERED_FRAMES - 1))
                    for i in range(METERED_FRAMES)})
    luminance = np.concatenate([
        srgb_decode(view.renderer.render(cameras[i], {"color"}).color).reshape(-1, 3)
        @ LUMINANCE for i in picks])
    median = max(float(np.median(luminance)), 1e-4)  # a black view: at most 1800x brighter
    lighting = replace(view.lighting, exposure=view.lighting.exposure * MID_GREY / median)
    view.renderer.relight(lighting)
    return lighting


def _finished(out: Path, index: int, read: Callable[[int], Frame]) -> bool:
    """Whether frame ``index`` has its marker and files that pass their checks; a frame
    with a marker whose files do not is rendered again, with a warning naming the file."""
    marker = out / "progress" / f"{frame_name(index)}.done"
    if not is_marker(marker):
        return False
    try:
        read(index)
    except UserError as err:
        warnings.warn(f"rendering {frame_name(index)} again: {err}", stacklevel=2)
        marker.unlink()
        return False
    return True


def _render_frames(view: EnvironmentView, out: Path, sources: list[Camera],
                   where: np.ndarray | None, write: Callable[[int, RenderOutput], None],
                   read: Callable[[int], Frame]) -> int:
    """Render the frames not yet _finished from their ``sources`` (the pinhole cameras the
    lens resamples, glsynth.world.lens) and ``write`` them; how many were rendered."""
    rendered = 0
    for index, source in enumerate(sources):
        if _finished(out, index, read):
            continue
        # What a killed run or a damaged frame left there (a folder where a file goes) goes.
        shutil.rmtree(out / "frames" / frame_name(index), ignore_errors=True)
        write(index, _distorted(view.renderer.render(source), where))
        atomic_write_bytes(out / "progress" / f"{frame_name(index)}.done", b"")
        rendered += 1
    return rendered


def _velocities(cameras: list[Camera], times_s: list[float]) -> np.ndarray:
    """(N, 3) world velocity of each frame's camera, m/s: central differences along the path
    (one-sided at its ends); 0 between frames taken at the same time."""
    centres = np.array([c.pose[:3, 3] for c in cameras], np.float64).reshape(-1, 3)
    times = np.asarray(times_s, np.float64)
    after = np.minimum(np.arange(len(times)) + 1, len(times) - 1)
    before = np.maximum(np.arange(len(times)) - 1, 0)
    dt = (times[after] - times[before])[:, None]
    moved = centres[after] - centres[before]
    return np.divide(moved, dt, out=np.zeros_like(moved), where=dt > 0)


def export_flight(out: Path, frames: list[Frame], config: Config) -> dict:
    """sparse/0, transforms.json and points.ply from the frames' files; their counts."""
    points = sample_points(frames, config.flight.point_stride_px, config.flight.point_spacing_m)
    ids, pixels = visibility(frames, points["xyz"])
    seen_by: list[list[int]] = [[] for _ in range(len(points["xyz"]))]
    for j, frame_ids in enumerate(ids):
        for p in frame_ids:
            seen_by[p].append(j)
    write_colmap(out / "sparse" / "0", frames, points["xyz"], points["rgb"], ids, pixels)
    write_transforms(out / "transforms.json", frames)
    atomic_write_bytes(out / "points.ply", ply_bytes(
        points["xyz"], points["rgb"], points["component"], points["damage"],
        [np.array(s, np.int64) for s in seen_by]))
    return {"points": len(points["xyz"]), "observations": int(sum(len(i) for i in ids))}


def _check_renderer(config: Config) -> None:
    if config.render.renderer != "gl":
        raise UserError(f"[render] renderer = {config.render.renderer!r}: glsynth fly renders "
                        'with GL; set renderer = "gl" in --config')


@dataclass(frozen=True)
class CheckedFlight:
    """What check_flight found: the plan, its lens, and the canvas the lens resamples."""

    plan: FlightPlan
    lens: Lens
    size: Camera


def check_flight(config: Config, root_seed: int, env_index: int) -> CheckedFlight:
    """Plan and validate the flight, writing nothing: a refused plan leaves no folder."""
    _check_renderer(config)
    plan = plan_flight(build_environment(config, root_seed, env_index), config, validate=True)
    fc, r = config.flight, config.render
    lens = Lens(fc.camera_model, fc.k1, fc.k2)
    # The lens's canvas depends on the intrinsics alone, not on a pose; making it checks them.
    size = source_camera(Camera(r.width, r.height, fc.focal_mm, config.cameras.sensor_mm,
                                np.eye(4), r.znear_m, r.zfar_m), lens)
    return CheckedFlight(plan, lens, size)


def _finished_flight(out: Path) -> dict | None:
    """flight.json, written last, of a complete flight; None if the flight is not complete,
    or if the file is damaged (with a warning: the exports are then made again)."""
    path = out / "flight.json"
    if not os.path.lexists(path):
        return None
    try:
        return read_json(path, {"plan": str, "frames": int, "spacing_m": (int, float),
                                "parts_built": int, "parts": int, "points": int},
                         "it is made again", "flight summary")
    except UserError as err:
        warnings.warn(str(err), stacklevel=2)
        return None


def run_flight(config: Config, root_seed: int, env_index: int, out: Path,
               checked: CheckedFlight) -> dict:
    """Render the frames of a checked flight not yet written, then export; the caller holds
    the folder's run lock. Returns the flight's summary (flight.json) and timings."""
    _prepare(out, config, root_seed, env_index)
    done = _finished_flight(out)
    if done is not None:
        return {**done, "open_s": 0.0, "rendered": 0, "render_s_per_frame": None}
    plan, lens, size, fc = checked.plan, checked.lens, checked.size, config.flight
    t0 = time.perf_counter()
    source_config = replace(config, render=replace(config.render, width=size.width,
                                                   height=size.height),
                            materials=flight_materials(config.materials))
    cameras = plan.cameras(config)
    sources = [replace(c, width=size.width, height=size.height) for c in cameras]
    view = EnvironmentView.open(source_config, root_seed, env_index, cameras=sources)
    opened = time.perf_counter() - t0
    where = None if lens.pinhole else source_pixels(cameras[0], lens, size)
    t1 = time.perf_counter()
    with view.renderer:
        lighting = exposed(view, sources, fc.exposure)
        meta = {"root_seed": root_seed, "env": env_index, "renderer": "gl",
                "exposure": lighting.exposure}

        def info(index: int) -> dict:
            return free_camera_json(cameras[index], _frame_meta(lens, plan, index, meta))

        def read(index: int) -> Frame:
            return _read_frame(out, index, cameras[index], lens, info(index))

        velocities = _velocities(cameras, list(plan.times_s))

        def write(index: int, output: RenderOutput) -> None:
            # Photographed by [sensor]'s camera, moving along the path (motion blur).
            output = view.photograph(output, cameras[index], index, velocities[index])
            write_render(out / "frames" / frame_name(index), cameras[index], output,
                         _frame_meta(lens, plan, index, meta))

        rendered = _render_frames(view, out, sources, where, write, read)
    render_s = time.perf_counter() - t1
    export_environment(view.environment, out / "environment.glb", view.dressing.materials,
                       lighting)
    rings = ({"ring_overlap_pct": ring_overlap_pct(fc, sensor_height_mm(config))}
             if plan.plan == "orbit" else {})
    summary = {"plan": plan.plan, "frames": len(plan), "spacing_m": plan.spacing_m, **rings,
               "exposure": lighting.exposure,
               "duration_s": float(plan.times_s[-1]), "parts_built": len(view.scene.parts),
               "parts": len(view.environment.parts),
               **export_flight(out, [read(i) for i in range(len(plan))], config),
               "flight": config_to_dict(config)["flight"]}
    atomic_write_json(out / "flight.json", summary)
    return {**summary, "open_s": opened, "rendered": rendered,
            "render_s_per_frame": render_s / rendered if rendered else None}
