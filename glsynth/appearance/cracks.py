"""Cracks as curves with a width on a column's surface, placed by mechanics (issue 29).

A crack network holds straight segments in the member's mesh frame (metres) with a width at
each end. Columns are ``meshes.box((a, b, height))`` centred at their origin: x along the
track (a), y across (b), z up. The generators work on the unrolled lateral surface, a
coordinate ``s`` running counter-clockwise round the section (seen from +z) and ``z``, and
split every polyline where it turns a corner, so each segment lies on one face and a crack
turning a corner is two segments meeting on the shared edge.

Placement follows a column in double curvature under a lateral drift (docs/design.md, "Damage
by mechanics", gives every rule and its source): flexural cracks across the axis where the
moment exceeds the cracking moment, widest in the plastic-hinge zones at both ends; shear
cracks within SHEAR_BAND_DEG of the axis on the faces parallel to the drift, where the
shear-span ratio makes shear govern.
"""

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from glsynth.appearance import crack_paths
from glsynth.core.config import MAX_CRACK_WIDTH_MM, DamageConfig
from glsynth.core.seeding import child_rng

KINDS = ("flexural", "shear")
MAX_WIDTH_M = MAX_CRACK_WIDTH_MM / 1e3
"""No crack is wider than [damage] crack_width_mm allows at most."""
STEEL_MODULUS_MPA = 200_000.0
YIELD_CURVATURE_FACTOR = 2.10
"""phi_y = 2.10 eps_y / h for rectangular columns (Priestley, Calvi and Kowalsky 2007)."""
NEUTRAL_AXIS_RATIO = 0.25
"""c / h, the compression zone's share of the section depth at the column's axial load."""
EFFECTIVE_DEPTH_RATIO = 0.9
"""d / h: the tension bars' depth below the compression face."""
FLEXURAL_BAND_DEG = 10.0
"""Flexural cracks run within this angle of the horizontal (across the column's axis)."""
SHEAR_BAND_DEG = (30.0, 60.0)
"""Shear cracks run at these angles to the axis."""
STEP_M = 0.05
"""About the length of a crack polyline's steps; its roughness at shorter scales is drawn in
shaders/cracks.glsl (crack_paths)."""
EDGE_SNAP_M = 2e-4
"""A crack's vertex this close to a section's edge is moved onto it (_Section.snapped)."""
MIN_FORK_M = 0.02
"""A fork with less room than this on its face is not made."""
ECHELON_PIECES = (2, 4)
"""An en-echelon crack runs as this many parallel pieces at most (fewer on a short crack)."""
ECHELON_PIECE_M = 0.12
"""... none shorter than this along the crack."""
ECHELON_OFFSET_M = (0.003, 0.03)
"""The step across the crack between two pieces: log-uniform in this range (m), in one sense
along a crack (docs/design.md, "Cracks", gives the sources)."""
ECHELON_OVERLAP_M = (0.02, 0.06)
"""How far two pieces overlap along the crack: uniform in this range (m)."""
ECHELON_BRIDGE = 0.5
"""Chance that a step is bridged by a short crack from one piece to the next."""


