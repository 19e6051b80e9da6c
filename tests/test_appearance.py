import dataclasses
from collections import Counter

import numpy as np
import pytest

from glsynth.appearance.damage_bank import DamageBank
from glsynth.appearance.dressing import dress, open_repository
from glsynth.core.config import Config, DamageConfig, MaterialsConfig
from glsynth.core.labels import Component, Damage
from glsynth.world.environment import PartKind, build_environment

CONFIG = dataclasses.replace(Config(), damage=DamageConfig(resolution=64),
                             materials=MaterialsConfig(texture_size=32, images_per_category=4))


@pytest.fixture(scope="module")
def dressed():
    repo = open_repository(CONFIG)
    envs = [build_environment(CONFIG, 0, e) for e in range(3)]
    out = []
    for env in envs:
        bank = DamageBank(CONFIG.damage, 0)
        columns = {p.name for p in env.parts if p.kind is PartKind.COLUMN}
        out.append((env, dress(env, CONFIG, repo, bank, columns), bank))
    return out


def test_section_3_2_rules(dressed):
    sleeper_by_viaduct = {}
    for env, d, _ in dressed:
        for part in env.parts:
            a, m = d.assignments[part.name], d.materials[part.name]
            kind = part.kind
            if kind.component in (Component.SLAB, Component.BEAM) or (
                    kind is PartKind.COLUMN and not a.damage["damaged"]):
                assert (a.category, a.metallic, a.roughness) == ("concrete", 0.0, 1.0)
                assert 0.1 <= a.scale <= 1.0 and m.uv_scale == a.scale
            elif kind in (PartKind.RAIL, PartKind.WIRE):
                assert a.category == "steel" and a.metallic == 1.0 and 0 <= a.roughness <= 1
            elif kind in (PartKind.FENCE, PartKind.POLE, PartKind.PORTAL):
                assert a.category == "painted" and 0 <= a.metallic <= 1 and 0 <= a.roughness <= 1
            elif kind is PartKind.GROUND:
                assert a.category == "ground" and 0.0 <= a.scale <= 0.1
                assert (a.metallic, a.roughness) == (0.0, 1.0)
            elif kind is PartKind.SCENE:
                assert m.base_color[:3] == (0.0, 0.0, 0.0) and m.emissive == (0.5, 0.5, 0.5)
                assert m.emissive_map is not None
            elif kind is PartKind.SLEEPER:
                key = (env.env_index, part.viaduct)
                sleeper_by_viaduct.setdefault(key, set()).add((a.category, a.image, a.scale))
                if a.category == "steel":
                    assert a.metallic == 1.0 and 0 <= a.roughness <= 1
                else:
                    assert (a.metallic, a.roughness) == (0.0, 1.0)
            assert m.base_color_map is not None or m.emissive_map is not None
    # One sleeper material per viaduct (both tracks), drawn from all three categories.
    assert all(len(v) == 1 for v in sleeper_by_viaduct.values())
    kinds = Counter(next(iter(v))[0] for v in sleeper_by_viaduct.values())
    assert set(kinds) == {"concrete", "steel", "wood"}


def test_column_damage_assignment(dressed):
    records = [d.assignments[p.name].damage for env, d, _ in dressed for p in env.parts
               if p.kind is PartKind.COLUMN]
    n = len(records)
    undamaged = sum(not r["damaged"] for r in records)
    assert abs(undamaged / n - 0.1) < 4 * np.sqrt(0.09 / n)
    severities = Counter(r["severity"] for r in records if r["damaged"])
    assert set(severities) == {"slight", "medium", "severe"}
    assert all(0.2 <= r["scale"] <= 1.0 for r in records if r["damaged"])
    for env, d, _ in dressed:
        for p in env.parts:
            r = d.assignments[p.name].damage
            m = d.materials[p.name]
            if r and r["damaged"]:
                assert m.damage_mask is not None and m.normal_map is not None
                assert m.uv_scale == pytest.approx(r["scale"])
                assert set(np.unique(m.damage_mask)) <= {1, 2, 3}
                rebar = m.damage_mask == Damage.REBAR
                assert np.array_equal(m.metallic_map == 255, rebar)


def test_damage_textures_only_for_visible_columns_and_cached(tmp_path):
    repo = open_repository(CONFIG)
    env = build_environment(CONFIG, 1, 0)
    bank = DamageBank(CONFIG.damage, 1, cache_dir=tmp_path)
    d = dress(env, CONFIG, repo, bank, visible=set())
    assert bank.generated == 0 and bank.loaded == 0
    assert all(d.materials[p.name].damage_mask is None for p in env.parts)
    assert any(d.assignments[p.name].damage["damaged"] for p in env.parts
               if p.kind is PartKind.COLUMN)
    some = {p.name for p in env.parts if p.kind is PartKind.COLUMN and p.viaduct == 0}
    first = dress(env, CONFIG, repo, bank, visible=some)
    made = bank.generated
    assert 0 < made <= len(some) and len(list(tmp_path.rglob("*.npz"))) == made
    second = dress(env, CONFIG, repo, DamageBank(CONFIG.damage, 1, cache_dir=tmp_path), some)
    for name in some:
        a, b = first.materials[name], second.materials[name]
        if a.damage_mask is not None:
            assert a.damage_mask.tobytes() == b.damage_mask.tobytes()
            assert a.base_color_map.tobytes() == b.base_color_map.tobytes()
            assert a.normal_map.tobytes() == b.normal_map.tobytes()


