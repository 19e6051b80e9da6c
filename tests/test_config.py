import math

import pytest

from glsynth.core.config import (
    PRESETS,
    Config,
    DatasetConfig,
    EnvironmentConfig,
    config_from_dict,
    load_config,
)


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
