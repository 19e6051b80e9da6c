"""Girder cracks (glsynth.appearance.girder_cracks): on the curved girder's mesh, in their
orientation bands against the local track direction, in the clear spans, none on the top under
the slab, gravity cracks in the midspan soffit; and rendered where the network is."""

import dataclasses
import functools

import numpy as np
import pytest
from glhelpers import LIGHT, camera, render_config, scene_of
from scipy.spatial import cKDTree

from glsynth.appearance.cracks import (
    FLEXURAL_BAND_DEG,
    SHEAR_BAND_DEG,
    CrackNetwork,
    column_demand,
)
from glsynth.appearance.girder_cracks import girder_cracks, girder_spans, girder_sweep
from glsynth.appearance.materials import Material
from glsynth.core.config import Config, DamageConfig
from glsynth.core.labels import Component, Damage
from glsynth.core.seeding import Stream, make_rng
from glsynth.render.gl.renderer import Renderer
from glsynth.world.environment import Environment, Part, PartKind, build_environment
from glsynth.world.flights import surface_distance

CFG = DamageConfig(model="mechanics")
SEVERITIES = ("slight", "medium", "severe")


@functools.lru_cache(maxsize=1)
def curved_env() -> Environment:
    """Four viaducts at the tightest radius [environment] min_radius_m allows (100 m)."""
    base = Config()
    env_cfg = dataclasses.replace(base.environment, n_viaducts=4, min_radius_m=(100.0, 100.0))
    return build_environment(dataclasses.replace(base, environment=env_cfg), 1, 0)


def tightest_girders(env: Environment) -> list[Part]:
    tight = min(env.viaducts, key=lambda v: v.radius_m)
    assert tight.radius_m == pytest.approx(100.0)
    return [p for p in env.parts if p.viaduct == tight.index and p.kind is PartKind.GIRDER]


def cracks_of(env: Environment, part: Part, seed: int) -> CrackNetwork:
    d = env.config.design
    rng = make_rng(seed, 0, Stream.CRACKS)
    drift = column_demand(CFG, SEVERITIES[seed % 3], rng).drift
    sweep = girder_sweep(env, part)
    return girder_cracks(CFG, sweep, girder_spans(sweep, d.crossbeam_width_m),
                         d.girder_width_m, d.girder_depth_m, drift, rng)


_CENTRE_LINES: dict[int, tuple] = {}


def _coarse_centre_line(trajectory) -> tuple[np.ndarray, cKDTree]:
    """Arc lengths every 15 cm along ``trajectory`` and a k-d tree of its centre there in
    plan, found once per trajectory (kept beside it, so that its id stays its own)."""
    if id(trajectory) not in _CENTRE_LINES:
        grid = np.linspace(0, trajectory.centres_s[-1] + 30, 20001)[::10]
        centre = cKDTree(trajectory.frame(grid)[0][:, :2])
        _CENTRE_LINES[id(trajectory)] = (trajectory, grid, centre)
    return _CENTRE_LINES[id(trajectory)][1:]


def local(env: Environment, points: np.ndarray) -> tuple[np.ndarray, ...]:
    """Per point (n, 3): track arc length s, across offset a and height b below the deck top
    (the sweep's coordinates), and the track's unit tangent there."""
    traj = env.trajectory
    grid, centre = _coarse_centre_line(traj)
    s = grid[centre.query(points[:, :2])[1]]  # the nearest sample; a dense search took 5 s
    for _ in range(3):  # project onto the centre line: s += (p - P(s)) . t(s)
        p0, t, _ = traj.frame(s)
        s = s + np.sum((points - p0)[:, :2] * t[:, :2], 1)
    p0, t, n = traj.frame(s)
    return s, np.sum((points - p0) * n, 1), points[:, 2] - p0[:, 2], t


def test_girder_cracks_lie_on_the_curved_girder_in_their_bands_and_clear_spans():
    env = curved_env()
    d = env.config.design
    top, bottom = -d.slab_thickness_m, -d.slab_thickness_m - d.girder_depth_m
    angles, kinds, soffit_mid = [], [], 0
    for seed, part in enumerate(tightest_girders(env) * 3):
        net = cracks_of(env, part, seed)
        assert len(net.points) > 100
        ends = net.points.reshape(-1, 3)
        mids = net.points.mean(axis=1)
        assert surface_distance(part.mesh.triangles, ends).max() < 1e-4
        assert surface_distance(part.mesh.triangles, mids).max() < 1e-4
        s, a, b, t = local(env, mids)
        # Nothing on the top (under the slab) nor inside the cross beams over the rows.
        on_top = [np.abs(local(env, net.points[:, e])[2] - top) < 1e-4 for e in (0, 1)]
        assert not (on_top[0] & on_top[1]).any() and (on_top[0] | on_top[1]).any()
        rows = part.viaduct * d.length_m + np.array(d.column_rows_s)
        gap = np.abs(s[:, None] - rows[None]).min(1)
        # A rough crack near a joint runs along it (clipped there), and the curve stretches
        # the girder's outer side by up to 4 %.
        assert gap.min() >= d.crossbeam_width_m / 2 * 0.96 and s.min() > rows[0]
        assert s.max() < rows[-1]
        # Length-weighted angle of each crack from the section's plane (across the track).
        seg = net.points[:, 1] - net.points[:, 0]
        off = np.degrees(np.arcsin(np.clip(np.abs(np.sum(seg * t, 1)) / net.lengths_m, 0, 1)))
        length = np.bincount(net.crack, net.lengths_m, len(net.kinds))
        angles.append(np.bincount(net.crack, off * net.lengths_m, len(net.kinds)) / length)
        kinds += net.kinds
        # Gravity cracks across the soffit within 0.13 of the span of each span's middle.
        mid_s = (rows[:-1] + rows[1:]) / 2
        on_soffit = np.abs(b - bottom) < 5e-3
        soffit_mid += int((on_soffit & (np.abs(s[:, None] - mid_s).min(1) < 0.13 * 6)).sum())
    angles = np.concatenate(angles)
    shear = np.array([k == "shear" for k in kinds])
    inside = np.where(shear, (angles >= SHEAR_BAND_DEG[0]) & (angles <= SHEAR_BAND_DEG[1]),
                      angles <= FLEXURAL_BAND_DEG)
    assert inside.mean() >= 0.9 and len(angles) > 100
    assert soffit_mid > 50


