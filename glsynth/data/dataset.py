"""Dataset generation in the Tokaido layout (paper Sections 3.4, 4.2; format in docs/design.md).

Work comes in units: one environment (all its cameras) or a run of plates. A unit writes its
files atomically and then a marker under ``progress/`` holding its manifest rows and counts; a
run that is stopped and started again skips the units with markers and redoes the others,
rewriting identical bytes. The manifests are merged from the markers at the end, sorted, so
the dataset is the same whatever the number of workers or the order units finished in.
How units are run (one process, a local pool, Ray) is in glsynth/data/engines.py.
"""

import dataclasses
import hashlib
import json
import os
import resource
import shutil
import time
import warnings
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import TYPE_CHECKING

import numpy as np

from glsynth.core.config import Config, FiltersConfig, config_to_dict
from glsynth.core.errors import UserError, named
from glsynth.core.fileio import (
    BackgroundWriter,
    atomic_write_bytes,
    atomic_write_json,
    jsonable,
    png_bytes,
    write_files,
)
from glsynth.core.filters import (
    is_dark,
    label_reason,
    mask_damage,
    removal_before_resolve,
    view_rrdr,
)
from glsynth.core.labels import Damage
from glsynth.core.runlock import DRIVER_LOCK, WORKERS_LOCK
from glsynth.data.readers import is_marker, read_json
from glsynth.data.statistics import (
    CrackLength,
    ImageCounts,
    dataset_statistics,
    image_counts,
    read_removals,
)
from glsynth.data.tokaido import (
    IMAGE_SIZE,
    LABEL_STRIDE,
    FrameRecord,
    PuretexRecord,
    downsample_crack_width,
    downsample_labels,
    encode_crack_width,
    encode_depth,
    frame_paths,
    manifest_text,
    mark_cracked_blocks,
    puretex_paths,
)
from glsynth.data.visible_cracks import visible_cracks

if TYPE_CHECKING:  # the world layer is imported where a view is opened, not at import
    from glsynth.render.gl.renderer import Renderer, RenderOutput
    from glsynth.world.cameras import CameraPlacement

RUN_FILE = "glsynth_run.json"
REASONS = ("dark", "single_component", "too_close")
_FORMATS = {"component": "BMP", "damage": "BMP", "depth": "PNG", "crackwidth": "PNG"}
"""The label maps a kept view writes, with their file formats."""


def check_format(config: Config) -> None:
    r = config.render
    (w, h), stride = IMAGE_SIZE, LABEL_STRIDE
    if (r.width, r.height) != IMAGE_SIZE:
        raise UserError(f"render size {r.width}x{r.height}: the Tokaido format needs {w}x{h} "
                        f"images (labels {w // stride}x{h // stride}); set [render] width = {w} "
                        f"and height = {h}")


def environment_split(config: Config, env: int) -> str:
    d = config.dataset
    return "test" if env >= d.n_environments - d.n_test_environments else "train"


def plate_split(config: Config, index: int) -> str:
    d = config.dataset
    return "test" if index >= d.n_plates - d.n_test_plates else "train"


@dataclass(frozen=True)
class Task:
    kind: str
    """'env' or 'plates'."""
    first: int
    count: int = 1

    @property
    def marker(self) -> str:
        return (f"progress/env_{self.first:06d}.json" if self.kind == "env"
                else f"progress/plates_{self.first:07d}.json")


def plan(config: Config) -> list[Task]:
    d = config.dataset
    tasks = [Task("env", e) for e in range(d.n_environments)]
    tasks += [Task("plates", s, min(d.plates_per_task, d.n_plates - s))
              for s in range(0, d.n_plates, d.plates_per_task)]
    return tasks


def _row(placement: "CameraPlacement", paths: dict[str, str], in_rrdr: bool) -> dict:
    """A kept view's manifest row."""
    return dataclasses.asdict(FrameRecord(
        paths["image"], paths["component"], paths["damage"], paths["depth"],
        round(placement.camera.focal_mm, 6), placement.kind == "regular", in_rrdr))


def _counts(placement: "CameraPlacement", split: str, maps: dict[str, np.ndarray],
            in_rrdr: bool, cracks: list[dict]) -> dict:
    """A kept view's image counts (glsynth.data.statistics)."""
    return dataclasses.asdict(image_counts(
        placement.kind, split, maps["component"], maps["damage"], maps["depth"],
        round(placement.camera.focal_mm, 6), in_rrdr, maps["crackwidth"], CrackLength(
            sum(c["labelled_length_m"] for c in cracks), placement.camera.fx,
            placement.camera.width)))


