"""Dress an environment: a material for every part (Section 3.2) and damage for the columns
(Section 3.3), from the texture repository and the damage bank.

Each part draws from its own generator (MATERIALS stream, item = its index in the environment's
part list; sleepers per viaduct; column damage from the DAMAGE stream), so a part's material
never depends on which other parts are built. Damage textures are built only for columns in
``visible`` (seen by some camera of the environment); a damaged column no camera sees keeps its
sampled damage record but is drawn with plain concrete, which no image can show. Damage
materials are deferred (glsynth.appearance.materials.Materials): built when asked for, so that
the renderer holds one column's maps at a time, not the environment's.

Under ``[damage] model = "mechanics"`` a damaged visible column gets a crack network
(glsynth.appearance.cracks; its drift and cracks from the CRACKS stream, item = its index);
one of [damage] spalling_severities (medium and severe by default) also gets its Section 3.3
damage texture (the bank entry and scale drawn as under "paper"), confined to the
plastic-hinge zones at both ends of each clear span (Material.zones), its own concrete
elsewhere. Its severity is drawn as under "paper", so both models damage the same columns.
Cross and tie beams and the girders draw their severity, drift and cracks from the CRACKS
stream (item = their index); a girder's cracks are made per clear span on a straight box and
mapped onto its curved sweep (glsynth.appearance.girder_cracks).

Under ``[materials] concrete_detail = "on"`` every part of the concrete category gets concrete
detail (Material.detail_seed) from the DETAIL stream (item = its index), which draws nothing;
under ``weathering = true`` also its weathered albedo and hue (Material.weathering_tint) from
the WEATHERING stream (item = its index). Under ``ground_detail = true`` the ground's parts get
the ground's detail (Material.ground_detail), seeded from the DETAIL stream alike.
"""

import functools
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from glsynth.appearance import town_textures
from glsynth.appearance.crack_leachate import with_leachate
from glsynth.appearance.cracks import (
    CrackNetwork,
    beam_cracks,
    column_cracks,
    column_demand,
    crack_records,
    hinge_zones,
)
from glsynth.appearance.damage_bank import DamageBank, damage_factors
from glsynth.appearance.girder_cracks import girder_cracks, girder_spans, girder_sweep
from glsynth.appearance.materials import (
    Assignment,
    DamageZones,
    Material,
    Materials,
    sample_assignment,
    srgb_decode,
)
from glsynth.appearance.repository import TextureRepository, builtin_repository
from glsynth.appearance.signs import plate_image
from glsynth.core.config import Config, DamageConfig
from glsynth.core.labels import Component
from glsynth.core.seeding import Stream, make_rng, make_seed
from glsynth.world.environment import BOX_BEAMS, Environment, Part, PartKind
from glsynth.world.lighting import LUMINANCE
from glsynth.world.severe import DAMAGE_OF_KIND, clear_spans, column_damage_rng, draw_severity

SLEEPER_CATEGORIES = ("concrete", "steel", "wood")
_SLEEPER_ITEM = 10**6  # + viaduct index: one sleeper material per viaduct


@dataclass(frozen=True)
class Dressing:
    materials: Materials
    assignments: dict[str, Assignment]


def open_repository(config: Config,
                    interrupt: Callable[[], bool] | None = None) -> TextureRepository:
    """The configured repository, one per process: its decoded, resized images (read-only
    arrays) then serve every environment, and the renderer keeps their textures uploaded.
    Images added to the folder while the process runs are not seen. ``interrupt``: stops the
    making of a built-in one (builtin_repository)."""
    m = config.materials
    root = m.repository or builtin_repository(m.repository_seed, m.images_per_category,
                                              m.builtin_size, interrupt)
    return _repository(str(Path(root).resolve()), m.texture_size)


@functools.lru_cache(maxsize=2)
def _repository(root: str, size: int) -> TextureRepository:
    return TextureRepository(root, size)


