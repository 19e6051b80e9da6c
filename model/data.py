"""PyTorch Dataset over the Tokaido layout: glsynth's output and the released dataset alike.

Tasks (paper Section 4.2): "component" and "depth" use regular views by default; "damage" uses
regular and close-up views whose damage lies in the RRDR, and can add the pure-texture plates.
Images come as float32 (3, H, W) in [0, 1]; targets at FCN58's output size, ceil(H/3) x
ceil(W/3): int64 ids (0 = ignore) for the label tasks, float32 metres for depth.
``ImageFolder`` adds real labelled photos (images/ + labels/ with the same stems).
``InputCache`` keeps images already resized to the training size, so that epochs after the
first decode no PNG.
"""

import hashlib
import os
from pathlib import Path

import cv2
import numpy as np
import torch
from glsynth.model.settings import CLASS_NAMES, TASKS, VIEWS, target_size
from PIL import Image
from torch.utils.data import Dataset

from glsynth.core.errors import UserError, named
from glsynth.core.fileio import atomic_write_bytes
from glsynth.core.images import nearest_resize, read_photo
from glsynth.core.paths import cache_folder, cache_root
from glsynth.core.reading import remove_entry
from glsynth.data.readers import (
    cache_entry_bytes,
    map_size,
    read_cache_entry,
    read_depth_map,
    read_label_map,
)
from glsynth.data.tokaido import (
    IMAGE_SIZE,
    FrameRecord,
    PuretexRecord,
    decode_depth,
    read_manifest,
)

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp")


