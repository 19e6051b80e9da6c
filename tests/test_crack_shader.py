"""Shader unit tests: the GLSL crack functions (shaders/cracks.glsl) run alone over grids of
inputs through tests/shader_harness.py and match numpy references of the same functions within
float32 tolerance."""

import numpy as np
import pytest
from shader_harness import GlslHarness

from glsynth.appearance import crack_paths
from glsynth.appearance.cracks import CrackNetwork
from glsynth.core.geometry import segment_distance
from glsynth.core.seeding import Stream, make_rng
from glsynth.render.cracks_index import (
    ROUGH_FOOTPRINT_M,
    ROW,
    batches,
    box_cells,
    crack_contrast,
    pack_cracks,
)
from glsynth.render.gl.renderer import upload_cracks

EPS = float(np.finfo(np.float32).eps)
REACH = crack_paths.SHADER_CONSTANTS["CRACK_REACH_M"]


@pytest.fixture(scope="module")
def glsl():
    with GlslHarness("cracks.glsl") as harness:
        yield harness


def _rows(*columns: np.ndarray) -> np.ndarray:
    """Columns (n,) or (n, k) side by side, padded with zeros to (n, 4) float32."""
    out = np.hstack([np.asarray(c, np.float64).reshape(len(c), -1) for c in columns])
    return np.pad(out, ((0, 0), (0, 4 - out.shape[1]))).astype(np.float32)


def band_coverage(d, w, f):
    return np.clip((np.minimum(d + f / 2, w / 2) - np.maximum(d - f / 2, -w / 2)) / f, 0, 1)


def footprint_across(dpdx, dpdy, along):
    """The pixel's extent across the crack; where the crack runs along the normal, the
    footprint's larger extent."""
    across = np.cross(np.cross(dpdx, dpdy), along)
    size = np.linalg.norm(across, axis=-1, keepdims=True)
    u = across / np.where(size > 0, size, 1.0)
    extent = [np.linalg.norm(v, axis=-1) for v in (dpdx, dpdy, along)]
    degenerate = size[..., 0] <= 1e-3 * extent[0] * extent[1] * extent[2]
    return np.where(degenerate, extent[0] + extent[1],
                    np.abs(np.sum(dpdx * u, -1)) + np.abs(np.sum(dpdy * u, -1)))


def test_segment_distance_and_parameter_match_numpy(glsl):
    rng = make_rng(1, 0, Stream.DAMAGE)
    n = 4096
    a = rng.uniform(-3, 3, (n, 3))
    b = a + rng.normal(size=(n, 3)) * rng.uniform(0.01, 1.0, (n, 1))
    b[:64] = a[:64]  # degenerate segments: the distance to the point
    p = a + rng.uniform(-0.5, 1.5, (n, 1)) * (b - a) + rng.normal(0, 0.05, (n, 3))
    a, b, p = (x.astype(np.float32).astype(np.float64) for x in (a, b, p))
    out = glsl.run("distance(in0.xyz, in1.xyz + (in2.xyz - in1.xyz) * "
                   "segment_param(in0.xyz, in1.xyz, in2.xyz)), "
                   "segment_param(in0.xyz, in1.xyz, in2.xyz), 0.0, 0.0",
                   _rows(p), _rows(a), _rows(b))
    d, t = segment_distance(p, a, b)
    # float32 coordinates of up to 4.5 m: a few of their ulps (0.5 um each).
    assert np.abs(out[:, 0] - d).max() <= 8 * 4.5 * EPS
    length = np.linalg.norm(b - a, axis=1)
    assert np.all(np.abs(out[:, 1] - t) * length <= 8 * 4.5 * EPS)
    assert np.all(out[:64, 1] == 0)
    assert ((t == 0) | (t == 1)).sum() > 1000 and ((t > 0) & (t < 1)).sum() > 1000