def run_environment(config: Config, root_seed: int, env: int, out: Path, renderer) -> dict:
    """Render, filter and write every camera of one environment; returns its marker data:
    manifest rows, the counts of each written image (glsynth.data.statistics) and the views
    removed by camera kind and reason."""
    from glsynth.render.view import EnvironmentView
    from glsynth.world.environment import PartKind

    clock = _Clock()
    view = EnvironmentView.open(config, root_seed, env, renderer)
    clock.lap("environment, materials and damage textures")
    split = environment_split(config, env)
    rows, counts = [], []
    removed = {kind: dict.fromkeys(REASONS, 0) for kind in ("regular", "closeup")}
    columns = [p for p in view.environment.parts if p.kind is PartKind.COLUMN]
    networks, records = _crack_networks(view)
    to_cycles = []  # (placement, image path) of the kept views, with --renderer cycles
    with BackgroundWriter() as writer:
        for index in range(config.cameras.total):
            # The filters judge the render; only the views they keep are photographed.
            placement, output = view.render(index, photo=False, defer_colour=True)
            clock.lap("render and read back")
            reason, output = _filtered(view.renderer, output, config.filters)
            if reason is not None:
                removed[placement.kind][reason] += 1
                clock.lap("filters, RRDR and labels")
                continue
            maps, in_rrdr, widths = _label_maps(output, placement.camera, config.filters)
            cracks = visible_cracks(view.environment.parts, networks, records,
                                    placement.camera, widths, output.depth,
                                    maps["crackwidth"], LABEL_STRIDE)
            clock.lap("filters, RRDR and labels")
            paths = frame_paths(split, env, index)
            images = {paths[name]: (maps[name], fmt) for name, fmt in _FORMATS.items()}
            if config.render.renderer == "cycles":
                to_cycles.append((placement, paths["image"]))
            else:
                images[paths["image"]] = (view.photograph(output, placement.camera,
                                                          index).color, "PNG")
                clock.lap("camera model")
            meta = _view_meta(view, placement, root_seed, env, split, in_rrdr, columns)
            meta["cracks_in_view"] = cracks
            writer.submit(write_files, out, images,
                          {f"meta/{split}/image_case{env}_frame{index}.json": meta})
            rows.append(_row(placement, paths, in_rrdr))
            counts.append(_counts(placement, split, maps, in_rrdr, cracks))
            clock.lap("queue files")
    clock.lap("wait for the writer")
    if to_cycles:
        _write_cycles_colour(view, to_cycles, out, env, clock)
    atomic_write_json(out / "meta" / f"env_{env}.json", _env_description(view))
    clock.lap("encode and write files")
    return {"kind": "env", "env": env, "split": split, "rows": rows, "counts": counts,
            "removed": removed, "timings": clock.totals}


def _filtered(renderer: "Renderer", output: "RenderOutput", filters: FiltersConfig
              ) -> tuple[str | None, "RenderOutput"]:
    """removal_reason of a view rendered with its colour deferred (Renderer.render), and the
    output with its colour: the MSAA pass runs only where the single-sample colour leaves the
    answer open (removal_before_resolve), so a view removed by its labels, or dark by a clear
    margin, costs no MSAA pass; the answer is the same either way."""
    by_labels = label_reason(output.component, output.depth, filters)
    reason = removal_before_resolve(renderer.deferred_colour(resolved=False), by_labels,
                                    filters)
    if reason is not None:
        return reason, output
    colour = renderer.deferred_colour()
    reason = "dark" if is_dark(colour, filters) else by_labels
    return reason, dataclasses.replace(output, color=colour)


