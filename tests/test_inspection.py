"""The close-range inspection preset: cameras at member faces ([cameras] placement = "faces"),
slight damage only, the RRDR for cracks, and the paper preset left as it was."""

import dataclasses
import math

import numpy as np
import pytest
import trimesh
from glhelpers import LIGHT, plain_materials, render_config

from glsynth.appearance.dressing import crack_segments
from glsynth.core.config import (
    SEVERITIES,
    CameraConfig,
    Config,
    DamageConfig,
    FiltersConfig,
    config_from_dict,
    load_config,
)
from glsynth.core.errors import UserError
from glsynth.core.filters import crack_rrdr, pixels_per_cm, removal_reason, rrdr, view_rrdr
from glsynth.core.geometry import segment_distance
from glsynth.core.labels import Component, Damage
from glsynth.core.seeding import Stream, make_rng
from glsynth.render.gl.renderer import Renderer
from glsynth.render.raycast import ray_cast
from glsynth.render.scene import build_scene
from glsynth.world.cameras import sample_camera
from glsynth.world.environment import BOX_BEAMS, OPEN_KINDS, PartKind
from glsynth.world.face_cameras import (
    FOOT_FRAME,
    FOOT_GROUND_M,
    GROUND_CLEARANCE_M,
    FaceTargets,
    crack_aims,
    member_faces,
    place_camera,
    place_cameras,
)

INSPECTION = load_config("inspection")
SMALL = render_config(97, 55)
"""Odd sizes: the centre pixel lies on the optical axis."""
N = 40


def faces_config(**fields) -> CameraConfig:
    return dataclasses.replace(INSPECTION.cameras, n_closeup=N, **fields)


_CRACKS: dict[tuple[int, int], dict] = {}


def cracks_of(env) -> dict:
    """The environment's crack segments under the inspection preset, which its cameras aim at
    (made once per environment)."""
    key = (env.root_seed, env.env_index)
    if key not in _CRACKS:
        _CRACKS[key] = crack_segments(env, INSPECTION)
    return _CRACKS[key]


def placements(env, cameras: CameraConfig, render=SMALL, n: int = N) -> list:
    return place_cameras(env, cameras, render, range(n), cracks_of(env))


def check_geometry(env, p, cameras: CameraConfig) -> None:
    """The camera looks at its point on the member's face from the configured ranges."""
    parts = {q.name: q for q in env.parts}
    member, aim, cam = parts[p.face.member], p.face, p.camera
    point, position = np.array(aim.point), cam.pose[:3, 3]
    forward = -cam.pose[:3, 2]
    along = float((point - position) @ forward)  # distance along the optical axis
    assert np.isclose(along, aim.distance_m, rtol=0, atol=1e-9)
    assert np.linalg.norm(np.cross(point - position, forward)) < 1e-9  # the axis meets it
    lo, hi = cameras.face_distance_m
    assert lo - 1e-12 <= along <= hi + 1e-12
    local = np.linalg.inv(member.pose) @ np.append(point, 1.0)
    axis, sign = "xyz".index(aim.face[1]), 1 if aim.face[0] == "+" else -1
    half = member.mesh.extents / 2
    assert np.isclose(local[axis], sign * half[axis], atol=1e-9)  # on that face
    assert np.all(np.abs(local[:3]) <= half + 1e-9)
    normal = sign * member.pose[:3, axis]
    angle = math.degrees(math.acos(min(1.0, float(-forward @ normal))))
    assert np.isclose(angle, aim.angle_deg, atol=1e-6)
    assert angle <= cameras.face_angle_deg + 1e-5  # acos near 1 is good to about 1e-6 deg
    level = np.cross(forward, [0.0, 0.0, 1.0])  # image x when level
    if np.linalg.norm(level) < 1e-9:  # straight up at a soffit: x is rolled from the beam's axis
        level = np.cross(forward, np.cross(member.pose[:3, int(np.argmax(
            member.mesh.extents[:2]))], forward))
    level /= np.linalg.norm(level)
    roll = math.degrees(math.atan2(cam.pose[:3, 0] @ np.cross(-forward, level),
                                   cam.pose[:3, 0] @ level))
    assert abs(roll) <= cameras.face_roll_deg + 1e-9 and np.isclose(roll, aim.roll_deg)
    assert cameras.focal_mm[0] <= cam.focal_mm <= cameras.focal_mm[1]
    assert p.kind == "closeup"
    for q in env.parts:  # inside no box part: the members and the portal beams
        if q.kind in BOX_BEAMS | {PartKind.COLUMN, PartKind.PORTAL}:
            inner = np.linalg.inv(q.pose) @ np.append(position, 1.0)
            assert np.any(np.abs(inner[:3]) > q.mesh.extents / 2)
    assert position[2] >= env.trajectory.ground_at(np.array([p.s_m]))[0] + \
        GROUND_CLEARANCE_M - 0.02  # the ground between its 1 m sweep samples is linear in s


