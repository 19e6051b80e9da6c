"""A dataset's statistics next to the paper's (``glsynth stats``, and the generate report).

Both read the same per-image counts (``ImageCounts``): ``glsynth generate`` takes them from the
maps it writes, ``glsynth stats`` from the files of any Tokaido-layout dataset, glsynth's or the
released one. Removals by reason exist only where a glsynth run left its progress markers.

Definitions (docs/design.md):
- damage shares are concrete-damage and exposed-rebar pixels over the labelled pixels of the
  damage task's images (frames whose written map holds damage, plus the plates), the quantity
  the paper gives as 3.9 % and 0.4 % (Section 4.5);
- images for damage recognition are those frames plus the plates (paper: 4,990 + 3,000).
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from glsynth.core.errors import UserError, shown
from glsynth.core.labels import Component, Damage
from glsynth.data.readers import map_size, read_depth_map, read_json, read_label_map
from glsynth.data.tokaido import DEPTH_FAR_M, DEPTH_MAX_CODE, DEPTH_NEAR_M, read_manifest

DEPTH_EDGES_M = tuple(float(e) for e in np.arange(0.5, 30.5, 2.0))
"""Depth histogram bins [m]; sky (the 30 m clip) is counted apart."""
FOCAL_EDGES_MM = tuple(float(e) for e in range(15, 60, 5))
"""Focal-length histogram bins [mm] over the paper's [15, 55]."""
KINDS = ("regular", "closeup", "plate")
COMPONENTS = [c for c in Component if c != Component.UNLABELLED]

PAPER = {
    "images": {"regular": 8648, "closeup": 7288, "plate": 3000},
    "raw_views": {"regular": 10000, "closeup": 10000},
    "keep_rate": {"regular": 0.8648, "closeup": 0.7288},
    "damage_share": {"concrete": 0.039, "rebar": 0.004},
    "damage_images": 7990,
    "source": "Narazaki et al., Sections 3.4, 4.2, 4.5 and the conclusions",
}


@dataclass(frozen=True)
class ImageCounts:
    """What the statistics need of one image of the dataset."""

    kind: str
    """'regular', 'closeup' or 'plate'."""
    split: str
    component: tuple[int, ...] | None
    """Pixels per component id 0..8 of the written map; None for plates."""
    damage: tuple[int, ...]
    """Pixels per damage id 0..3 of the written map."""
    damage_in_rrdr: bool
    """The manifest's flag (always True for plates: they are damage-task images)."""
    focal_mm: float | None
    depth: tuple[int, ...] | None
    """Pixels per DEPTH_EDGES_M bin, then the sky (code 65535); None for plates."""

    @classmethod
    def from_json(cls, data: dict) -> "ImageCounts":
        """Back from dataclasses.asdict, as a run's progress markers store it."""
        def tup(values: list | None) -> tuple | None:
            return None if values is None else tuple(values)
        return cls(**{**data, "component": tup(data["component"]),
                      "damage": tuple(data["damage"]), "depth": tup(data["depth"])})


def image_counts(kind: str, split: str, component: np.ndarray | None, damage: np.ndarray,
                 depth_code: np.ndarray | None, focal_mm: float | None,
                 damage_in_rrdr: bool) -> ImageCounts:
    """Counts of one image from its written maps (ids and the uint16 depth code)."""
    comp = None if component is None else tuple(
        np.bincount(component.ravel(), minlength=len(Component))[:len(Component)].tolist())
    dmg = tuple(np.bincount(damage.ravel(), minlength=len(Damage))[:len(Damage)].tolist())
    depth = None
    if depth_code is not None:
        sky = depth_code == DEPTH_MAX_CODE
        metres = depth_code[~sky].astype(np.float64) / DEPTH_MAX_CODE * (
            DEPTH_FAR_M - DEPTH_NEAR_M) + DEPTH_NEAR_M
        hist = np.histogram(metres, bins=DEPTH_EDGES_M + (DEPTH_FAR_M,))[0]
        depth = tuple(hist.tolist()) + (int(sky.sum()),)
    return ImageCounts(kind, split, comp, dmg, bool(damage_in_rrdr), focal_mm, depth)


def read_image_counts(root: str | Path) -> list[ImageCounts]:
    """Counts of every image a Tokaido-layout dataset lists, read from its files (each map
    checked by glsynth.data.readers: mode, size a third of its image's, id range)."""
    root = Path(root)
    counts = []
    for split in ("train", "test"):
        for row in read_manifest(root, f"files_{split}.csv"):
            size = map_size(root / row.image)
            counts.append(image_counts(
                "regular" if row.regular else "closeup", split,
                read_label_map(root / row.component, "component", size),
                read_label_map(root / row.damage, "damage", size),
                read_depth_map(root / row.depth, size), row.focal_mm, row.damage_in_rrdr))
        puretex = root / f"files_puretex_{split}.csv"
        if puretex.is_file():
            for row in read_manifest(root, puretex.name):
                damage = read_label_map(root / row.damage, "damage", map_size(root / row.image))
                counts.append(image_counts("plate", split, None, damage, None, None, True))
    return counts


