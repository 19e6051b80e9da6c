"""En-echelon cracks and what leaching cracks leave on the concrete (issue 39, item 1;
docs/design.md, "Cracks" and "Damage by mechanics"): the pieces' steps and overlaps as
promised, widths measured back on rendered en-echelon cracks, and on real inspection renders
efflorescence whitening and rust reddening the face below a crack, a damp band darkening it
beside the crack, and the labels, widths and depth identical with the leachate or without."""

import dataclasses

import numpy as np
import pytest
from glhelpers import LIGHT, camera, half_inspection, quad, render_config, scene_of

from glsynth.appearance import crack_leachate, crack_paths
from glsynth.appearance import cracks as cracks_module
from glsynth.appearance.crack_leachate import EFFLORESCENCE, NONE, RUST, with_leachate
from glsynth.appearance.cracks import (
    ECHELON_OFFSET_M,
    ECHELON_OVERLAP_M,
    STEP_M,
    CrackNetwork,
    _echelon,
    column_cracks,
    column_demand,
)
from glsynth.appearance.materials import Material
from glsynth.assess.cracks import Intrinsics, measure_cracks, width_errors
from glsynth.core.config import DamageConfig
from glsynth.core.labels import Component, Damage
from glsynth.core.seeding import Stream, make_rng
from glsynth.render.cracks_index import pack_cracks
from glsynth.render.gl.renderer import Renderer
from glsynth.render.leachate_index import pack_leachate
from glsynth.render.view import EnvironmentView

LUMA = np.array([0.299, 0.587, 0.114])


def straight_line(length_m: float, width_m: float, seed: int, rough: bool = True):
    """A horizontal crack's (s, z, w), rough from crack_paths or straight, of constant width but
    at its tips."""
    rng = make_rng(seed, 0, Stream.CRACKS)
    s, z, arc = crack_paths.path(-length_m / 2, length_m / 2, 0.0, 0.0, STEP_M, rng)
    if not rough:
        s, z = arc - length_m / 2, np.zeros(len(s))
    w = np.full(len(s), width_m)
    w[[0, -1]] = 0.0
    return s, z, w


def test_en_echelon_pieces_step_and_overlap_as_promised():
    """Over 200 straight cracks (so that s is the distance along them): consecutive pieces
    overlap by ECHELON_OVERLAP_M along the crack and
    are stepped ECHELON_OFFSET_M across it, every step of a crack in one sense; the pieces
    close to a tip at each step."""
    overlaps, steps = [], []
    for seed in range(200):
        line = straight_line(0.6, 1e-3, seed, rough=False)
        pieces = _echelon(line, make_rng(seed, 1, Stream.CRACKS))
        trunk = [p for p in pieces if len(p[0]) > 2]  # bridges are two points
        assert 2 <= len(trunk) <= 4
        senses = set()
        for a, b in zip(trunk[:-1], trunk[1:]):
            overlaps.append(a[0][-1] - b[0][0])
            lo, hi = b[0][0], a[0][-1]
            at = np.linspace(lo, hi, 5)
            step = np.interp(at, b[0], b[1]) - np.interp(at, a[0], a[1])
            assert np.ptp(step) < 1e-9  # a piece is the line moved, not bent
            steps.append(abs(step[0]))
            senses.add(np.sign(step[0]))
            assert a[2][-1] == 0.0 and b[2][0] == 0.0  # each closes at the step
        assert len(senses) == 1
    assert ECHELON_OVERLAP_M[0] - 1e-9 <= min(overlaps) and max(overlaps) <= \
        ECHELON_OVERLAP_M[1] + 1e-9
    assert ECHELON_OFFSET_M[0] - 1e-9 <= min(steps) and max(steps) <= ECHELON_OFFSET_M[1] + 1e-9
    assert np.median(steps) == pytest.approx(np.sqrt(np.prod(ECHELON_OFFSET_M)), rel=0.3)


