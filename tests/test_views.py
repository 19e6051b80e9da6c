"""What the cameras see under the default reading of Section 3.4 (docs/design.md): cameras
anywhere within D of the centre line, at heights measured from the world origin. Views that
look at the track show rails and sleepers."""

import dataclasses

import numpy as np
import pytest

from glsynth.core.config import Config
from glsynth.core.labels import Component
from glsynth.render.gl.renderer import Renderer
from glsynth.render.view import EnvironmentView, preview_config
from glsynth.world.cameras import Camera, CameraPlacement, euler_xyz

# 960 px: a rail head (6.5 cm) 15 m away spans at least 1.7 px at the widest lens (15 mm).
CONFIG = preview_config(Config(), 960)
DESIGN = CONFIG.design
ENVIRONMENTS = 8


def looks_at_the_track(view: EnvironmentView, placement: CameraPlacement) -> bool:
    """From the pose alone: the camera stands above the deck inside its fences, or above the
    fence tops, and its optical axis meets the deck top between the rails of a track (the
    gauge, plus 0.3 m each side) within 15 m."""
    traj = view.environment.trajectory
    camera = placement.camera
    eye, forward = camera.pose[:3, 3], -camera.pose[:3, 2]
    point, _, normal = traj.frame(np.array([placement.s_m]))
    deck = point[0, 2]
    lateral = placement.side * placement.distance_m
    inside = abs(lateral) < DESIGN.deck_width_m / 2 - DESIGN.fence_thickness_m
    if eye[2] < deck + (0.5 if inside else DESIGN.fence_height_m + 0.5) or forward[2] > -0.2:
        return False
    t = (deck - eye[2]) / forward[2]
    hit = eye + t * forward
    u = float((hit[:2] - point[0, :2]) @ normal[0, :2])
    off_track = min(abs(u - DESIGN.track_spacing_m / 2), abs(u + DESIGN.track_spacing_m / 2))
    return t < 15 and off_track < DESIGN.gauge_m / 2 + 0.3


def test_views_that_look_at_the_track_show_rails_and_sleepers():
    """Each environment is opened for no camera first (built and its cameras placed, nothing
    dressed), then for the cameras that look at the track alone: the same bytes as an opening
    for all (tests/test_render_viaduct.py), at a fraction of the dressing."""
    found = 0
    with Renderer(CONFIG.render) as renderer:
        for env in range(ENVIRONMENTS):
            placed = EnvironmentView.open(CONFIG, 0, env, renderer, rendering=[])
            looking = [i for i in range(CONFIG.cameras.total)
                       if looks_at_the_track(placed, placed.camera(i))]
            if not looking:
                continue
            view = EnvironmentView.open(CONFIG, 0, env, renderer, rendering=looking)
            for index in looking:
                placement = view.camera(index)
                ids = np.unique(view.renderer.render(placement.camera, {"component"}).component)
                assert Component.RAIL in ids and Component.SLEEPER in ids, (env, index)
                found += 1
    assert found >= 5  # the reading puts cameras over the track in every few environments


def test_a_camera_over_the_track_looking_down_sees_both():
    with Renderer(CONFIG.render) as renderer:
        # This camera is not one of the environment's own: everything is uploaded.
        view = EnvironmentView.open(CONFIG, 0, 2, renderer, cull=False)
        traj = view.environment.trajectory
        s = traj.total_length_m / 2
        point, tangent, normal = traj.frame(np.array([s]))
        pose = np.eye(4)
        heading = np.arctan2(tangent[0, 1], tangent[0, 0])
        pose[:3, :3] = euler_xyz(np.radians(30.0), 0.0, heading - np.pi / 2)  # 60 deg down
        pose[:3, 3] = point[0] + DESIGN.track_spacing_m / 2 * normal[0] + [0, 0, 3.0]
        pose[:3, 3] -= 3.0 / np.tan(np.radians(60.0)) * tangent[0]  # aim at the track there
        camera = Camera(CONFIG.render.width, CONFIG.render.height, 24.0, 36.0, pose,
                        CONFIG.render.znear_m, CONFIG.render.zfar_m)
        ids = view.renderer.render(camera, {"component"}).component
        share = {c: float((ids == c).mean()) for c in (Component.RAIL, Component.SLEEPER)}
        assert share[Component.RAIL] > 0.01 and share[Component.SLEEPER] > 0.05


@pytest.mark.parametrize("height_from", ["origin", "ground"])
def test_height_is_measured_from_the_chosen_reference(height_from):
    from glsynth.world.cameras import environment_camera
    from glsynth.world.environment import build_environment

    cameras = dataclasses.replace(CONFIG.cameras, height_from=height_from)
    traj = build_environment(CONFIG, 0, 2).trajectory
    for index in range(20):
        p = environment_camera(traj, cameras, CONFIG.render, 0, 2, index)
        base = 0.0 if height_from == "origin" else traj.ground_at(np.array([p.s_m]))[0]
        assert p.camera.pose[2, 3] == pytest.approx(base + p.height_m)
