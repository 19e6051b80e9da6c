"""COLMAP itself on a glsynth flight (glsynth fly): does it reconstruct from the colour images
alone? Used by bench/bench_flight.py and, at small sizes, by tests/test_colmap_check.py.

On a flight's folder: SIFT features and sequential matching (each frame with the next
``overlap`` in flight order; no loop detection, which needs a vocabulary tree), then
- the point triangulator with the exact poses (sparse/0 without its points): the distance of
  each triangulated point to the true surfaces (exact point-to-triangle distance over the
  environment's meshes; beyond ``margin`` counts as an outlier), as median and 90th
  percentile, and the share of points on each component (the nearest part's);
- the incremental mapper from scratch, holding the flight's exact intrinsics: the share of
  frames it registers (largest model), and after a similarity alignment of its camera
  centres to the truth, the rotation and position errors.

Needs pycolmap (the [flights] extra); ``reconstruct`` says so in one line where it is missing.
"""

import shutil
from pathlib import Path

import numpy as np

from glsynth.core.errors import UserError
from glsynth.core.geometry import transform_points
from glsynth.core.labels import Component
from glsynth.world.environment import Environment
from glsynth.world.flights import surface_distance

try:
    import pycolmap
except ImportError:  # an optional extra: reconstruct() refuses in one line
    pycolmap = None


def reconstruct(env: Environment, out: Path, work: Path, overlap: int = 10,
                margin: float = 0.5, refine_intrinsics: bool = False) -> dict:
    """Features, matching, triangulation with the true poses and the mapper on the flight in
    ``out`` (its frames in order), working in ``work``; every figure, as a dict."""
    if pycolmap is None:
        raise UserError("the COLMAP check needs pycolmap: pip install -e .[flights]")
    work.mkdir(parents=True, exist_ok=True)
    n = len(list((out / "frames").iterdir()))
    names = [f"frames/frame_{i:04d}/image.png" for i in range(n)]
    database = features(out, work, names, overlap)
    return {"matching": match_stats(database),
            "triangulation_with_true_poses": triangulation(env, out, work, database, margin),
            "mapper": mapping(out, work, database, n, refine_intrinsics)}


def posed_model(out: Path, work: Path, database: Path) -> Path:
    """sparse/0 with its cameras and poses but no points, its images numbered as the
    database numbers them (by name): COLMAP's input for triangulating from known poses (each
    image's second line empty, points3D.txt empty)."""
    posed = work / "posed"
    posed.mkdir(parents=True, exist_ok=True)
    shutil.copy(out / "sparse" / "0" / "cameras.txt", posed / "cameras.txt")
    db = pycolmap.Database.open(database)
    ids = {image.name: image.image_id for image in db.read_all_images()}
    db.close()
    lines = [x for x in (out / "sparse" / "0" / "images.txt").read_text().splitlines()
             if not x.startswith("#")]
    posed_lines = []
    for pose in lines[0::2]:
        fields = pose.split()
        posed_lines += [" ".join([str(ids[fields[-1]]), *fields[1:]]), ""]
    (posed / "images.txt").write_text("\n".join(posed_lines) + "\n")
    (posed / "points3D.txt").write_text("")
    return posed


def features(out: Path, work: Path, names: list[str], overlap: int) -> Path:
    database = work / "database.db"
    database.unlink(missing_ok=True)
    cam = (out / "sparse" / "0" / "cameras.txt").read_text().splitlines()[1].split()
    reader = pycolmap.ImageReaderOptions(camera_model=cam[1], camera_params=",".join(cam[4:]))
    pycolmap.extract_features(database, out, image_names=names,
                              camera_mode=pycolmap.CameraMode.SINGLE, reader_options=reader)
    pairing = pycolmap.SequentialPairingOptions(overlap=overlap, loop_detection=False)
    pycolmap.match_sequential(database, pairing_options=pairing)
    return database


def match_stats(database: Path) -> dict:
    """SIFT keypoints per frame and verified (geometric) inlier matches between frames one
    and two apart in flight order, as medians (and the least keypoints)."""
    db = pycolmap.Database.open(database)
    try:
        frame = {im.image_id: int(Path(im.name).parent.name.split("_")[1])
                 for im in db.read_all_images()}
        keypoints = [db.read_keypoints(i).shape[0] for i in frame]
        inliers: dict[tuple[int, int], int] = {}
        for pair, geometry in zip(*db.read_two_view_geometries(), strict=True):
            a, b = sorted(frame[i] for i in pycolmap.pair_id_to_image_pair(pair))
            inliers[(a, b)] = geometry.inlier_matches.shape[0]
    finally:
        db.close()
    n = len(frame)
    return {"keypoints_per_frame_median": float(np.median(keypoints)),
            "keypoints_per_frame_min": int(min(keypoints)),
            **{f"inliers_to_frame_plus_{k}_median": float(np.median(
                [inliers.get((i, i + k), 0) for i in range(n - k)])) for k in (1, 2)}}


