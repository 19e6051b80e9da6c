import dataclasses

import numpy as np
import pytest
from glhelpers import render_config

from glsynth.appearance.damage_bank import DamageBank
from glsynth.appearance.repository import TextureRepository, generate_repository
from glsynth.core.config import Config, DamageConfig
from glsynth.core.labels import Component
from glsynth.data.plates import plate_mesh, plate_shot
from glsynth.render.gl.renderer import Renderer
from glsynth.render.raycast import ray_cast
from glsynth.world.environment import Part, PartKind

CONFIG = dataclasses.replace(Config(), damage=DamageConfig(resolution=128),
                             render=render_config(96, 54))


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("plates")
    repo = TextureRepository(generate_repository(tmp / "r", 0, 2, 32), 32)
    with Renderer(CONFIG.render) as renderer:
        yield repo, DamageBank(CONFIG.damage, 0, cache_dir=tmp), renderer


def shoot(setup, index):
    repo, bank, renderer = setup
    shot = plate_shot(CONFIG, 0, index, repo, bank)
    renderer.load(shot.scene, shot.lighting)
    return shot, renderer.render(shot.camera)


def test_a_plate_image_builds_only_the_plate_and_shows_its_damage(setup):
    for index in range(6):
        shot, out = shoot(setup, index)
        assert len(shot.scene.scene.mesh_nodes) == 1
        assert set(np.unique(out.damage)) <= {1, 2, 3}
        plate = out.component == Component.COLUMN
        assert plate.mean() > 0.8  # the plate nearly fills the frame
        assert shot.meta["severity"] in ("slight", "medium", "severe")
        assert 0 <= shot.meta["tilt_rad"] <= np.radians(35)
        # The plate shows a window of its damage texture: its labels are those of the mask
        # under each pixel centre, as an independent ray cast finds them.
        node = next(iter(shot.scene.scene.mesh_nodes))
        part = Part(node.name, PartKind.COLUMN, None, plate_mesh(CONFIG.damage.tile_m),
                    shot.scene.scene.get_pose(node))
        truth = ray_cast([part], {node.name: shot.scene.parts[node.name].material}, shot.camera)
        assert (truth.damage == out.damage).mean() > 0.999
        assert (truth.component == out.component).mean() > 0.999
        area = shot.meta["damage_params"]["area"]
        assert area > 0 and (out.damage[plate] != 1).any()


def test_plate_images_are_reproducible_from_their_index(setup):
    a = shoot(setup, 3)[1]
    shoot(setup, 4)
    b = shoot(setup, 3)[1]
    assert a.color.tobytes() == b.color.tobytes() and a.damage.tobytes() == b.damage.tobytes()