def read_removals(root: str | Path) -> dict[str, dict[str, int]] | None:
    """Views removed by the Section 3.4 filters, by camera kind and reason, from a glsynth
    run's progress markers; None for a dataset without them (the released one)."""
    markers = sorted(Path(root).glob("progress/env_*.json"))
    if not markers:
        return None
    removed: dict[str, dict[str, int]] = {"regular": {}, "closeup": {}}
    for marker in markers:
        fix = "remove it and run generate again to redo its unit"
        by_kind = read_json(marker, {"removed": dict}, fix)["removed"]
        if not all(isinstance(v, dict) for v in by_kind.values()):
            return None  # a run from before removals were recorded by camera kind
        if not all(k in removed and all(type(n) is int for n in v.values())
                   for k, v in by_kind.items()):
            raise UserError(f"{str(marker)!r}: removed = {shown(by_kind, 40)} is not counts "
                            f"by camera kind and reason; {fix}")
        for kind, reasons in by_kind.items():
            for reason, n in reasons.items():
                removed[kind][reason] = removed[kind].get(reason, 0) + n
    return removed


def _share(num: float, den: float) -> float | None:
    return float(num / den) if den else None


def dataset_statistics(images: list[ImageCounts],
                       removals: dict[str, dict[str, int]] | None) -> dict:
    """The statistics of the dataset, with the paper's values beside them where it gives one."""
    frames = [i for i in images if i.kind != "plate"]
    by_kind = {k: sum(i.kind == k for i in images) for k in KINDS}
    stats: dict = {"images": by_kind,
                   "images_by_split": {s: sum(i.split == s for i in images)
                                       for s in ("train", "test")}}
    if removals is not None:
        stats["removed"] = removals
        stats["keep_rate"] = {k: _share(by_kind[k], by_kind[k] + sum(removals[k].values()))
                              for k in ("regular", "closeup")}
    comp = np.zeros(len(Component), np.int64)
    shows = {k: {c.name.lower(): 0 for c in COMPONENTS} for k in ("regular", "closeup")}
    for image in frames:
        counts = np.asarray(image.component)
        comp += counts
        for c in COMPONENTS:
            shows[image.kind][c.name.lower()] += int(counts[c] > 0)
    labelled = comp[1:].sum()
    stats["component_pixel_share"] = {c.name.lower(): _share(comp[c], labelled)
                                      for c in COMPONENTS}
    stats["views_showing"] = {
        c.name.lower(): _share(sum(s[c.name.lower()] for s in shows.values()), len(frames))
        for c in COMPONENTS}
    stats["views_showing_by_kind"] = {
        k: {name: _share(n, by_kind[k]) for name, n in s.items()} for k, s in shows.items()}
    task = [i for i in images if i.damage_in_rrdr]
    dmg = np.sum([i.damage for i in task], axis=0) if task else np.zeros(len(Damage), np.int64)
    stats["damage_share"] = {"concrete": _share(dmg[Damage.CONCRETE], dmg[1:].sum()),
                             "rebar": _share(dmg[Damage.REBAR], dmg[1:].sum())}
    stats["damage_images"] = {"frames": sum(i.kind != "plate" for i in task),
                              "plates": by_kind["plate"], "total": len(task)}
    depth = np.sum([i.depth for i in frames], axis=0) if frames else None
    stats["depth_histogram"] = {
        "edges_m": list(DEPTH_EDGES_M) + [DEPTH_FAR_M],
        "pixels": None if depth is None else depth[:-1].tolist(),
        "sky_pixels": None if depth is None else int(depth[-1])}
    focals = [i.focal_mm for i in frames if i.focal_mm is not None]
    inside = [f for f in focals if FOCAL_EDGES_MM[0] <= f <= FOCAL_EDGES_MM[-1]]
    stats["focal_histogram"] = {
        "edges_mm": list(FOCAL_EDGES_MM),
        "images": np.histogram(inside, bins=FOCAL_EDGES_MM)[0].tolist(),
        "outside": len(focals) - len(inside), "unknown": len(frames) - len(focals)}
    stats["paper"] = PAPER
    return stats


def _pct(value: float | None, digits: int = 1) -> str:
    return "-" if value is None else f"{100 * value:.{digits}f} %"


