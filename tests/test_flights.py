"""Inspection flights: plan geometry and validation (no GL), and glsynth fly end to end at
192x108: its frames, the COLMAP model read by pycolmap, transforms.json, points.ply, resume."""

import hashlib
import json
import math
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest
from PIL import Image
from scipy.spatial.transform import Rotation

from glsynth.cli import main
from glsynth.core.config import config_from_dict, load_config
from glsynth.core.errors import UserError
from glsynth.data.flight import flight_materials
from glsynth.data.flight_export import label_interior, ply_bytes, read_ply, rotation_quaternion
from glsynth.render.view import EnvironmentView
from glsynth.world.cameras import Camera
from glsynth.world.environment import PartKind, build_environment
from glsynth.world.flights import (
    FlightPlan,
    environment_columns,
    frame_spacing_m,
    look_pose,
    plan_flight,
    ring_overlap_pct,
    surface_distance,
    validate_flight,
)
from glsynth.world.lens import Lens, resample, source_camera, source_pixels

# The paper's damage model: its labels come from textures and are the same from every view.
# The mechanics model labels a pixel that a crack's centreline crosses however thin the crack
# (docs/design.md, "Cracks"), so near a crack the labels depend on the view's pixel size, and a
# point's damage id may differ between frames by design.
# Without the others (class 8): these flights orbit column_v00_0l of seed 0, environment 0,
# which the demo preset jackets, and their messages and silhouettes are the column's.
SMALL = """[render]
width = 192
height = 108
msaa = 0
shadow_map_px = 256
sky_visibility_px = 128
[damage]
resolution = 64
model = "paper"
[materials]
texture_size = 64
builtin_size = 64
[environment]
jacket_probability = 0.0
brace_probability = 0.0
downpipe_probability = 0.0
trough_probability = 0.0
sign_probability = 0.0
[flight]
point_stride_px = 3
"""
TWO_VIADUCTS = SMALL.replace("[flight]\n", "n_viaducts = 2\ncutoff_factor = 1.0\n[flight]\n")
"""The rendered flights' environment: a flight (and a resume) builds it again, 3.3 CPU-s with
ten viaducts. Not for the culling and clearance tests: with two, the casters of shadows are
most of the parts, and the first viaduct's ties stand elsewhere."""
FRAMES = 30
NO_OTHERS = {f"{rule}_probability": 0.0 for rule in ("jacket", "brace", "downpipe", "trough",
                                                     "sign")}


def _config(**flight):
    return config_from_dict({"flight": flight, "environment": NO_OTHERS}, load_config("demo"))


@pytest.fixture(scope="module")
def demo_env():
    """Environments 0 and 1 of seed 0 under _config(), by index, built once for the plan
    tests: [flight] settings do not change what is built (a flight plan reads them from its
    config, not from the environment), and a build took 0.6 CPU-s, a dozen of them the file.
    The plans do not change an environment."""
    return {index: build_environment(_config(), 0, index) for index in (0, 1)}


def _forward(pose):
    return -pose[:3, 2]


def _part_distance(env, points, names):
    return np.min([surface_distance(p.mesh.triangles @ p.pose[:3, :3].T + p.pose[:3, 3],
                                    points) for p in env.parts if p.name in names], axis=0)


def test_orbit_rings_stand_off_spacing_and_heights(demo_env):
    config = _config(plan="orbit", column=3, heights_m=[1.5, 3.0], standoff_m=2.0,
                     focal_mm=24.0, forward_overlap_pct=80.0)
    env = demo_env[0]
    col = environment_columns(env)[3]
    plan = plan_flight(env, config)
    spacing = 0.2 * 2.0 * 36 / 24  # (1 - overlap) x stand-off x sensor / focal
    assert plan.spacing_m == pytest.approx(spacing)
    radius = 2.0 + math.hypot(*col.section_m) / 2
    per_ring = math.ceil(2 * math.pi * radius / spacing)
    assert len(plan) == 2 * per_ring
    pos = plan.poses[:, :3, 3]
    assert np.allclose(np.hypot(*(pos[:, :2] - col.center_xy).T), radius)
    assert np.allclose(pos[:per_ring, 2], col.bottom_z + 1.5)
    assert np.allclose(pos[per_ring:, 2], col.bottom_z + 3.0)
    steps = np.linalg.norm(np.diff(pos[:per_ring], axis=0), axis=1)
    assert steps.max() <= spacing + 1e-9 and steps.min() > 0.95 * spacing
    # Each camera looks horizontally at the column's axis; its image x is the direction of travel.
    to_axis = np.c_[col.center_xy - pos[:, :2], np.zeros(len(pos))]
    to_axis /= np.linalg.norm(to_axis, axis=1, keepdims=True)
    assert np.allclose([_forward(p) for p in plan.poses], to_axis)
    travel = np.diff(pos[:per_ring], axis=0)
    assert np.all(np.sum(travel * plan.poses[:per_ring - 1, :3, 0], axis=1) > 0)
    # The column's edges come as near as the stand-off, and nothing of it nearer.
    nearest = _part_distance(env, pos, {col.name})
    assert nearest.min() >= 2.0 - 1e-9 and nearest.min() == pytest.approx(2.0, abs=0.02)
    assert plan.times_s[1] == pytest.approx(steps[0] / config.flight.speed_mps)


