import math

import numpy as np
import pytest
import trimesh
from conftest import env_config

from glsynth.core.config import Config
from glsynth.core.labels import Component
from glsynth.world.environment import PartKind, build_environment
from glsynth.world.surroundings import TOWN_KINDS

EXPECTED_COMPONENT = {"column": Component.COLUMN, "beam": Component.BEAM, "slab": Component.SLAB,
                      "rail": Component.RAIL, "sleeper": Component.SLEEPER,
                      "nonstructural": Component.NONSTRUCTURAL,
                      "ground": Component.NONBRIDGE, "scene": Component.NONBRIDGE,
                      "nonbridge": Component.NONBRIDGE}
"""The component of a part by the first word of its name (the naming convention)."""


def local_extents(vertices: np.ndarray, heading: float) -> np.ndarray:
    """Extents of world vertices in the frame turned by ``heading`` about z."""
    c, s = math.cos(heading), math.sin(heading)
    along = vertices[:, :2] @ [c, s]
    across = vertices[:, :2] @ [-s, c]
    return np.array([np.ptp(along), np.ptp(across), np.ptp(vertices[:, 2])])


def test_every_part_is_named_tagged_and_finite(env0):
    names = [p.name for p in env0.parts]
    assert len(names) == len(set(names))
    for part in env0.parts:
        words = part.name.split("_")
        assert part.component == EXPECTED_COMPONENT[words[0]]
        assert part.kind.value in words
        if part.side is not None:
            assert part.side in ("l", "r") and part.side in words[-1]
        assert np.all(np.isfinite(part.world_vertices()))
        assert part.mesh.visual.uv.shape == (len(part.mesh.vertices), 2)
    # The paper's panels: no town and no others (class 8); crushed concrete and rebar only
    # under [damage] geometry (tests/test_severe_geometry.py).
    assert {p.kind for p in env0.parts} == {
        k for k in PartKind if k.component is not Component.OTHER} - TOWN_KINDS - {
        PartKind.CRUSHED, PartKind.REBAR}
    assert {p.name for p in env0.parts if p.kind is PartKind.GIRDER and p.side == "l"} \
        == {f"beam_v{v.index:02d}_girder_l" for v in env0.viaducts}


def test_closed_parts_wind_outwards(env0):
    for part in env0.parts:
        if part.component in {Component.COLUMN, Component.BEAM, Component.SLAB,
                              Component.RAIL, Component.SLEEPER}:
            assert part.mesh.volume > 0, part.name


def test_column_extents_equal_table3_sections_and_heights(env0):
    traj = env0.trajectory
    d = env0.config.design
    checked = 0
    for v in env0.viaducts:
        a_cm, b_cm = v.sections.column_cm
        for col in v.columns:
            part = next(p for p in env0.parts if p.name == col.name)
            world = part.world_vertices()
            # Heading from the trajectory itself, independent of the stored pose.
            row = int(col.name.split("_")[2][0])
            s_c = v.start_s_m + d.column_rows_s[row]
            heading = float(traj.heading(np.array([s_c]))[0])
            ext = local_extents(world, heading)
            assert np.allclose(ext[:2], (a_cm / 100, b_cm / 100), atol=1e-9)
            # Bottom at the lowest ground under the footprint (no footing), top inside the beam.
            ground = traj.ground_at(np.array([s_c - a_cm / 200, s_c + a_cm / 200]))
            assert world[:, 2].min() == pytest.approx(ground.min(), abs=1e-9)
            underside = traj.deck_at(np.array([s_c]))[0] - d.slab_thickness_m - d.girder_depth_m
            assert world[:, 2].max() == pytest.approx(underside + d.embed_m, abs=1e-9)
            assert ext[2] == pytest.approx(col.top_z - col.bottom_z, abs=1e-9)
            checked += 1
    assert checked == 8 * len(env0.viaducts)


def test_viaduct_heights_and_sections_match_table3(env0):
    for v, h, r in zip(env0.viaducts, env0.trajectory.heights_m, env0.trajectory.radii_m):
        assert v.height_m == h and v.radius_m == r
        ties = [p for p in env0.parts if p.viaduct == v.index and p.kind is PartKind.TIE_BEAM]
        assert (len(ties) == 10) == (h > 10.0)