def test_cameras_stand_at_member_faces_within_the_ranges(env0):
    cameras = faces_config(face_crack_share=0.0)
    found = placements(env0, cameras)
    for p in found:
        check_geometry(env0, p, cameras)
    parts = {q.name: q for q in env0.parts}
    assert {parts[p.face.member].component for p in found} == {Component.COLUMN, Component.BEAM}
    assert {p.face.face for p in found} >= {"+x", "-x", "+y", "-y"}
    distances = [p.face.distance_m for p in found]
    assert min(distances) < 1.0 and max(distances) > 2.3  # spread over the range


def test_crack_aimed_cameras_look_at_a_crack_from_where_they_resolve_it(env0):
    """About face_crack_share of the cameras aim at a point on a crack of their member's face,
    and stand where its width there spans face_crack_px pixels (or at the near end)."""
    cameras = faces_config()
    found = placements(env0, cameras, INSPECTION.render)  # 1920 px: a 0.2 mm crack needs < 1 m
    parts = {q.name: q for q in env0.parts}
    aimed = [p for p in found if p.face.crack_width_mm is not None]
    assert 0.5 * N <= len(aimed) < N  # 0.75 of 40 expected
    for p in aimed:
        check_geometry(env0, p, cameras)
        local, widths = cracks_of(env0)[p.face.member]
        pose = parts[p.face.member].pose
        a, b = (local[:, k] @ pose[:3, :3].T + pose[:3, 3] for k in (0, 1))
        gap, t = segment_distance(np.array(p.face.point), a, b)
        # The aim lies on a segment; at a vertex two segments meet it (an en-echelon bridge
        # joins a piece there, each with its own width), so one of them has the aim's width.
        on = np.flatnonzero(gap < 1e-9)
        assert on.size
        width_mm = 1e3 * (widths[on, 0] + t[on] * (widths[on, 1] - widths[on, 0]))
        assert np.isclose(width_mm, p.face.crack_width_mm, rtol=1e-9).any()
        width_mm = p.face.crack_width_mm
        span_px = width_mm / 1e3 * p.camera.fx / p.face.distance_m
        near = cameras.face_distance_m[0]
        assert span_px >= cameras.face_crack_px - 1e-9 or p.face.distance_m == near
    # At 9 px (3 in the labels) most slight cracks need the near end; the widest may stand
    # farther: the rule's span is met, or the camera could come no nearer.
    assert any(p.face.distance_m == cameras.face_distance_m[0] for p in aimed)


def test_crack_aims_are_drawn_by_the_area_the_cracks_open(env0):
    """A crack-aimed camera's point is drawn by length x width: the widths drawn average the
    area-weighted width of the environment's cracks on inspected faces, well above the
    length-weighted one (the hairlines that an inspector's photographs pass over)."""
    faces = member_faces(env0.parts)
    aims = crack_aims(env0.parts, faces, cracks_of(env0))
    lengths = np.linalg.norm(aims.segments[:, 1] - aims.segments[:, 0], axis=1)
    area = lengths * aims.widths_m.mean(axis=1)
    assert np.allclose(aims.weights, area / area.sum(), rtol=1e-12, atol=0)
    wa, wb = aims.widths_m.T
    at_end = np.where((wa > 0) & (wb > 0), (wa + wb) / 2, np.maximum(wa, wb))  # tips: not aimed
    by_area, by_length = area @ at_end / area.sum(), lengths @ at_end / lengths.sum()
    # 1,500 draws (a millisecond each): the mean's standard error is 2.3 % of it for these
    # widths, and the length-weighted mean lies 40 % under it.
    rng = make_rng(5, 0, Stream.CAMERAS)
    drawn = np.array([aims.draw(rng)[2] for _ in range(1500)])
    assert drawn.mean() == pytest.approx(by_area, rel=0.06)
    assert by_area > 1.5 * by_length and drawn.min() > 0
    # Cracks that open nothing (every width 0) give no aims: the cameras aim at faces.
    closed = {name: (ends, np.zeros_like(w)) for name, (ends, w) in cracks_of(env0).items()}
    assert crack_aims(env0.parts, faces, closed) is None