@dataclass(frozen=True)
class CrackNetwork:
    """Cracks on one member's surface, in the member's mesh frame (metres)."""

    points: np.ndarray
    """(N, 2, 3) float64: the end points of N straight segments, on the member's surface."""
    widths_m: np.ndarray
    """(N, 2) float64: the crack's width at each end point, in metres, measured across the
    crack on the surface; linear in between. Within [damage] crack_width_mm, at most
    MAX_WIDTH_M; 0 at a crack's tips."""
    crack: np.ndarray
    """(N,) int32: the crack (0 .. K-1) each segment belongs to."""
    kinds: tuple[str, ...]
    """(K,) per crack: "flexural" or "shear"."""
    rough: bool = False
    """The renderer carries each segment's path on below its end points, self-affine down to
    the pixel (shaders/cracks.glsl; the generators' cracks); false: straight segments."""
    leachate: np.ndarray | None = None
    """(K, 4) float64 per crack, or None (none leaches): what runs out of it
    (glsynth.appearance.crack_leachate: LEACHATE_FIELDS); colour only."""

    def __post_init__(self) -> None:
        n = len(self.points) if isinstance(self.points, np.ndarray) else -1
        for name, value, shape, dtype in (("points", self.points, (n, 2, 3), np.float64),
                                          ("widths_m", self.widths_m, (n, 2), np.float64),
                                          ("crack", self.crack, (n,), np.int32)):
            if not isinstance(value, np.ndarray) or value.shape != shape or value.dtype != dtype:
                got = (value.dtype, value.shape) if isinstance(value, np.ndarray) else value
                raise ValueError(f"CrackNetwork.{name}: {got}; must be {np.dtype(dtype)} "
                                 f"of shape {shape}")
        if not (np.all(np.isfinite(self.points)) and np.all(np.isfinite(self.widths_m))):
            raise ValueError("CrackNetwork: points and widths must be finite")
        if n and not (self.widths_m.min() >= 0 and self.widths_m.max(axis=1).min() > 0
                      and self.widths_m.max() <= MAX_WIDTH_M):
            raise ValueError(f"CrackNetwork.widths_m: {self.widths_m.min()} .. "
                             f"{self.widths_m.max()} m; must lie in [0, {MAX_WIDTH_M}] m, "
                             "positive at one end of every segment at least")
        if not isinstance(self.kinds, tuple) or any(k not in KINDS for k in self.kinds):
            raise ValueError(f"CrackNetwork.kinds = {self.kinds!r}: a tuple of {KINDS}")
        if self.leachate is not None and not (
                isinstance(self.leachate, np.ndarray) and self.leachate.dtype == np.float64
                and self.leachate.shape == (len(self.kinds), 4)
                and np.all(np.isfinite(self.leachate))):
            raise ValueError(f"CrackNetwork.leachate: must be None or float64 of shape "
                             f"({len(self.kinds)}, 4), finite")
        used = np.unique(self.crack)
        if not np.array_equal(used, np.arange(len(self.kinds))):
            raise ValueError(f"CrackNetwork.crack: ids {used.tolist()}; every crack "
                             f"0 .. {len(self.kinds) - 1} must have segments, and no other")

    @property
    def lengths_m(self) -> np.ndarray:
        """(N,) segment lengths."""
        return np.linalg.norm(self.points[:, 1] - self.points[:, 0], axis=1)

    def subset(self, keep: np.ndarray) -> "CrackNetwork":
        """The segments where ``keep`` (N,) bool is true, as a network of their own: the
        cracks left keep their order, numbered from 0."""
        ids, crack = np.unique(self.crack[keep], return_inverse=True)
        return CrackNetwork(self.points[keep], self.widths_m[keep], crack.astype(np.int32),
                            tuple(self.kinds[k] for k in ids), self.rough,
                            None if self.leachate is None else self.leachate[ids])


def empty_network() -> CrackNetwork:
    return CrackNetwork(np.zeros((0, 2, 3)), np.zeros((0, 2)), np.zeros(0, np.int32), ())


def crack_records(net: CrackNetwork) -> list[dict]:
    """Per crack: id, type, length in m, mean (over its length) and maximum width in mm."""
    lengths = net.lengths_m
    records = []
    for k, kind in enumerate(net.kinds):
        mine = net.crack == k
        length = float(lengths[mine].sum())
        mean = float((lengths[mine] * net.widths_m[mine].mean(axis=1)).sum() / length)
        records.append({"id": k, "type": kind, "length_m": round(length, 4),
                        "mean_width_mm": round(mean * 1e3, 4),
                        "max_width_mm": round(float(net.widths_m[mine].max()) * 1e3, 4)})
    return records


@dataclass(frozen=True)
class DriftDemand:
    """The drift a damaged member went through."""

    drift: float
    """Drift ratio: the sideways displacement of one end of a clear span against the other,
    over the span (a column's storey drift; a beam's chord rotation)."""
    axis: int
    """Its direction in the section: 0 along x (a column: the track), 1 along y (a column:
    across the track; a beam: vertical)."""


def column_demand(cfg: DamageConfig, severity: str, rng: np.random.Generator
                  ) -> DriftDemand:
    """A drift drawn uniformly from the severity's range, in a direction along the track or
    across it with equal chance."""
    drift = float(rng.uniform(*cfg.drift_range(severity)))
    return DriftDemand(drift, int(rng.integers(2)))


def strain_penetration_m(cfg: DamageConfig) -> float:
    """L_sp = hinge_bar_factor fy d_b: how far the bars' yielding reaches into the footing or
    joint."""
    return cfg.hinge_bar_factor * cfg.fy_mpa * cfg.bar_diameter_mm / 1e3


