"""Rough cracks (issue 39; docs/design.md, "Crack paths"): the self-affine centreline in the
generators and, below the polyline's vertices, in the shader, measured back from rendered
labels; widths closing at the tips; the width ground truth on rough cracks."""

import dataclasses

import numpy as np
import pytest
from glhelpers import LIGHT, camera, quad, render_config, scene_of

from glsynth.appearance import crack_paths
from glsynth.appearance.cracks import CrackNetwork, column_cracks, column_demand
from glsynth.appearance.materials import Material
from glsynth.assess.cracks import Intrinsics, error_summary, measure_cracks, width_errors
from glsynth.core.config import DamageConfig
from glsynth.core.labels import Component, Damage
from glsynth.core.seeding import Stream, make_rng
from glsynth.data.visible_cracks import near_crack, on_surface
from glsynth.render.gl.renderer import Renderer
from glsynth.world.environment import Part, PartKind
from glsynth.world.meshes import box

W, H = 960, 540
FOCAL_MM = 360.0  # fx = 10 W: 0.104 mm pixels on a plane 1 m away
MM_PER_PX = 1e3 / (10 * W)
ROWS_M = (-0.013, 0.013)
"""The rows of cracks across the view, 26 mm apart (a 48 mm segment's path strays up to
about 10 mm)."""
BAND_PX = 120
SEGMENT_M = 0.048
GREY = (0.25, 0.25, 0.25, 1.0)


def fit_hurst(traces: list[np.ndarray], lags: np.ndarray) -> float:
    """H of S(lag) ~ lag^(2H), S the mean squared difference over all traces."""
    s = [np.mean(np.concatenate([(t[lag:] - t[:-lag]) ** 2 for t in traces])) for lag in lags]
    return float(np.polyfit(np.log(lags), np.log(s), 1)[0] / 2)


def test_the_generators_paths_have_the_coarse_exponent_above_the_aggregate():
    """Offsets of 2 m cracks at 5 cm steps, 400 of them: S(x) ~ x^(2 H_coarse) from 5 cm to
    50 cm, and scaled as (A xi)^2 (x / xi)^(2H)."""
    c = crack_paths.SHADER_CONSTANTS
    rng = make_rng(39, 0, Stream.CRACKS)
    traces = [crack_paths.lateral_offsets(2.56, 9, rng) for _ in range(400)]  # 5 mm steps
    step = 2.56 / 2 ** 9
    lags = np.array([10, 20, 40, 80])  # 5-40 cm: the middle of the crack's scales
    assert fit_hurst(traces, lags) == pytest.approx(c["CRACK_HURST_COARSE"], abs=0.07)
    s = np.mean(np.concatenate([(t[20:] - t[:-20]) ** 2 for t in traces]))
    assert s == pytest.approx(float(crack_paths.structure(20 * step)), rel=0.25)


def rough_network(width_m: float, seed: int) -> CrackNetwork:
    """Two 48 mm segments per row of ROWS_M across a plane 1 m away, widths that differ in
    their last bits from segment to segment (they seed the shader's paths)."""
    rng = make_rng(seed, 0, Stream.CRACKS)
    points, widths = [], []
    for y in ROWS_M:
        for x0 in (-SEGMENT_M, 0.0):
            points.append([[x0, y, -1.0], [x0 + SEGMENT_M, y, -1.0]])
            widths.append(width_m * (1 + rng.uniform(0, 1e-3, 2)))
    n = len(points)
    return CrackNetwork(np.array(points), np.array(widths), np.arange(n, dtype=np.int32),
                        ("flexural",) * n, rough=True)


@pytest.fixture(scope="module")
def rough_renders():
    """Six renders of rough cracks 0.5 mm (4.8 px) wide on a plane 1 m away."""
    cam = camera(W, H, FOCAL_MM)
    plate = quad([[-0.1, -0.06, -1.0], [0.1, -0.06, -1.0], [0.1, 0.06, -1.0],
                  [-0.1, 0.06, -1.0]])
    outs = []
    with Renderer(render_config(W, H)) as r:
        for seed in range(6):
            net = rough_network(5e-4, seed)
            r.load(scene_of(("part", Component.COLUMN, plate,
                             Material(base_color=GREY, cracks=net))), LIGHT)
            outs.append(r.render(cam))
        assert r.ctx.error == "GL_NO_ERROR"
    return cam, outs