def pieces_per_crack(net: CrackNetwork) -> np.ndarray:
    """(K,) how many connected pieces each crack's segments form (joined at shared ends)."""
    keys = np.rint(net.points.reshape(-1, 3) * 1e6).astype(np.int64)
    _, node = np.unique(keys, axis=0, return_inverse=True)
    node = node.ravel().reshape(-1, 2)
    parent = np.arange(node.max() + 1)

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for a, b in node:
        parent[root(a)] = root(b)
    return np.array([len({root(a) for a in node[net.crack == k, 0]})
                     for k in range(len(net.kinds))])


def test_generated_cracks_run_en_echelon_where_drawn_and_stay_whole_otherwise(monkeypatch):
    """Pieces counted as the crack's connected parts: no bridge, so that each piece counts;
    forks join their trunk, so a crack that does not run en echelon is one part."""
    monkeypatch.setattr(cracks_module, "ECHELON_BRIDGE", 0.0)

    def cracks(echelon: float, seed: int) -> CrackNetwork:
        cfg = DamageConfig(model="mechanics", echelon_probability=echelon)
        rng = make_rng(seed, 0, Stream.CRACKS)
        return column_cracks(cfg, (0.7, 0.8), [(-2.5, 2.5)], column_demand(cfg, "severe", rng),
                             rng)

    whole = np.concatenate([pieces_per_crack(cracks(0.0, s)) for s in range(10)])
    stepped = np.concatenate([pieces_per_crack(cracks(1.0, s)) for s in range(10)])
    assert len(whole) > 100 and np.all(whole == 1)
    assert np.mean(stepped >= 2) > 0.8  # all but the shortest cracks
    default = np.concatenate([pieces_per_crack(cracks(0.3, s)) for s in range(10)])
    assert 0.15 < np.mean(default >= 2) < 0.45


def test_rendered_en_echelon_cracks_label_both_pieces_and_measure_back():
    """A 2 mm en-echelon crack on a plane 1 m away at 0.42 mm pixels: the labels show two
    pieces side by side where they overlap, the width map is the crack's width on every
    labelled pixel, and widths measured back from labels and depth are within 10 % (median,
    pixels >= 4 px wide)."""
    w, h, focal_mm = 960, 540, 86.4  # fx = 2304 px
    cam = camera(w, h, focal_mm)
    plate = quad([[-0.3, -0.15, -1.0], [0.3, -0.15, -1.0], [0.3, 0.15, -1.0],
                  [-0.3, 0.15, -1.0]])
    k = cam.K
    intrinsics = Intrinsics(k[0, 0], k[1, 1], k[0, 2], k[1, 2])
    errors, stacked = [], 0
    with Renderer(render_config(w, h)) as r:
        for seed in range(3):
            lines = _echelon(straight_line(0.36, 2e-3, seed), make_rng(seed, 2, Stream.CRACKS))
            points, widths = [], []
            for s, z, wid in lines:
                for i in range(len(s) - 1):
                    points.append([[s[i], z[i], -1.0], [s[i + 1], z[i + 1], -1.0]])
                    widths.append([wid[i], wid[i + 1]])
            keep = np.max(widths, axis=1) > 0
            net = CrackNetwork(np.array(points)[keep], np.array(widths)[keep],
                               np.zeros(int(keep.sum()), np.int32), ("flexural",), rough=True)
            r.load(scene_of(("part", Component.COLUMN, plate,
                             Material(base_color=(0.25, 0.25, 0.25, 1.0), cracks=net))), LIGHT)
            out = r.render(cam)
            labelled = out.damage == Damage.CONCRETE
            assert np.all(out.crack_width[labelled] > 0) and not out.crack_width[~labelled].any()
            runs = np.diff(labelled.astype(np.int8), axis=0).clip(0, 1).sum(0)
            stacked += int((runs >= 2).sum())  # columns crossing two pieces
            errors.append(width_errors(measure_cracks(out.damage, out.depth, intrinsics),
                                       out.crack_width))
    assert stacked > 30
    px = np.concatenate([e["truth_px"] for e in errors])
    rel = np.abs(np.concatenate([e["error_mm"] for e in errors])) / np.concatenate(
        [e["truth_mm"] for e in errors])
    assert (px >= 4).sum() > 1000
    assert np.median(rel[px >= 4]) <= 0.10


