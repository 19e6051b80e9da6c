"""A dataset's statistics next to the paper's (``glsynth stats``, and the generate report).

Both read the same per-image counts (``ImageCounts``): ``glsynth generate`` takes them from the
maps it writes, ``glsynth stats`` from the files of any Tokaido-layout dataset, glsynth's or the
released one. Removals by reason exist only where a glsynth run left its progress markers.

Definitions (docs/design.md):
- damage shares are concrete-damage and exposed-rebar pixels over the labelled pixels of the
  damage task's images (frames whose written map holds damage, plus the plates), the quantity
  the paper gives as 3.9 % and 0.4 % (Section 4.5);
- images for damage recognition are those frames plus the plates (paper: 4,990 + 3,000);
- the crack-width histogram counts the pixels of the written crack-width maps (each the widest
  crack of its 3x3 block) per width bin; crack length per m^2 is the labelled length of the
  cracks the views' meta lists over the area of column and beam surface the views show inside
  the RRDR (surface_area_m2), the region where cracks are labelled. Datasets without
  crack-width maps or crack lists (the released one, older glsynth datasets) have neither,
  and say so.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from glsynth.core.errors import UserError, named, shown
from glsynth.core.filters import rrdr
from glsynth.core.labels import Component, Damage
from glsynth.core.surfaces import MAX_AREA_FACTOR
from glsynth.data.readers import (
    map_size,
    read_crack_width_map,
    read_depth_map,
    read_json,
    read_label_map,
)
from glsynth.data.tokaido import (
    CRACK_WIDTH_STEP_MM,
    DEPTH_FAR_M,
    DEPTH_MAX_CODE,
    DEPTH_NEAR_M,
    crack_width_path,
    decode_depth,
    read_manifest,
)

DEPTH_EDGES_M = tuple(float(e) for e in np.arange(0.5, 30.5, 2.0))
"""Depth histogram bins [m]; sky (the 30 m clip) is counted apart."""
FOCAL_EDGES_MM = tuple(float(e) for e in range(15, 60, 5))
"""Focal-length histogram bins [mm] over the paper's [15, 55]."""
CRACK_WIDTH_EDGES_MM = (0.01, 0.05, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.7, 1.0, 1.5, 2.0, 3.0,
                        5.0, 10.0, 655.35)
"""Crack-width histogram bins [mm], each [low, high): finer than the grades of inspection
practice (0.2, 0.3, 0.5, 1.0 mm, edges here) over the generator's 0.05-5 mm; the first edge
is the smallest width a map can hold, the last its largest."""
CRACKED_MEMBERS = (Component.COLUMN, Component.BEAM)
"""The components whose surface can crack (columns, and cross and tie beams and girders, all
labelled beams)."""
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
    crack_width: tuple[int, ...] | None = None
    """Pixels per CRACK_WIDTH_EDGES_MM bin of the crack-width map; None without one."""
    crack_length_m: float | None = None
    """Labelled crack length (the meta's crack list); None without a list."""
    member_area_m2: float | None = None
    """Column and beam surface in view inside the RRDR (surface_area_m2), where
    crack_length_m is known."""

    @classmethod
    def from_json(cls, data: dict) -> "ImageCounts":
        """Back from dataclasses.asdict, as a run's progress markers store it."""
        def tup(values: list | None) -> tuple | None:
            return None if values is None else tuple(values)
        return cls(**{**data, "component": tup(data["component"]),
                      "damage": tuple(data["damage"]), "depth": tup(data["depth"]),
                      "crack_width": tup(data.get("crack_width"))})


@dataclass(frozen=True)
class CrackLength:
    """What crack length per m^2 needs of a view beside its maps."""

    labelled_m: float
    """The labelled length of the cracks the view shows (the meta's ``cracks_in_view``)."""
    focal_px: float
    """The photo's focal length in pixels."""
    photo_width: int
    """The photo's width in pixels (its label maps are narrower by the label stride)."""


def surface_area_m2(depth_m: np.ndarray, focal_px: float) -> np.ndarray:
    """The surface area each pixel of a depth map sees [m^2]: the parallelogram between the
    back-projected steps to its neighbours in x and in y. A step is the mean of the steps to
    the two neighbours where they agree within half their length (one smooth surface), else
    the step to the neighbour of nearer depth (the pixel's own surface at a silhouette or an
    edge). That is (z / f)^2 / cos(tilt) on a plane; at most MAX_AREA_FACTOR times (z / f)^2
    (glsynth.core.surfaces)."""
    h, w = depth_m.shape
    z = depth_m.astype(np.float64)
    # x, y and z of the back-projected points as planes of their own: the same arithmetic,
    # element by element, as on (h, w, 3) vectors, at a quarter of the time (no padded or
    # stacked copies).
    points = ((np.arange(w) - (w - 1) / 2)[None, :] * z / focal_px,
              (np.arange(h) - (h - 1) / 2)[:, None] * z / focal_px, z)
    ax, ay, az = _step(points, 1)
    bx, by, bz = _step(points, 0)
    # np.cross's terms, in its order.
    area = _length(ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx)
    return np.minimum(area, MAX_AREA_FACTOR * (z / focal_px) ** 2)