@pytest.mark.parametrize("height, row, column_cm, ties", [
    (5.0, 0, (60, 60), 0), (7.0, 0, (60, 60), 0), (10.0, 2, (80, 80), 0),
    (12.0, 3, (70, 70), 10), (14.0, 4, (80, 80), 10),
])
def test_table3_boundaries_end_to_end(height, row, column_cm, ties):
    """A flat, straight environment at exactly a Table 3 boundary height."""
    config = env_config(initial_height_m=(height, height), ground_amplitude_m=0.0,
                        height_amplitude_m=0.0, min_radius_m=(math.inf, math.inf))
    env = build_environment(config, 0, 0)
    for v in env.viaducts:
        assert v.height_m == height and v.sections.row == row
        assert v.sections.straight and v.sections.column_cm == column_cm
        assert sum(p.kind is PartKind.TIE_BEAM for p in env.parts if p.viaduct == v.index) == ties
        col = next(p for p in env.parts if p.name == v.columns[0].name)
        assert np.allclose(local_extents(col.world_vertices(), 0.0)[:2],
                           np.array(column_cm) / 100)


@pytest.mark.parametrize("radius", [math.inf, 500.0])
def test_straight_and_tightest_curve_environments_are_finite(radius):
    env = build_environment(env_config(min_radius_m=(radius, radius)), 1, 2)
    assert all(np.all(np.isfinite(p.world_vertices())) for p in env.parts)
    assert all(np.all(np.isfinite(p.mesh.face_normals)) for p in env.parts)
    assert all(v.sections.straight == math.isinf(radius) or v.radius_m > 5000
               for v in env.viaducts)
    if math.isinf(radius):
        d = env.config.design
        for part in (p for p in env.parts if p.kind is PartKind.RAIL):
            track = part.name.split("_")[2][1]  # e.g. rail_v03_t0l
            u = ((1 if track == "0" else -1) * d.track_spacing_m / 2
                 + (1 if part.side == "l" else -1) * (d.gauge_m + d.rail_head_width_m) / 2)
            y = part.world_vertices()[:, 1]
            # Straight track: each rail keeps its lateral offset, foot width wide.
            assert np.ptp(y) == pytest.approx(d.rail_foot_width_m, abs=1e-9)
            assert (y.min() + y.max()) / 2 == pytest.approx(u, abs=1e-9)


def test_columns_stand_on_the_ground_mesh(env0):
    ground = trimesh.util.concatenate(
        [trimesh.Trimesh(p.world_vertices(), p.mesh.faces, process=False)
         for p in env0.parts if p.kind is PartKind.GROUND])
    for v in env0.viaducts[:3]:
        for col in v.columns:
            origin = np.array([[*col.center_xy, 100.0]])
            hits, _, _ = ground.ray.intersects_location(origin, np.array([[0, 0, -1.0]]))
            # The ground under the column centre lies within its footprint's slope range.
            assert hits.shape[0] >= 1
            assert col.bottom_z <= hits[:, 2].max() + 1e-9
            assert hits[:, 2].max() - col.bottom_z < 0.05


def test_same_seed_identical_meshes_other_env_differs():
    a = build_environment(Config(), 3, 1)
    b = build_environment(Config(), 3, 1)
    c = build_environment(Config(), 3, 2)
    assert [p.name for p in a.parts] == [p.name for p in b.parts]
    for pa, pb in zip(a.parts, b.parts):
        assert pa.mesh.vertices.tobytes() == pb.mesh.vertices.tobytes()
        assert pa.pose.tobytes() == pb.pose.tobytes()
    col_a = next(p for p in a.parts if p.kind is PartKind.COLUMN)
    col_c = next(p for p in c.parts if p.kind is PartKind.COLUMN)
    assert col_a.world_vertices().tobytes() != col_c.world_vertices().tobytes()


def test_panels_stand_at_the_configured_distance(env0):
    traj = env0.trajectory
    s = np.linspace(0, traj.total_length_m, 2001)
    centre, _, _ = traj.frame(s)
    for part in env0.parts:
        if part.kind is PartKind.SCENE and part.viaduct is not None:
            xy = part.world_vertices()[:, :2]
            dist = np.min(np.linalg.norm(xy[:, None] - centre[None, :, :2], axis=2), axis=1)
            assert np.allclose(dist, 30.0, atol=0.05), part.name


def test_box_uvs_run_up_the_side_faces():
    from glsynth.world.meshes import box

    b = box((0.6, 0.8, 5.0))
    uv, normals = b.visual.uv, b.face_normals
    for f, n in enumerate(normals):
        if abs(n[2]) < 0.5:  # side face: v grows with z, u runs along the face in metres
            verts = b.faces[f]
            dv = np.diff(uv[verts, 1])
            dz = np.diff(b.vertices[verts, 2])
            assert np.allclose(dv, dz)
    assert b.volume > 0 and np.isclose(b.volume, 0.6 * 0.8 * 5.0)