def test_facade_rows_cover_the_side_at_the_stand_off(demo_env):
    config = _config(plan="facade", standoff_m=3.0, side="left", forward_overlap_pct=70.0,
                     side_overlap_pct=50.0)
    env = demo_env[1]
    plan = plan_flight(env, config)
    validate_flight(env, plan, config.flight.clearance_m)
    pos = plan.poses[:, :3, 3]
    left = {p.name for p in env.parts if p.viaduct == 0 and p.side == "l"
            and p.kind in (PartKind.COLUMN, PartKind.GIRDER)}
    # Horizontally, the outermost of the left columns' and girder's faces is 3 m away.
    across = []
    for name in left:
        z = [p.world_vertices()[:, 2] for p in env.parts if p.name == name][0]
        across.append(_part_distance(env, np.c_[pos[:, :2], np.full(len(pos), z.mean())],
                                     {name}).min())
    assert min(across) == pytest.approx(3.0, abs=1e-3)
    # Rows: the same count of frames each, flown back and forth, at most the overlap's
    # spacing apart along a row and the side overlap's spacing apart between rows.
    turns = np.all(np.isclose(np.diff(pos[:, :2], axis=0), 0.0), axis=1)  # row to row
    row_len = int(np.argmax(turns)) + 1
    rows = pos.reshape(-1, row_len, 3)
    assert len(rows) * row_len == len(plan) and len(rows) > 1
    assert np.allclose(rows[1, ::-1, :2], rows[0, :, :2])
    along = np.linalg.norm(np.diff(rows[0], axis=0), axis=1)
    assert along.max() <= frame_spacing_m(config.flight, 36.0) * 1.001
    tall = 3.0 * (36.0 * 1080 / 1920) / config.flight.focal_mm  # image height at 3 m
    same_s = np.stack([r[:, 2] if k % 2 == 0 else r[::-1, 2] for k, r in enumerate(rows)])
    assert np.diff(same_s, axis=0).max() <= 0.5 * tall + 1e-9
    forward = np.array([_forward(p) for p in plan.poses])
    assert np.allclose(forward[:, 2], 0.0)  # gimbal pitch 0


def test_the_right_facade_mirrors_the_left_across_the_track(demo_env):
    """Flown on the right, the rows stand as far to the right of the centre line as the left
    side's to its left, looking back across the track."""
    sides = {}
    for side in ("left", "right"):
        config = _config(plan="facade", standoff_m=3.0, side=side, length_m=12.0)
        env = demo_env[1]
        plan = plan_flight(env, config)
        validate_flight(env, plan, config.flight.clearance_m)
        s0 = env.viaducts[0].start_s_m
        point, _, normal = env.trajectory.frame(np.array([s0]))
        offset = (plan.poses[0, :2, 3] - point[0, :2]) @ normal[0, :2]
        sides[side] = (offset, _forward(plan.poses[0])[:2] @ normal[0, :2])
    assert sides["right"][0] == pytest.approx(-sides["left"][0]) and sides["left"][0] > 3.0
    assert sides["left"][1] == pytest.approx(-1.0) and sides["right"][1] == pytest.approx(1.0)