def _column_damage(config: Config, root_seed: int, env: int, ordinal: int) -> dict:
    d = config.damage
    rng = column_damage_rng(root_seed, env, ordinal)
    severity = draw_severity(d, rng)
    if severity is None:
        return {"damaged": False}
    return {"damaged": True, "severity": severity,
            "bank_index": int(rng.integers(d.bank_size)), "scale": float(rng.uniform(*d.scale))}


def beam_span(env: Environment, part: Part) -> tuple[int, tuple[float, float]] | None:
    """A cross or tie beam's long axis in its mesh frame (0: x, 1: y) and its clear span on
    that axis, between the faces of the columns that carry it; None for the girders (swept
    along the track, not boxes) and any other beam."""
    if part.kind not in BOX_BEAMS:
        return None
    viaduct = next(v for v in env.viaducts if v.index == part.viaduct)
    along, across = viaduct.columns[0].section_m
    axis = int(np.argmax(part.mesh.extents[:2]))
    if axis == 1:  # across the track: carried by the two columns of a row
        half = (env.config.design.column_spacing_m - across) / 2
    else:  # along the track: between neighbouring rows, centre to centre
        half = (float(part.mesh.extents[0]) - along) / 2
    return axis, (-half, half)


def _beam_network(env: Environment, cfg: DamageConfig, part: Part, drift: float,
                  rng: np.random.Generator) -> CrackNetwork:
    """The cracks of a girder (glsynth.appearance.girder_cracks) or a cross or tie beam."""
    if part.kind is PartKind.GIRDER:
        d = env.config.design
        sweep = girder_sweep(env, part)
        return girder_cracks(cfg, sweep, girder_spans(sweep, d.crossbeam_width_m),
                             d.girder_width_m, d.girder_depth_m, drift, rng)
    axis, span = beam_span(env, part)
    return beam_cracks(cfg, tuple(float(e) for e in part.mesh.extents), axis, span, drift, rng)


KnownCracks = dict[int, tuple[dict, CrackNetwork]]
"""A built member's record and (leaching) cracks by its part index, found once an opening: the
cameras that aim at cracks (crack_segments) and the dressing both need them, and a member's
cracks come from its own generator, so the first finding serves both."""


def _remembered(known: KnownCracks | None, ordinal: int,
                find: Callable[[], tuple[dict, CrackNetwork]]) -> tuple[dict, CrackNetwork]:
    """``find()``, or what it gave for ``ordinal`` before (a copy of the record)."""
    if known is None:
        return find()
    if ordinal not in known:
        known[ordinal] = find()
    record, cracks = known[ordinal]
    return dict(record), cracks


def _beam_damage(env: Environment, cfg: DamageConfig, part: Part, ordinal: int,
                 material: Material, seen: bool, known: KnownCracks | None = None
                 ) -> tuple[dict | None, Material]:
    """A girder's or a cross or tie beam's record and material under model = "mechanics"."""
    if part.kind is not PartKind.GIRDER and beam_span(env, part) is None:
        return None, material
    rng = make_rng(env.root_seed, env.env_index, Stream.CRACKS, ordinal)
    severity = draw_severity(cfg, rng)
    if severity is None:
        return {"damaged": False}, material
    record = {"damaged": True, "severity": severity, "built": seen}
    if not seen:
        return record, material

    def find() -> tuple[dict, CrackNetwork]:
        demand = column_demand(cfg, severity, rng)
        cracks = _beam_network(env, cfg, part, demand.drift, rng)
        return (_with_cracks(record, part, cracks, drift_pct=round(demand.drift * 100, 4)),
                _leaching(env, cfg, ordinal, cracks))

    record, cracks = _remembered(known, ordinal, find)
    return record, replace(material, cracks=cracks)


def _leaching(env: Environment, cfg: DamageConfig, ordinal: int, cracks: CrackNetwork
              ) -> CrackNetwork:
    """``cracks`` with [damage] leachate_share of them leaching, drawn from the LEACHATE
    stream (item = ``ordinal``, the part's index); as they are where the share is 0."""
    if not cfg.leachate_share or not cracks.kinds:
        return cracks
    rng = make_rng(env.root_seed, env.env_index, Stream.LEACHATE, ordinal)
    return with_leachate(cracks, cfg.leachate_share, rng)