def centrelines(damage: np.ndarray) -> list[np.ndarray]:
    """Per row of cracks and per segment, the labelled band's middle row in each column."""
    traces = []
    for y in ROWS_M:
        centre = (H - 1) / 2 - y / MM_PER_PX * 1e3
        band = slice(int(centre - BAND_PX), int(centre + BAND_PX))
        labelled = damage[band] == Damage.CONCRETE
        rows = np.arange(band.start, band.stop)[:, None]
        top = np.where(labelled, rows, H).min(0)
        bottom = np.where(labelled, rows, -1).max(0)
        edge = 25  # the segments span 96 mm of the view's 100 mm
        assert (bottom >= top)[edge:W - edge].all()  # every column crosses the crack
        middle = (top + bottom) / 2.0
        half = W // 2
        traces += [middle[edge:half - 4], middle[half + 4:W - edge]]
    return traces


def test_rendered_paths_have_the_fine_exponent_below_the_aggregate(rough_renders):
    """The rendered labels' centreline, 0.1 mm pixels: S(x) ~ x^(2 H_fine) from 0.4 to 4 mm,
    the scales the shader draws below the vertices; the path strays by millimetres."""
    _, outs = rough_renders
    traces = [t for out in outs for t in centrelines(out.damage)]
    hurst = fit_hurst(traces, np.array([4, 8, 16, 32]))
    assert hurst == pytest.approx(crack_paths.SHADER_CONSTANTS["CRACK_HURST_FINE"], abs=0.1)
    spread = np.std(np.concatenate([t - t.mean() for t in traces])) * MM_PER_PX
    assert 0.5 < spread < 10.0


def test_rough_cracks_widths_are_measured_back_within_10_percent(rough_renders):
    """The width map stays exact on rough cracks: measured back from labels and depth, the
    median error on skeleton pixels of cracks >= 4 px wide is at most 10 %."""
    cam, outs = rough_renders
    k = cam.K
    intrinsics = Intrinsics(k[0, 0], k[1, 1], k[0, 2], k[1, 2])
    errors = []
    for out in outs:
        truth = out.crack_width
        labelled = out.damage == Damage.CONCRETE
        assert np.abs(truth[labelled] / 0.5 - 1).max() < 2e-3 and not truth[~labelled].any()
        errors.append(width_errors(measure_cracks(out.damage, out.depth, intrinsics), truth))
    summary = error_summary(errors)
    assert summary["at_least_2px"]["pixels"] > 5000
    assert summary["at_least_2px"]["median_relative_error"] <= 0.10


def test_widths_fluctuate_and_close_to_zero_at_every_tip():
    """Generated networks: at every free end of a crack (a vertex of one segment) the width
    is 0; along cracks the width fluctuates round the mechanics' (log-normal)."""
    cfg = DamageConfig()
    ratios = []
    for seed in range(6):
        rng = make_rng(seed, 0, Stream.CRACKS)
        net = column_cracks(cfg, (0.7, 0.8), [(-2.5, 2.5)], column_demand(cfg, "severe", rng),
                            rng)
        ends = net.points.reshape(-1, 3).round(9)
        _, inverse, counts = np.unique(ends, axis=0, return_inverse=True, return_counts=True)
        free = counts[inverse.ravel()] == 1
        assert free.sum() >= 2 * len(net.kinds)
        assert np.all(net.widths_m.ravel()[free] == 0.0)
        inner = net.widths_m.ravel()[~free]
        assert inner.min() >= 0 and (inner > 0).mean() > 0.95
        for k in range(len(net.kinds)):
            w = net.widths_m[net.crack == k, 0]
            w = w[w > np.median(w) / 4]
            ratios.append(np.std(np.log(w)))
    assert 0.15 < np.median(ratios) < 0.6