def _label_maps(output, camera, filters) -> tuple[dict[str, np.ndarray], bool, np.ndarray]:
    """The maps a kept view writes, at a LABEL_STRIDE-th of its size: component ids, damage
    ids inside the RRDR, encoded depth, encoded crack widths inside the RRDR; whether the
    damage map shows damage; and the render's crack widths inside the RRDR (full size, mm).
    Crack pixels of the render keep their block (docs/design.md)."""
    widths = output.crack_width
    if widths.any():  # a view without cracks (all of the paper model's) skips the copy
        # Outside the RRDR a crack's pixels are unlabelled, so the map holds no width there.
        widths = np.where(view_rrdr(filters, output.depth, camera.fx), widths, np.float32(0))
    blocks = downsample_crack_width(widths)
    # The maps sample each block's centre pixel, and the RRDR's mask and the depth's code are
    # pixel by pixel: taken at the sampled pixels alone, they give the same maps for a ninth
    # of the work.
    depth = downsample_labels(output.depth)
    reliable = view_rrdr(filters, depth, camera.fx)
    maps = {"component": downsample_labels(output.component),
            "damage": mark_cracked_blocks(mask_damage(downsample_labels(output.damage),
                                                      reliable), blocks),
            "depth": encode_depth(depth),
            "crackwidth": encode_crack_width(blocks)}
    # The flag describes the map that is written: damage inside the RRDR at full size
    # can vanish in the 3x downsampling.
    return maps, bool(np.any(maps["damage"] >= Damage.CONCRETE)), widths


def _crack_networks(view) -> tuple[dict, dict[str, list[dict]]]:
    """The crack networks of the environment's dressed parts and their records (the
    dressing's per-crack id, member, type, length and widths), by part name."""
    networks, records = {}, {}
    for name, assignment in view.dressing.assignments.items():
        listed = (assignment.damage or {}).get("cracks")
        if listed:
            networks[name] = view.dressing.materials[name].cracks
            records[name] = listed
    return networks, records


def _view_meta(view, placement, root_seed: int, env: int, split: str, in_rrdr: bool,
               columns: list) -> dict:
    """meta/<split>/image_case<E>_frame<C>.json: where the camera stands and the damage of the
    columns it sees."""
    from glsynth.world.visibility import visible_parts

    seen = visible_parts(columns, [placement.camera])
    return {"root_seed": root_seed, "env": env, "camera_index": placement.index,
            "kind": placement.kind, "split": split, "camera": placement.camera.to_json(),
            "placement": {"s_m": placement.s_m, "side": placement.side,
                          "distance_m": placement.distance_m,
                          "height_m": placement.height_m,
                          "euler_xyz_rad": list(placement.euler_xyz_rad),
                          **({"face": placement.face.to_json()} if placement.face else {})},
            "damage_in_rrdr": in_rrdr,
            "columns_in_view": {n: jsonable(view.dressing.assignments[n].damage)
                                for n in sorted(seen)}}


def _write_cycles_colour(view, to_cycles: list, out: Path, env: int, clock: "_Clock") -> None:
    """The views the GL filters kept, coloured by Cycles; their labels stay GL's."""
    from glsynth.render.cycles import cycles_colour

    colours = cycles_colour(view, [p for p, _ in to_cycles], out / ".tmp" / f"cycles_{env}")
    clock.lap("Cycles colour")
    for (_, image), colour in zip(to_cycles, colours):
        atomic_write_bytes(out / image, png_bytes(colour))
    clock.lap("encode and write files")


def _env_description(view) -> dict:
    from glsynth.render.export import describe

    info = describe(view.environment)
    info["materials"] = {n: jsonable(a)
                         for n, a in view.dressing.assignments.items()}
    return info


def run_plates(config: Config, root_seed: int, task: Task, out: Path, renderer) -> dict:
    from glsynth.appearance.damage_bank import DamageBank
    from glsynth.appearance.dressing import open_repository
    from glsynth.data.plates import plate_shot

    clock = _Clock()
    repository = open_repository(config)
    bank = DamageBank(config.damage, root_seed)
    rows: dict[str, list] = {"train": [], "test": []}
    counts = []
    with BackgroundWriter() as writer:
        for index in range(task.first, task.first + task.count):
            shot = plate_shot(config, root_seed, index, repository, bank)
            renderer.load(shot.scene, shot.lighting)
            clock.lap("plate damage textures")
            output = renderer.render(shot.camera, {"color", "damage"})
            clock.lap("render and read back")
            if config.render.renderer == "cycles":
                output = dataclasses.replace(output, color=_cycles_plate(config, root_seed, shot,
                                                                         out))
                clock.lap("Cycles colour")
            paths = puretex_paths(index)
            damage = downsample_labels(output.damage)
            writer.submit(write_files, out, {paths["image"]: (output.color, "PNG"),
                                             paths["damage"]: (damage, "BMP")},
                          {f"meta/puretex/image_{index}.json": {
                              "root_seed": root_seed, **jsonable(shot.meta),
                              "camera": shot.camera.to_json()}})
            split = plate_split(config, index)
            rows[split].append([paths["image"], paths["damage"]])
            counts.append(dataclasses.asdict(image_counts("plate", split, None, damage, None, None,
                                                          True)))
            clock.lap("queue files")
    clock.lap("wait for the writer")
    return {"kind": "plates", "first": task.first, "rows": rows, "counts": counts,
            "timings": clock.totals}


