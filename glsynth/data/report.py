"""What a generation run reports to people: report.json's record of each run (images, time,
memory) and a contact sheet of samples with label overlays."""

import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image

from glsynth.core.errors import UserError, named
from glsynth.core.images import nearest_resize, read_photo
from glsynth.core.palette import COMPONENT_RGB, DAMAGE_RGB, depth_rgb, overlay
from glsynth.data.readers import map_size, read_depth_map, read_json, read_label_map
from glsynth.data.tokaido import decode_depth, read_manifest


@dataclass(frozen=True)
class RunTally:
    """Sums over the unit results (glsynth.data.dataset.run_task) of one run."""

    images: int
    worker_seconds_by_phase: dict[str, float]
    worker_peak_rss_mib: dict[int, int]
    """Each worker process's peak resident memory, by process id."""


def images_written(result: dict) -> int:
    """Images one unit wrote: a kept view of an environment, or a plate."""
    rows = result["rows"]
    return len(rows) if result["kind"] == "env" else sum(len(r) for r in rows.values())


def tally_results(results: Iterable[dict]) -> RunTally:
    images, seconds, peaks = 0, {}, {}
    for result in results:
        images += images_written(result)
        for phase, spent in result["timings"].items():
            seconds[phase] = seconds.get(phase, 0.0) + spent
        worker = result["worker"]
        peaks[worker["pid"]] = max(peaks.get(worker["pid"], 0), worker["peak_rss_mib"])
    return RunTally(images, seconds, peaks)


def run_record(tally: RunTally, engine: str, workers: int, wall_s: float) -> dict:
    """One run's entry in report.json."""
    images = tally.images
    return {"engine": engine, "workers": workers, "wall_s": round(wall_s, 2),
            "images_written_this_run": images,
            "images_per_s": round(images / wall_s, 3) if wall_s > 0 and images else None,
            "worker_seconds_by_phase": {k: round(v, 2)
                                        for k, v in tally.worker_seconds_by_phase.items()},
            "worker_peak_rss_mib": sorted(tally.worker_peak_rss_mib.values())}


def recorded_runs(report: Path) -> list[dict]:
    """The runs recorded in a dataset's report.json; none before its first report. Read before
    any work, so an unreadable report is refused with one line."""
    if not os.path.lexists(report):
        return []
    fix = "move it aside and run again"
    runs = read_json(report, {"runs": list}, fix, "dataset report")["runs"]
    if not all(isinstance(run, dict) for run in runs):
        raise UserError(f"dataset report {named(report)}: runs holds other than run records, "
                        f"so it is not a report of this glsynth; {fix}")
    return runs


def with_runs(summary: dict, earlier: list[dict], run: dict) -> dict:
    """report.json: the dataset's summary (glsynth.data.dataset.merge), this run's record on
    top and every run's below, with their totals. A resumed or repeated run must not hide the
    time of the run that made the data."""
    runs = [*earlier, run]
    return {**summary, **run, "runs": runs,
            "wall_s_all_runs": round(sum(r["wall_s"] or 0 for r in runs), 2),
            "images_written_all_runs": sum(r["images_written_this_run"] or 0 for r in runs)}


def contact_sheet(root: Path, samples: int = 6, width: int = 320) -> np.ndarray:
    """Rows of (image | components | damage | depth) for up to ``samples`` evenly spread
    training and test views."""
    records = read_manifest(root, "files_train.csv") + read_manifest(root, "files_test.csv")
    if not records:
        return np.zeros((8, 4 * width, 3), np.uint8)
    picks = np.linspace(0, len(records) - 1, min(samples, len(records))).round().astype(int)
    height = width * 9 // 16
    rows = []
    for i in picks:
        r = records[i]
        image = np.asarray(Image.fromarray(read_photo(root / r.image)).resize((width, height)))
        size, shape = map_size(root / r.image), (height, width)
        comp = nearest_resize(read_label_map(root / r.component, "component", size), shape)
        dmg = nearest_resize(read_label_map(root / r.damage, "damage", size), shape)
        depth = decode_depth(nearest_resize(read_depth_map(root / r.depth, size), shape))
        rows.append(np.concatenate([image, overlay(image, comp, COMPONENT_RGB, 0.55),
                                    overlay(image, dmg, DAMAGE_RGB, 0.8, skip=(1,)),
                                    depth_rgb(depth)], axis=1))
    return np.concatenate(rows, axis=0)