def hinge_length_m(cfg: DamageConfig, shear_span_m: float) -> float:
    """Priestley and Park (1987): Lp = hinge_span_factor L + L_sp (L in m)."""
    if shear_span_m < 0:
        raise ValueError(f"shear_span_m = {shear_span_m!r}: must be >= 0")
    return cfg.hinge_span_factor * shear_span_m + strain_penetration_m(cfg)


def hinge_zones(cfg: DamageConfig, spans: Sequence[tuple[float, float]]
                ) -> tuple[tuple[float, float], ...]:
    """The plastic-hinge zones [z0, z0 + Lp] and [z1 - Lp, z1] of each clear span (z0, z1),
    Lp at most the shear span (a short span's two zones then meet at mid-span)."""
    zones = []
    for z0, z1 in spans:
        lp = min(hinge_length_m(cfg, (z1 - z0) / 2), (z1 - z0) / 2)
        zones += [(z0, z0 + lp), (z1 - lp, z1)]
    return tuple(zones)


def yield_curvature(cfg: DamageConfig, depth_m: float) -> float:
    """phi_y = YIELD_CURVATURE_FACTOR eps_y / h of a rectangular section, eps_y = fy / Es."""
    return YIELD_CURVATURE_FACTOR * cfg.fy_mpa / STEEL_MODULUS_MPA / depth_m


@dataclass(frozen=True)
class SpanMechanics:
    """One clear span of a member in double curvature (a column between the ground, tie beams
    and the cross beam; a beam between the columns): moment linear, zero at mid-span, largest
    at both ends; shear constant. Lengths in metres; z0, z1 along the member's axis in its
    mesh frame."""

    z0: float
    z1: float
    depth_m: float
    """h, the section's depth in the drift's direction."""
    shear_span_m: float
    """Half the clear span: the distance from an end to the point of zero moment."""
    hinge_m: float
    """Plastic-hinge length Lp at each end (at most the shear span)."""
    yield_drift: float
    """theta_y = phi_y (L + L_sp) / 3 of the half span as a cantilever."""
    cracked_m: float
    """Flexural cracks reach this far from each end: where M > M_cr, and the hinge past
    yield."""
    shear_governs: bool
    """a / d below [damage] shear_span_ratio."""


def span_mechanics(cfg: DamageConfig, z0: float, z1: float, depth_m: float, drift: float
                   ) -> SpanMechanics:
    if not (z1 > z0 and depth_m > 0 and drift >= 0):
        raise ValueError(f"span ({z0}, {z1}), depth {depth_m}, drift {drift}: need z1 > z0, "
                         "depth > 0, drift >= 0")
    shear_span = (z1 - z0) / 2
    hinge = min(hinge_length_m(cfg, shear_span), shear_span)
    yield_drift = yield_curvature(cfg, depth_m) * (shear_span + strain_penetration_m(cfg)) / 3
    moment = min(drift / yield_drift, 1.0)  # M_end / M_y: elastic, then perfectly plastic
    cracked = shear_span * max(0.0, 1.0 - cfg.cracking_moment_ratio / moment) if moment else 0.0
    if drift > yield_drift:
        cracked = max(cracked, hinge)
    governs = shear_span / (EFFECTIVE_DEPTH_RATIO * depth_m) < cfg.shear_span_ratio
    return SpanMechanics(z0, z1, depth_m, shear_span, hinge, yield_drift, cracked, governs)


def flexural_width_m(cfg: DamageConfig, span: SpanMechanics, drift: float, x: np.ndarray,
                     spacing_m: float) -> np.ndarray:
    """Surface width of a flexural crack ``x`` from the nearest end: the crack spacing times
    the strain of the tension face, curvature times (h - c). Curvature: elastic, linear in
    the moment, plus the plastic rotation theta - theta_y spread over Lp (Priestley and Park's
    hinge model)."""
    elastic = yield_curvature(cfg, span.depth_m) * min(drift / span.yield_drift, 1.0)
    phi = elastic * (1.0 - x / span.shear_span_m)  # the moment falls to zero at mid-span
    plastic = max(drift - span.yield_drift, 0.0) / span.hinge_m if span.hinge_m > 0 else 0.0
    phi = phi + np.where(x <= span.hinge_m, plastic, 0.0)
    return spacing_m * phi * (1.0 - NEUTRAL_AXIS_RATIO) * span.depth_m