def _cycles_plate(config: Config, root_seed: int, shot, out: Path) -> np.ndarray:
    """A plate's colour by the Cycles twin (its own Blender process: each plate is a scene)."""
    from glsynth.render.cycles import cycles_seed, display, render_linear, require_blender

    work = out / ".tmp" / f"cycles_plate_{shot.index}"
    seed = cycles_seed(root_seed, 0, 1_000_000 + shot.index)
    try:
        result = render_linear([shot.part], {shot.part.name: shot.material}, shot.lighting,
                               [shot.camera], [seed], config.cycles.samples, work,
                               require_blender())
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return display(result.linear[0], shot.lighting)


class _Clock:
    """Seconds spent per named phase (reported, never written into the dataset)."""

    def __init__(self) -> None:
        self.totals: dict[str, float] = {}
        self.last = time.perf_counter()

    def lap(self, phase: str) -> None:
        now = time.perf_counter()
        self.totals[phase] = self.totals.get(phase, 0.0) + now - self.last
        self.last = now


def run_task(config: Config, root_seed: int, task: Task, out: Path, renderer) -> dict:
    """Run one unit and write its marker; the returned result adds its timings."""
    t0 = time.perf_counter()
    if task.kind == "env":
        result = run_environment(config, root_seed, task.first, out, renderer)
    else:
        result = run_plates(config, root_seed, task, out, renderer)
    timings = result.pop("timings")
    atomic_write_json(out / task.marker, result)
    # ru_maxrss is KiB on Linux: this worker process's peak so far.
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return {**result, "timings": timings, "seconds": time.perf_counter() - t0,
            "worker": {"pid": os.getpid(), "peak_rss_mib": round(peak)}}


def run_identity(config: Config, root_seed: int) -> dict:
    settings = config_to_dict(config)
    digest = hashlib.sha256(json.dumps([root_seed, settings], sort_keys=True,
                                       default=str).encode()).hexdigest()
    return {"root_seed": root_seed, "config_sha256": digest}


def pending_tasks(config: Config, out: Path) -> list[Task]:
    """The units without a valid marker. A marker that is unreadable or breaks its contract
    (read_marker) is removed with a warning naming it, and its unit is done again."""
    pending = []
    for task in plan(config):
        path = out / task.marker
        if is_marker(path):
            try:
                read_marker(path, task)
                continue
            except UserError as err:
                warnings.warn(f"redoing unit {task.marker}: {err}", stacklevel=2)
                path.unlink(missing_ok=True)
        pending.append(task)
    return pending


MARKER_FIX = "remove it and run the same command again to redo its unit"


def _inside(image: object) -> bool:
    """Whether a marker row's image names a file inside the dataset (a relative path that
    never climbs out), as run_task writes them."""
    return (isinstance(image, str) and bool(image) and not PurePosixPath(image).is_absolute()
            and ".." not in PurePosixPath(image).parts)


def read_marker(path: Path, task: Task) -> dict:
    """A progress marker of ``task``, as run_task wrote it: its kind and unit, its manifest
    rows and its image counts, each of the right form."""
    data = read_json(path, {"kind": str, "rows": (list, dict), "counts": list}, MARKER_FIX)
    try:
        counts = [ImageCounts.from_json(c) for c in data["counts"]]
        if data["kind"] == "env":
            ok = (data["env"] == task.first and data["split"] in ("train", "test")
                  and isinstance(data["removed"], dict)
                  and all(_inside(FrameRecord(**r).image) for r in data["rows"]))
        else:
            ok = data["first"] == task.first and all(
                _inside(PuretexRecord(*r).image)
                for split in ("train", "test") for r in data["rows"][split])
        ok = ok and data["kind"] == task.kind and all(isinstance(c.split, str) for c in counts)
    except (TypeError, KeyError, ValueError, AttributeError) as err:
        raise UserError(f"{named(path)} is not a progress marker of this glsynth "
                        f"({type(err).__name__}); {MARKER_FIX}") from None
    if not ok:
        raise UserError(f"{named(path)} is not the marker of unit {task.marker}; {MARKER_FIX}")
    return data


