import math
import re
import typing

import pytest

from glsynth.core.checks import literal_choices
from glsynth.core.config import (
    PRESETS,
    CameraConfig,
    Config,
    CyclesConfig,
    DamageConfig,
    DatasetConfig,
    EnvironmentConfig,
    LightingConfig,
    MaterialsConfig,
    RenderConfig,
    config_from_dict,
    config_to_dict,
    load_config,
)
from glsynth.core.design import StandardDesign
from glsynth.core.errors import UserError


def test_presets_are_valid_and_differ_where_meant():
    paper, demo = load_config("paper"), load_config("demo")
    assert paper.dataset.n_environments == 200 and paper.dataset.n_test_environments == 25
    assert demo.dataset.n_environments < paper.dataset.n_environments
    assert set(PRESETS) >= {"paper", "demo"}


@pytest.mark.parametrize("field, value, message", [
    ("n_viaducts", 0, r"environment\.n_viaducts = 0: must be in \[1, 1000\]"),
    ("n_viaducts", 2.5, "must be an integer"),
    ("initial_height_m", (4.0, 12.0), r"initial_height_m = \(4\.0, 12\.0\).*5\.0 <= a <= b <= 14"),
    ("initial_height_m", (12.0, 6.5), "initial_height_m"),
    ("min_radius_m", (50.0, 5000.0), "min_radius_m"),
    ("min_radius_m", (500.0, math.inf), r"finite, or \[inf, inf\]"),
    ("max_slope", 0.0, r"max_slope = 0\.0: must be in \(0\.0, 0\.2\]"),
    ("sweep_step_m", math.nan, "sweep_step_m"),
    ("cylinder_segments", 2, "cylinder_segments"),
])
def test_bad_environment_values_name_field_value_and_range(field, value, message):
    with pytest.raises(ValueError, match=message) as info:
        EnvironmentConfig(**{field: value})
    assert "Fix it in the [environment] table" in str(info.value)


def test_dataset_test_split_cannot_exceed_environments():
    with pytest.raises(ValueError, match="n_test_environments = 5"):
        DatasetConfig(n_environments=3, n_test_environments=5)


def test_panels_must_stand_beyond_the_deck():
    with pytest.raises(ValueError, match="panel_distance_m"):
        config_from_dict({"environment": {"panel_distance_m": 6.0}})


def test_toml_overlay_with_inf_and_int_coercion(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text("[environment]\nmin_radius_m = [inf, inf]\nmax_slope = 0.01\n"
                    "initial_height_m = [7, 8]\n[dataset]\nn_environments = 4\n"
                    "n_test_environments = 1\n")
    config = load_config("paper", path)
    assert config.environment.min_radius_m == (math.inf, math.inf)
    assert config.environment.initial_height_m == (7.0, 8.0)
    assert config.environment.max_slope == 0.01
    assert config.dataset.n_environments == 4
    assert config.design == Config().design


@pytest.mark.parametrize("text, message", [
    ("[environmnet]\nn_viaducts = 3\n", r"unknown config section \[environmnet\]"),
    ("[environment]\nn_viaduct = 3\n", r"unknown key\(s\) \['n_viaduct'\]"),
    ("[environment]\nn_viaducts = -3\n", r"environment\.n_viaducts = -3"),
    ("[environment\n", "not valid TOML"),
])
def test_bad_toml_files_say_what_is_wrong(tmp_path, text, message):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ValueError, match=message):
        load_config("demo", path)


def test_missing_file_and_unknown_preset():
    with pytest.raises(ValueError, match="does not exist"):
        load_config("demo", "/nonexistent/x.toml")
    with pytest.raises(ValueError, match="preset = 'fast'.*demo"):
        load_config("fast")


def test_configs_are_frozen():
    with pytest.raises(AttributeError):
        Config().environment.n_viaducts = 3


def _toml(sections: dict[str, dict]) -> str:
    """TOML text of flat sections of numbers, strings and sequences of numbers."""
    def value(v):
        if isinstance(v, str):
            return f'"{v}"'
        if isinstance(v, (tuple, list)):
            return "[" + ", ".join(repr(float(x)) for x in v) + "]"
        return repr(v)
    return "".join(f"[{name}]\n" + "".join(f"{k} = {value(v)}\n" for k, v in keys.items())
                   for name, keys in sections.items())


