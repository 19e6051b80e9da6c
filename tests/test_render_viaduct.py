"""Rendering real viaduct views: agreement with an independent CPU ray cast, valid ids,
reproducibility, and the render/preview commands."""

import json

import numpy as np
import pytest
from glhelpers import LIGHT, loaded_renderer, plain_materials, render_config
from PIL import Image

from glsynth.cli import main
from glsynth.core.config import Config
from glsynth.core.filters import removal_reason
from glsynth.core.labels import COMPONENT_IDS, DAMAGE_IDS, Damage
from glsynth.render.gl.renderer import Renderer
from glsynth.render.raycast import mask_lookup
from glsynth.render.raycast import ray_cast as glsynth_ray_cast
from glsynth.render.scene import build_scene
from glsynth.world.cameras import environment_camera

RC = render_config(160, 90)
CAMERAS = Config().cameras
TWO_VIADUCTS_TOML = "[environment]\nn_viaducts = 2\ncutoff_factor = 1.0\n"
"""For the tests of the commands' and openings' plumbing: each opening builds and dresses the
environment again, 2-3 CPU-s with the default ten viaducts. Not for the culling tests: with
two, every part may shadow some view or hide its sky, and none is culled."""


def two_viaducts(config: Config) -> Config:
    import dataclasses

    return dataclasses.replace(config, environment=dataclasses.replace(
        config.environment, n_viaducts=2, cutoff_factor=1.0))


@pytest.fixture(scope="module")
def loaded(env0):
    with loaded_renderer(env0, RC) as r:
        yield r


def cam(env0, index):
    return environment_camera(env0.trajectory, CAMERAS, RC, 0, 0, index).camera


def ray_cast(env0, camera):
    """Nearest hit per pixel centre: (depth along the optical axis, component id), sky = inf."""
    truth = glsynth_ray_cast(env0.parts, plain_materials(env0), camera)
    return np.where(truth.depth < camera.zfar, truth.depth, np.inf), truth.component


@pytest.mark.parametrize("index", [0, 55])
def test_depth_and_labels_match_a_cpu_ray_cast(env0, loaded, index):
    camera = cam(env0, index)
    out = loaded.render(camera)
    depth, comp = ray_cast(env0, camera)
    # Interior pixels: the ray cast's component and depth are the same in the 3x3 neighbourhood.
    interior = np.zeros(depth.shape, bool)
    core = (slice(1, -1), slice(1, -1))
    same = np.ones(depth[core].shape, bool)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            shifted = (slice(1 + dr, depth.shape[0] - 1 + dr),
                       slice(1 + dc, depth.shape[1] - 1 + dc))
            same &= comp[shifted] == comp[core]
            same &= np.isclose(depth[shifted], depth[core], rtol=0.05) | (
                np.isinf(depth[shifted]) & np.isinf(depth[core]))
    interior[core] = same
    assert interior.mean() > 0.6
    hit = interior & np.isfinite(depth)
    assert hit.sum() > 1000
    assert np.allclose(out.depth[hit], depth[hit], rtol=1e-4)
    assert np.array_equal(out.component[interior], comp[interior])
    assert len(np.unique(comp[interior])) >= 3


def test_label_maps_hold_only_valid_ids(env0, loaded):
    for index in range(0, 100, 7):
        out = loaded.render(cam(env0, index))
        assert set(np.unique(out.component)) <= COMPONENT_IDS - {0, 8}
        assert set(np.unique(out.damage)) <= DAMAGE_IDS - {0}
        assert np.all(np.isfinite(out.depth)) and out.depth.min() > 0.0
        assert out.depth.max() <= RC.zfar_m


def test_a_camera_renders_the_same_bytes_alone_or_in_a_batch(env0, loaded):
    batch = [loaded.render(cam(env0, i)) for i in range(4)]
    with Renderer(RC) as alone:
        alone.load(build_scene(env0.parts, plain_materials(env0)), LIGHT)
        single = alone.render(cam(env0, 2))
    for name in ("color", "component", "damage", "depth"):
        assert getattr(single, name).tobytes() == getattr(batch[2], name).tobytes()


def test_only_requested_passes_are_returned(env0, loaded):
    out = loaded.render(cam(env0, 1), {"depth"})
    assert out.color is None and out.component is None and out.depth is not None
    with pytest.raises(ValueError, match="passes"):
        loaded.render(cam(env0, 1), {"normals"})