def test_a_crack_aimed_camera_labels_its_centre_pixel_with_the_crack(tmp_path):
    """Rendered: the centre pixel of each crack-aimed camera is concrete damage, with the
    aimed crack's width in the crack-width map (the pixel's centre lies on its centreline)."""
    from glsynth.render.view import EnvironmentView

    eight = TINY.replace("n_closeup = 3", "n_closeup = 8")
    (tmp_path / "tiny.toml").write_text(eight + "[render]\nwidth = 97\nheight = 55\nmsaa = 0\n")
    config = load_config("inspection", tmp_path / "tiny.toml")
    checked = 0
    with Renderer(config.render) as renderer:
        view = EnvironmentView.open(config, 0, 0, renderer)
        for index in range(config.cameras.total):
            placement, out = view.render(index, frozenset({"damage"}))
            if placement.face.crack_width_mm is None:
                continue
            assert out.damage[27, 48] == Damage.CONCRETE
            assert np.isclose(out.crack_width[27, 48], placement.face.crack_width_mm,
                              rtol=1e-4)
            checked += 1
    assert checked >= 3


def test_the_centre_pixel_shows_the_member_at_the_aimed_point(env0):
    """An independent ray cast (Embree) and the GL labels agree with the placement."""
    cameras = faces_config()
    found = placements(env0, cameras, n=12)
    parts = {q.name: q for q in env0.parts}
    with Renderer(SMALL) as renderer:
        renderer.load(build_scene(env0.parts, plain_materials(env0)), LIGHT)
        for p in found:
            truth = ray_cast(env0.parts, plain_materials(env0), p.camera)
            row, col = (SMALL.height - 1) // 2, (SMALL.width - 1) // 2
            component = int(parts[p.face.member].component)
            assert truth.component[row, col] == component
            assert np.isclose(truth.depth[row, col], p.face.distance_m, rtol=1e-5)
            gl = renderer.render(p.camera, frozenset({"component", "depth"}))
            assert gl.component[row, col] == component
            assert np.isclose(gl.depth[row, col], p.face.distance_m, rtol=1e-3)


