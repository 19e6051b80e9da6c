"""The released Tokaido dataset layout (IC-SHM 2021), written by glsynth and read back.

    <root>/files_train.csv, files_test.csv, files_puretex_train.csv, files_puretex_test.csv
    <root>/img_syn_raw/{train,test}/image_case{E}_frame{C}_Scene.png     RGB 1920x1080
    <root>/synthetic/{train,test}/labcmp/image_case{E}_frame{C}.bmp      component ids, 640x360
    <root>/synthetic/{train,test}/labdmg/image_case{E}_frame{C}.bmp      damage ids, 640x360
    <root>/synthetic/{train,test}/depth/image_case{E}_frame{C}.png       uint16 depth, 640x360
    <root>/synthetic/{train,test}/crackwidth/image_case{E}_frame{C}.png  uint16 crack width
    <root>/images_puretex/image_{N}.png, <root>/synthetic_puretex/labdmg/image_{N}.bmp

The crackwidth folder is glsynth's, beyond the released layout (which loaders read unchanged):
its path is derived from the damage label's (crack_width_path); the manifests do not list it.

Manifests have no header. files_{train,test}.csv: image, component label, damage label, depth,
focal length [mm], regular-image flag, damage-in-RRDR flag ('True'/'False'). Puretex manifests:
image, damage label. Paths are relative to the root; readers accept / and \\ separators.
Depth: uint16, linear from 0.5 m (0) to 30 m (65535), clipped; no geometry is 65535.
Crack width: uint16 in 0.01 mm steps (0..655.35 mm), 0 where no crack is; each map pixel holds
the widest crack of its 3x3 block of the render (downsample_crack_width).
"""

import csv
import io
import math
from dataclasses import dataclass
from pathlib import Path, PurePosixPath, PureWindowsPath

import numpy as np

from glsynth.core.errors import UserError, named, shown
from glsynth.core.images import nearest_resize
from glsynth.core.labels import Damage
from glsynth.core.reading import MAX_MANIFEST_BYTES, read_bytes

DEPTH_NEAR_M = 0.5
DEPTH_FAR_M = 30.0
DEPTH_MAX_CODE = 65535
IMAGE_SIZE = (1920, 1080)
"""(width, height) of a Tokaido image; its label and depth maps are LABEL_STRIDE times smaller."""
LABEL_STRIDE = 3  # 1920x1080 -> 640x360
CRACK_WIDTH_STEP_MM = 0.01
"""One code step of a crack-width map; code 65535 is 655.35 mm (cracks are at most 10 mm)."""


def frame_paths(split: str, env: int, camera: int) -> dict[str, str]:
    """Root-relative paths (with /) of one regular or close-up image and its maps: the four
    the manifest lists, and the crack-width map, which it does not."""
    _check_split(split)
    stem = f"image_case{env}_frame{camera}"
    damage = f"synthetic/{split}/labdmg/{stem}.bmp"
    return {"image": f"img_syn_raw/{split}/{stem}_Scene.png",
            "component": f"synthetic/{split}/labcmp/{stem}.bmp", "damage": damage,
            "depth": f"synthetic/{split}/depth/{stem}.png",
            "crackwidth": crack_width_path(damage)}


def crack_width_path(damage_label: str) -> str:
    """The crack-width map of a frame, from its damage label's root-relative path (either
    separator): ``synthetic/{split}/crackwidth/<stem>.png``, with /."""
    damage = PurePosixPath(_norm(damage_label))
    return str(damage.parent.parent / "crackwidth" / f"{damage.stem}.png")


def puretex_paths(index: int) -> dict[str, str]:
    return {"image": f"images_puretex/image_{index}.png",
            "damage": f"synthetic_puretex/labdmg/image_{index}.bmp"}


def _check_split(split: str) -> None:
    if split not in ("train", "test"):
        raise ValueError(f"split = {split!r}: must be 'train' or 'test'")


