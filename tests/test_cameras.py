import math

import numpy as np
import pytest

from glsynth.core.config import CameraConfig, Config, RenderConfig
from glsynth.core.seeding import Stream, make_rng
from glsynth.world.cameras import Camera, environment_camera, euler_xyz, sample_camera

CFG = Config()


def placements(env0, indices):
    return [environment_camera(env0.trajectory, CFG.cameras, CFG.render, 0, 0, i)
            for i in indices]


@pytest.mark.parametrize("placement", ["within", "at"])
def test_section_3_4_ranges(env0, placement):
    traj = env0.trajectory
    cameras = CameraConfig(placement=placement)
    lateral = {"regular": [], "closeup": []}
    for i in range(100):
        p = environment_camera(traj, cameras, CFG.render, 0, 0, i)
        regular = p.index < 50
        d = 10.0 if regular else 5.0
        cam = p.camera
        assert p.kind == ("regular" if regular else "closeup")
        assert 15.0 <= cam.focal_mm <= 55.0 and cam.sensor_mm == 36.0
        assert (cam.width, cam.height) == (1920, 1080)
        point, _, normal = traj.frame(np.array([p.s_m]))
        offset = cam.pose[:2, 3] - point[0, :2]
        assert np.isclose(np.linalg.norm(offset), p.distance_m)
        assert np.isclose(offset @ normal[0, :2], p.side * p.distance_m)
        if placement == "at":
            assert p.distance_m == d
        else:
            assert 0 <= p.distance_m <= d
        lateral[p.kind].append(p.side * p.distance_m / d)
        lo, hi = (1.0, 10.0) if regular else (1.0, 6.5)
        assert lo <= cam.pose[2, 3] <= hi  # above the world origin (height_from = "origin")
        rx, ry, rz = p.euler_xyz_rad
        assert math.pi / 4 <= rx <= 3 * math.pi / 4 and abs(ry) <= math.pi / 12
        assert abs(rz) <= math.pi / 2
        assert np.allclose(cam.pose[:3, :3] @ cam.pose[:3, :3].T, np.eye(3))
        assert np.isclose(np.linalg.det(cam.pose[:3, :3]), 1.0)
    if placement == "within":  # uniform over [-D, D]: both sides, near and far
        for values in lateral.values():
            assert min(values) < -0.5 and max(values) > 0.5
            assert sum(abs(v) < 0.5 for v in values) >= 10


def test_euler_zero_offsets_look_horizontally_at_the_centre_line(env0):
    cameras = CameraConfig(rot_x_deg=(90.0, 90.0), rot_y_deg=(0.0, 0.0), rot_z_deg=(0.0, 0.0))
    for i in range(10):
        p = sample_camera(env0.trajectory, cameras, CFG.render, i,
                          make_rng(0, 0, Stream.CAMERAS, i))
        forward = -p.camera.pose[:3, 2]
        _, _, normal = env0.trajectory.frame(np.array([p.s_m]))
        assert np.allclose(forward, -p.side * normal[0], atol=1e-12)
        assert np.allclose(p.camera.pose[:3, 1], [0, 0, 1], atol=1e-12)  # image up is world up


def test_blender_euler_convention():
    # Blender: rotation X = 90 deg turns the camera's view (-z) to +y.
    r = euler_xyz(math.pi / 2, 0.0, 0.0)
    assert np.allclose(r @ [0, 0, -1], [0, 1, 0])
    assert np.allclose(euler_xyz(0, 0, math.pi / 2) @ [1, 0, 0], [0, 1, 0])


def test_intrinsics_and_gl_projection_agree():
    rng = make_rng(0, 0, Stream.CAMERAS, 0)
    pose = np.eye(4)
    pose[:3, :3] = euler_xyz(1.2, 0.1, -0.3)
    pose[:3, 3] = [3.0, -2.0, 5.0]
    cam = Camera(640, 360, 24.0, 36.0, pose, 0.05, 2000.0)
    assert np.allclose(cam.K, [[cam.fx, 0, 319.5], [0, cam.fx, 179.5], [0, 0, 1]])
    assert cam.fx == pytest.approx(24.0 / 36.0 * 640)
    cam_pts = np.column_stack([rng.uniform(-3, 3, 50), rng.uniform(-2, 2, 50),
                               -rng.uniform(0.5, 500, 50), np.ones(50)])
    world = (pose @ cam_pts.T).T
    view = (cam.view() @ world.T).T
    # OpenCV pixel coordinates from K (x right, y down, z forward).
    cv = np.column_stack([view[:, 0], -view[:, 1], -view[:, 2]])
    uv = (cam.K @ cv.T).T
    uv = uv[:, :2] / uv[:, 2:]
    clip = (cam.projection() @ view.T).T
    ndc = clip[:, :3] / clip[:, 3:]
    col = (ndc[:, 0] + 1) / 2 * cam.width - 0.5
    row = (1 - ndc[:, 1]) / 2 * cam.height - 0.5
    assert np.allclose(np.column_stack([col, row]), uv, atol=1e-6)
    # Rays: depth along the optical axis equals the ray parameter.
    origin, dirs = cam.rays()
    assert np.allclose((dirs @ pose[:3, :3])[..., 2], -1.0)
    assert np.allclose(origin, pose[:3, 3])


def test_camera_is_reproducible_alone(env0):
    a = placements(env0, [7])[0]
    batch = placements(env0, range(10))
    assert a.camera.pose.tobytes() == batch[7].camera.pose.tobytes()
    assert a.camera.focal_mm == batch[7].camera.focal_mm


def test_bad_camera_index(env0):
    with pytest.raises(ValueError, match=r"camera index = 100: must be in \[0, 99\]"):
        placements(env0, [100])


def test_render_config_errors():
    with pytest.raises(ValueError, match=r"render\.msaa = 3"):
        RenderConfig(msaa=3)
    with pytest.raises(ValueError, match=r"render\.zfar_m = 0\.01"):
        RenderConfig(zfar_m=0.01)
