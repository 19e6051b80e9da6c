"""The disk caches that opening an environment fills (under glsynth.core.paths.cache_root),
named by what their entries' names are made from."""

from glsynth.appearance.damage_bank import DamageBank
from glsynth.appearance.repository import builtin_root
from glsynth.core.config import Config


def disk_caches(config: Config) -> dict[str, object]:
    """What names each cache's entries under ``config``, the root seed aside: two configs
    that give the same values here write the same entries, and one that gives other values
    writes new ones (the texture repository read, the images decoded at texture_size, the
    damage bank's folder)."""
    m = config.materials
    repository = m.repository or builtin_root(m.repository_seed, m.images_per_category,
                                              m.builtin_size)
    return {"texture repository": str(repository),
            "decoded images": (str(repository), m.texture_size),
            "damage bank": DamageBank(config.damage, 0).dir.name}