def test_leachate_draws_are_nested_and_rust_favours_wide_cracks():
    rng = make_rng(0, 0, Stream.CRACKS)
    net = column_cracks(DamageConfig(model="mechanics"), (0.7, 0.8), [(-2.5, 2.5)],
                        column_demand(DamageConfig(model="mechanics"), "severe", rng), rng)
    table = {share: with_leachate(net, share, make_rng(0, 0, Stream.LEACHATE)).leachate
             for share in (0.0, 0.3, 1.0)}
    assert np.all(table[0.0][:, 0] == NONE) and np.all(table[1.0][:, 0] != NONE)
    some = table[0.3][:, 0] != NONE
    assert 0 < some.sum() < len(some)
    assert np.array_equal(table[0.3][some], table[1.0][some])  # the same cracks, the same way
    lo, hi = crack_leachate.STREAK_M
    assert np.all((table[1.0][:, 2] >= lo) & (table[1.0][:, 2] <= hi))
    kinds, widest = [], []
    for seed in range(300):
        one = dataclasses.replace(net, widths_m=net.widths_m * 0.01 * 100 ** (seed / 300))
        t = with_leachate(one, 1.0, make_rng(seed, 0, Stream.LEACHATE)).leachate
        kinds.append(t[:, 0])
        per_crack = np.zeros(len(t))
        np.maximum.at(per_crack, one.crack, one.widths_m.max(axis=1))
        widest.append(per_crack)
    kinds, widest = np.concatenate(kinds), np.concatenate(widest)
    narrow, wide = widest < 0.2e-3, widest > 1e-3
    assert np.mean(kinds[wide] == RUST) > np.mean(kinds[narrow] == RUST) + 0.3
    assert set(np.unique(kinds)) == {EFFLORESCENCE, RUST}


def test_every_point_a_run_reaches_reads_its_segment():
    """pack_leachate's cells: points below a leaching segment, as far as its run goes, and
    beside it within its damp band, list it in their cell."""
    rng = make_rng(3, 0, Stream.CRACKS)
    cfg = DamageConfig(model="mechanics")
    net = with_leachate(column_cracks(cfg, (0.7, 0.8), [(-2.5, 2.5)],
                                      column_demand(cfg, "severe", rng), rng), 1.0,
                        make_rng(3, 0, Stream.LEACHATE))
    index = pack_cracks(net)
    leach = pack_leachate(net, index.origin)
    assert pack_leachate(dataclasses.replace(net, leachate=None), index.origin) is None
    cells = leach.cells.reshape(-1, 2)
    entries = leach.entries.ravel()
    table = net.leachate[net.crack]
    for i in make_rng(3, 1, Stream.CRACKS).choice(len(net.points), 60, replace=False):
        a, b = net.points[i] - index.origin.astype(np.float64)
        mid = (a + b) / 2
        for p in (mid - [0, 0, 0.98 * table[i, 2]], mid + [0, 0, 0.9 * table[i, 3]], a, b):
            c = np.floor((p - leach.origin) / leach.cell_m).astype(int)
            assert np.all(c >= 0) and np.all(c < leach.dims)
            first, count = cells[c[0] + leach.dims[0] * (c[1] + leach.dims[1] * c[2])]
            assert i in entries[first:first + count]