def soffit_width_m(cfg: DamageConfig, span: SpanMechanics, x: np.ndarray, spacing_m: float
                   ) -> np.ndarray:
    """Width of a gravity crack in a beam's soffit ``x`` from the span's start, 0 where the
    sagging moment stays below M_cr. A beam fixed at both ends under a uniform load carries
    M = wL^2/12 (6 xi - 6 xi^2 - 1) (xi = x / L): wL^2/24 sagging at midspan, where the
    section works at [damage] beam_service_moment_ratio of its M_y."""
    xi = x / (span.z1 - span.z0)
    moment = cfg.beam_service_moment_ratio * (6 * xi - 6 * xi * xi - 1) / 0.5  # M / M_y
    width = spacing_m * yield_curvature(cfg, span.depth_m) * moment * (1.0 - NEUTRAL_AXIS_RATIO) \
        * span.depth_m
    return np.where(moment >= cfg.cracking_moment_ratio, width, 0.0)


def shear_width_m(drift: float, spacing_m: float) -> float:
    """Width of a diagonal crack in a shear-governed span: the crack spacing times the
    principal tensile strain, which is half the shear strain at 45 degrees (Vecchio and
    Collins 1986); a squat span's drift is taken to be all shear strain."""
    return spacing_m * drift / 2