def test_a_waypoint_beyond_the_grounds_edge_is_refused(demo_env):
    env = demo_env[0]
    far = FlightPlan("orbit", look_pose(np.array([1e5, 1e5, 2.0]), 0.0, 0.0)[None],
                     np.zeros(1), 1.0, 24.0)
    with pytest.raises(UserError, match=r"waypoint 0 is beyond the ground's edge \(no ground "
                                        r"under it\); move the flight over the environment"):
        validate_flight(env, far, 1.0)


def test_underdeck_flies_the_stand_off_under_the_slab(demo_env):
    config = _config(plan="underdeck", standoff_m=2.0, gimbal_pitch_deg=90.0)
    env = demo_env[0]
    plan = plan_flight(env, config)
    validate_flight(env, plan, config.flight.clearance_m)
    pos = plan.poses[:, :3, 3]
    assert np.allclose(_part_distance(env, pos, {"slab_v00"}), 2.0, atol=1e-3)
    assert np.allclose([_forward(p) for p in plan.poses], [0.0, 0.0, 1.0])


def test_a_plan_through_a_column_is_refused_in_one_line(demo_env):
    env = demo_env[0]
    col = environment_columns(env)[0]
    centre = np.array([*col.center_xy, col.bottom_z + 2.0])
    poses = np.stack([look_pose(centre + [dx, 4.0, 0.0], -math.pi / 2, 0.0)
                      for dx in (0.0, 0.0)])
    poses[1, :3, 3] = centre - [0.0, 4.0, 0.0]  # from one side of the column to the other
    plan = FlightPlan("orbit", poses, np.zeros(2), 1.0, 24.0)
    with pytest.raises(UserError) as refused:
        validate_flight(env, plan, 1.0)
    message = str(refused.value)
    assert "\n" not in message and "from waypoint 0 to 1" in message and col.name in message
    inside = FlightPlan("orbit", look_pose(centre, 0.0, 0.0)[None], np.zeros(1), 1.0, 24.0)
    with pytest.raises(UserError, match=f"waypoint 0 starts inside {col.name}"):
        validate_flight(env, inside, 1.0)
    below = FlightPlan("orbit", look_pose(centre + [0.0, 4.0, -4.0], 0.0, 0.0)[None],
                       np.zeros(1), 1.0, 24.0)
    with pytest.raises(UserError, match=r"waypoint 0 is 2\.\d\d m below the ground"):
        validate_flight(env, below, 1.0)