@pytest.fixture(scope="module")
def column_renders():
    """A generated column's cracks seen from 0.5 m (0.8 mm pixels), 640x360: the network, the
    column's mesh, the camera, and the renders of the cracks as straight segments (False)
    and along their rough paths (True)."""
    cfg = DamageConfig()
    rng = make_rng(3, 0, Stream.CRACKS)
    net = column_cracks(cfg, (0.7, 0.8), [(-2.5, 2.5)], column_demand(cfg, "severe", rng), rng)
    column = box((0.7, 0.8, 5.0))
    pose = np.eye(4)
    pose[:3, :3] = [[0, 0, 1], [1, 0, 0], [0, 1, 0]]  # looking down -x at face x = +0.35
    pose[:3, 3] = [0.85, 0.0, -2.0]
    cam = camera(640, 360, 36.0, pose)
    outs = {}
    with Renderer(render_config(640, 360)) as r:
        for rough in (False, True):
            r.load(scene_of(("part", Component.COLUMN, column,
                             Material(base_color=GREY,
                                      cracks=dataclasses.replace(net, rough=rough)))), LIGHT)
            outs[rough] = r.render(cam)
    return net, column, cam, outs


def test_rough_cracks_label_more_of_a_crack_aimed_view_than_straight_ones(column_renders):
    """The rough paths cover more pixels than the same cracks as straight segments, and every
    crack pixel has a width."""
    *_, outs = column_renders
    shares = []
    for rough in (False, True):
        labelled = outs[rough].damage == Damage.CONCRETE
        assert labelled.any() and (outs[rough].crack_width[labelled] >= 0).all()
        shares.append(labelled.mean())
    assert shares[1] > 1.05 * shares[0]


def test_the_crack_lists_samples_follow_the_rough_paths_onto_their_labels(column_renders):
    """The meta JSON's crack list (glsynth.data.visible_cracks) samples each crack's path: on
    the rough render, at least 97 % of the chord length whose samples land on the visible
    surface has labels within a pixel, as on straight cracks; samples taken along the chords
    instead find labels for less than 85 % of it (the paths stray by millimetres, several
    pixels)."""
    net, column, cam, outs = column_renders
    out = outs[True]
    near = near_crack(out.crack_width)
    part = Part("column", PartKind.COLUMN, None, column, np.eye(4))

    def labelled_share(sampled: CrackNetwork) -> float:
        row, col, _, weight, on = on_surface(sampled, part, cam, out.depth)
        found = on.copy()
        found[on] = near[row[on], col[on]]
        return float(weight[found].sum() / weight[on].sum())

    assert labelled_share(net) >= 0.97
    assert labelled_share(dataclasses.replace(net, rough=False)) < 0.85


def _numpy_scalars(x: float) -> float:
    """structure(x) as the generators computed it before the float path: arithmetic on 0-d
    arrays gives numpy scalars, and their power is the C library's pow on any machine."""
    c = crack_paths.SHADER_CONSTANTS
    xi = c["CRACK_AGGREGATE_M"]
    hurst = c["CRACK_HURST_FINE"] if x < xi else c["CRACK_HURST_COARSE"]
    return float((c["CRACK_ROUGHNESS"] * xi) ** 2
                 * (np.float64(x) / xi) ** np.float64(2 * hurst))


def test_one_length_keeps_the_bits_the_generators_had():
    """Every crack an inspection or demo opening draws comes from path(), one length at a
    time; a rounding change there changes rendered images, and no byte test at the paper
    preset sees it. The float path against numpy scalars (np.power's vectorised loop in its
    place moved 43 of 600 cracks' offsets in the last bit) and against a 0-d array, both
    roughness regimes and the halvings' lengths included."""
    rng = make_rng(0, 0, Stream.CRACKS)
    lengths = np.concatenate([rng.uniform(1e-5, 3.0, 5000), rng.uniform(0.01, 0.03, 5000),
                              0.016 * 2.0 ** -np.arange(20), [0.016, 0.0]])
    for x in map(float, lengths):
        assert crack_paths.structure(x) == _numpy_scalars(x), x
        for f in (crack_paths.structure, crack_paths.midpoint_sd):
            fast, numpy = f(x), f(np.asarray(x))
            assert isinstance(fast, float) and fast == float(numpy), (f.__name__, x)