def test_the_render_lighting_and_cycles_sections_round_trip_through_toml(tmp_path):
    config = Config(
        render=RenderConfig(width=640, height=360, msaa=0, renderer="cycles", shadow_map_px=0,
                            sky_visibility_maps=9, ao="ssao", ao_samples=8),
        lighting=LightingConfig(sun_elevation_deg=(30.0, 40.0), sun_irradiance=(1.5, 2.0),
                                sky="uniform", sky_rgb=(0.5, 0.6, 0.7),
                                uniform_sky_strength=0.8, ground_albedo=0.3, exposure=1.5),
        cycles=CyclesConfig(samples=16))
    as_dict = config_to_dict(config)
    path = tmp_path / "c.toml"
    path.write_text(_toml({s: as_dict[s] for s in ("render", "lighting", "cycles")}))
    loaded = load_config("paper", path)
    assert (loaded.render, loaded.lighting, loaded.cycles) == \
        (config.render, config.lighting, config.cycles)
    assert loaded.render != RenderConfig() and loaded.lighting != LightingConfig()


def _moved(key: str, new: str) -> str:
    return rf"\[render\] {key} moved: write it as {re.escape(new)}"


def _removed(key: str, now: str) -> str:
    return rf"\[render\] {key} was removed: .*{now}.*; delete the line"


@pytest.mark.parametrize("key, value, message", [
    ("sun_intensity", "[3.0, 3.0]", _moved("sun_intensity", "[lighting] sun_irradiance")),
    ("ambient_intensity", "0.6", _moved("ambient_intensity", "[lighting] uniform_sky_strength")),
    ("cycles_samples", "64", _moved("cycles_samples", "[cycles] samples")),
    ("exposure", "1.0", _moved("exposure", "[lighting] exposure")),
    ("sky_rgb", "[0.5, 0.5, 0.5]", _moved("sky_rgb", "[lighting] sky_rgb")),
    ("turbidity", "[2.0, 3.0]", _moved("turbidity", "[lighting] turbidity")),
    ("ambient", '"hemisphere"', _removed("ambient", "spherical harmonics")),
    ("ambient", '"sh"', _removed("ambient", "spherical harmonics")),
    ("tone_map", '"exponential"', _removed("tone_map", "Standard view transform")),
])
def test_an_old_render_key_gets_one_line_saying_where_it_went(tmp_path, key, value, message):
    """Keys that moved to [lighting] or [cycles] name their new place; the keys of the retired
    lighting modes say what glsynth does instead. One line each (fullmatch: no newline)."""
    path = tmp_path / "old.toml"
    path.write_text(f"[render]\nwidth = 640\n{key} = {value}\n")
    with pytest.raises(UserError) as info:
        load_config("demo", path)
    assert re.fullmatch(message, str(info.value)), str(info.value)


@pytest.mark.parametrize("cls, field, good, bad", [
    (RenderConfig, "msaa", 16, 3), (RenderConfig, "msaa", 0, False),
    (RenderConfig, "sky_visibility_maps", 4, 5), (RenderConfig, "sky_visibility_maps", 9, 9.0),
    (RenderConfig, "renderer", "cycles", "blender"), (RenderConfig, "ao", "ssao", "hbao"),
    (LightingConfig, "sky", "uniform", "hosek"),
    (CameraConfig, "placement", "at", "beside"), (CameraConfig, "height_from", "ground", "sea"),
])
def test_enumerated_fields_take_exactly_their_literal_choices(cls, field, good, bad):
    choices = typing.get_args(typing.get_type_hints(cls)[field])
    assert literal_choices(cls, field) == choices and good in choices
    assert getattr(cls(**{field: good}), field) == good
    with pytest.raises(UserError, match=rf"\.{field} = {bad!r}: must be one of "):
        cls(**{field: bad})


def test_every_enumerated_config_field_is_literal_typed():
    """A str field of a config section is a free path or an enumeration: only
    materials.repository is free, so every other one must list its choices in its type."""
    for cls in (EnvironmentConfig, CameraConfig, RenderConfig, LightingConfig, CyclesConfig,
                DamageConfig, DatasetConfig, MaterialsConfig, StandardDesign):
        for name, hint in typing.get_type_hints(cls).items():
            if hint is str:
                assert (cls, name) == (MaterialsConfig, "repository"), (cls.__name__, name)
