"""PyTorch Dataset over the Tokaido layout: glsynth's output and the released dataset alike.

Tasks (paper Section 4.2): "component" and "depth" use regular views by default; "damage" uses
regular and close-up views whose damage lies in the RRDR, and can add the pure-texture plates.
Images come as float32 (3, H, W) in [0, 1]; targets at a third of the image size (FCN58's output):
int64 ids (0 = ignore) for the label tasks, float32 metres for depth.
"""

from pathlib import Path

import numpy as np
import torch
from PIL import Image
from torch.utils.data import Dataset

from glsynth.tokaido import FrameRecord, PuretexRecord, decode_depth, read_manifest

TASKS = ("component", "damage", "depth")


class TokaidoDataset(Dataset):
    def __init__(self, root: str | Path, split: str = "train", task: str = "component", *,
                 views: str | None = None, puretex: bool = False,
                 image_size: tuple[int, int] = (1920, 1080)) -> None:
        """views: "regular", "closeup" or "all" (default: regular for component/depth, all
        for damage). image_size: (width, height), a multiple of 3 in each direction."""
        if task not in TASKS:
            raise ValueError(f"task = {task!r}: choose one of {TASKS}")
        if split not in ("train", "test"):
            raise ValueError(f"split = {split!r}: choose 'train' or 'test'")
        if image_size[0] % 3 or image_size[1] % 3:
            raise ValueError(f"image_size = {image_size}: width and height must be multiples "
                             "of 3 (the targets are a third of the image)")
        if puretex and task != "damage":
            raise ValueError("puretex = True: plate images have only damage labels; use "
                             "task='damage'")
        views = views or ("all" if task == "damage" else "regular")
        if views not in ("regular", "closeup", "all"):
            raise ValueError(f"views = {views!r}: choose 'regular', 'closeup' or 'all'")
        self.root, self.task, self.size = Path(root), task, image_size
        frames: list[FrameRecord] = read_manifest(self.root, f"files_{split}.csv")
        self.items: list[FrameRecord | PuretexRecord] = [
            r for r in frames
            if (views == "all" or r.regular == (views == "regular"))
            and (task != "damage" or r.damage_in_rrdr)]
        if puretex:
            self.items += read_manifest(self.root, f"files_puretex_{split}.csv")

    def __len__(self) -> int:
        return len(self.items)

    def _image(self, rel: str) -> torch.Tensor:
        with Image.open(self.root / rel) as im:
            im = im.convert("RGB")
            if im.size != self.size:
                im = im.resize(self.size, Image.Resampling.BILINEAR)
            array = np.asarray(im, dtype=np.float32) / 255.0
        return torch.from_numpy(array).permute(2, 0, 1).contiguous()

    def _map(self, rel: str) -> np.ndarray:
        target = (self.size[0] // 3, self.size[1] // 3)
        with Image.open(self.root / rel) as im:
            if im.size != target:
                im = im.resize(target, Image.Resampling.NEAREST)
            return np.asarray(im)

    def __getitem__(self, index: int) -> tuple[torch.Tensor, torch.Tensor]:
        item = self.items[index]
        image = self._image(item.image)
        if self.task == "depth":
            depth = decode_depth(self._map(item.depth))
            return image, torch.from_numpy(depth)
        rel = item.component if self.task == "component" else item.damage
        return image, torch.from_numpy(self._map(rel).astype(np.int64))