def _constant_mask(kind: PartKind) -> np.ndarray:
    """The one-texel damage mask of a part whose every point has one damage id (severe damage
    as geometry: crushed concrete, exposed rebar)."""
    mask = np.full((1, 1), int(DAMAGE_OF_KIND[kind]), np.uint8)
    mask.flags.writeable = False
    return mask


CONSTANT_MASKS = {kind: _constant_mask(kind) for kind in DAMAGE_OF_KIND}
"""One array per kind, shared by its parts: the renderer and the glTF store it once."""


def _with_cracks(record: dict, part: Part, cracks: CrackNetwork, **demand: object) -> dict:
    """``record`` with the demand's fields and the crack list of ``part``."""
    return {**record, **demand,
            "cracks": [{"member": part.name, **r} for r in crack_records(cracks)]}


def _mechanics_damage(env: Environment, cfg: DamageConfig, part: Part, ordinal: int,
                      damage: dict, material: Material, known: KnownCracks | None = None
                      ) -> tuple[dict, Material]:
    """A damaged column's record and material under model = "mechanics": its drift and, if
    a camera sees it, its cracks on the concrete material (the record lists them)."""
    record = {"damaged": True, "severity": damage["severity"], "built": damage["built"]}
    if not damage["built"]:
        return record, material

    def find() -> tuple[dict, CrackNetwork]:
        rng = make_rng(env.root_seed, env.env_index, Stream.CRACKS, ordinal)
        demand = column_demand(cfg, damage["severity"], rng)
        section = tuple(float(e) for e in part.mesh.extents[:2])
        cracks = column_cracks(cfg, section, clear_spans(env, part), demand, rng)
        return (_with_cracks(record, part, cracks, drift_pct=round(demand.drift * 100, 4),
                             drift_axis="xy"[demand.axis]),
                _leaching(env, cfg, ordinal, cracks))

    record, cracks = _remembered(known, ordinal, find)
    return record, replace(material, cracks=cracks)


