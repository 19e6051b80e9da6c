"""surface_area_m2 on coordinate planes gives, bit for bit, what the same arithmetic on
(h, w, 3) point vectors gives (the form it had before, kept here as the reference), on depth
maps of rendered viaduct views."""

import numpy as np
import pytest
from glhelpers import loaded_renderer, render_config

from glsynth.core.config import Config
from glsynth.core.seeding import Stream, make_rng
from glsynth.core.surfaces import MAX_AREA_FACTOR
from glsynth.data.statistics import surface_area_m2
from glsynth.world.cameras import environment_camera

RC = render_config(320, 180)


def vector_area(depth_m: np.ndarray, focal_px: float) -> np.ndarray:
    """The reference: the steps and their cross product on stacked (h, w, 3) points."""
    h, w = depth_m.shape
    rows, cols = np.mgrid[0:h, 0:w]
    z = depth_m.astype(np.float64)
    points = np.stack([(cols - (w - 1) / 2) * z / focal_px, (rows - (h - 1) / 2) * z / focal_px,
                       z], axis=-1)

    def step(axis: int) -> np.ndarray:
        d = np.diff(points, axis=axis)
        before, after = [(0, 0)] * 3, [(0, 0)] * 3
        before[axis], after[axis] = (1, 0), (0, 1)
        back, ahead = np.pad(d, before, mode="edge"), np.pad(d, after, mode="edge")
        near = np.where((np.abs(ahead[..., 2]) <= np.abs(back[..., 2]))[..., None], ahead, back)
        size = (np.linalg.norm(ahead, axis=-1) + np.linalg.norm(back, axis=-1)) / 2
        smooth = np.linalg.norm(ahead - back, axis=-1) <= 0.5 * size
        return np.where(smooth[..., None], (ahead + back) / 2, near)

    area = np.linalg.norm(np.cross(step(1), step(0)), axis=-1)
    return np.minimum(area, MAX_AREA_FACTOR * (z / focal_px) ** 2)


@pytest.fixture(scope="module")
def depths(env0):
    cameras = [environment_camera(env0.trajectory, Config().cameras, RC, 0, 0, i).camera
               for i in (0, 20, 55, 80)]
    with loaded_renderer(env0, RC) as r:
        return [(r.render(c, {"depth"}).depth, c.fx) for c in cameras]


def test_the_area_of_rendered_views_is_the_vector_forms_to_the_bit(depths):
    for depth, focal in depths:
        area = surface_area_m2(depth, focal)
        assert area.dtype == np.float64 and area.shape == depth.shape
        assert area.tobytes() == vector_area(depth, focal).tobytes()
    # The views hold silhouettes (depth jumping by half) beside smooth surfaces, so both
    # kinds of step are taken.
    jumps = np.concatenate([(np.abs(np.diff(d, axis=1)) > 0.5 * d[:, 1:]).ravel()
                            for d, _ in depths])
    assert 0.0 < jumps.mean() < 0.1


def test_a_wide_or_tall_map_keeps_its_axes():
    rng = make_rng(3, 0, Stream.GEOMETRY)
    for shape in ((2, 7), (9, 2), (5, 5)):
        depth = rng.uniform(1.0, 80.0, shape).astype(np.float32)
        assert surface_area_m2(depth, 50.0).tobytes() == vector_area(depth, 50.0).tobytes()