def encode_depth(depth_m: np.ndarray) -> np.ndarray:
    """Linear uint16 code: 0.5 m -> 0, 30 m -> 65535, clipped outside; NaN counts as far."""
    d = np.nan_to_num(np.asarray(depth_m, dtype=np.float64), nan=DEPTH_FAR_M)
    code = np.rint((d - DEPTH_NEAR_M) / (DEPTH_FAR_M - DEPTH_NEAR_M) * DEPTH_MAX_CODE)
    return np.clip(code, 0, DEPTH_MAX_CODE).astype(np.uint16)


def decode_depth(code: np.ndarray) -> np.ndarray:
    """value / 65535 * 29.5 + 0.5 metres, float32."""
    c = np.asarray(code, dtype=np.float64)
    return (c / DEPTH_MAX_CODE * (DEPTH_FAR_M - DEPTH_NEAR_M) + DEPTH_NEAR_M).astype(np.float32)


def downsample_labels(labels: np.ndarray, stride: int = LABEL_STRIDE) -> np.ndarray:
    """Nearest sampling at the centre pixel of each stride x stride block."""
    return nearest_resize(labels, _block_grid(labels, stride))


def encode_crack_width(width_mm: np.ndarray) -> np.ndarray:
    """uint16 code in CRACK_WIDTH_STEP_MM steps, clipped at 65535; a positive width below
    half a step is code 1, so that no crack of the map reads as no crack."""
    w = np.asarray(width_mm, dtype=np.float64)
    if not np.all(w >= 0):  # NaN fails too
        raise ValueError("crack widths must be finite millimetres >= 0")
    code = np.clip(np.rint(w / CRACK_WIDTH_STEP_MM), 0, 65535)
    return np.where((w > 0) & (code == 0), 1, code).astype(np.uint16)


def decode_crack_width(code: np.ndarray) -> np.ndarray:
    """code x 0.01 millimetres, float32."""
    return (np.asarray(code, dtype=np.float64) * CRACK_WIDTH_STEP_MM).astype(np.float32)


def _block_grid(values: np.ndarray, stride: int) -> tuple[int, int]:
    """Rows and columns of stride x stride blocks of a map."""
    h, w = values.shape[:2]
    if h % stride or w % stride:
        raise ValueError(f"map {w}x{h}: width and height must be multiples of {stride}")
    return h // stride, w // stride


def downsample_crack_width(width_mm: np.ndarray, stride: int = LABEL_STRIDE) -> np.ndarray:
    """The widest crack of each stride x stride block: a crack of any width at any offset
    keeps at least one pixel, with a width it has somewhere in the block."""
    _block_grid(width_mm, stride)
    widest = width_mm[::stride, ::stride].copy()
    # The maximum of strided views: 40x faster than reshaping and reducing over two axes.
    for r in range(stride):
        for c in range(stride):
            np.maximum(widest, width_mm[r::stride, c::stride], out=widest)
    return widest


def downsample_damage(damage: np.ndarray, block_width_mm: np.ndarray,
                      stride: int = LABEL_STRIDE) -> np.ndarray:
    """downsample_labels, then concrete damage wherever the block holds a crack pixel
    (exposed rebar stays), as the crack-width map marks it: a crack thinner than a block is
    kept. ``block_width_mm`` is downsample_crack_width of the render's crack widths. Without
    cracks (the paper model) this is downsample_labels exactly."""
    return mark_cracked_blocks(downsample_labels(damage, stride), block_width_mm)


def mark_cracked_blocks(blocks: np.ndarray, block_width_mm: np.ndarray) -> np.ndarray:
    """downsample_damage's crack rule on damage ids already downsampled (``blocks``): concrete
    damage wherever the block holds a crack pixel, exposed rebar kept."""
    if block_width_mm.shape != blocks.shape:
        raise ValueError(f"block crack widths {block_width_mm.shape} and damage blocks "
                         f"{blocks.shape} differ in size")
    cracked = block_width_mm > 0
    return np.where(cracked & (blocks < Damage.CONCRETE), Damage.CONCRETE, blocks
                    ).astype(blocks.dtype)


@dataclass(frozen=True)
class FrameRecord:
    image: str
    component: str
    damage: str
    depth: str
    focal_mm: float | None
    """None where the manifest leaves it empty."""
    regular: bool
    damage_in_rrdr: bool