def _length(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """The length of vectors given by their coordinates' planes, summed in the order that
    np.linalg.norm(axis=-1) sums three coordinates, so to the same bits."""
    return np.sqrt((x * x + y * y) + z * z)


def _step(points: tuple[np.ndarray, ...], axis: int) -> tuple[np.ndarray, ...]:
    """surface_area_m2's step to the neighbours along ``axis``, as (x, y, z) planes: the
    differences to the next point (``ahead``) and from the previous one (``back``), each
    repeated at the border."""
    diffs = [np.diff(p, axis=axis) for p in points]
    first, last = [slice(None)] * 2, [slice(None)] * 2
    first[axis], last[axis] = slice(0, 1), slice(-1, None)
    back = [np.concatenate([d[tuple(first)], d], axis=axis) for d in diffs]
    ahead = [np.concatenate([d, d[tuple(last)]], axis=axis) for d in diffs]
    near = np.abs(ahead[2]) <= np.abs(back[2])
    size = (_length(*ahead) + _length(*back)) / 2
    smooth = _length(*(a - b for a, b in zip(ahead, back, strict=True))) <= 0.5 * size
    return tuple(np.where(smooth, (a + b) / 2, np.where(near, a, b))
                 for a, b in zip(ahead, back, strict=True))


def crack_width_counts(code: np.ndarray) -> tuple[int, ...]:
    """Pixels of a crack-width map (uint16 codes) per CRACK_WIDTH_EDGES_MM bin."""
    edges = np.rint(np.asarray(CRACK_WIDTH_EDGES_MM) / CRACK_WIDTH_STEP_MM).astype(np.int64)
    hist = np.bincount(np.searchsorted(edges, code[code > 0], side="right"),
                       minlength=len(edges) + 1)
    hist[-2] += hist[-1]  # the last bin holds its upper edge, the largest code
    return tuple(hist[1:-1].tolist())


def image_counts(kind: str, split: str, component: np.ndarray | None, damage: np.ndarray,
                 depth_code: np.ndarray | None, focal_mm: float | None,
                 damage_in_rrdr: bool, crack_code: np.ndarray | None = None,
                 cracks: CrackLength | None = None) -> ImageCounts:
    """Counts of one image from its written maps (ids, the uint16 depth and crack-width
    codes) and the visible length of its cracks."""
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
    widths = None if crack_code is None else crack_width_counts(crack_code)
    length = area = None
    if cracks is not None and component is not None and depth_code is not None:
        depth_m = decode_depth(depth_code)
        # The RRDR from the written depth, as `glsynth assess` takes it: the crack list
        # counts labelled cracks, which lie inside the RRDR of the render.
        members = np.isin(component, CRACKED_MEMBERS) & rrdr(depth_m, cracks.focal_px)
        length = float(cracks.labelled_m)
        focal = cracks.focal_px * component.shape[1] / cracks.photo_width
        area = float(surface_area_m2(depth_m, focal)[members].sum()) if members.any() else 0.0
    return ImageCounts(kind, split, comp, dmg, bool(damage_in_rrdr), focal_mm, depth, widths,
                       length, area)


def _crack_length(root: Path, split: str, image: str) -> CrackLength | None:
    """The labelled crack length and the photo's focal length of a frame, from the meta JSON
    glsynth writes beside it; None where there is none or it lists no cracks (older runs)."""
    stem = Path(image).name.removesuffix("_Scene.png")
    path = root / "meta" / split / f"{stem}.json"
    if not path.is_file():
        return None
    meta = read_json(path, {"camera": dict}, "generate the dataset again, or move the file "
                     "aside")
    if "cracks_in_view" not in meta:
        return None
    camera = meta["camera"]
    return CrackLength(sum(c["labelled_length_m"] for c in meta["cracks_in_view"]),
                       camera["K"][0][0], camera["width"])


def read_image_counts(root: str | Path) -> list[ImageCounts]:
    """Counts of every image a Tokaido-layout dataset lists, read from its files (each map
    checked by glsynth.data.readers: mode, size a third of its image's, id range); crack
    widths and lengths where the dataset has crack-width maps and crack lists."""
    root = Path(root)
    counts = []
    for split in ("train", "test"):
        for row in read_manifest(root, f"files_{split}.csv"):
            size = map_size(root / row.image)
            widths = root / crack_width_path(row.damage)
            counts.append(image_counts(
                "regular" if row.regular else "closeup", split,
                read_label_map(root / row.component, "component", size),
                read_label_map(root / row.damage, "damage", size),
                read_depth_map(root / row.depth, size), row.focal_mm, row.damage_in_rrdr,
                read_crack_width_map(widths, size) if widths.is_file() else None,
                _crack_length(root, split, row.image)))
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
            raise UserError(f"{named(marker)}: removed = {shown(by_kind, 40)} is not counts "
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
    stats.update(crack_statistics(frames))
    stats["paper"] = PAPER
    return stats


def crack_statistics(frames: list[ImageCounts]) -> dict:
    """The crack-width histogram over the frames with crack-width maps and the crack length
    per m^2 of member surface over those with crack lists; None where no frame has them."""
    with_widths = [i.crack_width for i in frames if i.crack_width is not None]
    lengths = [(i.crack_length_m, i.member_area_m2) for i in frames
               if i.crack_length_m is not None]
    length, area = (float(np.sum(v)) for v in zip(*lengths)) if lengths else (0.0, 0.0)
    return {"crack_width_histogram": {
                "edges_mm": list(CRACK_WIDTH_EDGES_MM), "images": len(with_widths),
                "pixels": np.sum(with_widths, axis=0).tolist() if with_widths else None},
            "crack_length": None if not lengths else {
                "images": len(lengths), "labelled_length_m": length, "member_area_m2": area,
                "per_m2": _share(length, area)}}


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
    outside = f" ({f['outside']} outside 15-55)" if f["outside"] else ""
    rows.append(("focal lengths [mm], per 5 mm from 15", "U[15, 55]",
                 " ".join(str(v) for v in f["images"]) + outside))
    rows += _crack_rows(stats)
    return "\n".join(f"| {a} | {b} | {c} |" for a, b, c in rows) + "\n"


def _crack_rows(stats: dict) -> list[tuple[str, str, str]]:
    hist, length = stats["crack_width_histogram"], stats["crack_length"]
    if hist["pixels"] is None:
        widths = "no crack widths (no crackwidth maps)"
    else:
        edges = hist["edges_mm"]
        widths = ", ".join(f"{lo:g}-{hi:g}: {n:,}" for lo, hi, n in
                           zip(edges, edges[1:], hist["pixels"]) if n) or "no crack pixels"
    per_m2 = "no crack lists (no meta cracks_in_view)" if length is None else (
        f"{length['per_m2']:.3f} m/m^2 ({length['labelled_length_m']:.1f} m over "
        f"{length['member_area_m2']:.1f} m^2)" if length["per_m2"] is not None else
        "no member surface in view")
    return [("crack-width pixels per bin [mm]", "not given", widths),
            ("crack length per m^2 of column and beam surface in the RRDR", "not given", per_m2)]


def statistics_figure(stats: dict, path: Path) -> None:
    """Bar charts: images by kind, keep rates, views showing each class, damage shares, the
    depth and focal-length histograms; the paper's values as hatched bars where it has them."""
    import matplotlib.pyplot as plt

    from glsynth.core.plots import save_figure

    fig, axes = plt.subplots(2, 4, figsize=(20, 8), layout="constrained")
    ax = axes[0, 0]
    kinds = list(KINDS)
    ax.bar(kinds, [stats["images"][k] for k in kinds])
    ax.set_title("images by kind")
    ax = axes[0, 1]
    x = np.arange(2)
    ax.bar(x - 0.2, [PAPER["keep_rate"][k] for k in ("regular", "closeup")], 0.4,
           hatch="//", fill=False, label="paper")
    if stats.get("keep_rate"):
        # A kind with no cameras (the inspection preset's regular) has no keep rate.
        ax.bar(x + 0.2, [stats["keep_rate"][k] or 0 for k in ("regular", "closeup")], 0.4,
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
    _crack_axes(stats, axes[0, 3], axes[1, 3])
    save_figure(fig, path)


def _crack_axes(stats: dict, widths, lengths) -> None:
    """The crack-width histogram (one bar per bin) and the crack length per m^2, or what the
    dataset lacks for them."""
    hist = stats["crack_width_histogram"]
    edges = hist["edges_mm"]
    names = [f"{lo:g}-{hi:g}" for lo, hi in zip(edges, edges[1:])]
    widths.bar(names, hist["pixels"] or [0] * len(names))
    widths.tick_params(axis="x", labelrotation=90)
    widths.set_xlabel("crack width [mm]"), widths.set_ylabel("pixels")
    widths.set_title("crack widths: map pixels per bin" if hist["pixels"] is not None
                     else "no crack widths")
    (_, _, value), = _crack_rows(stats)[1:]
    lengths.axis("off")
    lengths.set_title("crack length per m^2 of column\nand beam surface in the RRDR")
    lengths.text(0.5, 0.5, value, ha="center", va="center")


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

