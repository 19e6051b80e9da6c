"""Crack networks on the girders (issue 29), in their mesh frame, which is the world frame.

A girder is a rectangle (glsynth.world.environment.girder_profile) swept along the curved
track in straight pieces between the viaduct's sweep samples (viaduct_samples). Its cracks are
made per clear span, between the faces of the cross beams over neighbouring column rows, on a
straight virtual box (cracks.beam_cracks: the span's length along the girder's centre line,
the girder's width and depth), and mapped onto the mesh: a box point x along the centre line
and (y, z) in the section lands on the mesh's facet strip at that arc length, at the same
place in the section, interpolated over the strip's two triangles as the mesh draws them, so
every mapped point lies on the mesh (to float64 rounding).

Chords: a segment is split first where it crosses a sample (the edge between two facet
strips), so each lies in one strip. A side strip is a planar quad, so a chord there lies on
it. A soffit strip is two triangles, twisted where the grade and the curve meet: their
dihedral angle is about 4 t / w for a twist t = w (ds / R) g / 4 (w the girder's width, ds
the sweep step, R the radius, g the grade), 5e-5 m at w = 1 m, ds = 1 m, R = 100 m (the
smallest [environment] min_radius_m allows) and g = 2 % (Table 4's largest), so a 5 cm
segment crossing the diagonal leaves the surface by about 0.05 x 2e-4 / 4 = 2.5e-6 m, the
sagitta of a chord over a kink (its length times the angle, over 4; 2.6e-6 m measured,
tests/test_girder_cracks.py bounds it by 1e-4 m). Unsplit, a 5 cm segment
across a sample would leave the side's surface by up to 0.05 (ds / R) / 4 = 1.25e-4 m at
R = 100 m: more than the cracks' narrowest half width.

Lengths: the box's x is arc length along the girder's centre line; along its edges the
facets are longer or shorter by w / 2R (0.5 % at R = 100 m), which stretches the cracks
there by as much.

The girder's top lies under the slab, so segments on it are dropped: the hogging cracks near
the supports show only where they turn down the sides.
"""

import dataclasses
from dataclasses import dataclass

import numpy as np

from glsynth.appearance.cracks import CrackNetwork, beam_cracks, empty_network
from glsynth.core.config import DamageConfig
from glsynth.core.geometry import segment_distance
from glsynth.world.environment import Environment, Part, girder_profile, viaduct_samples

_UP = np.array([0.0, 0.0, 1.0])
_ON_TOP_M = 1e-9
"""A box point this close to the section's top lies on it."""


@dataclass(frozen=True)
class GirderSweep:
    """The straight pieces a girder's mesh was swept in (glsynth.world.meshes.sweep)."""

    path: np.ndarray
    """(K, 3) the deck top's centre line at the sweep samples."""
    across: np.ndarray
    """(K, 3) unit left normals there."""
    profile: np.ndarray
    """(4, 2) the swept rectangle (across, up), counter-clockwise from the soffit's edge."""
    g: np.ndarray
    """(K,) arc length along the girder's centre line (the section's centre) at the samples."""
    supports_g: np.ndarray
    """Arc length g at each column row."""

    @property
    def centre(self) -> np.ndarray:
        return self.profile.mean(axis=0)

    def vertex(self, k: np.ndarray, q: np.ndarray) -> np.ndarray:
        """(n, 3) mesh points of profile points ``q`` (n, 2) at samples ``k`` (n,)."""
        return self.path[k] + q[:, :1] * self.across[k] + q[:, 1:] * _UP


def girder_sweep(env: Environment, part: Part) -> GirderSweep:
    """The sweep of girder ``part`` (PartKind.GIRDER, on side l or r) of ``env``."""
    d, traj = env.config.design, env.trajectory
    s = viaduct_samples(env.config, traj, part.viaduct)
    path, _, across = traj.frame(s)
    profile = girder_profile(d, part.side)
    centre = profile.mean(axis=0)
    line = path + centre[0] * across + centre[1] * _UP
    g = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(line, axis=0), axis=1))])
    rows = part.viaduct * d.length_m + np.array(d.column_rows_s)
    return GirderSweep(path, across, profile, g, np.interp(rows, s, g))


def girder_spans(sweep: GirderSweep, crossbeam_width_m: float) -> list[tuple[float, float]]:
    """Clear spans (g0, g1) between the cross beams' faces over neighbouring rows; the
    cantilevers past the end rows get none (their hogging cracks lie on the top)."""
    half = crossbeam_width_m / 2
    return [(float(a + half), float(b - half))
            for a, b in zip(sweep.supports_g[:-1], sweep.supports_g[1:])]