def nearest_surfaces(env: Environment, points: np.ndarray, margin: float
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Distance of each point to the nearest part's surface (inf beyond ``margin`` of every
    part's box) and that part's component id."""
    best = np.full(len(points), np.inf)
    component = np.zeros(len(points), int)
    for part in env.parts:
        corners = part.world_vertices()
        lo, hi = corners.min(0) - margin, corners.max(0) + margin
        near = np.flatnonzero(np.all((points >= lo) & (points <= hi), axis=1))
        triangles = transform_points(part.pose, part.mesh.triangles)
        for chunk in np.array_split(near, max(1, len(near) * len(triangles) // 2_000_000)):
            if chunk.size:
                d = surface_distance(triangles, points[chunk])
                better = d < best[chunk]
                best[chunk[better]], component[chunk[better]] = d[better], int(part.component)
    return best, component


def triangulation(env: Environment, out: Path, work: Path, database: Path,
                  margin: float) -> dict:
    model = pycolmap.Reconstruction(str(posed_model(out, work, database)))
    tri = work / "triangulated"
    tri.mkdir(exist_ok=True)
    model = pycolmap.triangulate_points(model, database, out, tri)
    xyz = np.array([p.xyz for p in model.points3D.values()])
    if not len(xyz):
        return {"points": 0}
    dist, component = nearest_surfaces(env, xyz, margin)
    near = dist[np.isfinite(dist)]
    shares = {Component(c).name.lower(): float(np.mean(component[np.isfinite(dist)] == c))
              for c in np.unique(component[np.isfinite(dist)])}
    return {"points": len(xyz), "outliers_beyond_margin": int(np.sum(~np.isfinite(dist))),
            "median_distance_mm": 1000 * float(np.median(near)),
            "p90_distance_mm": 1000 * float(np.percentile(near, 90)),
            "mean_track_length": float(np.mean([p.track.length()
                                                for p in model.points3D.values()])),
            "share_by_component": shares}


def rotation_angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    cos = (np.trace(a @ b.T) - 1) / 2
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def mapping(out: Path, work: Path, database: Path, n_frames: int,
            refine_intrinsics: bool) -> dict:
    mapped = work / "mapped"
    shutil.rmtree(mapped, ignore_errors=True)
    mapped.mkdir()
    # The flight's intrinsics are exact (cameras.txt); refined from an orbit, COLMAP lets the
    # PINHOLE camera's fy drift (2-6x fx measured), which no texture can fix.
    options = pycolmap.IncrementalPipelineOptions(
        ba_refine_focal_length=refine_intrinsics, ba_refine_principal_point=False,
        ba_refine_extra_params=refine_intrinsics)
    models = pycolmap.incremental_mapping(database, out, mapped, options=options)
    if not models:
        return {"registered_share": 0.0}
    model = max(models.values(), key=lambda m: m.num_reg_images())
    truth = pycolmap.Reconstruction(str(out / "sparse" / "0"))
    by_name = {im.name: im for im in truth.images.values()}
    pairs = [(im, by_name[im.name]) for im in model.images.values() if im.has_pose]
    result = {"registered_share": len(pairs) / n_frames, "models": len(models)}
    if len(pairs) < 3:  # too few to align
        return result
    src = np.array([a.projection_center() for a, _ in pairs])
    tgt = np.array([b.projection_center() for _, b in pairs])
    sim = pycolmap.estimate_sim3d(src, tgt)
    if sim is None:
        return result
    rot = sim.rotation.matrix()
    angles = [rotation_angle_deg(a.cam_from_world().rotation.matrix() @ rot.T,
                                 b.cam_from_world().rotation.matrix()) for a, b in pairs]
    moved = np.array([sim * c for c in src])
    errors = np.linalg.norm(moved - tgt, axis=1)
    return {**result, "median_rotation_error_deg": float(np.median(angles)),
            "max_rotation_error_deg": float(np.max(angles)),
            "median_position_error_mm": 1000 * float(np.median(errors)),
            "p90_position_error_mm": 1000 * float(np.percentile(errors, 90))}
