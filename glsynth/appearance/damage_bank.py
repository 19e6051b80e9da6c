"""The damage-texture bank (paper: 1,000 textures per severity), made lazily and cached.

Texture k of a severity comes from its own generator, make_rng(root_seed, 0, DAMAGE_BANK, item),
so it is the same whichever columns ask for it and in which order. Only the seed-determined
part is cached on disk (mask, displacement, parameters, image choices; compressed .npz); the
RGB, metallic and normal maps are rebuilt from it and the repository on load.
"""

import dataclasses
import hashlib
import io
import json
import os
import warnings
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

import numpy as np

from glsynth.appearance.damage import (
    SEVERITIES,
    DamageMaps,
    DamageParams,
    compose_rgb,
    damage_maps,
    metallic_map,
    normal_map,
    sample_params,
)
from glsynth.appearance.materials import Material
from glsynth.appearance.repository import TextureRepository
from glsynth.core.config import DamageConfig
from glsynth.core.errors import UserError, named, shown
from glsynth.core.fileio import atomic_write_bytes
from glsynth.core.paths import cache_folder, cache_root
from glsynth.core.reading import MAX_ARRAY_BYTES, check_file, parse_json, remove_entry
from glsynth.core.seeding import Stream, make_rng

BANK_VERSION = 1
T = TypeVar("T")


@dataclass(frozen=True)
class BankEntry:
    severity: str
    index: int
    params: DamageParams
    maps: DamageMaps
    images: tuple[int, int, int]
    """Repository indices: intact concrete, damaged concrete, steel."""


class DamageBank:
    def __init__(self, cfg: DamageConfig, root_seed: int, cache_dir: Path | None = None
                 ) -> None:
        self.cfg = cfg
        self.root_seed = root_seed
        key = json.dumps([BANK_VERSION, root_seed, cfg.texture_settings()], sort_keys=True)
        digest = hashlib.sha256(key.encode()).hexdigest()[:16]
        self.dir = (cache_dir or cache_root()) / f"damage-{digest}"
        self.generated = 0
        self.loaded = 0

    def _item(self, severity: str, index: int) -> int:
        if severity not in SEVERITIES:
            raise ValueError(f"severity = {severity!r}: choose one of {SEVERITIES}")
        if not 0 <= index < self.cfg.bank_size:
            raise ValueError(f"bank index = {index}: must be in [0, {self.cfg.bank_size - 1}]")
        return SEVERITIES.index(severity) * 10**6 + index

    def _path(self, severity: str, index: int) -> Path:
        return self.dir / f"{severity}_{index:06d}.npz"

    def entry(self, severity: str, index: int, repository: TextureRepository) -> BankEntry:
        item = self._item(severity, index)
        path = self._path(severity, index)
        stored = _stored(path, lambda: self._read(path, severity, index))
        if stored is not None:
            self.loaded += 1
            return stored
        rng = make_rng(self.root_seed, 0, Stream.DAMAGE_BANK, item)
        params = sample_params(self.cfg, severity, rng)
        images = (int(rng.integers(repository.count("concrete"))),
                  int(rng.integers(repository.count("concrete"))),
                  int(rng.integers(repository.count("steel"))))
        maps = damage_maps(params, self.cfg, rng)
        entry = BankEntry(severity, index, params, maps, images)
        self._write(path, entry)
        self.generated += 1
        return entry

    def _write(self, path: Path, entry: BankEntry) -> None:
        buf = io.BytesIO()
        meta = {"params": dataclasses.asdict(entry.params), "images": entry.images,
                "threshold": entry.maps.threshold}
        np.savez_compressed(buf, mask=entry.maps.mask, displacement=entry.maps.displacement_m,
                            meta=np.frombuffer(json.dumps(meta).encode(), np.uint8))
        cache_folder(path.parent)
        atomic_write_bytes(path, buf.getvalue())

    def _read(self, path: Path, severity: str, index: int) -> BankEntry:
        with np.load(path, allow_pickle=False) as data:
            meta = _meta(path, data)
            maps = DamageMaps(data["mask"], data["displacement"], meta["threshold"])
        mask, depth = maps.mask, maps.displacement_m
        if mask.ndim != 2 or depth.shape != mask.shape:
            raise ValueError(f"mask {mask.shape} and displacement {depth.shape} differ")
        # DamageMaps' contract: uint8 ids up to 3, float32 depths >= 0 (NaN fails the test).
        if mask.dtype != np.uint8 or depth.dtype != np.float32 or not (
                mask.size and mask.max() <= 3 and depth.min() >= 0
                and np.isfinite(depth).all()):
            raise ValueError(f"mask {mask.dtype} or displacement {depth.dtype} out of contract")
        params, images = _record(meta)
        return BankEntry(severity, index, params, maps, images)

    def record(self, severity: str, index: int, repository: TextureRepository
               ) -> tuple[DamageParams, tuple[int, int, int]]:
        """An entry's parameters and repository images, without reading its maps (an entry
        not yet made is made)."""
        self._item(severity, index)  # validates
        path = self._path(severity, index)

        def read() -> tuple[DamageParams, tuple[int, int, int]]:
            with np.load(path, allow_pickle=False) as data:  # members are read when asked for
                return _record(_meta(path, data))

        stored = _stored(path, read)
        if stored is None:
            entry = self.entry(severity, index, repository)
            return entry.params, entry.images
        return stored

    def material(self, severity: str, index: int, repository: TextureRepository,
                 scale: float) -> Material:
        """The damage material of entry ``index`` at texture scale ``scale``."""
        return damage_material(self.entry(severity, index, repository), repository, self.cfg,
                               scale)