def resize_rgb(rgb: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """uint8 (H, W, 3) brought to size = (W, H): area averaging when shrinking (no aliasing,
    and 5x faster than Pillow's bilinear to 480x270), bilinear when enlarging."""
    if (rgb.shape[1], rgb.shape[0]) == size:
        return rgb
    shrink = size[0] <= rgb.shape[1] and size[1] <= rgb.shape[0]
    return cv2.resize(rgb, size, interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)


def to_tensor(rgb: np.ndarray) -> torch.Tensor:
    """uint8 (H, W, 3) -> float32 (3, H, W) in [0, 1]."""
    return torch.from_numpy(rgb.astype(np.float32) / 255.0).permute(2, 0, 1).contiguous()


def image_tensor(image: Image.Image | np.ndarray, size: tuple[int, int]) -> torch.Tensor:
    """RGB float32 (3, H, W) in [0, 1], resized to size = (W, H) (resize_rgb)."""
    im = image if isinstance(image, Image.Image) else Image.fromarray(image)
    return to_tensor(resize_rgb(np.asarray(im.convert("RGB")), size))


def read_rgb(path: Path) -> np.ndarray:
    """uint8 (H, W, 3) of an image file; OpenCV decodes PNG about 10-15 % faster than Pillow."""
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:  # missing, damaged or a format OpenCV lacks: read_photo names the problem
        return read_photo(path)
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def load_image(path: Path, size: tuple[int, int]) -> torch.Tensor:
    return to_tensor(resize_rgb(read_rgb(path), size))


def load_map(path: Path, kind: str, size: tuple[int, int],
             expected: tuple[int, int] | None = None) -> np.ndarray:
    """A "component" or "damage" label map or a "depth" code map, checked by its reader
    (of size ``expected`` when given) and resized to ``size`` by nearest sampling (ids never
    blend)."""
    values = (read_depth_map(path, expected) if kind == "depth"
              else read_label_map(path, kind, expected))
    return nearest_resize(values, (size[1], size[0]))


def _digest(text: str, n: int) -> str:
    return hashlib.sha256(text.encode()).hexdigest()[:n]


class InputCache:
    """Images of one dataset resized to one size, as .npz entries (glsynth.data.readers)
    under $GLSYNTH_CACHE/inputs/<dataset and size>/<image path>/<image size and mtime>.npz, so
    an image that changes is decoded again (and its old entry removed); another dataset
    folder or size has a folder of its own. Each entry holds its key (image path, size, mtime,
    training size): an entry that is foreign, stale, damaged or of another dtype or shape is
    made again with a warning. The tensors are bit-identical to load_image's. Writes are
    atomic: loader processes may share a cache."""

    def __init__(self, root: Path, size: tuple[int, int], base: Path | None = None) -> None:
        self.size = size
        key = f"{os.path.realpath(root)}|{size[0]}x{size[1]}"
        self.dir = (base or cache_root()) / "inputs" / f"{Path(root).name}-{_digest(key, 16)}"

    def load(self, path: Path) -> torch.Tensor:
        stat = path.stat()
        # A folder per image, so that a miss lists only that image's old entries.
        folder = self.dir / _digest(os.path.realpath(path), 20)
        entry = folder / f"{_digest(f'{stat.st_size}:{stat.st_mtime_ns}', 12)}.npz"
        key = (f"{os.path.realpath(path)}|{stat.st_size}:{stat.st_mtime_ns}|"
               f"{self.size[0]}x{self.size[1]}")
        rgb = read_cache_entry(entry, key, (self.size[1], self.size[0], 3))
        if rgb is not None:
            return to_tensor(rgb)
        rgb = resize_rgb(read_rgb(path), self.size)
        for stale in cache_folder(folder).glob("*.np[yz]"):
            remove_entry(stale)
        atomic_write_bytes(entry, cache_entry_bytes(rgb, key))
        return to_tensor(rgb)


class TokaidoDataset(Dataset):
    def __init__(self, root: str | Path, split: str = "train", task: str = "component", *,
                 views: str | None = None, puretex: bool = False,
                 image_size: tuple[int, int] = IMAGE_SIZE, cache: bool = False) -> None:
        """views: "regular", "closeup" or "all" (default: regular for component/depth, all
        for damage). image_size: (width, height) the images are resized to. cache: read
        them through an InputCache."""
        if task not in TASKS:
            raise ValueError(f"task = {task!r}: choose one of {TASKS}")
        if split not in ("train", "test"):
            raise ValueError(f"split = {split!r}: choose 'train' or 'test'")
        if puretex and task != "damage":
            raise ValueError("puretex = True: plate images have only damage labels; use "
                             "task='damage'")
        views = views or ("all" if task == "damage" else "regular")
        if views not in VIEWS:
            raise ValueError(f"views = {views!r}: choose one of {VIEWS}")
        self.root, self.task, self.size = Path(root), task, image_size
        self.cache = InputCache(self.root, image_size) if cache else None
        frames: list[FrameRecord] = read_manifest(self.root, f"files_{split}.csv")
        self.items: list[FrameRecord | PuretexRecord] = [
            r for r in frames
            if (views == "all" or r.regular == (views == "regular"))
            and (task != "damage" or r.damage_in_rrdr)]
        if puretex:
            self.items += read_manifest(self.root, f"files_puretex_{split}.csv")

    def __len__(self) -> int:
        return len(self.items)

    def target(self, index: int) -> torch.Tensor:
        """The target alone (class statistics need no image decoding)."""
        item, size = self.items[index], target_size(self.size)
        expected = map_size(self.root / item.image)
        if self.task == "depth":
            return torch.from_numpy(decode_depth(load_map(self.root / item.depth, "depth",
                                                          size, expected)))
        rel = item.component if self.task == "component" else item.damage
        return torch.from_numpy(load_map(self.root / rel, self.task, size,
                                         expected).astype(np.int64))

    def image(self, index: int) -> torch.Tensor:
        path = self.root / self.items[index].image
        return self.cache.load(path) if self.cache else load_image(path, self.size)

    def __getitem__(self, index: int) -> tuple[torch.Tensor, torch.Tensor]:
        return self.image(index), self.target(index)


class ImageFolder(Dataset):
    """Real labelled photos: DIR/images/<stem>.{png,jpg,jpeg,bmp} with DIR/labels/<stem>.{png,
    bmp} holding the task's ids (0 = unlabelled). Images are resized to image_size."""

    def __init__(self, root: str | Path, task: str,
                 image_size: tuple[int, int] = IMAGE_SIZE) -> None:
        if task not in CLASS_NAMES:
            raise UserError(f"extra image folders carry labels; task {task!r} has none "
                            "(use them for component or damage)")
        self.root, self.task, self.size = Path(root), task, image_size
        images = sorted(p for p in (self.root / "images").glob("*")
                        if p.suffix.lower() in IMAGE_SUFFIXES)
        if not images:
            raise UserError(f"extra data {named(root)}: no images in {named(self.root)}/images;"
                            " put photos in images/ and id maps with the same stems in labels/")
        self.items = []
        for image in images:
            labels = [self.root / "labels" / f"{image.stem}{s}" for s in (".png", ".bmp")]
            found = [p for p in labels if p.exists()]
            if not found:
                raise UserError(f"extra data: no label map for {named(image)}; expected "
                                f"{str(labels[0])!r} or .bmp")
            self.items.append((image, found[0]))

    def __len__(self) -> int:
        return len(self.items)

    def target(self, index: int) -> torch.Tensor:
        ids = load_map(self.items[index][1], self.task, target_size(self.size))
        return torch.from_numpy(ids.astype(np.int64))

    def __getitem__(self, index: int) -> tuple[torch.Tensor, torch.Tensor]:
        return load_image(self.items[index][0], self.size), self.target(index)