def test_foot_views_take_in_a_column_foot_and_the_ground_before_it(env0):
    """Every foot view aims at a column face from level or above, at a point raised above the
    ground line by FOOT_FRAME of half the view's height; an independent ray cast (Embree)
    finds the ground at the bottom of the frame, below the aimed column."""
    cameras = faces_config(face_crack_share=0.0, face_foot_share=1.0)
    found = placements(env0, cameras, n=12)
    parts = {q.name: q for q in env0.parts}
    scene = FaceTargets.of(env0).scene
    for p in found:
        check_geometry(env0, p, cameras)
        assert parts[p.face.member].kind is PartKind.COLUMN
        point = np.array(p.face.point)
        assert p.camera.pose[2, 3] >= point[2] - 1e-9  # from level or above
        axis, sign = "xyz".index(p.face.face[1]), 1 if p.face.face[0] == "+" else -1
        normal = sign * parts[p.face.member].pose[:3, axis]
        ground = float(scene.ground_below(point + FOOT_GROUND_M * normal).min())
        half_view = (p.face.distance_m * cameras.sensor_mm * SMALL.height / SMALL.width
                     / (2.0 * p.camera.focal_mm))
        assert FOOT_FRAME[0] * half_view - 1e-9 <= ground <= FOOT_FRAME[1] * half_view + 1e-9
        truth = ray_cast(env0.parts, plain_materials(env0), p.camera)
        assert truth.component[-1, (SMALL.width - 1) // 2] == Component.NONBRIDGE


def test_foot_views_leave_the_other_cameras_as_they_were(env0):
    """The foot draw has a generator of its own: cameras that are not foot views stand where
    they stand without them: exactly the cameras not aimed at a crack whose foot draw falls
    under the share move."""
    without = placements(env0, faces_config(face_foot_share=0.0), n=24)
    with_feet = placements(env0, faces_config(face_foot_share=0.5), n=24)
    moved = [a.index for a, b in zip(without, with_feet)
             if a.camera.pose.tobytes() != b.camera.pose.tobytes()]
    drawn = [p.index for p in without if p.face.crack_width_mm is None
             and make_rng(env0.root_seed, env0.env_index, Stream.FOOT_VIEWS, p.index).random()
             < 0.5]
    parts = {q.name: q for q in env0.parts}
    assert moved == drawn and moved
    for i in moved:
        assert with_feet[i].face.crack_width_mm is None and without[i].face.crack_width_mm is None
        assert parts[with_feet[i].face.member].kind is PartKind.COLUMN


def test_placement_is_deterministic_and_per_camera(env0):
    cameras = faces_config()
    first = placements(env0, cameras, n=6)
    alone = sorted((place_camera(env0, cameras, SMALL, i, cracks_of(env0))
                    for i in (5, 3, 0, 1, 2, 4)),
                   key=lambda p: p.index)
    for a, b in zip(first, alone):
        assert a.camera.pose.tobytes() == b.camera.pose.tobytes()
        assert a.face == b.face and a.camera.focal_mm == b.camera.focal_mm
    assert len({p.camera.pose.tobytes() for p in first}) == 6
    with pytest.raises(ValueError, match="camera index"):
        place_camera(env0, cameras, SMALL, N, cracks_of(env0))


@pytest.mark.parametrize("fields", [
    {"face_distance_m": (0.3, 0.3)}, {"face_distance_m": (3.0, 3.0)},
    {"focal_mm": (24.0, 24.0)}, {"focal_mm": (105.0, 105.0)},
    {"face_angle_deg": 0.0}, {"face_angle_deg": 30.0, "face_roll_deg": 0.0}])
def test_extremes_of_the_ranges(env0, fields):
    cameras = faces_config(**fields)
    found = placements(env0, cameras, n=10)
    for p in found:
        check_geometry(env0, p, cameras)
    if "face_distance_m" in fields:
        assert all(p.face.distance_m == fields["face_distance_m"][0] for p in found)
    if "focal_mm" in fields:
        assert all(p.camera.focal_mm == fields["focal_mm"][0] for p in found)
    if fields.get("face_angle_deg") == 0.0:
        assert all(p.face.angle_deg < 1e-6 for p in found)
    if fields.get("face_roll_deg") == 0.0:
        assert all(abs(p.camera.pose[2, 0]) < 1e-12 for p in found)


@pytest.mark.parametrize("section, values, field", [
    ("cameras", {"face_angle_deg": 91.0}, "face_angle_deg"),
    ("cameras", {"face_angle_deg": -1.0}, "face_angle_deg"),
    ("cameras", {"face_distance_m": [3.0, 0.3]}, "face_distance_m"),
    ("cameras", {"face_distance_m": [0.0, 3.0]}, "face_distance_m"),
    ("cameras", {"face_distance_m": [-1.0, 3.0]}, "face_distance_m"),
    ("cameras", {"face_roll_deg": 60.0}, "face_roll_deg"),
    ("cameras", {"n_regular": 2}, "n_regular"),
    ("cameras", {"face_crack_share": 1.5}, "face_crack_share"),
    ("cameras", {"face_crack_share": -0.1}, "face_crack_share"),
    ("cameras", {"face_crack_px": -1.0}, "face_crack_px"),
    ("cameras", {"face_foot_share": 1.5}, "face_foot_share"),
    ("cameras", {"placement": "within", "n_regular": 2, "face_crack_share": 0.0,
                 "face_foot_share": 0.5}, "face_foot_share"),
    ("cameras", {"placement": "within", "n_regular": 2}, "face_crack_share"),
    ("damage", {"severities": ["slight", "slight"]}, "severities"),
    ("damage", {"severities": ["light"]}, "severities"),
    ("damage", {"severities": []}, "severities"),
    ("filters", {"rrdr_crack_mm": -0.1}, "rrdr_crack_mm"),
    ("filters", {"rrdr_footprint_factor": 0.0}, "rrdr_footprint_factor"),
    ("filters", {"min_components": 0}, "min_components"),
])
def test_bad_inspection_settings_give_one_clear_line(section, values, field):
    with pytest.raises(UserError) as err:
        config_from_dict({section: values}, INSPECTION)
    message = str(err.value)
    assert "\n" not in message and f"{section}.{field}" in message


def test_cameras_aim_at_cracks_only_under_mechanics():
    paper = {"model": "paper", "severities": ["slight", "medium", "severe"],
             "spalling_severities": ["medium", "severe"]}
    with pytest.raises(UserError) as err:
        config_from_dict({"damage": paper}, INSPECTION)
    assert "cameras.face_crack_share" in str(err.value) and "mechanics" in str(err.value)


def test_severities_subset_only_under_mechanics():
    with pytest.raises(UserError, match="severities"):
        DamageConfig(severities=("slight",))  # model = "paper" draws all three
    assert DamageConfig(model="mechanics", severities=("slight",)).severities == ("slight",)


def test_trajectory_placements_refuse_faces(env0):
    with pytest.raises(ValueError, match="place_camera"):
        sample_camera(env0.trajectory, faces_config(), SMALL, 0,
                      make_rng(0, 0, Stream.CAMERAS, 0))


def test_the_preset_asks_for_what_the_issue_does():
    c = INSPECTION
    assert c.cameras.placement == "faces" and c.cameras.n_regular == 0
    assert c.cameras.face_distance_m == (0.3, 3.0) and c.cameras.face_angle_deg == 30.0
    assert c.cameras.focal_mm == (24.0, 105.0) and c.cameras.sensor_mm == 36.0
    assert (c.render.width, c.render.height) == (1920, 1080)
    assert c.damage.model == "mechanics" and c.damage.severities == ("slight", "medium")
    assert c.damage.crack_width_mm == (0.05, 3.0)
    assert c.filters.rrdr_crack_mm == 0.2 and c.filters.rrdr_footprint_factor == 2.0


def test_solid_parts_are_closed(env0):
    """The inside test counts crossings of closed surfaces: every part but the open ground
    and scene panels must be closed."""
    for part in env0.parts:
        merged = trimesh.Trimesh(part.mesh.vertices, part.mesh.faces)  # merges seam vertices
        assert merged.is_watertight == (part.kind not in OPEN_KINDS), part.name


def test_member_faces_are_the_inspected_faces_of_each_member(env0):
    """Four lateral faces per column; two sides and the soffit per cross or tie beam; no
    girder; outward normals and the faces' true areas (the weights of the draw)."""
    faces = member_faces(env0.parts)
    parts = {q.name: q for q in env0.parts}
    by_member: dict[str, set] = {}
    for f in faces:
        by_member.setdefault(f.member, set()).add(f.label)
        part = parts[f.member]
        axis = "xyz".index(f.label[1])
        others = [e for a, e in enumerate(part.mesh.extents) if a != axis]
        assert np.isclose(f.area, others[0] * others[1])
        for step, outside in ((1e-3, True), (-1e-3, False)):
            local = np.linalg.inv(part.pose) @ np.append(f.centre + step * f.normal, 1.0)
            assert bool(np.any(np.abs(local[:3]) > part.mesh.extents / 2)) == outside
    columns = {n for n in parts if n.startswith("column_")}
    beams = {n for n in parts if "_cross_" in n or "_tie_" in n}
    assert set(by_member) == columns | beams
    assert all(by_member[n] == {"+x", "-x", "+y", "-y"} for n in columns)
    for name in beams:
        across = "yx"[int(np.argmax(parts[name].mesh.extents[:2]))]
        assert by_member[name] == {f"+{across}", f"-{across}", "-z"}


def test_rrdr_for_cracks_at_its_boundary():
    """Footprint depth / f_px exactly k w is inside; a hair more is outside."""
    f_px, width_mm, k = 1000.0, 0.25, 2.0
    boundary = 0.5  # m: 0.5 / 1000 = 2 x 0.25 mm
    depth = np.array([boundary, boundary * (1 + 1e-12), 0.1, 0.0, -1.0, np.inf, np.nan])
    assert crack_rrdr(depth, f_px, width_mm, k).tolist() == [True, False, True, False, False,
                                                             False, False]
    filters = FiltersConfig(rrdr_crack_mm=width_mm, rrdr_footprint_factor=k)
    assert view_rrdr(filters, depth, f_px).tolist() == crack_rrdr(depth, f_px, width_mm, k
                                                                  ).tolist()
    # The same rule in px/cm: at least 10 / (k w[mm]) = 20 px/cm, away from the boundary.
    far = np.linspace(0.01, 3.0, 997)
    far = far[np.abs(far - boundary) > 1e-6]
    assert np.array_equal(crack_rrdr(far, f_px, width_mm, k),
                          pixels_per_cm(far, f_px) >= 10 / (k * width_mm))
    with pytest.raises(ValueError, match="focal_px"):
        crack_rrdr(depth, 0.0, width_mm, k)


def test_paper_and_demo_keep_their_filters_and_rrdr():
    for preset in ("paper", "demo"):
        c = load_config(preset)
        assert c.filters == FiltersConfig() and c.cameras.placement == "within"
        assert c.damage.severities == SEVERITIES
    assert Config().filters == FiltersConfig(min_intensity=30.0, min_components=2,
                                             min_depth_m=0.5, rrdr_px_per_cm=1.5,
                                             rrdr_crack_mm=0.0)
    depth = np.linspace(0.0, 40.0, 1200).reshape(30, 40)
    assert np.array_equal(view_rrdr(FiltersConfig(), depth, 2933.0), rrdr(depth, 2933.0))
    image = np.full((4, 4, 3), 100, np.uint8)
    one = np.full((4, 4), 4, np.uint8)
    far = np.full((4, 4), 2.0)
    assert removal_reason(image, one, far) == "single_component"
    assert removal_reason(image, one, far, INSPECTION.filters) is None
    near = far.copy()
    near[0, 0] = 0.3
    assert removal_reason(image, np.arange(16).reshape(4, 4) % 2, near) == "too_close"
    assert removal_reason(image, one, near, INSPECTION.filters) is None


TINY = """
[dataset]
n_environments = 1
n_test_environments = 0
[cameras]
n_closeup = 3
[materials]
texture_size = 32
builtin_size = 64
images_per_category = 3
"""


def test_slight_and_medium_damage_with_cracks_of_005_to_3_mm(tmp_path):
    from glsynth.appearance.damage_bank import DamageBank
    from glsynth.appearance.dressing import dress, open_repository
    from glsynth.world.environment import build_environment

    (tmp_path / "tiny.toml").write_text(TINY)
    config = load_config("inspection", tmp_path / "tiny.toml")
    env = build_environment(config, 0, 0)
    dressing = dress(env, config, open_repository(config), DamageBank(config.damage, 0),
                     {p.name for p in env.parts})
    damaged = [a.damage for a in dressing.assignments.values()
               if a.damage and a.damage.get("damaged")]
    assert damaged and {d["severity"] for d in damaged} == {"slight", "medium"}
    cracks = [c for d in damaged for c in d.get("cracks", [])]
    assert cracks
    # The mechanics' widths lie in 0.05-3 mm; along a crack they vary and close at the tips.
    assert all(0 < c["mean_width_mm"] <= c["max_width_mm"] <= 3.0 + 1e-9 for c in cracks)
    assert max(c["max_width_mm"] for c in cracks) > 1.0  # medium drifts open wider cracks
    intact = sum(1 for a in dressing.assignments.values()
                 if a.damage and not a.damage.get("damaged"))
    assert intact  # undamaged_probability = 0.2


@pytest.mark.slow
def test_generate_and_stats_on_the_inspection_preset(tmp_path):
    """The Tokaido layout at the preset's 1920x1080 with face cameras, and glsynth stats."""
    import json

    from glsynth.cli import main
    from glsynth.data.tokaido import read_manifest

    (tmp_path / "tiny.toml").write_text(TINY)
    out = tmp_path / "ds"
    assert main(["generate", "--preset", "inspection", "--config", str(tmp_path / "tiny.toml"),
                 "--seed", "0", "--out", str(out)]) == 0
    rows = read_manifest(out, "files_train.csv")
    assert rows and not read_manifest(out, "files_puretex_train.csv")
    for r in rows:
        assert 24.0 <= r.focal_mm <= 105.0 and not r.regular
        meta = json.loads((out / "meta" / "train" / r.image.split("/")[-1].replace(
            "_Scene.png", ".json")).read_text())
        face = meta["placement"]["face"]
        assert 0.3 <= face["distance_m"] <= 3.0 and face["angle_deg"] <= 30.0
    assert main(["stats", str(out), "--out", str(tmp_path / "stats")]) == 0
    stats = json.loads((tmp_path / "stats" / "stats.json").read_text())
    assert stats["images"]["closeup"] == len(rows) and stats["images"]["regular"] == 0