def test_girder_spans_run_between_the_cross_beams_faces():
    env = curved_env()
    d = env.config.design
    for part in tightest_girders(env):
        spans = girder_spans(girder_sweep(env, part), d.crossbeam_width_m)
        assert len(spans) == d.n_spans
        lengths = np.array([g1 - g0 for g0, g1 in spans])
        # Along the girder's centre line, u = +-3 m left of the track's, whose heading turns
        # by k 6 m over a span: (1 - k u) x 6 m, less a cross beam's width; a grade of up to
        # 2 % lengthens it by up to 1.2 mm.
        rows = part.viaduct * d.length_m + np.array(d.column_rows_s)
        turn = np.diff(env.trajectory.heading(rows))
        u = (1 if part.name.endswith("l") else -1) * d.column_spacing_m / 2
        assert np.abs(turn).min() == pytest.approx(6.0 / 100, rel=1e-6)
        assert lengths == pytest.approx(6.0 - turn * u - d.crossbeam_width_m, abs=1.5e-3)


def test_a_rendered_girder_shows_crack_labels_where_the_network_is():
    """From 1.5 m under the soffit at mid-span, looking up: every pixel labelled concrete
    damage lies within 1.5 px of the projected network, and the network's soffit points in
    view fall on labelled pixels."""
    env = curved_env()
    part = tightest_girders(env)[0]
    net = dataclasses.replace(cracks_of(env, part, 2), rough=False)  # the placement alone
    d = env.config.design
    rows = part.viaduct * d.length_m + np.array(d.column_rows_s)
    s_mid = (rows[1] + rows[2]) / 2
    p0, t, n = (x[0] for x in env.trajectory.frame(np.array([s_mid])))
    target = p0 + d.column_spacing_m / 2 * n + (-d.slab_thickness_m - d.girder_depth_m) * \
        np.array([0, 0, 1.0])
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 2] = t, [0, 0, -1.0]
    pose[:3, 1] = np.cross(pose[:3, 2], pose[:3, 0])
    pose[:3, 3] = target - [0, 0, 1.5]
    w, h = 160, 120
    cam = camera(w, h, pose=pose)
    with Renderer(render_config(w, h)) as r:
        r.load(scene_of((part.name, Component.BEAM, part.mesh,
                         Material(base_color=(0.4, 0.4, 0.4, 1.0), cracks=net))), LIGHT)
        out = r.render(cam)
    labelled = out.damage == Damage.CONCRETE
    assert labelled.sum() > 50
    # Dense points along the segments, projected.
    u = np.linspace(0, 1, 33)[:, None, None]
    pts = (net.points[:, 0] + u * (net.points[:, 1] - net.points[:, 0])).reshape(-1, 3)
    view = (pts - pose[:3, 3]) @ pose[:3, :3]
    depth = -view[:, 2]
    k = cam.K
    x = k[0, 0] * view[:, 0] / depth + k[0, 2]
    y = -k[1, 1] * view[:, 1] / depth + k[1, 2]
    shown = (depth > 0) & (x > 1) & (x < w - 2) & (y > 1) & (y < h - 2)
    px = np.stack([np.round(y[shown]), np.round(x[shown])], 1).astype(int)
    facing = np.abs(out.depth[px[:, 0], px[:, 1]] - depth[shown]) < 0.01  # the soffit's
    assert facing.sum() > 200
    hit = labelled[px[facing, 0], px[facing, 1]]
    assert hit.mean() >= 0.95
    yy, xx = np.nonzero(labelled)
    near = np.min(np.hypot(yy[:, None] - y[shown][None], xx[:, None] - x[shown][None]), 1)
    assert near.max() <= 1.5
    widths = out.crack_width[labelled]  # closing to 0 at the tips
    assert widths.min() >= 0 and widths.max() <= CFG.crack_width_mm[1] + 1e-6