def _stored(path: Path, read: Callable[[], T]) -> T | None:
    """What ``read`` makes of a bank entry on disk; None where there is none, or where it is
    not a readable entry (a folder, a FIFO, a truncated file), which is then removed with a
    warning so that it is made again."""
    if not os.path.lexists(path):
        return None
    try:
        check_file(path, "damage-bank entry", MAX_ARRAY_BYTES, "it is made again")
        return read()
    except (UserError, OSError, ValueError, KeyError, TypeError, EOFError,
            zipfile.BadZipFile) as err:
        warnings.warn(f"damage bank: making {named(path)} again ({shown(str(err), 100)})",
                      stacklevel=3)
        remove_entry(path)
        return None


def _meta(path: Path, data: np.lib.npyio.NpzFile) -> dict:
    meta = parse_json(data["meta"].tobytes(), f"damage-bank entry {named(path)}",
                      "it is made again")
    if not isinstance(meta, dict):
        raise ValueError("its meta is not a JSON object")
    return meta


def _record(meta: dict) -> tuple[DamageParams, tuple[int, int, int]]:
    p = meta["params"]
    params = DamageParams(**{**p, "period_px": tuple(p["period_px"])})
    return params, tuple(meta["images"])


def damage_factors(cfg: DamageConfig, scale: float) -> Material:
    """A damaged column's material without its maps: its factors, repeating every
    tile_m / scale metres (the maps carry the colour, metallic and relief)."""
    return Material(base_color=(1.0, 1.0, 1.0, 1.0), metallic=1.0, roughness=1.0,
                    uv_scale=scale / cfg.tile_m)


def damage_material(entry: BankEntry, repository: TextureRepository, cfg: DamageConfig,
                    scale: float) -> Material:
    """The PBR material of a damaged column: RGB, metallic and normal maps plus the
    damage-id mask, repeating every tile_m / scale metres."""
    size = entry.maps.mask.shape[0]
    images = [_fit(repository.image(cat, i), size)
              for cat, i in zip(("concrete", "concrete", "steel"), entry.images)]
    return dataclasses.replace(damage_factors(cfg, scale),
                               base_color_map=compose_rgb(entry.maps.mask, *images),
                               metallic_map=metallic_map(entry.maps.mask),
                               normal_map=normal_map(entry.maps.displacement_m,
                                                     cfg.tile_m / size),
                               damage_mask=entry.maps.mask)


def _fit(image: np.ndarray, size: int) -> np.ndarray:
    """Tile or crop a square repository image to size x size."""
    reps = -(-size // image.shape[0])
    return np.tile(image, (reps, reps, 1))[:size, :size]