def test_crack_texel_finds_every_entry_of_rows_of_ROW_texels(glsl):
    # The shader masks and shifts by CRACK_ROW_BITS: entries past the first rows (a network's
    # later segments and cells) must land where cracks_index._rows put them.
    index = np.concatenate([np.arange(3 * ROW + 5), [ROW * 1000 - 1, ROW * 1000]])
    out = glsl.run("vec2(crack_texel(int(in0.x))), 0.0, 0.0", _rows(index))
    assert np.array_equal(out[:, :2], np.stack([index % ROW, index // ROW], 1))


def test_width_is_linear_along_the_segment_and_exact_where_the_ends_agree(glsl):
    rng = make_rng(2, 0, Stream.DAMAGE)
    w0, w1, t = rng.uniform(0.05, 5.0, 2048), rng.uniform(0.05, 5.0, 2048), rng.uniform(0, 1, 2048)
    w1[:512] = w0[:512]
    rows = _rows(w0, w1, t)
    out = glsl.run("crack_width_at(in0.x, in0.y, in0.z), 0.0, 0.0, 0.0", rows)[:, 0]
    w0, w1, t = (rows[:, k].astype(np.float64) for k in range(3))
    assert np.abs(out - (w0 + (w1 - w0) * t)).max() <= 4 * 5.0 * EPS
    assert np.array_equal(out[:512], rows[:512, 0])  # constant width: bit-exact


def test_band_coverage_matches_the_box_filter(glsl):
    d, w, f = (g.ravel() for g in np.meshgrid(np.linspace(0, 6, 61), np.geomspace(0.05, 5, 25),
                                              np.geomspace(0.01, 8, 25), indexing="ij"))
    rows = _rows(d, w, f)
    out = glsl.run("band_coverage(in0.x, in0.y, in0.z), 0.0, 0.0, 0.0", rows)[:, 0]
    d, w, f = (rows[:, k].astype(np.float64) for k in range(3))
    ref = band_coverage(d, w, f)
    assert np.all(np.abs(out - ref) <= 4 * EPS * (d + w + f) / f + 1e-7)
    assert out.min() == 0 and out.max() == 1
    # Across the crack, the coverage integrates to the width (the filter keeps the area).
    step = 0.001
    offsets = np.arange(-6, 6, step) + step / 2
    for width, footprint in ((0.1, 1.0), (2.0, 0.5), (0.05, 7.0)):
        rows = _rows(np.abs(offsets), np.full_like(offsets, width),
                     np.full_like(offsets, footprint))
        out = glsl.run("band_coverage(in0.x, in0.y, in0.z), 0.0, 0.0, 0.0", rows)[:, 0]
        assert out.sum() * step == pytest.approx(width, rel=1e-3)


def test_the_paths_offsets_match_their_numpy_twin(glsl):
    """crack_offset, seeded from a segment's end widths as crack_rough seeds it, against
    crack_paths.shader_offsets (which the meta JSON's crack lists follow): segments of 5 mm to
    0.3 m, footprints of 20 um to 5 cm (from every level of halving to none), everywhere along
    them. The piece it reports is the path's finest interval around t: as long as the length
    over 2^levels, its ends on the path, its slope theirs (flat where the clamp holds it)."""
    rng = make_rng(5, 0, Stream.DAMAGE)
    n = 8192
    t, length = rng.uniform(0, 1, n), rng.uniform(0.005, 0.3, n)
    widths_mm = rng.uniform(0.05, 5.0, (n, 2)).astype(np.float32)
    finest = np.exp(rng.uniform(np.log(2e-5), np.log(0.05), n))
    rows = _rows(t, length, widths_mm)
    out = glsl.run("crack_offset(in0.x, in0.y, crack_hash(floatBitsToUint(in0.z) ^ "
                   "crack_hash(floatBitsToUint(in0.w))), in1.x)", rows, _rows(finest))
    offset, slope, before, after = out.T.astype(np.float64)
    t, length, finest = (x.astype(np.float32).astype(np.float64) for x in (t, length, finest))
    seeds = crack_paths.segment_seeds(widths_mm.astype(np.float64) / 1000.0)
    ref = crack_paths.shader_offsets(t, length, seeds, finest)
    assert np.abs(offset - ref).max() <= 1e-7  # float32 sums of offsets of up to 30 mm
    assert np.std(ref) > 1e-3 and np.abs(ref).max() <= REACH
    levels = np.floor(np.log2(length / np.maximum(
        finest, length * 2.0 ** -crack_paths.SHADER_CONSTANTS["CRACK_LEVELS"])))
    piece = length * 2.0 ** -np.maximum(levels, 0)
    assert np.allclose(before + after, piece, rtol=1e-5, atol=1e-9)
    starts, ends = (crack_paths.shader_offsets(np.clip(x, 0, 1), length, seeds, finest)
                    for x in (t - before / length, t + after / length))
    free = np.abs(np.concatenate([starts, ends])).reshape(2, -1).max(0) < REACH
    # float32: t and the piece's ends to a few ulps, times slopes of up to about 16.
    assert np.abs(offset - slope * before - starts)[free].max() <= 2e-6
    assert np.abs(offset + slope * after - ends)[free].max() <= 2e-6
    assert np.abs(slope).max() > 1 and free.mean() > 0.99
    # At footprints of a segment's length or more, the path is its chord.
    assert np.array_equal(ref[finest >= length], np.zeros((finest >= length).sum()))


def test_chips_break_a_share_of_each_lip_inside_their_cells(glsl):
    """crack_chip_at at the coarse scale along 2,000 cells of a 1 mm crack, both lips: a chip
    in CRACK_CHIP_CHANCE of the cells, each lip on its own; none reaches past its cell; each
    CRACK_CHIP_MIN to CRACK_CHIP_MAX widths deep at its middle. The two scales together
    (crack_chip) are the deeper of the two."""
    c = crack_paths.SHADER_CONSTANTS
    w, cells, per = 1e-3, 2000, 32
    cell = c["CRACK_CHIP_CELL_WIDTHS"] * w + c["CRACK_CHIP_CELL_M"]
    u = np.tile(np.arange(cells * per) / per * cell, 2)  # each cell from its start
    side = np.repeat([0, 1], cells * per)
    rows = _rows(u, side, np.full(len(u), 4321), np.full(len(u), w))
    out = glsl.run("crack_chip_at(in0.x, uint(in0.y), uint(in0.z), in0.w, 1.0, "
                   "CRACK_CHIP_CHANCE), crack_chip(in0.x, uint(in0.y), uint(in0.z), in0.w), "
                   "crack_chip_at(in0.x, uint(in0.y), uint(in0.z), in0.w, 0.25, "
                   "2.0 * CRACK_CHIP_CHANCE), 0.0", rows)
    depth = out[:, 0].reshape(2, cells, per)
    chipped = depth.max(-1) > 0
    assert chipped.mean() == pytest.approx(c["CRACK_CHIP_CHANCE"], abs=0.03)
    assert (chipped[0] & chipped[1]).mean() == pytest.approx(c["CRACK_CHIP_CHANCE"] ** 2,
                                                              abs=0.03)
    assert np.all(depth[..., 0] < 0.02 * w)  # where one cell meets the next
    deepest = depth.max(-1)[chipped] / w
    # Samples 1/32 of a cell apart come within 3 % of a chip's middle depth.
    assert deepest.min() >= 0.97 * c["CRACK_CHIP_MIN"]
    assert deepest.max() <= c["CRACK_CHIP_MAX"] * (1 + 1e-5)
    assert deepest.max() >= 0.95 * c["CRACK_CHIP_MAX"]
    assert np.array_equal(out[:, 1], np.maximum(out[:, 0], out[:, 2]))
    assert 0 < out[:, 2].max() <= 0.25 * c["CRACK_CHIP_MAX"] * w * (1 + 1e-5)


def test_a_chip_darkens_less_than_the_opening_and_the_lip_beyond_it(glsl):
    """crack_coverage across a 1 mm rough crack with a 0.5 mm chip on the pixel's side, at a
    footprint of 1 um: the opening darkens fully, the chip by CRACK_CHIP_SHARE, the rounded lip
    beyond it by CRACK_LIP_SHARE, then nothing; on a straight crack (u_crack_rough false) only
    the opening."""
    c = crack_paths.SHADER_CONSTANTS
    w, chip, lip = 1e-3, 5e-4, c["CRACK_LIP_M"]
    d = np.array([0.0, 0.45 * w, 0.5 * w + 0.5 * chip, 0.5 * w + chip + 0.5 * lip,
                  0.5 * w + chip + 1.5 * lip])
    rows = _rows(d, np.full(5, w), np.full(5, chip), np.full(5, 1e-6))
    expression = "crack_coverage(in0.x, in0.y, in0.z, in0.w), 0.0, 0.0, 0.0"
    for rough, want in ((True, [1.0, 1.0, c["CRACK_CHIP_SHARE"], c["CRACK_LIP_SHARE"], 0.0]),
                        (False, [1.0, 1.0, 0.0, 0.0, 0.0])):
        def setup(prog, rough=rough):
            prog["u_crack_rough"].value = rough
        out = glsl.run(expression, rows, setup=setup)[:, 0]
        assert out == pytest.approx(want, abs=1e-4), rough


def test_footprint_across_the_crack_matches_numpy(glsl):
    rng = make_rng(3, 0, Stream.DAMAGE)
    n = 2048
    dpdx, dpdy = rng.normal(0, 1e-3, (n, 3)), rng.normal(0, 1e-3, (n, 3))
    along = rng.normal(size=(n, 3))
    along[:32] = np.cross(dpdx[:32], dpdy[:32])  # along the normal: the fallback
    rows = [_rows(x) for x in (dpdx, dpdy, along)]
    out = glsl.run("footprint_across(in0.xyz, in1.xyz, in2.xyz), 0.0, 0.0, 0.0", *rows)[:, 0]
    dpdx, dpdy, along = (r[:, :3].astype(np.float64) for r in rows)
    ref = footprint_across(dpdx, dpdy, along)
    assert np.allclose(ref[:32], np.linalg.norm(dpdx[:32], axis=1)
                       + np.linalg.norm(dpdy[:32], axis=1))
    assert np.abs(out / ref - 1).max() <= 1e-4
    # A pixel of side s on a fronto-parallel surface: s across a crack along y, s sqrt(2)
    # across a diagonal one.
    rows = [_rows(np.array([[s, 0, 0], [s, 0, 0]])) for s in (2e-3,)]
    rows += [_rows(np.array([[0, 2e-3, 0], [0, 2e-3, 0]])), _rows(np.array([[0, 1, 0],
                                                                             [1, 1, 0]]))]
    out = glsl.run("footprint_across(in0.xyz, in1.xyz, in2.xyz), 0.0, 0.0, 0.0", *rows)[:, 0]
    assert out == pytest.approx([2e-3, 2e-3 * np.sqrt(2)], rel=1e-6)


def _column_network(rng: np.random.Generator) -> CrackNetwork:
    """40 segments on the lateral faces of a 0.8 x 0.6 m column, some across its corners."""
    a, b = 0.4, 0.3
    starts, ends = [], []
    for k in range(20):
        z = rng.uniform(-2, 2)
        y0, dz = rng.uniform(-b, b), rng.uniform(-0.1, 0.1)
        corner = np.array([a, b if k % 2 else -b, z + dz])  # on the edge x = a, y = +-b
        starts += [[a, y0, z], corner]
        ends += [corner, [rng.uniform(-a, a), corner[1], z + 2 * dz]]
    widths = rng.uniform(5e-5, 5e-3, (40, 2))
    widths[1::2, 0] = widths[::2, 1]  # one width at the corner, on both faces
    return CrackNetwork(np.stack([starts, ends], 1), widths, np.repeat(np.arange(20), 2)
                        .astype(np.int32), ("flexural",) * 20)


def _brute_force(p, dpdx, dpdy, network):
    """crack_hit over every segment, in float64: (coverage, width mm, labelled, distance to
    the nearest labelling boundary, gap between the two nearest labelling segments)."""
    a, b = network.points[:, 0], network.points[:, 1]
    d, t = segment_distance(p[:, None], a[None], b[None])
    w = network.widths_m[:, 0] + (network.widths_m[:, 1] - network.widths_m[:, 0]) * t
    f = footprint_across(dpdx[:, None], dpdy[:, None], (b - a)[None])
    coverage = band_coverage(d, w, f).max(1)
    labels = d <= 0.5 * np.maximum(w, f)
    nearest = np.argmin(np.where(labels, d, np.inf), 1)
    width = np.where(labels.any(1), w[np.arange(len(p)), nearest] * 1000, 0.0)
    nearest_two = np.sort(np.where(labels, d, np.inf), 1)[:, :2]
    # No labelling segment at all: an infinite gap, not inf - inf (NaN, and a RuntimeWarning);
    # such pixels are not labelled, so their widths are not compared either way.
    gap = np.subtract(nearest_two[:, 1], nearest_two[:, 0], out=np.full(len(p), np.inf),
                      where=np.isfinite(nearest_two[:, 0]))
    return (coverage, width, labels.any(1), np.abs(d - 0.5 * np.maximum(w, f)).min(1), gap)


def test_crack_hit_through_the_grid_matches_every_segment(glsl):
    """The grid lookup (crack_grid and crack_cell_index, as crack_hit calls them; the cell
    lists and the neighbours that large pixels read) finds what a search of every segment
    finds, for pixel footprints up to four cell edges (|dpdx| + |dpdy| <= 20 cm)."""
    rng = make_rng(4, 0, Stream.DAMAGE)
    network = _column_network(rng)
    index = pack_cracks(network)
    n = 8192
    seg = rng.integers(0, 40, n)
    a, b = network.points[seg, 0], network.points[seg, 1]
    p = a + rng.uniform(0, 1, (n, 1)) * (b - a)
    on_x = np.isclose(np.abs(p[:, 0]), 0.4)
    # Pixel sides on the surface (m), across the face and along z: square pixels near and
    # far, and a grazing view's long pixels (a half footprint beyond a cell edge: it needs the
    # neighbouring cells).
    sides = np.array([[5e-5, 5e-5], [1e-3, 1e-3], [2e-2, 2e-2], [0.1, 0.1], [0.02, 0.17]])
    side = sides[rng.integers(0, len(sides), n)]
    # Along the face, off the crack: the largest pixels as far as their half footprint.
    large = side[:, 1] >= 0.1
    p[:, 2] += np.where(large, rng.uniform(-0.1, 0.1, n), rng.normal(0, 0.02, n))
    dpdx = np.where(on_x[:, None], [0, 1, 0], [1, 0, 0]) * side[:, :1]
    dpdy = np.array([0, 0, 1.0]) * side[:, 1:]
    origin = index.origin.astype(np.float64)  # the shader reads positions relative to it
    rows = [_rows(x) for x in (p - origin, dpdx, dpdy)]
    textures = upload_cracks(glsl.ctx, index, crack_contrast(network))
    out = glsl.run("crack_hit(in0.xyz, in1.xyz, in2.xyz).coverage, "
                   "crack_hit(in0.xyz, in1.xyz, in2.xyz).width_mm, "
                   "float(crack_hit(in0.xyz, in1.xyz, in2.xyz).labelled), "
                   "float(crack_cell_index(crack_grid(in0.xyz)))", *rows,
                   setup=lambda prog: textures.bind(prog, glsl.units))
    for texture in textures.textures:
        texture.release()
    p, dpdx, dpdy = (r[:, :3].astype(np.float64) for r in rows)
    coverage, width, labelled, margin, runner_up = _brute_force(p + origin, dpdx, dpdy,
                                                                network)
    cell = np.floor(p / index.cell_m).astype(int)
    cell_id = cell[:, 0] + index.dims[0] * (cell[:, 1] + index.dims[1] * cell[:, 2])
    clear = margin > 1e-6  # not on a labelling boundary to float32 precision
    assert np.array_equal(out[:, 3], cell_id)
    # A float32 distance near 2.5 m is good to a few of its ulps (0.24 um): over the pixel
    # footprint, that much coverage.
    footprint = np.linalg.norm(dpdx, axis=1)  # the smaller side
    assert np.all(np.abs(out[:, 0] - coverage) <= 8 * 2.5 * EPS / footprint + 1e-6)
    assert np.array_equal(out[clear, 2] == 1, labelled[clear])
    # Where two labelling segments (the two sides of a corner) lie as near to float32
    # precision, either one's width is right.
    agree = clear & labelled & (runner_up > 1e-6)
    # The width's float32 error is its slope times the nearest point's: within 1 um, a fiftieth
    # of the thinnest crack.
    assert np.abs(out[agree, 1] - width[agree]).max() <= 1e-3  # mm
    assert labelled.mean() > 0.3 and (coverage > 0).mean() > 0.3


def _rough_network(rng: np.random.Generator) -> CrackNetwork:
    """The column network with each segment cut into 4 cm steps, as the generators' rough
    cracks are (their paths then stray a few millimetres), rough."""
    network = _column_network(rng)
    points, widths = [], []
    for (a, b), (w0, w1) in zip(network.points, network.widths_m, strict=True):
        cuts = np.linspace(0, 1, max(1, round(np.linalg.norm(b - a) / 0.04)) + 1)
        ends = a + cuts[:, None] * (b - a)
        points.append(np.stack([ends[:-1], ends[1:]], 1))
        w = w0 + cuts * (w1 - w0)
        widths.append(np.stack([w[:-1], w[1:]], 1))
    points, widths = np.concatenate(points), np.concatenate(widths)
    return CrackNetwork(points, widths, np.zeros(len(points), np.int32), ("flexural",), True)


def test_a_paths_stray_bound_holds_at_every_footprint():
    """path_bounds: no offset of a segment's path, at any footprint and anywhere along it,
    lies further from its chord than its stray; the stray is a near bound, not the shader's
    3 cm margin for all."""
    rng = make_rng(7, 0, Stream.DAMAGE)
    n = 2000
    length = rng.uniform(0.005, 0.3, n)
    seeds = crack_paths.segment_seeds(rng.uniform(5e-5, 5e-3, (n, 2)))
    stray = crack_paths.path_bounds(length, seeds)
    t = rng.uniform(0, 1 - 1e-6, (n, 300))
    for finest in (1e-5, 3e-4, 3e-3, 1e-2):
        offsets = crack_paths.shader_offsets(t, length[:, None], seeds[:, None], finest)
        assert np.all(np.abs(offsets).max(1) <= stray)
        assert np.median(np.abs(offsets).max(1) / stray) > 0.5
    short = length < 0.05
    assert np.all(stray <= REACH) and np.median(stray[short]) < 0.2 * REACH


def test_a_pixel_is_measured_to_the_piece_of_the_path_beside_it(glsl):
    """crack_piece_distance2 against the distance to a segment in float64: pixels off pieces
    of slopes 0 to about 16 (the path's finest pieces reach 2-3) and lengths of 1 um to
    1 cm, the pixel anywhere along the piece; where the foot of the perpendicular lies on the
    piece, the distance is the tangent line's, as before."""
    rng = make_rng(13, 0, Stream.DAMAGE)
    n = 8192
    slope = rng.choice([-1, 1], n) * np.concatenate([np.zeros(64), rng.exponential(1.5, n - 64)])
    piece = np.exp(rng.uniform(np.log(1e-6), np.log(1e-2), n))
    before = rng.uniform(0, 1, n) * piece
    after = piece - before
    across = rng.normal(0, 1, n) * piece * rng.choice([0.1, 1, 10], n)
    rows = _rows(across, slope, before, after)
    out = glsl.run("crack_piece_distance2(in0.x, in0.y, in0.z, in0.w), 0.0, 0.0, 0.0",
                   rows)[:, 0]
    across, slope, before, after = (x.astype(np.float64) for x in rows.T)
    # The pixel and the piece's ends in the plane (along the chord, across it, 0).
    zero = np.zeros(n)
    pixel = np.stack([zero, across, zero], 1)
    start = np.stack([-before, -slope * before, zero], 1)
    end = np.stack([after, slope * after, zero], 1)
    ref, _ = segment_distance(pixel, start, end)
    scale = np.abs(across) + np.abs(slope) * piece + piece
    assert np.all(np.abs(np.sqrt(out) - ref) <= 4 * EPS * scale)
    line = np.abs(across) / np.sqrt(1 + slope ** 2)
    foot = across * slope / (1 + slope ** 2)
    on_piece = (foot > -before) & (foot < after)
    assert 0.2 < on_piece.mean() < 0.9
    assert np.all(np.abs(np.sqrt(out[on_piece]) - line[on_piece])
                  <= 4 * EPS * scale[on_piece])


def test_nothing_of_a_rough_crack_lies_further_from_its_path_than_its_edge(glsl):
    """crack_hit on isolated rough segments of 1-10 cm and 0.5-5 mm, through their lists
    (list_reach and the read box), for pixels of 50 um to the exact range's 7 cm: a pixel is
    labelled only within half its width or footprint of the path the shader draws at that
    footprint (crack_paths.shader_offsets, sampled every 2 um), and darkened only within its
    edge (half the width, the deepest chip and the lip) and half the footprint. A band drawn
    across the tangent of a steep pixel-long piece reached (w / 2)(sqrt(1 + slope^2) - 1)
    further: needles on the lips, in labels and image alike."""
    from scipy.spatial import cKDTree

    c = crack_paths.SHADER_CONSTANTS
    rng = make_rng(14, 0, Stream.DAMAGE)
    m = 24
    a = np.stack([np.arange(m) % 5 * 0.5, np.zeros(m), np.arange(m) // 5 * 0.5], 1)
    angle = rng.uniform(0, np.pi, m)
    length = np.exp(rng.uniform(np.log(0.01), np.log(0.1), m))
    b = a + np.stack([np.cos(angle), np.zeros(m), np.sin(angle)], 1) * length[:, None]
    widths = np.exp(rng.uniform(np.log(5e-4), np.log(5e-3), (m, 2)))
    network = CrackNetwork(np.stack([a, b], 1), widths, np.zeros(m, np.int32), ("flexural",),
                           True)
    index = pack_cracks(network)
    textures = upload_cracks(glsl.ctx, index, crack_contrast(network))
    origin = index.origin.astype(np.float64)
    seeds = crack_paths.segment_seeds(widths)
    edge = (0.5 + c["CRACK_CHIP_MAX"]) * widths.max(1) + c["CRACK_LIP_M"]
    labelled = darkened = 0
    for side in (5e-5, 2e-4, 1e-3, 7e-3, 0.07):
        n = 6000
        seg = rng.integers(0, m, n)
        t = rng.uniform(0, 1, n)
        across = np.cross(b - a, [0.0, 1.0, 0.0])[seg]  # across the chord, in the plane
        across /= np.linalg.norm(across, axis=1, keepdims=True)
        p = a[seg] + t[:, None] * (b - a)[seg] \
            + across * rng.uniform(-1, 1, (n, 1)) * (1.5 * edge[seg, None] + side)
        dpdx, dpdy = np.tile([side, 0, 0], (n, 1)), np.tile([0, 0, side], (n, 1))
        rows = [_rows(x) for x in (p - origin, dpdx, dpdy)]
        out = glsl.run("crack_hit(in0.xyz, in1.xyz, in2.xyz).coverage, "
                       "crack_hit(in0.xyz, in1.xyz, in2.xyz).width_mm, "
                       "float(crack_hit(in0.xyz, in1.xyz, in2.xyz).labelled), 0.0", *rows,
                       setup=lambda prog: textures.bind(prog, glsl.units))
        p = rows[0][:, :3].astype(np.float64) + origin
        gap = np.full(n, np.inf)
        for k in range(m):
            mine = seg == k
            samples = np.linspace(0, 1, int(length[k] / 2e-6) + 1)
            offsets = crack_paths.shader_offsets(samples, length[k], seeds[k], side)
            sense = np.cross([0.0, 1.0, 0.0], b[k] - a[k])  # crack_rough's across
            path = a[k] + samples[:, None] * (b[k] - a[k]) \
                + offsets[:, None] * sense / np.linalg.norm(sense)
            gap[mine] = cKDTree(path).query(p[mine])[0]
        width = widths[seg, 0] + (widths[seg, 1] - widths[seg, 0]) * t
        # The pixel's footprint across a crack (footprint_across) is at most its diagonal.
        across_px = np.sqrt(2) * side
        tolerance = 4e-6  # the samples' spacing, float32 positions 2 m from the corner
        on = out[:, 2] == 1
        assert np.all(gap[on] <= 0.5 * np.maximum(width[on], across_px) + tolerance), side
        dark = out[:, 0] > 0
        assert np.all(gap[dark] <= edge[seg[dark]] + 0.5 * across_px + tolerance), side
        labelled += on.sum()
        darkened += (dark & ~on).sum()
    for texture in textures.textures:
        texture.release()
    assert labelled > 3000 and darkened > 1500


def test_a_rough_networks_cells_list_every_path_within_the_footprint_of_their_points():
    """pack_cracks, rough network: from every corner and from random points of cells near its
    cracks, every segment whose path (crack_paths.shader_offsets, sampled finely at the finest
    footprint) or chipped lips come within ROUGH_FOOTPRINT_M is in the cell's list."""
    from glsynth.render.cracks_index import ROUGH_FOOTPRINT_M

    c = crack_paths.SHADER_CONSTANTS
    rng = make_rng(9, 0, Stream.DAMAGE)
    network = _rough_network(rng)
    index = pack_cracks(network)
    assert index.rough and index.footprint_m == ROUGH_FOOTPRINT_M
    a, b = network.points[:, 0], network.points[:, 1]
    t = np.linspace(0, 1, 257)[None, :]
    stray = np.abs(crack_paths.shader_offsets(
        t, np.linalg.norm(b - a, axis=1)[:, None],
        crack_paths.segment_seeds(network.widths_m)[:, None], 1e-5)).max(1)
    edge = stray + (0.5 + c["CRACK_CHIP_MAX"]) * network.widths_m.max(1) + c["CRACK_LIP_M"]
    # Cells around points near the cracks; in each, its 8 corners (a hair inside) and 8
    # random points.
    seg = rng.integers(0, len(a), 1500)
    near = a[seg] + rng.uniform(0, 1, (1500, 1)) * (b[seg] - a[seg]) \
        + rng.normal(0, 0.03, (1500, 3))
    origin = index.origin.astype(np.float64)
    ijk = np.floor((near - origin) / index.cell_m).astype(int)
    ijk = np.unique(ijk[np.all((ijk >= 0) & (ijk < index.dims), 1)], axis=0)
    corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)]) * 0.999 \
        + 0.0005
    inside = np.concatenate([corners, rng.uniform(0, 1, (8, 3))])
    points = origin + (ijk[:, None] + inside[None]) * index.cell_m  # (cells, 16, 3)
    d, _ = segment_distance(points.reshape(-1, 1, 3), a[None], b[None])
    need = (d <= edge + ROUGH_FOOTPRINT_M).reshape(len(ijk), len(inside), -1).any(1)
    cells, entries = index.cells.reshape(-1, 2), index.entries.ravel()
    cell_id = ijk[:, 0] + index.dims[0] * (ijk[:, 1] + index.dims[1] * ijk[:, 2])
    for k in range(len(ijk)):
        start, count = cells[cell_id[k]]
        assert set(np.nonzero(need[k])[0]) <= set(entries[start:start + count])
    # The lists are near what is needed: the corners reach about as far as the lists.
    listed = cells[cell_id, 1].sum()
    assert need.sum() > 2000 and listed < 1.5 * need.sum()


def test_a_rough_networks_short_lists_find_what_every_segment_finds(glsl, monkeypatch):
    """crack_hit on a rough network through its cell lists (each segment as far as its own
    path, chips and lips reach; list_reach) gives, bit for bit, what it gives when every cell
    lists every segment, for pixels near and far up to the documented bound (|dpdx| + |dpdy|
    <= 14 cm), grazing ones included."""
    import glsynth.render.cracks_index as cracks_index

    rng = make_rng(8, 0, Stream.DAMAGE)
    network = _rough_network(rng)
    n = 8192
    seg = rng.integers(0, len(network.points), n)
    a, b = network.points[seg, 0], network.points[seg, 1]
    p = a + rng.uniform(0, 1, (n, 1)) * (b - a)
    on_x = np.isclose(np.abs(p[:, 0]), 0.4)
    sides = np.array([[5e-5, 5e-5], [1e-3, 1e-3], [1e-2, 1e-2], [0.07, 0.07], [0.02, 0.12]])
    side = sides[rng.integers(0, len(sides), n)]
    p[:, 2] += rng.normal(0, 0.01, n) + np.where(side[:, 1] >= 0.07,
                                                 rng.uniform(-0.07, 0.07, n), 0.0)
    dpdx = np.where(on_x[:, None], [0, 1, 0], [1, 0, 0]) * side[:, :1]
    dpdy = np.array([0, 0, 1.0]) * side[:, 1:]
    short = pack_cracks(network)
    monkeypatch.setattr(cracks_index, "list_reach",
                        lambda net, cell: (np.full(len(net.points), 1e3), 1e3))
    every = pack_cracks(network)
    assert short.origin.tobytes() == every.origin.tobytes()
    assert every.longest == len(network.points) > 4 * short.longest
    origin = short.origin.astype(np.float64)
    rows = [_rows(x) for x in (p - origin, dpdx, dpdy)]
    outs = []
    for index in (short, every):
        textures = upload_cracks(glsl.ctx, index, crack_contrast(network))
        outs.append(glsl.run("crack_hit(in0.xyz, in1.xyz, in2.xyz).coverage, "
                             "crack_hit(in0.xyz, in1.xyz, in2.xyz).width_mm, "
                             "float(crack_hit(in0.xyz, in1.xyz, in2.xyz).labelled), 0.0",
                             *rows, setup=lambda prog, t=textures: t.bind(prog, glsl.units)))
        for texture in textures.textures:
            texture.release()
    assert np.array_equal(outs[0], outs[1])
    assert (outs[0][:, 2] == 1).mean() > 0.2 and (outs[0][:, 0] > 0).mean() > 0.3



@pytest.mark.parametrize("rough", [False, True])
def test_the_read_box_holds_the_cells_within_the_footprint_beyond_the_own_cells(glsl, rough):
    """crack_box: a pixel reads exactly the grid cells that come within its half footprint
    less the index's footprint_m of it (each axis apart; at most one cell edge more each way;
    inside the grid), counted here cell by cell from their intervals. With each cell listing
    every path within footprint_m of its points (the tests above), a segment that reaches a
    pixel comes within footprint_m of a point of some cell of its box: so no smaller box is
    exact, and a larger one only walks more."""
    rng = make_rng(11, 0, Stream.DAMAGE)
    network = _rough_network(rng) if rough else _column_network(rng)
    index = pack_cracks(network)
    cell, dims = index.cell_m, np.asarray(index.dims)
    n = 20_000
    # Points anywhere in the grid and a cell beyond it; pixels from 0.1 mm to 30 cm across,
    # so that some read their own cell alone and some reach past one cell edge beyond
    # footprint_m and past the grid's sides.
    p = rng.uniform(-cell, dims * cell + cell, (n, 3)).astype(np.float32)
    scale = np.where(rng.uniform(0, 1, (2, n, 1)) < 0.5, rng.uniform(0, 0.1, (2, n, 1)),
                     10 ** rng.uniform(-4, -1.5, (2, n, 1)))
    dpdx, dpdy = (rng.normal(0, 1, (2, n, 3)) * scale).astype(np.float32)
    half = 0.5 * (np.linalg.norm(dpdx.astype(np.float64), axis=1)
                  + np.linalg.norm(dpdy.astype(np.float64), axis=1))
    extra = np.clip(half - index.footprint_m, 0, cell)[:, None]
    # Cell i spans [i, i + 1) cell edges: it is read where the pixel's reach overlaps it.
    base = np.floor(p / cell).astype(int)
    offsets = np.arange(-3, 4)
    i = base[:, :, None] + offsets  # (n, 3, 7) candidate cells per axis
    overlap = (p[:, :, None] + extra[:, :, None] >= i * cell) \
        & (p[:, :, None] - extra[:, :, None] < (i + 1) * cell) \
        & (i >= 0) & (i < dims[None, :, None])
    empty = ~overlap.any(2)
    first = np.where(empty, 0, i[np.arange(n)[:, None], np.arange(3), overlap.argmax(2)])
    last = np.where(empty, -1, i[np.arange(n)[:, None], np.arange(3),
                                 6 - overlap[:, :, ::-1].argmax(2)])
    # Not compared: pixels whose reach ends within float32 rounding of a cell side.
    for sign in (-1, 1):
        edge = (p + sign * extra) / cell
        clear = np.abs(edge - np.round(edge)) > 1e-4
        if sign < 0:
            keep = clear.all(1)
        else:
            keep &= clear.all(1)

    def setup(prog) -> None:  # the uniforms crack_box reads, as CrackTextures.bind sets them
        prog["u_crack_cell_m"].value = index.cell_m
        prog["u_crack_dims"].value = tuple(index.dims)
        prog["u_crack_footprint_m"].value = index.footprint_m

    rows = [_rows(x) for x in (p, dpdx, dpdy)]
    # Both ends in each run: an end the expression never reads is compiled away with its
    # uniforms.
    box = [glsl.run(f"vec3(crack_box(in0.xyz, in1.xyz, in2.xyz).{end}), "
                    f"float(crack_box(in0.xyz, in1.xyz, in2.xyz).{other}.x)", *rows,
                    setup=setup)[:, :3] for end, other in (("lo", "hi"), ("hi", "lo"))]
    assert index.footprint_m == (ROUGH_FOOTPRINT_M if rough else cell)
    assert keep.mean() > 0.99
    # A pixel beyond the grid's side reads nothing (lo > hi on that axis): the grid reaches
    # two cell edges beyond every crack's edge.
    outside, read = empty.any(1), ~(box[0] > box[1]).any(1)
    assert np.array_equal(read[keep], ~outside[keep])
    inside = keep & ~outside
    assert np.array_equal(box[0][inside], first[inside])
    assert np.array_equal(box[1][inside], last[inside])
    # Every case is there: own cell only, one more, the clamp at one edge, the grid's sides.
    spans = (last - first)[inside]
    assert all((spans == k).any() for k in (0, 1, 2))
    assert (extra[:, 0] == cell).mean() > 0.05 and (extra[:, 0] == 0).mean() > 0.05
    assert 0.01 < outside.mean() < 0.5


def test_each_cell_lists_every_segment_within_reach_of_its_points():
    """pack_cracks: from any point of a cell, every segment whose crack edge lies within one
    cell edge is in the cell's list; ``longest`` is the longest list."""
    rng = make_rng(5, 0, Stream.DAMAGE)
    network = _column_network(rng)
    index = pack_cracks(network)
    cells = index.cells.reshape(-1, 2)
    entries = index.entries.ravel()
    assert index.longest == cells[:, 1].max() > 0
    seg = rng.integers(0, len(network.points), 20000)
    a, b = network.points[seg, 0], network.points[seg, 1]
    p = a + rng.uniform(0, 1, (20000, 1)) * (b - a) + rng.normal(0, 0.06, (20000, 3))
    ijk = np.floor((p - index.origin) / index.cell_m).astype(int)
    inside = np.all((ijk >= 0) & (ijk < index.dims), 1)
    d, _ = segment_distance(p[:, None], network.points[None, :, 0], network.points[None, :, 1])
    near = d <= network.widths_m.max(1) / 2 + index.cell_m
    assert np.all(inside | ~near.any(1))  # no point outside the grid is near a crack
    cell_id = ijk[:, 0] + index.dims[0] * (ijk[:, 1] + index.dims[1] * ijk[:, 2])
    for k in np.nonzero(inside & near.any(1))[0]:
        start, count = cells[cell_id[k]]
        assert set(np.nonzero(near[k])[0]) <= set(entries[start:start + count])
    assert (inside & near.any(1)).sum() > 5000 and (~near.any(1)).sum() > 1000


def test_cell_lists_are_exactly_the_segments_within_reach_of_the_cell_centre(monkeypatch):
    """pack_cracks tests the pairs in batches of segments (cracks_index.batches); its lists
    hold exactly the segments that segment_distance puts within reach (half the widest width
    plus two cell edges) of each cell's centre, ascending, even across batch boundaries and
    for a zero-length segment."""
    import glsynth.render.cracks_index as cracks_index

    monkeypatch.setattr(cracks_index, "BATCH", 500)  # many batches
    network = _column_network(make_rng(6, 0, Stream.DAMAGE))
    network = CrackNetwork(np.concatenate([network.points, network.points[:1, :1].repeat(2, 1)]),
                           np.concatenate([network.widths_m, [[2e-3, 2e-3]]]),
                           np.append(network.crack, 20).astype(np.int32),
                           network.kinds + ("flexural",))
    index = pack_cracks(network)
    # The grid's corner in float64 (the index keeps it in float32, as the shader reads it).
    origin, cell, _ = cracks_index._grid(network.points.reshape(-1, 3),
                                         network.widths_m.max() / 2)
    ijk = np.stack(np.meshgrid(*(np.arange(n) for n in index.dims), indexing="ij"), -1)
    centre = origin + (ijk.reshape(-1, 3) + 0.5) * cell
    d, _ = segment_distance(centre[:, None], network.points[None, :, 0],
                            network.points[None, :, 1])
    near = d <= network.widths_m.max(1) / 2 + 2 * index.cell_m
    cells, entries = index.cells.reshape(-1, 2), index.entries.ravel()
    cell_id = ijk[..., 0] + index.dims[0] * (ijk[..., 1] + index.dims[1] * ijk[..., 2])
    for k, c in enumerate(cell_id.ravel()):
        start, count = cells[c]
        assert list(entries[start:start + count]) == list(np.nonzero(near[k])[0])
    assert near.sum() > 1000 and near[:, -1].any()


def test_box_cells_are_every_cell_of_each_box_in_order():
    """Boxes of several shapes, one a single cell and one wider than tall: the cells listed
    are those of nested loops over each box, z outermost and x fastest, box after box."""
    first = np.array([[0, 0, 0], [5, 2, 1], [3, 7, 4], [1, 1, 1]])
    size = np.array([[2, 3, 1], [1, 1, 1], [4, 2, 3], [3, 1, 2]])
    box, (x, y, z) = box_cells(first, size)
    expected = [(b, f[0] + i, f[1] + j, f[2] + k) for b, (f, n) in enumerate(zip(first, size))
                for k in range(n[2]) for j in range(n[1]) for i in range(n[0])]
    assert list(zip(box, x, y, z)) == expected


def test_batches_hold_at_most_their_budget_and_every_item_once():
    count = np.array([3, 4, 9, 1, 1, 2, 5, 2])
    runs = batches(count, 6)
    assert runs[0].start == 0 and runs[-1].stop == len(count)
    assert all(a.stop == b.start for a, b in zip(runs, runs[1:]))
    # Each run as long as the budget allows, and an item over the budget alone.
    assert [(r.start, r.stop) for r in runs] == [(0, 1), (1, 2), (2, 3), (3, 6), (6, 7), (7, 8)]
    # A run that fills the budget exactly takes its last item.
    assert [(r.start, r.stop) for r in batches(np.array([2, 4, 6, 3, 3]), 6)] == [
        (0, 2), (2, 3), (3, 5)]
    assert batches(np.array([], np.int64), 6) == []