def statistics_table(stats: dict) -> str:
    """Markdown: one row per statistic, the paper's value beside the dataset's."""
    p, n = PAPER, stats["images"]
    rows = [("statistic", "paper", "this dataset"), ("---", "---", "---")]
    for kind in KINDS:
        rows.append((f"images: {kind}", f"{p['images'][kind]:,}", f"{n[kind]:,}"))
    keep = stats.get("keep_rate")
    for kind in ("regular", "closeup"):
        rows.append((f"keep rate: {kind}", _pct(p["keep_rate"][kind]),
                     _pct(keep[kind]) if keep else "no metadata"))
        if keep:
            removed = ", ".join(f"{r} {v}" for r, v in sorted(stats["removed"][kind].items())
                                if v) or "none"
            rows.append((f"removed: {kind}", "not given", removed))
    by_kind = stats["views_showing_by_kind"]
    for name, share in stats["views_showing"].items():
        rows.append((f"views showing {name} (all / regular / close-up)", "not given",
                     f"{_pct(share)} / {_pct(by_kind['regular'][name])} / "
                     f"{_pct(by_kind['closeup'][name])}"))
    for name, share in stats["component_pixel_share"].items():
        rows.append((f"pixel share: {name}", "not given", _pct(share)))
    for name in ("concrete", "rebar"):
        rows.append((f"damage share: {name}", _pct(p["damage_share"][name]),
                     _pct(stats["damage_share"][name], 2)))
    d = stats["damage_images"]
    rows.append(("images for damage recognition", f"{p['damage_images']:,}",
                 f"{d['total']:,} ({d['frames']:,} views + {d['plates']:,} plates)"))
    depth = stats["depth_histogram"]
    if depth["pixels"] is not None:
        total = sum(depth["pixels"]) + depth["sky_pixels"]
        near = sum(depth["pixels"][:5]) / total if total else 0
        rows.append(("depth: pixels nearer than 10.5 m / sky", "0.5-30 m range",
                     f"{_pct(near)} / {_pct(depth['sky_pixels'] / total if total else 0)}"))
    f = stats["focal_histogram"]
    rows.append(("focal lengths [mm], per 5 mm from 15", "U[15, 55]",
                 " ".join(str(v) for v in f["images"])))
    return "\n".join(f"| {a} | {b} | {c} |" for a, b, c in rows) + "\n"


def statistics_figure(stats: dict, path: Path) -> None:
    """Bar charts: images by kind, keep rates, views showing each class, damage shares, the
    depth and focal-length histograms; the paper's values as hatched bars where it has them."""
    import matplotlib.pyplot as plt

    from glsynth.core.plots import save_figure

    fig, axes = plt.subplots(2, 3, figsize=(15, 8), layout="constrained")
    ax = axes[0, 0]
    kinds = list(KINDS)
    ax.bar(kinds, [stats["images"][k] for k in kinds])
    ax.set_title("images by kind")
    ax = axes[0, 1]
    x = np.arange(2)
    ax.bar(x - 0.2, [PAPER["keep_rate"][k] for k in ("regular", "closeup")], 0.4,
           hatch="//", fill=False, label="paper")
    if stats.get("keep_rate"):
        ax.bar(x + 0.2, [stats["keep_rate"][k] for k in ("regular", "closeup")], 0.4,
               label="dataset")
    ax.set_xticks(x, ["regular", "closeup"]), ax.set_ylim(0, 1), ax.legend()
    ax.set_title("keep rate after the Section 3.4 filters")
    ax = axes[0, 2]
    names = list(stats["views_showing"])
    ax.barh(names, [stats["views_showing"][n] or 0 for n in names])
    ax.set_xlim(0, 1), ax.set_title("share of views showing each component")
    ax = axes[1, 0]
    x = np.arange(2)
    ax.bar(x - 0.2, [PAPER["damage_share"][k] for k in ("concrete", "rebar")], 0.4,
           hatch="//", fill=False, label="paper")
    ax.bar(x + 0.2, [stats["damage_share"][k] or 0 for k in ("concrete", "rebar")], 0.4,
           label="dataset")
    ax.set_xticks(x, ["concrete damage", "exposed rebar"]), ax.legend()
    ax.set_title("damage share of damage-task pixels")
    ax = axes[1, 1]
    depth = stats["depth_histogram"]
    if depth["pixels"] is not None:
        edges = depth["edges_m"]
        ax.bar(edges[:-1], depth["pixels"], np.diff(edges), align="edge")
    ax.set_xlabel("depth [m]"), ax.set_title("depth histogram (sky apart)")
    ax = axes[1, 2]
    f = stats["focal_histogram"]
    ax.bar(f["edges_mm"][:-1], f["images"], np.diff(f["edges_mm"]), align="edge")
    ax.set_xlabel("focal length [mm]"), ax.set_title("focal-length histogram")
    save_figure(fig, path)


def write_statistics(root: str | Path, out: str | Path) -> dict:
    """``glsynth stats``: stats.json, stats.md and stats.png in ``out``."""
    from glsynth.core.fileio import atomic_write_bytes, atomic_write_json

    root, out = Path(root), Path(out)
    stats = dataset_statistics(read_image_counts(root), read_removals(root))
    stats["dataset"] = str(root)
    atomic_write_json(out / "stats.json", stats)
    atomic_write_bytes(out / "stats.md", statistics_table(stats).encode())
    statistics_figure(stats, out / "stats.png")
    return stats