def check_run_folder(out: Path, config: Config, root_seed: int) -> None:
    """A worker's check that it sees the driver's output folder (a shared path on a cluster)."""
    run_file = out / RUN_FILE
    if not run_file.exists():
        raise UserError(
            f"{named(run_file)} is not visible to this worker: with several machines --out "
            "must be a shared filesystem mounted at the same path on every node")
    recorded = read_json(run_file, {"config_sha256": str}, RUN_FILE_FIX)
    if recorded.get("config_sha256") != run_identity(config, root_seed)["config_sha256"]:
        raise UserError(f"{named(run_file)} belongs to another run than this worker's")


RUN_FILE_FIX = ("it is damaged or not glsynth's: move the folder aside and generate into a new "
                "--out")


def prepare_output(out: Path, config: Config, root_seed: int) -> None:
    """Create or reopen an output folder; refuse one that holds a different run."""
    identity = run_identity(config, root_seed)
    if out.exists() and not out.is_dir():
        raise UserError(f"--out {named(out)} is a file; give a folder for the dataset")
    run_file = out / RUN_FILE
    if run_file.exists():
        previous = read_json(run_file, {"config_sha256": str, "root_seed": int}, RUN_FILE_FIX)
        if previous.get("config_sha256") != identity["config_sha256"] or \
                previous.get("root_seed") != root_seed:
            raise UserError(f"--out {named(out)} holds a run with other settings (seed "
                            f"{previous.get('root_seed')}); use a new folder, or the same "
                            "preset, config and seed to resume it")
    elif out.exists() and any(p.name not in (DRIVER_LOCK, WORKERS_LOCK) for p in out.iterdir()):
        raise UserError(f"--out {named(out)} is not empty and holds no glsynth run; "
                        "use a new or empty folder")
    # A killed run can leave temporary files of interrupted atomic writes: remove them (the
    # caller holds the folder's lock, so no other run is writing them).
    for stale in out.rglob(".*.tmp") if out.exists() else ():
        stale.unlink()
    atomic_write_json(run_file, {**identity, "config": config_to_dict(config)})
    free = shutil.disk_usage(out).free
    if free < 200 * 2**20:
        raise UserError(f"only {free / 2**20:.0f} MiB free under {named(out)}; the dataset "
                      "needs more (about 4 MB per kept image): free space or choose another "
                      "--out")


def merge(config: Config, out: Path) -> dict:
    """Write the four manifests from the markers, sorted; return the dataset's counts and its
    statistics (glsynth.data.statistics, the code behind ``glsynth stats``)."""
    frames: dict[str, list] = {"train": [], "test": []}
    plates: dict[str, list] = {"train": [], "test": []}
    counts: list[ImageCounts] = []
    for task in plan(config):
        data = read_marker(out / task.marker, task)
        counts += [ImageCounts.from_json(c) for c in data["counts"]]
        if data["kind"] == "env":
            frames[data["split"]] += [(data["env"], r["image"], r) for r in data["rows"]]
        else:
            for split in ("train", "test"):
                plates[split] += data["rows"][split]
    for split in ("train", "test"):
        ordered = [FrameRecord(**r) for _, _, r in sorted(
            frames[split], key=lambda x: (x[0], _frame_number(x[1])))]
        atomic_write_bytes(out / f"files_{split}.csv", manifest_text(ordered).encode())
        pure = [PuretexRecord(*r) for r in sorted(plates[split], key=lambda r: _plate_no(r[0]))]
        atomic_write_bytes(out / f"files_puretex_{split}.csv", manifest_text(pure).encode())
    stats = dataset_statistics(counts, read_removals(out))
    return {"kept": stats["images"]["regular"] + stats["images"]["closeup"],
            "plates": stats["images"]["plate"], "statistics": stats,
            "label_size": [side // LABEL_STRIDE for side in IMAGE_SIZE]}


def _frame_number(image: str) -> int:
    return int(image.rsplit("_frame", 1)[1].split("_")[0])


def _plate_no(image: str) -> int:
    return int(image.rsplit("_", 1)[1].split(".")[0])