class _Section:
    """The unrolled lateral surface of an a x b box section: faces 0..3 are x = +a/2, y = +b/2,
    x = -a/2, y = -b/2, met in that order as s grows (counter-clockwise seen from +z)."""

    def __init__(self, a: float, b: float) -> None:
        self.a, self.b = a, b
        self.starts = np.array([0.0, b, b + a, 2 * b + a])
        self.perimeter = 2 * (a + b)

    def face(self, s: np.ndarray) -> np.ndarray:
        """Face index of unrolled s, counting on past the perimeter (face 5 is face 1)."""
        turns = np.floor(s / self.perimeter)
        within = s - turns * self.perimeter
        return (4 * turns + np.searchsorted(self.starts, within, side="right") - 1).astype(int)

    def face_start(self, face: np.ndarray) -> np.ndarray:
        return np.floor_divide(face, 4) * self.perimeter + self.starts[np.mod(face, 4)]

    def face_width(self, face: int) -> float:
        return self.b if face % 2 == 0 else self.a

    def face_bounds(self, s: float) -> tuple[float, float]:
        """The s range of the face that holds ``s``."""
        face = self.face(np.array([s]))
        start = float(self.face_start(face)[0])
        return start, start + self.face_width(int(face[0]))

    def points(self, s: np.ndarray, z: np.ndarray) -> np.ndarray:
        """(n, 3) points (x, y, z) of unrolled (s, z)."""
        face = self.face(s)
        t = s - self.face_start(face)  # distance along the face, counter-clockwise
        ha, hb = self.a / 2, self.b / 2
        x = np.choose(face % 4, [np.full_like(t, ha), ha - t, np.full_like(t, -ha), t - ha])
        y = np.choose(face % 4, [t - hb, np.full_like(t, hb), hb - t, np.full_like(t, -hb)])
        return np.stack([x, y, z], axis=1)

    def snapped(self, s: np.ndarray) -> np.ndarray:
        """``s`` with every vertex within EDGE_SNAP_M of an edge moved onto it: a vertex that
        close would leave a sliver of a segment along the edge, where it is split (a tenth of
        a millimetre along a crack is far below its path's roughness)."""
        face = self.face(s)
        start = self.face_start(face)
        end = start + np.where(face % 2 == 0, self.b, self.a)
        return np.where(s - start < EDGE_SNAP_M, start, np.where(end - s < EDGE_SNAP_M, end, s))

    def segments(self, s: np.ndarray, z: np.ndarray, w: np.ndarray, line: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Polylines' segments (M, 2, 3), end widths (M, 2) and polyline ids (M,), split
        where one crosses an edge so that every segment lies on one face. The polylines'
        vertices are concatenated, ``line`` naming each vertex's polyline; steps are shorter
        than a face."""
        s = self.snapped(s)
        face = self.face(s)
        cross = np.flatnonzero((face[1:] != face[:-1]) & (line[1:] == line[:-1]))
        edge = self.face_start(np.maximum(face[cross], face[cross + 1]))
        f = (edge - s[cross]) / (s[cross + 1] - s[cross])
        s = np.insert(s, cross + 1, edge)
        z = np.insert(z, cross + 1, z[cross] + f * (z[cross + 1] - z[cross]))
        w = np.insert(w, cross + 1, w[cross] + f * (w[cross + 1] - w[cross]))
        line = np.insert(line, cross + 1, line[cross])
        p = self.points(s, z)
        seg, width = np.stack([p[:-1], p[1:]], axis=1), np.stack([w[:-1], w[1:]], axis=1)
        keep = (line[1:] == line[:-1]) & (np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1) > 1e-9)
        return seg[keep], width[keep], line[:-1][keep]


_Polyline = tuple[np.ndarray, np.ndarray, np.ndarray]
"""(s, z, width) of a crack's vertices on the unrolled surface."""


def _branch(line: _Polyline, face: tuple[float, float], rng: np.random.Generator
            ) -> _Polyline | None:
    """A fork from a vertex of ``line`` in its outer quarter at either tip (where a crack
    meets tougher material ahead and splits), 15-35 degrees off the crack's chord, 5-20 % of
    its length, about half its width at the fork and closing to zero at its own tip; kept on the
    face ``face`` (its s range), or None where there is no room."""
    s, z, w = line
    quarter = max(1, (len(s) - 1) // 4)
    outer = np.r_[1:quarter + 1, len(s) - 1 - quarter:len(s) - 1]
    inner = outer[(s[outer] > face[0]) & (s[outer] < face[1])]
    if len(inner) == 0:
        return None
    k = int(rng.choice(inner))
    sense = 1.0 if s[-1] > s[0] else -1.0
    chord = np.degrees(np.arctan2(z[-1] - z[0], abs(s[-1] - s[0])))
    angle = float(np.clip(chord + rng.choice([-1.0, 1.0]) * rng.uniform(15, 35), -70, 70))
    reach = rng.uniform(0.05, 0.2) * float(np.hypot(np.diff(s), np.diff(z)).sum())
    end = float(np.clip(s[k] + sense * reach * np.cos(np.radians(angle)), *face))
    if abs(end - s[k]) < MIN_FORK_M:
        return None
    sb, zb, arc = crack_paths.path(s[k], end, 0.0, angle, STEP_M, rng)
    widths = crack_paths.width_profile(arc, np.full(len(arc), w[k] / 2), rng, first_is_tip=False)
    return sb, zb - zb[0] + z[k], np.minimum(widths, w[k])  # no wider than its trunk


def _piece(line: _Polyline, arc: np.ndarray, lo: float, hi: float, shift: np.ndarray,
           taper: tuple[float, float], joints: list[float]) -> _Polyline:
    """The part of ``line`` between arc lengths lo and hi (interpolated there, and at
    ``joints``, where bridges meet it), moved by ``shift`` (s, z), its width closing as the
    square root of the distance to an end over ``taper`` (m at the start and the end; 0: that
    end keeps its width, a tip already)."""
    inner = (arc > lo) & (arc < hi)
    at = np.unique(np.concatenate([[lo], arc[inner], joints, [hi]]))
    s, z, w = (np.interp(at, arc, values) for values in line)
    for length, to_end in ((taper[0], at - lo), (taper[1], hi - at)):
        if length > 0:
            w = w * np.sqrt(np.clip(to_end / length, 0.0, 1.0))
    return s + shift[0], z + shift[1], w


def _echelon(line: _Polyline, rng: np.random.Generator) -> list[_Polyline]:
    """``line`` as parallel pieces stepped across it, each overlapping the next (en echelon),
    some steps bridged by a short crack; ``[line]`` where it is too short for two pieces. The
    pieces keep the line's path and widths, close to a tip over the overlap at each step, and
    step ECHELON_OFFSET_M across the crack, all in one sense, the middle piece staying where
    the mechanics put the crack."""
    s, z, w = line
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(s), np.diff(z)))])
    n = min(int(rng.integers(ECHELON_PIECES[0], ECHELON_PIECES[1] + 1)),
            int(arc[-1] / ECHELON_PIECE_M))
    if n < 2:
        return [line]
    # Pieces move along the member's axis (z), by the step over the chord's share across it,
    # so that they are stepped ECHELON_OFFSET_M across the crack and keep its s: a diagonal
    # crack's pieces stay on its face.
    across = abs(s[-1] - s[0]) / max(float(np.hypot(s[-1] - s[0], z[-1] - z[0])), 1e-9)
    axis_step = np.array([0.0, 1.0 / max(across, 0.1)])
    cuts = arc[-1] * (np.arange(1, n) + rng.uniform(-0.2, 0.2, n - 1)) / n
    overlap = rng.uniform(*ECHELON_OVERLAP_M, n - 1)
    steps = np.exp(rng.uniform(*np.log(ECHELON_OFFSET_M), n - 1)) * rng.choice([-1.0, 1.0])
    offsets = np.concatenate([[0.0], np.cumsum(steps)])
    offsets -= offsets[n // 2]
    starts = np.concatenate([[0.0], cuts - overlap / 2])
    ends = np.concatenate([cuts + overlap / 2, [arc[-1]]])
    lengths = np.concatenate([[0.0], overlap, [0.0]])
    # A bridge runs from the piece before a step, a quarter overlap past the cut, to the piece
    # after it, a quarter overlap before the cut: vertices of both pieces, so no bridge end is
    # free (every free end of a crack is a tip).
    bridged = np.flatnonzero(rng.random(n - 1) < ECHELON_BRIDGE)
    ends_at = {k: (cuts[k] + overlap[k] / 4, cuts[k] - overlap[k] / 4) for k in bridged}
    pieces = [_piece(line, arc, starts[i], ends[i], offsets[i] * axis_step,
                     (lengths[i], lengths[i + 1]),
                     [ends_at[k][j] for k, j in ((i, 0), (i - 1, 1)) if k in ends_at])
              for i in range(n)]
    for k in bridged:
        joints = [(pieces[k + j], np.interp(ends_at[k][j], arc, s) + offsets[k + j] * axis_step[0])
                  for j in (0, 1)]
        pieces.append(_bridge(joints, rng))
    return pieces


def _bridge(joints: list[tuple[_Polyline, float]], rng: np.random.Generator) -> _Polyline:
    """A short straight crack across a step between two pieces, each end the vertex of its
    piece nearest to the given s, 30-60 % as wide as the pieces there (before their taper)."""
    k = [int(np.argmin(np.abs(piece[0] - at))) for piece, at in joints]
    s, z = (np.array([piece[q][i] for (piece, _), i in zip(joints, k)]) for q in (0, 1))
    w = np.array([piece[2][i] for (piece, _), i in zip(joints, k)])
    return s, z, np.maximum(w, 1e-3 * w.max(initial=0.0)) * rng.uniform(0.3, 0.6)


def _clip_z(line: _Polyline, z0: float, z1: float) -> _Polyline | None:
    """The run of vertices around the middle one that stays within [z0, z1]."""
    s, z, w = line
    inside = (z >= z0) & (z <= z1)
    mid = len(z) // 2
    if not inside[mid]:
        return None
    lo = mid - int(np.argmin(inside[mid::-1])) + 1 if not inside[:mid].all() else 0
    hi = mid + int(np.argmin(inside[mid:])) if not inside[mid:].all() else len(z)
    return (s[lo:hi], z[lo:hi], w[lo:hi]) if hi - lo >= 2 else None


def _flexural(cfg: DamageConfig, sec: _Section, face: int, z_at: float, width_m: float,
              rng: np.random.Generator) -> _Polyline:
    """A crack across tension face ``face`` at width_m, turning both corners onto the side
    faces for 15-45 % of their width and narrowing there to the smallest width (the strain
    falls towards the neutral axis), then closing at its tips. Its chord runs within
    FLEXURAL_BAND_DEG of horizontal; its path is rough (crack_paths)."""
    w_lo, w_hi = cfg.crack_width_m
    start = float(sec.starts[face])
    end = start + sec.face_width(face)
    side = sec.face_width(face + 1)
    lo, hi = start - rng.uniform(0.15, 0.45) * side, end + rng.uniform(0.15, 0.45) * side
    angle = float(np.clip(rng.normal(0.0, 3.0), -0.8 * FLEXURAL_BAND_DEG,
                          0.8 * FLEXURAL_BAND_DEG))
    s, z, arc = crack_paths.path(lo, hi, z_at, angle, STEP_M, rng)
    past = np.clip(np.maximum(start - s, 0.0) / (start - lo)
                   + np.maximum(s - end, 0.0) / (hi - end), 0.0, 1.0)
    mechanics = width_m + (w_lo - width_m) * past
    return s, z, np.minimum(crack_paths.width_profile(arc, mechanics, rng), w_hi)


def _shear(cfg: DamageConfig, sec: _Section, face: int, z_at: float, width_m: float,
           rng: np.random.Generator) -> _Polyline:
    """A diagonal crack across face ``face`` (parallel to the drift), its chord at 35-55
    degrees to the axis with either sense (the load reverses), widest mid-face, closing at
    both tips; its path is rough (crack_paths)."""
    w_lo, w_hi = cfg.crack_width_m
    start, wide = float(sec.starts[face]), sec.face_width(face)
    lo, hi = start + rng.uniform(0.02, 0.1) * wide, start + wide - rng.uniform(0.02, 0.1) * wide
    inclination = rng.uniform(SHEAR_BAND_DEG[0] + 5, SHEAR_BAND_DEG[1] - 5)
    s, z, arc = crack_paths.path(lo, hi, z_at, rng.choice([-1.0, 1.0]) * inclination,
                                 STEP_M, rng)
    s = np.clip(s, start, start + wide)  # a diagonal crack stays on its face
    mechanics = w_lo + (width_m - w_lo) * (1.0 - np.abs(2 * arc / arc[-1] - 1.0))
    return s, z, np.minimum(crack_paths.width_profile(arc, mechanics, rng), w_hi)


def _positions(extent_m: float, spacing_m: float, rng: np.random.Generator) -> np.ndarray:
    """Distances from an end of cracks about ``spacing_m`` apart (each gap 0.8-1.2 times it),
    the first within half a spacing of the end, none past ``extent_m``."""
    gaps = spacing_m * rng.uniform(0.8, 1.2, int(extent_m / (0.8 * spacing_m)) + 2)
    x = rng.uniform(0.02, 0.5) * spacing_m + np.concatenate([[0.0], np.cumsum(gaps)])
    return x[x <= extent_m]


_Raw = list[tuple[str, _Polyline]]
"""Cracks of one span before clipping and forking: (kind, polyline)."""


def _span_cracks(cfg: DamageConfig, sec: _Section, span: SpanMechanics, demand: DriftDemand,
                 spacing_m: float, rng: np.random.Generator) -> _Raw:
    """Flexural cracks from both ends of a span, on both faces across the drift (the load
    reverses), and shear cracks on both faces along it where shear governs."""
    w_lo, w_hi = cfg.crack_width_m
    across = (0, 2) if demand.axis == 0 else (1, 3)  # faces whose normal is the drift's
    along = (1, 3) if demand.axis == 0 else (0, 2)
    cracks: _Raw = []
    for end, sense in ((span.z0, 1.0), (span.z1, -1.0)):
        x = _positions(min(span.cracked_m, span.shear_span_m), spacing_m, rng)
        widths = flexural_width_m(cfg, span, demand.drift, x, spacing_m)
        for xi, wi in zip(x[widths >= w_lo], widths[widths >= w_lo]):
            for face in across:
                cracks.append(("flexural", _flexural(cfg, sec, face, end + sense * xi,
                                                     min(wi, w_hi), rng)))
    width = shear_width_m(demand.drift, spacing_m)
    if span.shear_governs and width >= w_lo:
        for face in along:
            for z in span.z0 + _positions(span.z1 - span.z0, spacing_m, rng):
                cracks.append(("shear", _shear(cfg, sec, face, float(z), min(width, w_hi), rng)))
    return cracks


def _finish(cfg: DamageConfig, sec: _Section, span: SpanMechanics, cracks: _Raw,
            rng: np.random.Generator, echelon_rng: np.random.Generator
            ) -> list[tuple[str, list[_Polyline]]]:
    """Keep each crack within its span, fork some and run some en echelon (their pieces and
    bridges, without the fork): (kind, [trunk, fork?]) or (kind, [pieces, bridges]). The
    steps draw from ``echelon_rng`` alone, so ``rng`` draws what it drew without them and
    every crack that does not run en echelon is as it was."""
    out = []
    for kind, line in cracks:
        if kind == "flexural":  # one near an end runs along the joint with the beam or footing
            line = (line[0], np.clip(line[1], span.z0, span.z1), line[2])
        else:  # a diagonal crack ends at the joint
            line = _clip_z(line, span.z0, span.z1)
        if line is None:
            continue
        lines = [line]
        if rng.random() < cfg.branch_probability:
            middle = float(line[0][len(line[0]) // 2])
            fork = _branch(line, sec.face_bounds(middle), rng)
            if fork is not None and np.all((fork[1] >= span.z0) & (fork[1] <= span.z1)):
                lines.append(fork)
        if cfg.echelon_probability and echelon_rng.random() < cfg.echelon_probability:
            lines = [(piece[0], np.clip(piece[1], span.z0, span.z1), piece[2])
                     for piece in _echelon(line, echelon_rng)]
        out.append((kind, lines))
    return out


def _network(sec: _Section, cracks: list[tuple[str, list[_Polyline]]],
             axes: tuple[int, int, int] = (0, 1, 2)) -> CrackNetwork:
    """The network of ``cracks`` on ``sec``; the generators' x, y, z (z the member's axis) are
    the mesh frame's axes ``axes``."""
    if not cracks:
        return empty_network()
    lines = [(k, line) for k, (_, group) in enumerate(cracks) for line in group]
    s, z, w = (np.concatenate([line[i] for _, line in lines]) for i in range(3))
    index = np.repeat(np.arange(len(lines)), [len(line[0]) for _, line in lines])
    canonical, widths, which = sec.segments(s, z, w, index)
    mesh = np.empty_like(canonical)
    mesh[..., list(axes)] = canonical
    owner = np.array([k for k, _ in lines], np.int32)
    return CrackNetwork(mesh, widths, owner[which], tuple(kind for kind, _ in cracks), True)


def column_cracks(cfg: DamageConfig, section_m: tuple[float, float],
                  spans: Sequence[tuple[float, float]], demand: DriftDemand,
                  rng: np.random.Generator) -> CrackNetwork:
    """The crack network of a column of section (a, b) (along x, along y) whose clear spans
    run from z0 to z1 in its mesh frame, under ``demand``. Cracks are spaced at the column's
    hoop spacing, drawn from [damage] stirrup_spacing_m: hoops start the cracks (docs/design.md
    gives the source)."""
    sec = _Section(*section_m)
    spacing = float(rng.uniform(*cfg.stirrup_spacing_m))
    echelon_rng = child_rng(rng)
    cracks = []
    for z0, z1 in spans:
        span = span_mechanics(cfg, z0, z1, section_m[demand.axis], demand.drift)
        cracks += _finish(cfg, sec, span, _span_cracks(cfg, sec, span, demand, spacing, rng),
                          rng, echelon_rng)
    return _network(sec, cracks)


def _soffit_cracks(cfg: DamageConfig, sec: _Section, span: SpanMechanics, spacing_m: float,
                   rng: np.random.Generator) -> _Raw:
    """Gravity cracks across the soffit (face 3) around midspan, turning up the sides."""
    w_lo, w_hi = cfg.crack_width_m
    x = _positions(span.z1 - span.z0, spacing_m, rng)
    widths = soffit_width_m(cfg, span, x, spacing_m)
    return [("flexural", _flexural(cfg, sec, 3, span.z0 + xi, min(wi, w_hi), rng))
            for xi, wi in zip(x[widths >= w_lo], widths[widths >= w_lo])]


def beam_cracks(cfg: DamageConfig, extents_m: tuple[float, float, float], axis: int,
                span_m: tuple[float, float], drift: float, rng: np.random.Generator
                ) -> CrackNetwork:
    """The crack network of a box beam of ``extents_m`` (x, y, z; centred) running along mesh
    axis ``axis`` (0: x, 1: y), clear between its supports at ``span_m`` on that axis. Its ends
    rotate with the joints by the drift of its columns: flexural cracks near both supports on
    the top and the soffit (and shear cracks where a / d governs), as a column's; gravity
    cracks in the soffit at midspan. Cracks are spaced at the stirrup spacing."""
    other = 1 - axis
    sec = _Section(extents_m[other], extents_m[2])  # generators' y is the mesh's z
    spacing = float(rng.uniform(*cfg.stirrup_spacing_m))
    span = span_mechanics(cfg, *span_m, extents_m[2], drift)
    raw = (_span_cracks(cfg, sec, span, DriftDemand(drift, 1), spacing, rng)
           + _soffit_cracks(cfg, sec, span, spacing, rng))
    return _network(sec, _finish(cfg, sec, span, raw, rng, child_rng(rng)), (other, 2, axis))