def test_dressing_is_reproducible_and_independent_of_visibility():
    repo = open_repository(CONFIG)
    env = build_environment(CONFIG, 2, 1)
    all_columns = {p.name for p in env.parts if p.kind is PartKind.COLUMN}
    a = dress(env, CONFIG, repo, DamageBank(CONFIG.damage, 2), all_columns)
    b = dress(env, CONFIG, repo, DamageBank(CONFIG.damage, 2), set())
    for p in env.parts:
        x, y = a.assignments[p.name], b.assignments[p.name]
        assert (x.category, x.image, x.scale, x.metallic) == (y.category, y.image, y.scale,
                                                             y.metallic)
        if x.damage:
            assert {k: v for k, v in x.damage.items() if k in ("damaged", "severity",
                                                               "bank_index", "scale")} == \
                {k: v for k, v in y.damage.items() if k in ("damaged", "severity",
                                                           "bank_index", "scale")}


def test_damage_materials_are_built_when_read_and_not_kept(tmp_path):
    """Dressing reads only the bank entries' parameters; each read of a damaged column's
    material builds it anew (same bytes, new arrays, so nothing holds the maps), and its
    factors come without maps and without building."""
    repo = open_repository(CONFIG)
    env = build_environment(CONFIG, 3, 0)
    columns = {p.name for p in env.parts if p.kind is PartKind.COLUMN}
    maker = DamageBank(CONFIG.damage, 3, cache_dir=tmp_path)
    dress(env, CONFIG, repo, maker, columns)  # makes the entries
    bank = DamageBank(CONFIG.damage, 3, cache_dir=tmp_path)
    d = dress(env, CONFIG, repo, bank, columns)
    assert bank.loaded == 0 and bank.generated == 0  # parameters only: no maps were read
    damaged = [n for n in columns if d.assignments[n].damage["damaged"]]
    assert damaged and len(d.materials) == len(env.parts) and set(d.materials) == {
        p.name for p in env.parts}
    name = damaged[0]
    first, second = d.materials[name], d.materials[name]
    assert bank.loaded == 2
    assert first.base_color_map is not second.base_color_map
    assert first.base_color_map.tobytes() == second.base_color_map.tobytes()
    light = d.materials.factors(name)
    assert light.base_color_map is None and light.damage_mask is None
    assert (light.uv_scale, light.metallic, light.roughness) == (
        first.uv_scale, first.metallic, first.roughness)
    plain = next(p.name for p in env.parts if p.kind is PartKind.SLAB)
    assert d.materials.factors(plain) is d.materials[plain]
    record = d.assignments[name].damage
    entry = bank.entry(record["severity"], record["bank_index"], repo)
    assert record["params"] == entry.params and record["images"] == list(entry.images)


def test_built_in_order_gives_every_material_in_order_building_one_ahead():
    """Deferred materials are built in a background thread one ahead of the caller, so at
    most two exist at a time; plain mappings pass through; a failed build raises here."""
    import threading

    from glsynth.appearance.materials import Material, Materials, built_in_order

    alive, most, lock = [0], [0], threading.Lock()

    def build(k: int):
        def make() -> Material:
            with lock:
                alive[0] += 1
                most[0] = max(most[0], alive[0])
            return Material(metallic=k / 10, base_color_map=np.full((2, 2, 3), k, np.uint8))
        return make

    names = [f"column_{k}" for k in range(6)] + ["slab_0"]
    m = Materials({"slab_0": Material()},
                  {f"column_{k}": (Material(), build(k)) for k in range(6)})
    got = []
    for name, material in zip(names, built_in_order(m, names), strict=True):
        got.append(material)
        if name != "slab_0":
            assert material.base_color_map[0, 0, 0] == int(name[-1])
        with lock:
            alive[0] -= 1 if name != "slab_0" else 0
    assert got[-1] is m["slab_0"] and most[0] <= 2
    plain = {"a": Material(), "b": Material(metallic=1.0)}
    assert list(built_in_order(plain, ["b", "a"])) == [plain["b"], plain["a"]]

    def broken() -> Material:
        raise RuntimeError("bank entry unreadable")

    bad = Materials({}, {"column_0": (Material(), broken)})
    with pytest.raises(RuntimeError, match="unreadable"):
        list(built_in_order(bad, ["column_0"]))


def test_materials_mapping_lists_ready_and_deferred_and_refuses_both():
    from glsynth.appearance.materials import Material, Materials, factors

    built = []

    def build() -> Material:
        built.append(1)
        return Material(metallic=1.0, base_color_map=np.zeros((2, 2, 3), np.uint8))

    plain = Material()
    m = Materials({"slab_0": plain}, {"column_0": (Material(metallic=1.0), build)})
    assert len(m) == 2 and set(m) == {"slab_0", "column_0"} and "column_0" in m
    assert "rail_0" not in m
    assert factors(m, "column_0").base_color_map is None and not built
    assert m["column_0"].base_color_map is not None and len(built) == 1
    assert factors({"slab_0": plain}, "slab_0") is plain
    with pytest.raises(ValueError, match="both ready and deferred"):
        Materials({"column_0": plain}, {"column_0": (plain, build)})