def crack_segments(env: Environment, config: Config, known: KnownCracks | None = None
                   ) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Every damaged column's and cross and tie beam's crack segments (the members face
    cameras aim at; not the girders'), seen by a camera or not: end points (N, 2, 3) in
    its mesh frame and widths (N, 2) in metres. They are the networks ``dress`` gives the
    seen members, for cameras that aim at cracks ([cameras] face_crack_share); none under
    model = "paper". ``known``: kept for ``dress`` of the same opening."""
    if config.damage.model != "mechanics":
        return {}
    out = {}
    for ordinal, part in enumerate(env.parts):
        if part.kind is PartKind.COLUMN:
            damage = _column_damage(config, env.root_seed, env.env_index, ordinal)
            if not damage["damaged"]:
                continue
            _, material = _mechanics_damage(env, config.damage, part, ordinal,
                                            {**damage, "built": True}, Material(), known)
        elif part.kind in BOX_BEAMS:  # none aims at a girder
            _, material = _beam_damage(env, config.damage, part, ordinal, Material(), True,
                                       known)
        else:
            continue
        if material.cracks is not None and len(material.cracks.points):
            out[part.name] = (material.cracks.points, material.cracks.widths_m)
    return out


def spalls(cfg: DamageConfig, severity: str) -> bool:
    """Under mechanics, columns of [damage] spalling_severities (by default medium and severe)
    spall in their hinge zones; the others only crack (docs/design.md, "Damage by
    mechanics")."""
    return severity in cfg.spalling_severities


def spalled_material(bank: DamageBank, repository: TextureRepository, damage: dict,
                     cracked: Material, zones: tuple[tuple[float, float], ...]) -> Material:
    """The bank's damage material of ``damage`` (severity, bank index, scale) with the
    cracks of ``cracked`` (the column's concrete material), confined to ``zones``; the
    concrete of ``cracked`` outside them."""
    built = bank.material(damage["severity"], damage["bank_index"], repository,
                          damage["scale"])
    return replace(built, cracks=cracked.cracks,
                   zones=DamageZones(zones, cracked.base_color_map, cracked.uv_scale))


def _spalling(env: Environment, config: Config, bank: DamageBank,
              repository: TextureRepository, part: Part, damage: dict, record: dict,
              material: Material) -> tuple[dict, tuple[Material, Callable[[], Material]]]:
    """A spalling column's record (the bank entry and its hinge zones added) and deferred
    material: the factors, and the function that builds the maps."""
    key = (damage["severity"], damage["bank_index"])
    params, images = bank.record(*key, repository)
    zones = hinge_zones(config.damage, clear_spans(env, part))
    record = {**record, "bank_index": damage["bank_index"], "scale": damage["scale"],
              "params": params, "images": list(images),
              "hinge_zones_m": [[round(z, 4) for z in zone] for zone in zones]}
    factors = replace(damage_factors(config.damage, damage["scale"]), cracks=material.cracks)
    build = functools.partial(spalled_material, bank, repository, damage, material, zones)
    return record, (factors, build)


def _with_detail(material: Material,
                 deferred: dict[str, tuple[Material, Callable[[], Material]]], name: str,
                 detail: dict) -> Material:
    """``material`` with the concrete detail fields ``detail`` (_detail); a deferred one's
    factors and builder are replaced in ``deferred`` too."""
    if name in deferred:
        factors, build = deferred[name]
        deferred[name] = (replace(factors, **detail), lambda: replace(build(), **detail))
    return replace(material, **detail)


WARM_GREY = ((1.03, 1.0, 0.95), (1.10, 1.0, 0.84))
"""The range of weathered concrete's hue, linear RGB over its luminance (docs/design.md,
"Weathered concrete": concrete's reflectance rises from blue to red)."""


def _detail_seed(env: Environment, ordinal: int) -> int:
    """Part ``ordinal``'s 32-bit detail seed (concrete's or the ground's) from the DETAIL
    stream."""
    return make_seed(env.root_seed, env.env_index, Stream.DETAIL, ordinal) % 2**32


def _detail(config: Config, env: Environment, ordinal: int, image: np.ndarray,
            means: dict[int, tuple[np.ndarray, np.ndarray]]) -> dict:
    """The Material fields of a concrete part's detail: its seed from the DETAIL stream and,
    under [materials] weathering, the tint that gives it an albedo and hue drawn from the
    WEATHERING stream (item = ``ordinal``, the part's index) in place of ``image``'s mean.
    ``means``: each image's linear mean by id (the image is kept beside it, so the id stays
    its own): the repository's dozen images serve hundreds of parts, so each is decoded once
    (docs/results.md, "Cracks found once an opening", has the measurement)."""
    detail: dict = {"detail_seed": _detail_seed(env, ordinal)}
    if config.materials.weathering:
        rng = make_rng(env.root_seed, env.env_index, Stream.WEATHERING, ordinal)
        albedo = rng.uniform(*config.materials.concrete_albedo)
        warm, cool = np.array(WARM_GREY[1]), np.array(WARM_GREY[0])
        hue = cool + rng.uniform() * (warm - cool)
        target = albedo * hue / float(hue @ LUMINANCE)
        if id(image) not in means:
            means[id(image)] = (image, np.maximum(srgb_decode(image).mean((0, 1)), 1e-3))
        mean = means[id(image)][1]
        detail["weathering_tint"] = tuple(float(v) for v in target / mean)
    return detail


TOWN_TEXTURE_PX = 512
"""Largest size of the town's own textures: a 3 m facade bay at 6 mm a pixel, where the
town is seen from 8 m and more."""


def _image(repository: TextureRepository, config: Config, a: Assignment) -> np.ndarray:
    """The assignment's image: from the town's own textures for their categories, else from
    the repository."""
    if a.category in town_textures.CATEGORIES:
        return town_textures.image(a.category, a.image,
                                   min(repository.size, TOWN_TEXTURE_PX),
                                   config.materials.repository_seed)
    return repository.image(a.category, a.image)


def _dress_column(env: Environment, config: Config, bank: DamageBank,
                  repository: TextureRepository, part: Part, ordinal: int, material: Material,
                  built: bool, known: KnownCracks | None,
                  deferred: dict[str, tuple[Material, Callable[[], Material]]]
                  ) -> tuple[dict, Material]:
    """A column's damage record and material: its drawn damage, by mechanics (with spalling
    deferred where it spalls) or from the damage bank (deferred); ``built``: the column is
    seen, so its damage is made. Deferred builders go into ``deferred``."""
    damage = _column_damage(config, env.root_seed, env.env_index, ordinal)
    if not damage["damaged"]:
        return damage, material
    damage["built"] = built
    if config.damage.model == "mechanics":
        sampled = damage
        damage, material = _mechanics_damage(env, config.damage, part, ordinal, sampled,
                                             material, known)
        if built and spalls(config.damage, damage["severity"]):
            damage, deferred[part.name] = _spalling(env, config, bank, repository, part,
                                                    sampled, damage, material)
    elif built:
        key = (damage["severity"], damage["bank_index"])
        params, images = bank.record(*key, repository)
        damage.update(params=params, images=list(images))
        deferred[part.name] = (damage_factors(config.damage, damage["scale"]),
                               functools.partial(bank.material, *key, repository,
                                                 damage["scale"]))
    return damage, material


def dress(env: Environment, config: Config, repository: TextureRepository, bank: DamageBank,
          visible: set[str], known: KnownCracks | None = None) -> Dressing:
    """Materials and damage of every part; cracks of the members in ``visible`` (``known``:
    those crack_segments found in this opening)."""
    cfg = config.materials
    root, index = env.root_seed, env.env_index
    materials: dict[str, Material] = {}
    deferred: dict[str, tuple[Material, Callable[[], Material]]] = {}
    assignments = {}
    means: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    for ordinal, part in enumerate(env.parts):
        kind = part.kind
        if kind is PartKind.SLEEPER:
            rng = make_rng(root, index, Stream.MATERIALS, _SLEEPER_ITEM + part.viaduct)
            category = SLEEPER_CATEGORIES[int(rng.integers(len(SLEEPER_CATEGORIES)))]
        else:
            rng = make_rng(root, index, Stream.MATERIALS, ordinal)
            category = ""
        a = sample_assignment(kind, cfg, rng, category, repository.count)
        image = _image(repository, config, a)
        if kind is PartKind.SIGN:
            image = plate_image(int(rng.integers(1, 1000)))
        if kind is PartKind.SCENE:
            material = Material(base_color=(0.0, 0.0, 0.0, 1.0), roughness=1.0,
                                emissive=(cfg.panel_emission,) * 3, emissive_map=image)
        else:
            material = Material(base_color=(1.0, 1.0, 1.0, 1.0), metallic=a.metallic,
                                roughness=a.roughness, uv_scale=a.scale, base_color_map=image,
                                damage_mask=CONSTANT_MASKS.get(kind))
        if kind is PartKind.COLUMN:
            damage, material = _dress_column(env, config, bank, repository, part, ordinal,
                                             material, part.name in visible, known, deferred)
            a = replace(a, damage=damage)
        elif kind.component is Component.BEAM and config.damage.model == "mechanics":
            damage, material = _beam_damage(env, config.damage, part, ordinal, material,
                                            part.name in visible, known)
            a = replace(a, damage=damage)
        if cfg.concrete_detail == "on" and a.category == "concrete":
            material = _with_detail(material, deferred, part.name,
                                    _detail(config, env, ordinal, image, means))
        elif cfg.ground_detail and kind is PartKind.GROUND:
            material = replace(material, ground_detail=True,
                               detail_seed=_detail_seed(env, ordinal))
        if part.name not in deferred:
            materials[part.name] = material
        assignments[part.name] = a
    return Dressing(Materials(materials, deferred), assignments)