@pytest.fixture(scope="module")
def leaching_views():
    """Inspection seed 11, environment 0, camera 5 (a column's face, a 1 mm crack across it,
    0.12 mm pixels at half the preset's size): without leachate, and with every crack
    leaching efflorescence only, rust only, and only damp (no deposit)."""
    outputs = {}
    # MSAA off and small sky maps (half_inspection): shading the four views share, not what
    # the leachate adds (the two took a fifth of the openings' CPU).
    base = half_inspection(small_sky=True)
    settings = {"off": (0.0, None, None), "white": (1.0, (0.0, 0.0), None),
                "rust": (1.0, (1.0, 1.0), None), "damp": (1.0, None, (0.0, 0.0))}
    # Culled for camera 5 alone (rendering=[5]: the same bytes, tests/test_render_viaduct.py),
    # on one renderer: an opening of every camera's parts took 12 CPU-s, four of them the file.
    with Renderer(base.render) as renderer:
        for name, (share, rust, strength) in settings.items():
            with pytest.MonkeyPatch.context() as mp:
                if rust is not None:
                    mp.setattr(crack_leachate, "RUST_SHARE", rust)
                if strength is not None:
                    mp.setattr(crack_leachate, "STRENGTH", strength)
                cfg = dataclasses.replace(base, damage=dataclasses.replace(
                    base.damage, leachate_share=share))
                view = EnvironmentView.open(cfg, 11, 0, renderer, rendering=[5])
                outputs[name] = view.render(5, frozenset({"color", "damage", "depth"}),
                                            photo=False)[1]
    return outputs


def rows_from_crack(output) -> np.ndarray:
    """(H, W) signed rows from the labelled crack in each column (positive below it), NaN in
    columns it does not cross."""
    crack = output.crack_width > 0
    rows = np.arange(crack.shape[0])[:, None].astype(float)
    top = np.where(crack, rows, np.inf).min(0)
    bottom = np.where(crack, rows, -np.inf).max(0)
    below = np.where(rows > bottom, rows - bottom, np.where(rows < top, rows - top, 0.0))
    return np.where(np.isfinite(top)[None, :], below, np.nan)


def test_labels_widths_and_depth_are_the_same_with_leachate_or_without(leaching_views):
    off = leaching_views["off"]
    assert (off.crack_width > 0).sum() > 1000
    for name in ("white", "rust", "damp"):
        other = leaching_views[name]
        for field in ("damage", "component", "crack_width", "depth"):
            assert np.array_equal(getattr(other, field), getattr(off, field)), (name, field)
        assert not np.array_equal(other.color, off.color)


def test_efflorescence_whitens_and_rust_reddens_the_face_below_the_crack(leaching_views):
    """Against the same view without leachate: the face 60-200 px (7-24 mm) below the crack
    gains more light under efflorescence, and more red over blue under rust,
    than the face as far above it, where nothing runs."""
    off = leaching_views["off"]
    rows = rows_from_crack(off)
    below = (rows >= 60) & (rows <= 200)
    above = (rows <= -60) & (rows >= -200)
    assert below.sum() > 12_500 and above.sum() > 12_500
    base = off.color.astype(float)
    white = leaching_views["white"].color.astype(float) @ LUMA - base @ LUMA
    assert white[below].mean() > 4.0 and white[below].mean() > white[above].mean() + 3.0
    rust = leaching_views["rust"].color.astype(float)
    redness = (rust[..., 0] - rust[..., 2]) - (base[..., 0] - base[..., 2])
    assert redness[below].mean() > 2.0 and redness[below].mean() > redness[above].mean() + 1.5


def test_the_damp_band_darkens_the_face_beside_the_crack(leaching_views):
    """Damp only: darker next to the crack on both sides, and the darkening fades away from
    it; never lighter anywhere."""
    off = leaching_views["off"]
    rows = rows_from_crack(off)
    dark = leaching_views["damp"].color.astype(float) @ LUMA - off.color.astype(float) @ LUMA
    near = np.abs(rows) <= 15
    far = np.abs(rows) >= 250
    assert dark[near & (rows != 0)].mean() < -3.0
    assert dark[far].mean() > 0.5 * dark[near & (rows != 0)].mean()
    assert dark.max() <= 1.0  # 8-bit rounding only