def test_render_command_writes_the_documented_files(tmp_path):
    cfg = tmp_path / "small.toml"
    cfg.write_text("[render]\nwidth = 192\nheight = 108\n[damage]\nresolution = 128\n"
                   "[materials]\ntexture_size = 64\nbuiltin_size = 64\nimages_per_category = 3\n"
                   + TWO_VIADUCTS_TOML)
    out = tmp_path / "r"
    assert main(["render", "--seed", "0", "--env", "1", "--camera", "7", "--config", str(cfg),
                 "--out", str(out)]) == 0
    image = np.array(Image.open(out / "image.png"))
    comp = np.array(Image.open(out / "component.png"))
    dmg = np.array(Image.open(out / "damage.png"))
    depth = np.load(out / "depth.npy")
    # The demo preset's cracks (mechanics): a width only where the damage map says concrete.
    crack_width = np.load(out / "crack_width.npy")
    assert crack_width.dtype == np.float32 and crack_width.shape == (108, 192)
    assert np.all(dmg[crack_width > 0] == Damage.CONCRETE) and (crack_width >= 0).all()
    assert image.shape == (108, 192, 3) and image.dtype == np.uint8
    assert comp.shape == dmg.shape == (108, 192) and comp.dtype == np.uint8
    assert depth.shape == (108, 192) and depth.dtype == np.float32
    info = json.loads((out / "camera.json").read_text())
    k = np.array(info["K"])
    assert k.shape == (3, 3) and k[0, 0] == pytest.approx(info["focal_mm"] / 36.0 * 192)
    assert np.array(info["pose"]).shape == (4, 4)
    assert (info["width"], info["height"], info["kind"]) == (192, 108, "closeup")
    # Several cameras go to subfolders.
    assert main(["render", "--seed", "0", "--env", "1", "--camera", "1", "2", "--config",
                 str(cfg), "--out", str(tmp_path / "many")]) == 0
    assert (tmp_path / "many" / "camera_002" / "depth.npy").exists()


def test_preview_command(quick_config, tmp_path):
    out = tmp_path / "p.png"
    assert main(["preview", "--seed", "0", "--env", "0", "--cameras", "2", "--width", "96",
                 "--config", str(quick_config), "--out", str(out)]) == 0
    assert Image.open(out).size == (4 * 96, 2 * 54)


CLOSEUPS = (3, 4, 5)
"""The close-ups of the culling tests' six cameras (three regular ones first)."""


def test_parts_no_camera_sees_are_not_uploaded_and_change_nothing():
    import dataclasses

    from glsynth.render.view import EnvironmentView, preview_config
    from glsynth.world.visibility import occlusion_extent

    config = preview_config(Config(), 160)
    config = dataclasses.replace(config, cameras=dataclasses.replace(
        config.cameras, n_regular=3, n_closeup=3))
    with Renderer(config.render) as renderer:
        # The close-ups (3-5): a regular camera sees the ground to the horizon, and every
        # part may hide the sky from some of it.
        culled = EnvironmentView.open(config, 0, 1, renderer, rendering=CLOSEUPS)
        full = EnvironmentView.open(config, 0, 1, renderer=renderer, cull=False)
        assert len(culled.scene.parts) < len(full.scene.parts) == len(full.environment.parts)
        outputs = {}
        for view in (culled, full):
            view.renderer.load(view.scene, view.lighting,
                               occlusion_extent(view.environment.parts))
            outputs[view is culled] = [view.render(i)[1] for i in CLOSEUPS]
        for a, b in zip(outputs[True], outputs[False]):
            for name in ("color", "component", "damage", "depth"):
                assert getattr(a, name).tobytes() == getattr(b, name).tobytes(), name


def _damage_textures(view) -> int:
    """How many columns of an opened view got their damage textures built (the seen ones)."""
    return sum(bool(a.damage and a.damage.get("built"))
               for a in view.dressing.assignments.values())


ALONE = (0, 2, 3, 5)
"""The cameras opened for alone: regular and close-up, each kind's first and last."""


def test_an_opening_for_some_cameras_uploads_less_and_renders_them_the_same():
    """glsynth render --camera: culled by the asked cameras alone (their far sky occlusion
    included), the same bytes as an opening for all of the environment's cameras."""
    import dataclasses

    from glsynth.render.view import EnvironmentView, preview_config

    config = preview_config(Config(), 320)
    config = dataclasses.replace(config, cameras=dataclasses.replace(
        config.cameras, n_regular=3, n_closeup=3))
    with Renderer(config.render) as renderer:
        every = EnvironmentView.open(config, 0, 1, renderer)
        expected = {i: every.render(i)[1] for i in ALONE}
        uploaded, damaged = len(every.scene.parts), _damage_textures(every)
        for i in ALONE:
            alone = EnvironmentView.open(config, 0, 1, renderer, rendering=[i])
            assert len(alone.scene.parts) <= uploaded and _damage_textures(alone) <= damaged
            fewer = len(alone.scene.parts) < uploaded or _damage_textures(alone) < damaged
            assert fewer, i
            out = alone.render(i)[1]
            for name in ("color", "component", "damage", "depth"):
                assert getattr(out, name).tobytes() == getattr(expected[i], name).tobytes(), \
                    (i, name)