@dataclass(frozen=True)
class PuretexRecord:
    image: str
    damage: str


def _flag(text: str, where: str) -> bool:
    if text == "True":
        return True
    if text == "False":
        return False
    raise UserError(f"{where}: flag {shown(text)} must be 'True' or 'False'")


def manifest_text(rows: list[FrameRecord] | list[PuretexRecord]) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    for r in rows:
        if isinstance(r, FrameRecord):
            focal = "" if r.focal_mm is None else repr(float(r.focal_mm))
            writer.writerow([r.image, r.component, r.damage, r.depth, focal, str(r.regular),
                             str(r.damage_in_rrdr)])
        else:
            writer.writerow([r.image, r.damage])
    return buf.getvalue()


def safe_path(root: Path, relative: str, where: str) -> Path:
    """root / relative, accepting / or \\ separators; refuses paths that leave the root."""
    parts = PureWindowsPath(relative).parts if "\\" in relative else PurePosixPath(relative).parts
    if not parts or PurePosixPath(relative).is_absolute() or PureWindowsPath(relative).drive:
        raise UserError(f"{where}: path {shown(relative)} must be relative to the dataset root")
    try:
        path = root.joinpath(*parts).resolve()
    except (ValueError, OSError) as err:  # a NUL byte; a symlink loop
        raise UserError(f"{where}: path {shown(relative)} is not a usable path ({err})") \
            from None
    if not path.is_relative_to(root.resolve()):
        raise UserError(f"{where}: path {shown(relative)} escapes the dataset root "
                        f"{named(root)}")
    return path


def read_manifest(root: str | Path, name: str) -> list[FrameRecord] | list[PuretexRecord]:
    """Rows of files_{train,test}.csv (7 columns) or files_puretex_*.csv (2 columns)."""
    root = Path(root)
    path = root / name
    data = read_bytes(path, "manifest", MAX_MANIFEST_BYTES,
                      f"is {named(root)} a Tokaido-layout dataset root?")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise UserError(f"manifest {named(path)} is not UTF-8 text (byte {err.start}); save it "
                        "as UTF-8") from None
    rows = []
    try:
        for line_no, row in enumerate(csv.reader(io.StringIO(text, newline="")), start=1):
            rows += _manifest_row(root, row, f"{named(path)} line {line_no}")
    except csv.Error as err:
        raise UserError(f"manifest {named(path)}: {err}; each line holds 7 (frames) or 2 "
                        "(plates) comma-separated paths and values") from None
    return rows


MAX_FIELD = 1024
"""Characters a manifest field may hold: paths in the Tokaido layout are under 100."""


def _manifest_row(root: Path, row: list[str], where: str) -> list[FrameRecord | PuretexRecord]:
    """The record of one manifest line (none for a blank line)."""
    long = [len(col) for col in row if len(col) > MAX_FIELD]
    if long:
        raise UserError(f"{where}: a field of {long[0]:,} characters, over the {MAX_FIELD} a "
                        "manifest field may hold; fix the line")
    if not row:
        return []
    if len(row) == 7:
        for col in row[:4]:
            safe_path(root, col, where)
        focal = _focal(row[4], where)
        return [FrameRecord(*(_norm(c) for c in row[:4]), focal,
                            _flag(row[5], where), _flag(row[6], where))]
    if len(row) == 2:
        for col in row:
            safe_path(root, col, where)
        return [PuretexRecord(_norm(row[0]), _norm(row[1]))]
    raise UserError(f"{where}: {len(row)} columns; frame manifests have 7, puretex "
                    "manifests 2")


def _focal(text: str, where: str) -> float | None:
    """The focal-length column: empty (unknown) or a finite length > 0 in millimetres."""
    if not text.strip():
        return None
    try:
        focal = float(text)
    except ValueError:
        focal = math.nan
    if not (math.isfinite(focal) and focal > 0):
        raise UserError(f"{where}: focal length {shown(text)} must be a number of millimetres > 0, "
                        "or empty when unknown")
    return focal


def _norm(relative: str) -> str:
    """Root-relative path with / separators."""
    return relative.replace("\\", "/")