def test_the_command_refuses_a_colliding_plan_before_rendering(tmp_path, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text(SMALL + "standoff_m = 0.4\n")
    out = tmp_path / "flight"
    code = main(["fly", "--seed", "0", "--env", "0", "--plan", "orbit", "--config", str(cfg),
                 "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert "waypoint 0 is 0." in err and "from column_v00_0l" in err
    assert not out.exists() or {p.name for p in out.iterdir()} <= {".glsynth.lock",
                                                                   ".glsynth.workers.lock"}


def test_zero_length_flights_have_one_frame_per_row_or_ring(demo_env):
    orbit = _config(plan="orbit", arc_deg=0.0, heights_m=[1.5, 2.5, 3.5])
    env = demo_env[0]
    plan = plan_flight(env, orbit)
    assert len(plan) == 3 and np.allclose(plan.poses[:, :2, 3], plan.poses[0, :2, 3])
    facade = _config(plan="facade", length_m=0.0, standoff_m=3.0)
    plan = plan_flight(env, facade)
    assert np.allclose(plan.poses[:, :2, 3], plan.poses[0, :2, 3]) and len(plan) > 1
    assert plan.times_s[-1] == pytest.approx((plan.poses[-1, 2, 3] - plan.poses[0, 2, 3])
                                             / facade.flight.speed_mps)


def test_an_orbits_rings_report_their_overlap():
    """At 2 m with 24 mm on a 36 x 20.25 mm sensor an image is 1.6875 m tall: rings 0.5 m
    apart share 70.4 % of it, 3.5 m apart nothing."""
    config = _config(heights_m=[1.0, 1.5, 5.0], standoff_m=2.0, focal_mm=24.0)
    assert ring_overlap_pct(config.flight, 36.0 * 1080 / 1920) == [70.4, 0.0]


def test_too_fast_for_the_frame_rate_is_refused(demo_env):
    config = _config(speed_mps=30.0, frame_rate_hz=10.0)
    with pytest.raises(UserError, match="fly at most 6.000 m/s"):
        plan_flight(demo_env[0], config)


def test_frames_nearer_than_the_frame_rate_allows_are_refused(demo_env):
    """An orbit's chords are shorter than its arc spacing: at a speed the spacing allows
    exactly, its frames would still come too fast."""
    config = _config(frame_rate_hz=10.0)
    speed = frame_spacing_m(config.flight, config.cameras.sensor_mm) * 10.0
    config = _config(frame_rate_hz=10.0, speed_mps=speed)
    with pytest.raises(UserError, match=r"waypoints \d+ and \d+ are 0\.\d+ m apart"):
        plan_flight(demo_env[0], config)
    slower = _config(frame_rate_hz=10.0, speed_mps=0.9 * speed)
    assert len(plan_flight(demo_env[0], slower)) > 1


def test_coinciding_waypoints_are_refused_naming_the_heights(demo_env):
    config = _config(arc_deg=0.0, heights_m=[1.5, 1.5])
    with pytest.raises(UserError, match=r"flight.heights_m = \[1.5, 1.5\]: waypoints 0 and 1 "
                                        "coincide"):
        plan_flight(demo_env[0], config)


def test_quaternion_matches_scipy_on_every_branch():
    matrices = list(Rotation.random(50, random_state=0).as_matrix())
    matrices += [np.diag(d) for d in ([1, -1, -1], [-1, 1, -1], [-1, -1, 1], [1, 1, 1])]
    for r in matrices:
        q = rotation_quaternion(r)
        expected = Rotation.from_matrix(r).as_quat(scalar_first=True)
        assert np.allclose(q, expected * np.sign(expected[0] or 1.0), atol=1e-12)


def test_ply_round_trip(tmp_path):
    xyz = np.array([[1.0, 2.0, 3.0], [-4.5, 0.25, 1e-9], [7.0, 8.0, 9.0]])
    rgb = np.array([[1, 2, 3], [4, 5, 6], [255, 0, 7]], np.uint8)
    frames = [np.array([0, 5]), np.array([], np.int64), np.array([70000])]
    path = tmp_path / "points.ply"
    path.write_bytes(ply_bytes(xyz, rgb, np.array([4, 3, 1]), np.array([1, 2, 3]), frames))
    back = read_ply(path)
    assert np.array_equal(back["xyz"], xyz) and np.array_equal(back["rgb"], rgb)
    assert back["component"].tolist() == [4, 3, 1] and back["damage"].tolist() == [1, 2, 3]
    assert [f.tolist() for f in back["frames"]] == [[0, 5], [], [70000]]


# --- glsynth fly end to end ------------------------------------------------------------------

def _fly_args(cfg: Path, out: Path) -> list[str]:
    return ["fly", "--seed", "0", "--env", "0", "--plan", "orbit", "--config", str(cfg),
            "--out", str(out)]


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fly")
    cfg = folder / "small.toml"
    cfg.write_text(TWO_VIADUCTS + f"max_frames = {FRAMES}\n")
    out = folder / "flight"
    assert main(_fly_args(cfg, out)) == 0
    return cfg, out


def _digests(out: Path) -> dict[str, str]:
    return {str(p.relative_to(out)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(out.rglob("*")) if p.is_file() and not p.name.startswith(".")}


def test_frames_are_render_files_in_flight_order(flight):
    cfg, out = flight
    names = sorted(p.name for p in (out / "frames").iterdir())
    assert names == [f"frame_{i:04d}" for i in range(FRAMES)]
    for name in ("image.png", "component.png", "damage.png", "depth.npy", "crack_width.npy",
                 "camera.json"):
        assert (out / "frames" / "frame_0007" / name).is_file()
    assert np.load(out / "frames" / "frame_0007" / "depth.npy").shape == (108, 192)
    config = load_config("demo", cfg)
    plan = plan_flight(build_environment(config, 0, 0), config)
    for i, pose in enumerate(plan.poses):
        info = json.loads((out / "frames" / f"frame_{i:04d}" / "camera.json").read_text())
        assert np.array_equal(np.array(info["pose"]), pose) and info["frame"] == i
        assert info["time_s"] == plan.times_s[i]


@pytest.fixture(scope="module")
def colmap_model(flight):
    pycolmap = pytest.importorskip("pycolmap", reason="pycolmap is not installed (the "
                                   "[flights] extra): the COLMAP model is not read back")
    _, out = flight
    return pycolmap.Reconstruction(str(out / "sparse" / "0"))


def _reprojection(out: Path, model, edge_px: int = 1) -> list[tuple[float, int]]:
    """Per frame, through pycolmap's poses and camera model: the share of the points the
    frame sees (points.ply) that land on their own component and damage ids, and how many it
    sees. Away from silhouettes and label edges (the pixel's block of edge_px around it holds
    one id of each kind) every point must land on its own ids."""
    cloud = read_ply(out / "points.ply")
    assert len(model.points3D) == len(cloud["xyz"])
    shares = []
    for image_id, image in sorted(model.images.items()):
        j = image_id - 1
        folder = out / "frames" / f"frame_{j:04d}"
        comp = np.asarray(Image.open(folder / "component.png"))
        dmg = np.asarray(Image.open(folder / "damage.png"))
        sees = np.array([i for i, f in enumerate(cloud["frames"]) if j in f])
        cam = np.array([image.cam_from_world() * p for p in cloud["xyz"][sees]])
        uv = model.cameras[image.camera_id].img_from_cam(cam)
        col, row = np.floor(uv[:, 0]).astype(int), np.floor(uv[:, 1]).astype(int)
        same = (comp[row, col] == cloud["component"][sees]) & \
            (dmg[row, col] == cloud["damage"][sees])
        interior = label_interior((comp, dmg), edge_px)[row, col]
        assert same[interior].all(), f"frame {j}: {np.sum(~same[interior])} interior misses"
        assert interior.mean() > 0.5
        shares.append((same.mean(), len(same)))
    return shares


@pytest.mark.slow  # COLMAP's reader (pycolmap)
def test_pycolmap_reprojects_points_onto_their_labels(flight, colmap_model):
    _, out = flight
    shares = _reprojection(out, colmap_model)
    assert len(shares) == FRAMES
    # Every interior point lands on its ids (_reprojection); the rest lie on edges. In the
    # demo preset's town (192x108 px) the columns' silhouettes against far walls and the sky
    # put up to 0.14 % of a frame's points there (0.04 % with the panels).
    assert all(share >= 0.998 for share, _ in shares), shares
    assert sum(n for _, n in shares) > 1000 * FRAMES


def _same_rays(out: Path, model, atol: float) -> None:
    """transforms.json's ray through every pixel centre, undistorted by OpenCV with its
    k1, k2 (nerfstudio's OPENCV model), is COLMAP's ray through it, and its camera centre
    COLMAP's."""
    nerf = json.loads((out / "transforms.json").read_text())
    w, h = nerf["w"], nerf["h"]
    u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    pixels = np.stack([u.ravel(), v.ravel()], axis=1)
    k = np.array([[nerf["fl_x"], 0, nerf["cx"]], [0, nerf["fl_y"], nerf["cy"]], [0, 0, 1]])
    dist = np.array([nerf["k1"], nerf["k2"], nerf["p1"], nerf["p2"]])
    undistorted = cv2.undistortPoints(
        pixels.reshape(-1, 1, 2), k, dist, None, None, None,
        (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)).reshape(-1, 2)
    normalized = model.cameras[1].cam_from_img(pixels)
    for frame in nerf["frames"]:
        c2w = np.array(frame["transform_matrix"])
        local = np.stack([undistorted[:, 0], -undistorted[:, 1], -np.ones(len(pixels))], 1)
        rays = local @ c2w[:3, :3].T
        image = model.images[frame["colmap_im_id"]]
        world_from_cam = image.cam_from_world().inverse()
        colmap_rays = np.c_[normalized, np.ones(len(pixels))] @ \
            world_from_cam.rotation.matrix().T
        unit = rays / np.linalg.norm(rays, axis=1, keepdims=True)
        colmap_unit = colmap_rays / np.linalg.norm(colmap_rays, axis=1, keepdims=True)
        assert np.abs(unit - colmap_unit).max() < atol
        assert np.allclose(c2w[:3, 3], image.projection_center(), atol=1e-12)


@pytest.mark.slow  # COLMAP's reader (pycolmap)
def test_transforms_json_and_colmap_give_the_same_rays(flight, colmap_model):
    _same_rays(flight[1], colmap_model, 1e-12)


def test_points_carry_their_frames_and_a_stated_density(flight):
    _, out = flight
    cloud = read_ply(out / "points.ply")
    cells = np.floor(cloud["xyz"] / 0.05).astype(np.int64)
    assert len(np.unique(cells, axis=0)) == len(cells)  # one point per 5 cm cube
    assert all(len(f) >= 1 for f in cloud["frames"])
    assert set(np.unique(cloud["component"])) <= set(range(1, 9))
    assert set(np.unique(cloud["damage"])) <= {1, 2, 3}


@pytest.mark.slow  # COLMAP's reader (pycolmap)
def test_single_frame_flight(tmp_path):
    cfg = tmp_path / "one.toml"
    cfg.write_text(TWO_VIADUCTS + "max_frames = 1\n")
    out = tmp_path / "one"
    assert main(_fly_args(cfg, out)) == 0
    assert [p.name for p in (out / "frames").iterdir()] == ["frame_0000"]
    cloud = read_ply(out / "points.ply")
    assert len(cloud["xyz"]) > 100 and all(f.tolist() == [0] for f in cloud["frames"])
    pycolmap = pytest.importorskip("pycolmap", reason="pycolmap is not installed: the "
                                   "one-image model is not read back")
    model = pycolmap.Reconstruction(str(out / "sparse" / "0"))
    assert len(model.images) == 1 and len(model.points3D) == len(cloud["xyz"])


@pytest.mark.slow  # COLMAP's reader (pycolmap)
def test_a_zero_length_flight_renders_and_exports(tmp_path):
    """An orbit of arc 0 is one frame per ring, each above the last."""
    cfg = tmp_path / "zero.toml"
    cfg.write_text(TWO_VIADUCTS + "arc_deg = 0.0\nheights_m = [1.5, 3.0]\n")
    out = tmp_path / "zero"
    assert main(_fly_args(cfg, out)) == 0
    assert sorted(p.name for p in (out / "frames").iterdir()) == ["frame_0000", "frame_0001"]
    summary = json.loads((out / "flight.json").read_text())
    assert summary["frames"] == 2 and summary["duration_s"] == pytest.approx(1.5 / 2.0)
    assert summary["ring_overlap_pct"] == [11.1]  # 1.5 m apart, 1.6875 m tall at 2 m
    cloud = read_ply(out / "points.ply")
    assert len(cloud["xyz"]) > 100 and {0, 1} <= {j for f in cloud["frames"] for j in f}
    assert len(json.loads((out / "transforms.json").read_text())["frames"]) == 2
    pycolmap = pytest.importorskip("pycolmap", reason="pycolmap is not installed: the "
                                   "two-image model is not read back")
    model = pycolmap.Reconstruction(str(out / "sparse" / "0"))
    assert len(model.images) == 2 and len(model.points3D) == len(cloud["xyz"])


@pytest.mark.slow  # COLMAP's reader (pycolmap)
def test_under_mechanics_components_reproject_exactly(tmp_path):
    """The demo preset's mechanics damage labels every pixel a crack's centreline crosses, so
    a point's damage id may differ between frames; its component id may not."""
    pycolmap = pytest.importorskip("pycolmap", reason="pycolmap is not installed")
    cfg = tmp_path / "mechanics.toml"
    cfg.write_text(TWO_VIADUCTS.replace('model = "paper"\n', "") + "max_frames = 10\n")
    assert load_config("demo", cfg).damage.model == "mechanics"
    out = tmp_path / "mechanics"
    assert main(_fly_args(cfg, out)) == 0
    model = pycolmap.Reconstruction(str(out / "sparse" / "0"))
    cloud = read_ply(out / "points.ply")
    for image_id, image in model.images.items():
        folder = out / "frames" / f"frame_{image_id - 1:04d}"
        sees = [i for i, f in enumerate(cloud["frames"]) if image_id - 1 in f]
        uv = model.cameras[1].img_from_cam(np.array([image.cam_from_world() * p
                                                     for p in cloud["xyz"][sees]]))
        comp = np.asarray(Image.open(folder / "component.png"))
        landed = comp[np.floor(uv[:, 1]).astype(int), np.floor(uv[:, 0]).astype(int)]
        assert np.array_equal(landed, cloud["component"][sees]), image_id


def test_a_flight_builds_only_what_its_frames_can_see(tmp_path):
    """Looking up at the deck from under it, 10 frames see a few of the environment's parts:
    only those, and the parts that may shadow them, are built, and they render the same as
    with every part built."""
    cfg = tmp_path / "under.toml"
    # The pinhole colour: the camera model (tests/test_camera_model.py) would redraw it.
    cfg.write_text(SMALL + "max_frames = 10\nplan = \"underdeck\"\ngimbal_pitch_deg = 60.0\n"
                   "[sensor]\nenabled = false\n")
    out = tmp_path / "under"
    assert main(["fly", "--seed", "0", "--env", "0", "--plan", "underdeck", "--config",
                 str(cfg), "--out", str(out)]) == 0
    summary = json.loads((out / "flight.json").read_text())
    assert summary["parts_built"] < summary["parts"] / 2, summary
    config = load_config("demo", cfg)
    plan = plan_flight(build_environment(config, 0, 0), config)
    view = EnvironmentView.open(replace(config, materials=flight_materials(config.materials)),
                                0, 0, cull=False, cameras=plan.cameras(config))
    with view.renderer:
        view.renderer.relight(replace(view.lighting, exposure=summary["exposure"]))
        for i in (0, 9):
            whole = view.renderer.render(plan.cameras(config)[i])
            folder = out / "frames" / f"frame_{i:04d}"
            assert np.array_equal(whole.color, np.asarray(Image.open(folder / "image.png")))
            assert np.array_equal(whole.component,
                                  np.asarray(Image.open(folder / "component.png")))


def test_a_complete_flight_is_left_as_it_is(flight, capsys):
    cfg, out = flight
    before = _digests(out)
    assert main(_fly_args(cfg, out)) == 0
    assert "(0 rendered now)" in capsys.readouterr().out and _digests(out) == before


def test_a_killed_flight_resumes_to_the_same_bytes(flight, tmp_path):
    cfg, complete = flight
    out = tmp_path / "killed"
    proc = subprocess.Popen([sys.executable, "-m", "glsynth", *_fly_args(cfg, out)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    progress = out / "progress"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        if progress.is_dir() and len(list(progress.iterdir())) >= 3:
            proc.send_signal(signal.SIGKILL)
            break
        time.sleep(0.002)
    proc.wait()
    done = len(list(progress.iterdir()))
    assert 3 <= done < FRAMES, f"the kill came at {done} of {FRAMES} frames"
    assert not (out / "flight.json").exists()
    assert main(_fly_args(cfg, out)) == 0
    assert _digests(out) == _digests(complete)


# --- radial distortion ------------------------------------------------------------------------

def test_the_lens_check_refuses_folding_lenses_only():
    """Barrel distortion turns back beyond some radius: a lens is refused only where that
    comes before the image's corners (24 mm on a 36 mm sensor: the corner at r = 0.861)."""
    camera = Camera(1920, 1080, 24.0, 36.0, np.eye(4), 0.05, 100.0)
    for k1, k2 in ((-0.12, 0.0), (-0.15, 0.0), (0.3, 0.0), (-0.2, 0.05)):
        lens = Lens("OPENCV", k1, k2)
        source = source_camera(camera, lens)  # accepted
        corners = (np.array([[-0.5, -0.5], [1919.5, 1079.5]]) - camera.K[:2, 2]) / \
            camera.K[0, 0]
        assert np.allclose(lens.distort(lens.undistort(corners)), corners, atol=1e-12), k1
        assert source.width >= camera.width
    for k1, k2 in ((-0.3, 0.0), (-0.2, -0.1)):  # the radius turns back at 1.05 and 0.97 x rd
        with pytest.raises(UserError, match="folds the image over before its corners"):
            source_camera(camera, Lens("OPENCV", k1, k2))


def test_a_refused_lens_writes_nothing(tmp_path, capsys):
    cfg = tmp_path / "fold.toml"
    cfg.write_text(SMALL + 'camera_model = "SIMPLE_RADIAL"\nk1 = -0.9\n')
    out = tmp_path / "fold"
    assert main(_fly_args(cfg, out)) == 2
    assert "flight.k1 = -0.9" in capsys.readouterr().err
    assert not out.exists() or {p.name for p in out.iterdir()} <= {".glsynth.lock",
                                                                   ".glsynth.workers.lock"}


def test_distortion_maps_a_straight_edge_to_colmaps_curve():
    pycolmap = pytest.importorskip("pycolmap", reason="pycolmap is not installed")
    lens = Lens("OPENCV", -0.2, 0.05)
    camera = Camera(400, 300, 24.0, 36.0, np.eye(4), 0.05, 100.0)
    source = source_camera(camera, lens)
    assert source.width > camera.width  # barrel distortion shows more than the pinhole
    # A straight edge: the plane x = 0.55 z of the camera, left of it component 4, right 1.
    # In the pinhole source it is the straight column boundary at f 0.55 + cx.
    k = source.K
    edge = k[0, 0] * 0.55 + k[0, 2]
    cols = np.arange(source.width)[None, :].repeat(source.height, 0)
    labels = np.where(cols < edge, 4, 1).astype(np.uint8)
    out = resample(labels, source_pixels(camera, lens, source), nearest=True)
    assert set(np.unique(out)) == {1, 4}
    model = pycolmap.Camera(model="OPENCV", width=400, height=300,
                            params=lens.colmap_params(camera)[1])
    rows = np.arange(300)
    # pycolmap's u along the edge at each row's centre, from the ray (0.55, y, 1) that
    # meets that row: y found by undistorting the row's centre at the predicted u.
    ys = []
    for row in rows:
        y = (row + 0.5 - 150) / k[1, 1]
        for _ in range(20):
            u, v = model.img_from_cam(np.array([[0.55, y, 1.0]]))[0]
            y -= (v - (row + 0.5)) / k[1, 1]
        ys.append(y)
    predicted = model.img_from_cam(np.c_[np.full(300, 0.55), ys, np.ones(300)])
    assert np.allclose(predicted[:, 1], rows + 0.5, atol=1e-6)
    boundary = np.array([np.flatnonzero(r == 4).max() + 1.0 for r in out])  # COLMAP's u
    assert np.abs(boundary - predicted[:, 0]).max() <= 1.0
    bow = predicted[:, 0].max() - predicted[:, 0].min()
    assert bow > 5  # a straight line would miss the curve by pixels


@pytest.mark.slow  # COLMAP's reader (pycolmap)
@pytest.mark.parametrize("model_name, k1, k2", [("OPENCV", -0.2, 0.05),
                                                 ("SIMPLE_RADIAL", 0.15, 0.0)])
def test_a_distorted_flight_reprojects_through_colmaps_model(tmp_path, model_name, k1, k2):
    pycolmap = pytest.importorskip("pycolmap", reason="pycolmap is not installed")
    cfg = tmp_path / "lens.toml"
    # The lens alone: a severe column's bars and hoops, 1-2 pixels wide in these 192 x 108
    # frames, add label edges that nearest resampling misses (docs/design.md, "Open fences
    # and severe damage as geometry": 97.95 % in the worst frame with them, 98.5 % without).
    cfg.write_text(TWO_VIADUCTS.replace("[damage]\n", "[damage]\ngeometry = false\n")
                   + f'max_frames = 10\ncamera_model = "{model_name}"\nk1 = {k1}\n'
                   f"k2 = {k2}\n")
    out = tmp_path / "lens"
    assert main(_fly_args(cfg, out)) == 0
    model = pycolmap.Reconstruction(str(out / "sparse" / "0"))
    assert model.cameras[1].model.name == model_name
    # Nearest lookup moves a label edge by up to half a source pixel, on top of the half
    # output pixel of any reprojection, and where barrel distortion shrinks the image it
    # steps over one-pixel details: edges and details miss more often than in a pinhole
    # frame (docs/design.md, Inspection flights: 99.5 % overall, 98 % in the worst frame).
    shares = _reprojection(out, model, edge_px=2)
    seen = sum(n for _, n in shares)
    assert sum(share * n for share, n in shares) / seen >= 0.995
    assert min(share for share, _ in shares) >= 0.98, shares
    _same_rays(out, model, 1e-9)
    for name in ("component", "damage"):
        ids = np.unique(np.asarray(Image.open(out / "frames" / "frame_0004" / f"{name}.png")))
        assert set(ids.tolist()) <= set(range(9 if name == "component" else 4))