def test_parts_that_only_shadow_a_view_or_hide_its_sky_are_kept():
    import dataclasses

    from glsynth.render.scene import build_scene
    from glsynth.render.view import EnvironmentView, preview_config
    from glsynth.world.visibility import visible_parts

    config = preview_config(Config(), 160)
    config = dataclasses.replace(config, cameras=dataclasses.replace(
        config.cameras, n_regular=3, n_closeup=3))
    with Renderer(config.render) as renderer:
        view = EnvironmentView.open(config, 0, 1, renderer, rendering=CLOSEUPS)
        seen = visible_parts(view.environment.parts, [view.camera(i).camera for i in CLOSEUPS])
        assert seen < set(view.scene.parts) < {p.name for p in view.environment.parts}
        kept = [view.render(i)[1].color for i in CLOSEUPS]
        view.renderer.load(build_scene([p for p in view.environment.parts if p.name in seen],
                                       view.dressing.materials), view.lighting)
        seen_only = [view.render(i)[1].color for i in CLOSEUPS]
        # Dropping the unseen casters would lose shadows or sky occlusion in some view.
        assert any(not np.array_equal(a, b) for a, b in zip(kept, seen_only))


def test_mask_lookup_samples_like_gl():
    mask = np.arange(12, dtype=np.uint8).reshape(3, 4)  # row 0 is the image's top
    uv = np.array([[0.0, 0.0], [0.999, 0.999], [1.1, -0.1], [0.3, 0.5]])
    assert mask_lookup(mask, uv).tolist() == [8, 3, 0, 5]  # (1.1, -0.1) wraps to the top


def test_damage_labels_match_the_ray_cast_through_the_damage_masks():
    from glsynth.render.view import EnvironmentView, preview_config

    config = preview_config(Config(), 320)
    with Renderer(config.render) as renderer:
        view = EnvironmentView.open(config, 0, 0, renderer)
        damaged = 0.0
        # Views not removed for their geometry (a camera inside a column is clipped by the near
        # plane where the ray cast is not); a view too dark for the dataset is fine here.
        for index in (5, 30, 85):
            placement, out = view.render(index)
            assert removal_reason(out.color, out.component, out.depth) in (None, "dark")
            truth = glsynth_ray_cast(view.environment.parts, view.dressing.materials,
                                     placement.camera)
            assert (out.damage == truth.damage).mean() > 0.9999
            assert (out.component == truth.component).mean() > 0.9999
            damaged = max(damaged, float((truth.damage >= 2).mean()))
        assert damaged > 0.05


def test_opening_an_environment_frees_the_previous_one_first(monkeypatch):
    """A worker's peak memory holds one environment's textures, not two: before dressing the
    next environment only the repository's textures (read-only images, shared) remain."""
    import glsynth.render.view as view_module
    from glsynth.render.view import EnvironmentView, preview_config

    config = preview_config(two_viaducts(Config()), 96)
    with Renderer(config.render) as renderer:
        EnvironmentView.open(config, 0, 0, renderer)
        assert renderer._draws
        real_dress = view_module.dress

        def dress_after_release(*args, **kwargs):
            assert not renderer._draws and not renderer._scene_textures
            sources = [a for arrays, _ in renderer._textures.values() for a in arrays
                       if a is not None]
            assert sources and not any(a.flags.writeable for a in sources)
            return real_dress(*args, **kwargs)

        monkeypatch.setattr(view_module, "dress", dress_after_release)
        EnvironmentView.open(config, 0, 1, renderer)
        assert renderer._draws


@pytest.mark.parametrize("stop_at", [2, 5])
def test_an_interrupted_opening_leaves_its_renderer_empty_and_usable(stop_at):
    """``interrupt()`` is asked at each stage of an opening (building, dressing, uploading)
    and before each part's upload: its first True (here at the dressing stage, or at the
    second part's upload) raises RenderInterrupted with nothing of the scene left on the
    renderer given, which then opens and renders as a fresh one does."""
    from glsynth.render.gl.renderer import RenderInterrupted
    from glsynth.render.view import EnvironmentView, preview_config

    config = preview_config(two_viaducts(Config()), 96)
    asked = []

    def interrupt() -> bool:
        asked.append(True)
        return len(asked) >= stop_at

    with Renderer(config.render) as renderer, Renderer(config.render) as fresh:
        with pytest.raises(RenderInterrupted):
            EnvironmentView.open(config, 0, 0, renderer, interrupt=interrupt)
        assert len(asked) == stop_at and renderer._draws == []
        again = EnvironmentView.open(config, 0, 0, renderer).render(0)[1]
        expected = EnvironmentView.open(config, 0, 0, fresh).render(0)[1]
        for name in ("color", "component", "damage", "depth"):
            assert np.array_equal(getattr(again, name), getattr(expected, name)), name