def _split_at(net: CrackNetwork, cuts: np.ndarray) -> CrackNetwork:
    """``net`` with every segment split where its x crosses one of ``cuts`` (sorted), in
    order. Few segments cross a cut (docs/results.md, "Measurements behind code choices"):
    the rest are written at once, through the same arithmetic (p0 + t (p1 - p0), t = 0 and
    1)."""
    p, w, c = net.points, net.widths_m, net.crack
    lo, hi = np.minimum(p[:, 0, 0], p[:, 1, 0]), np.maximum(p[:, 0, 0], p[:, 1, 0])
    first, last = np.searchsorted(cuts, lo, "right"), np.searchsorted(cuts, hi, "left")
    counts = 1 + np.maximum(last - first, 0)
    start = np.cumsum(counts) - counts
    points = np.empty((int(counts.sum()), 2, 3))
    widths = np.empty((len(points), 2))
    whole = counts == 1
    for end, t in enumerate((0.0, 1.0)):
        points[start[whole], end] = p[whole, 0] + t * (p[whole, 1] - p[whole, 0])
        widths[start[whole], end] = w[whole, 0] + t * (w[whole, 1] - w[whole, 0])
    for i in np.flatnonzero(~whole):
        x0, x1 = p[i, 0, 0], p[i, 1, 0]
        t = np.sort(np.concatenate([[0.0], (cuts[first[i]:last[i]] - x0) / (x1 - x0), [1.0]]))
        ends = p[i, 0] + t[:, None] * (p[i, 1] - p[i, 0])
        width = w[i, 0] + t * (w[i, 1] - w[i, 0])
        rows = slice(start[i], start[i] + counts[i])
        points[rows] = np.stack([ends[:-1], ends[1:]], axis=1)
        widths[rows] = np.stack([width[:-1], width[1:]], axis=1)
    return CrackNetwork(points, widths, np.repeat(c, counts).astype(np.int32), net.kinds,
                        net.rough)


def _edges(profile: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For section points ``q`` (n, 2) on the rectangle's outline: the edge j (from corner j to
    j + 1) each lies on, and its parameter e in [0, 1] along it."""
    gap, e = segment_distance(q[:, None], profile, np.roll(profile, -1, axis=0))
    j = np.argmin(gap, axis=1)
    return j, e[np.arange(len(q)), j]


def on_mesh(sweep: GirderSweep, points: np.ndarray) -> np.ndarray:
    """Mesh points (n, 3) of box points (n, 3): x the arc length g along the girder, (y, z)
    the offset from the section's centre (across, up). The facet strip between samples k and
    k + 1 is the triangles (k, A), (k, B), (k + 1, B) and (k, A), (k + 1, B), (k + 1, A) of
    the profile edge A-B (glsynth.world.meshes.sweep), interpolated as drawn."""
    k = np.clip(np.searchsorted(sweep.g, points[:, 0], "right") - 1, 0, len(sweep.g) - 2)
    f = ((points[:, 0] - sweep.g[k]) / (sweep.g[k + 1] - sweep.g[k]))[:, None]
    j, e = _edges(sweep.profile, sweep.centre + points[:, 1:])
    e = e[:, None]
    a, b = sweep.profile[j], sweep.profile[(j + 1) % len(sweep.profile)]
    a0, b0, a1, b1 = (sweep.vertex(kk, q) for kk, q in ((k, a), (k, b), (k + 1, a), (k + 1, b)))
    upper = a0 + e * (b0 - a0) + f * (b1 - b0)  # triangle (k, A), (k, B), (k + 1, B)
    lower = a0 + f * (a1 - a0) + e * (b1 - a1)  # triangle (k, A), (k + 1, B), (k + 1, A)
    return np.where(e >= f, upper, lower)


def _below_top(net: CrackNetwork, depth_m: float) -> CrackNetwork:
    """``net`` without its segments on the section's top (z = depth / 2), cracks renumbered."""
    return net.subset(~np.all(net.points[..., 2] >= depth_m / 2 - _ON_TOP_M, axis=1))


def _joined(nets: list[CrackNetwork]) -> CrackNetwork:
    nets = [n for n in nets if len(n.points)]
    if not nets:
        return empty_network()
    offsets = np.cumsum([0] + [len(n.kinds) for n in nets[:-1]])
    return CrackNetwork(np.concatenate([n.points for n in nets]),
                        np.concatenate([n.widths_m for n in nets]),
                        np.concatenate([n.crack + o for n, o in zip(nets, offsets)]
                                       ).astype(np.int32),
                        tuple(k for n in nets for k in n.kinds), any(n.rough for n in nets))


def girder_cracks(cfg: DamageConfig, sweep: GirderSweep, spans: list[tuple[float, float]],
                  width_m: float, depth_m: float, drift: float, rng: np.random.Generator
                  ) -> CrackNetwork:
    """The crack network of a girder of section ``width_m`` x ``depth_m`` over its clear
    ``spans`` (g0, g1), its ends rotating by ``drift`` (module docstring)."""
    nets = []
    for g0, g1 in spans:
        half = (g1 - g0) / 2
        box = beam_cracks(cfg, (g1 - g0, width_m, depth_m), 0, (-half, half), drift, rng)
        box = _below_top(box, depth_m)
        if not len(box.points):
            continue
        shifted = box.points + np.array([g0 + half, 0.0, 0.0])
        box = _split_at(dataclasses.replace(box, points=shifted), sweep.g)
        mapped = on_mesh(sweep, box.points.reshape(-1, 3)).reshape(box.points.shape)
        nets.append(dataclasses.replace(box, points=mapped))
    return _joined(nets)
