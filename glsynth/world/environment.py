"""One random environment: a trajectory of N standard-design viaducts as named, tagged meshes.

Every part has a unique name, a kind (PartKind, which gives its component id in
glsynth.core.labels), the viaduct it belongs to (None for environment-wide parts), a mesh in its
own frame, a 4x4 world-from-mesh pose and, for one of a left/right pair, its side. Code asks a
part's kind, never its name. Footings are underground and not modelled; columns start at the ground.
"""

from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum

import numpy as np
import trimesh

from glsynth.core import design
from glsynth.core.config import Config
from glsynth.core.geometry import transform_points
from glsynth.core.labels import Component
from glsynth.core.seeding import Stream, make_rng
from glsynth.world import meshes
from glsynth.world.fences import open_fence
from glsynth.world.trajectory import Trajectory, generate_trajectory


class PartKind(Enum):
    """What a part is; the value is its word in part names (slab_v00, beam_v00_tie_1)."""

    SLAB = "slab"
    GIRDER = "girder"
    """Swept along the track under the slab, one on each column line."""
    CROSS_BEAM = "cross"
    """A box across the track over a row of columns."""
    TIE_BEAM = "tie"
    """A box between columns at mid height, where Table 3 has intermediate beams."""
    COLUMN = "column"
    SLEEPER = "sleeper"
    RAIL = "rail"
    WIRE = "wire"
    FENCE = "fence"
    POLE = "pole"
    PORTAL = "portal"
    GROUND = "ground"
    SCENE = "scene"
    """A photo panel beside or across the track."""
    BUILDING = "building"
    """The town's walls: houses, blocks and warehouses (glsynth.world.surroundings)."""
    ROOF = "roof"
    ROAD = "road"
    """Roads and parking, just above the ground."""
    VEHICLE = "vehicle"
    TREE = "tree"
    """Crowns, trunks and hedges."""
    BARRIER = "barrier"
    """Sound barriers beside the roads."""
    UTILITY = "utility"
    """Utility poles and their wires."""
    TERRAIN = "terrain"
    """The land around the town, rising to a ring of far hills."""
    CRUSHED = "crushed"
    """A viaduct's crushed column concrete: the reduced sections of its severe columns' hinge
    bands (glsynth.world.severe)."""
    REBAR = "rebar"
    """A viaduct's exposed reinforcement in those bands: buckled bars and broken hoops."""
    JACKET = "jacket"
    """Steel jackets of a viaduct's retrofitted columns (glsynth.world.others)."""
    BRACE = "brace"
    """Steel X braces between the columns of a viaduct's rows."""
    DOWNPIPE = "downpipe"
    """Drainage pipes from the slab down a column."""
    TROUGH = "trough"
    """Cable troughs under the slab overhang."""
    SIGN = "sign"
    """Numbered plates on columns."""

    @property
    def component(self) -> Component:
        return _COMPONENT[self]


_COMPONENT = {
    PartKind.SLAB: Component.SLAB, PartKind.GIRDER: Component.BEAM,
    PartKind.CROSS_BEAM: Component.BEAM, PartKind.TIE_BEAM: Component.BEAM,
    PartKind.COLUMN: Component.COLUMN, PartKind.SLEEPER: Component.SLEEPER,
    PartKind.RAIL: Component.RAIL, PartKind.WIRE: Component.NONSTRUCTURAL,
    PartKind.FENCE: Component.NONSTRUCTURAL, PartKind.POLE: Component.NONSTRUCTURAL,
    PartKind.PORTAL: Component.NONSTRUCTURAL, PartKind.GROUND: Component.NONBRIDGE,
    PartKind.SCENE: Component.NONBRIDGE, PartKind.BUILDING: Component.NONBRIDGE,
    PartKind.ROOF: Component.NONBRIDGE, PartKind.ROAD: Component.NONBRIDGE,
    PartKind.VEHICLE: Component.NONBRIDGE, PartKind.TREE: Component.NONBRIDGE,
    PartKind.BARRIER: Component.NONBRIDGE, PartKind.UTILITY: Component.NONSTRUCTURAL,
    PartKind.TERRAIN: Component.NONBRIDGE,
    PartKind.CRUSHED: Component.COLUMN, PartKind.REBAR: Component.COLUMN,
    PartKind.JACKET: Component.OTHER, PartKind.BRACE: Component.OTHER,
    PartKind.DOWNPIPE: Component.OTHER, PartKind.TROUGH: Component.OTHER,
    PartKind.SIGN: Component.OTHER}

BOX_BEAMS = frozenset({PartKind.CROSS_BEAM, PartKind.TIE_BEAM})
"""The beams built as boxes between columns (the girders are swept along the track)."""
OPEN_KINDS = frozenset({PartKind.GROUND, PartKind.SCENE, PartKind.ROAD, PartKind.TERRAIN})
"""The kinds swept as open surfaces; every other part is a closed solid."""


@dataclass(frozen=True)
class Part:
    name: str
    kind: PartKind
    viaduct: int | None
    mesh: trimesh.Trimesh
    pose: np.ndarray
    """4x4 world-from-mesh."""
    side: str | None = None
    """"l" (+ across, left of the track) or "r" for one of a left/right pair, else None."""

    @property
    def component(self) -> Component:
        return self.kind.component

    def world_vertices(self) -> np.ndarray:
        return transform_points(self.pose, self.mesh.vertices)


@dataclass(frozen=True)
class ColumnInfo:
    name: str
    center_xy: tuple[float, float]
    bottom_z: float
    top_z: float
    heading: float
    section_m: tuple[float, float]
    """(along track, across track)."""


@dataclass(frozen=True)
class ViaductInfo:
    index: int
    start_s_m: float
    height_m: float
    radius_m: float
    """math.inf when straight."""
    sections: design.SectionChoice
    footprint_xy: np.ndarray
    """Deck outline: left edge forward, then right edge back, (P, 2) world metres."""
    columns: tuple[ColumnInfo, ...]


@dataclass(frozen=True)
class Environment:
    root_seed: int
    env_index: int
    config: Config
    trajectory: Trajectory
    viaducts: tuple[ViaductInfo, ...]
    parts: tuple[Part, ...]


def _samples(s0: float, s1: float, step: float, breaks: np.ndarray) -> np.ndarray:
    """Arc lengths from s0 to s1 at most ``step`` apart, including any breakpoints inside."""
    n = max(1, int(np.ceil((s1 - s0) / step - 1e-9)))
    s = np.linspace(s0, s1, n + 1)
    inside = breaks[(breaks > s0) & (breaks < s1)]
    return np.unique(np.concatenate([s, inside]))


def viaduct_samples(config: Config, trajectory: Trajectory, i: int) -> np.ndarray:
    """The arc lengths at which viaduct i's slab, girders, track and fences are swept."""
    length = config.design.length_m
    return _samples(i * length, (i + 1) * length, config.environment.sweep_step_m,
                    trajectory.centres_s)


GIRDER_SIDES = ("l", "r")
"""A viaduct's girders, beam_vXX_girder_l and _r: on the left (+ across) and right column line."""


def girder_profile(d: design.StandardDesign, side: str) -> np.ndarray:
    """The rectangle swept along the track for the girder on ``side`` (meshes.rectangle: soffit,
    outer or inner side, top, side): (across, up) from the deck top's centre line."""
    u = (1 if side == "l" else -1) * d.column_spacing_m / 2
    return meshes.rectangle(u - d.girder_width_m / 2, u + d.girder_width_m / 2,
                            -d.slab_thickness_m - d.girder_depth_m, -d.slab_thickness_m)


class _Builder:
    """Holds the trajectory and design while parts are made; the result is plain data."""

    def __init__(self, config: Config, trajectory: Trajectory) -> None:
        self.config = config
        self.cfg = config.environment
        self.d = config.design
        self.traj = trajectory
        self.up = np.array([0.0, 0.0, 1.0])
        self.parts: list[Part] = []

    def add(self, name: str, kind: PartKind, viaduct: int | None,
            mesh: trimesh.Trimesh, pose: np.ndarray | None = None, side: str | None = None
            ) -> None:
        self.parts.append(Part(name, kind, viaduct, mesh, np.eye(4) if pose is None else pose,
                               side))

    def along(self, s: np.ndarray, offset: float = 0.0, base: str = "deck",
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Path at lateral ``offset`` on the deck top (or the ground), with its sweep frame."""
        points, _, normal = self.traj.frame(s)
        if base == "ground":
            points[:, 2] = self.traj.ground_at(s)
        path = points + offset * normal
        return path, normal, np.tile(self.up, (len(s), 1))

    def deck_sweep(self, s: np.ndarray, profile: np.ndarray, **kw) -> trimesh.Trimesh:
        path, across, up = self.along(s)
        return meshes.sweep(profile, path, across, up, closed=True, caps=True, **kw)

    # --- viaduct ---------------------------------------------------------------------------
    def viaduct(self, i: int) -> ViaductInfo:
        d, traj = self.d, self.traj
        s0 = i * d.length_m
        height = float(traj.heights_m[i])
        radius = float(traj.radii_m[i])
        sections = design.cross_sections(height, radius)
        s = viaduct_samples(self.config, traj, i)
        tag = f"v{i:02d}"
        t_s, half_w = d.slab_thickness_m, d.deck_width_m / 2
        self.add(f"slab_{tag}", PartKind.SLAB, i,
                 self.deck_sweep(s, meshes.rectangle(-half_w, half_w, -t_s, 0.0)))
        for side in GIRDER_SIDES:
            self.add(f"beam_{tag}_girder_{side}", PartKind.GIRDER, i,
                     self.deck_sweep(s, girder_profile(d, side)), side=side)
        columns = self.columns_and_beams(i, sections, tag)
        self.track(i, s, tag)
        self.fences_and_poles(i, s, tag)
        left, _, _ = self.along(s, half_w)
        right, _, _ = self.along(s, -half_w)
        footprint = np.concatenate([left[:, :2], right[::-1, :2]])
        return ViaductInfo(i, s0, height, radius, sections, footprint, columns)

    def columns_and_beams(self, i: int, sections: design.SectionChoice, tag: str
                          ) -> tuple[ColumnInfo, ...]:
        d, traj = self.d, self.traj
        a, b = (x / 100.0 for x in sections.column_cm)
        rows_s = i * d.length_m + np.array(d.column_rows_s)
        points, _, normal = traj.frame(rows_s)
        heading = traj.heading(rows_s)
        underside = traj.deck_at(rows_s) - d.slab_thickness_m - d.girder_depth_m
        columns = []
        centers = np.zeros((len(rows_s), 2, 3))
        for r, s_c in enumerate(rows_s):
            # Ground is linear in s under a column: its lowest point is at one footprint edge.
            bottom = float(min(traj.ground_at(s_c - a / 2), traj.ground_at(s_c + a / 2)))
            top = float(underside[r] + d.embed_m)
            # Cross beam over the row, reaching from girder edge to girder edge.
            cross_len = d.column_spacing_m + d.girder_width_m
            cz = underside[r] + (d.girder_depth_m + d.embed_m) / 2
            self.add(f"beam_{tag}_cross_{r}", PartKind.CROSS_BEAM, i,
                     meshes.box((d.crossbeam_width_m, cross_len, d.girder_depth_m + d.embed_m)),
                     meshes.pose(heading[r], [points[r, 0], points[r, 1], cz]))
            for k, (side, sign) in enumerate((("l", 1), ("r", -1))):
                xy = points[r, :2] + sign * d.column_spacing_m / 2 * normal[r, :2]
                centers[r, k] = [xy[0], xy[1], bottom]
                name = f"column_{tag}_{r}{side}"
                self.add(name, PartKind.COLUMN, i, meshes.box((a, b, top - bottom)),
                         meshes.pose(heading[r], [xy[0], xy[1], (top + bottom) / 2]), side)
                columns.append(ColumnInfo(name, (float(xy[0]), float(xy[1])), bottom, top,
                                          float(heading[r]), (a, b)))
        if sections.intermediate_beam_cm is not None:
            depth, width = (x / 100.0 for x in sections.intermediate_beam_cm)
            z = 0.5 * (max(c.bottom_z for c in columns) + underside.min())
            for r in range(len(rows_s)):  # across the track, between the pair of a row
                mid = centers[r].mean(axis=0)
                self.add(f"beam_{tag}_tie_{r}", PartKind.TIE_BEAM, i,
                         meshes.box((width, d.column_spacing_m, depth)),
                         meshes.pose(heading[r], [mid[0], mid[1], z]))
            for k, side in enumerate("lr"):  # along the track, between neighbouring rows
                for r in range(len(rows_s) - 1):
                    p, q = centers[r, k], centers[r + 1, k]
                    chord = q[:2] - p[:2]
                    mid = (p[:2] + q[:2]) / 2
                    self.add(f"beam_{tag}_tie_{side}{r}", PartKind.TIE_BEAM, i,
                             meshes.box((float(np.hypot(*chord)), width, depth)),
                             meshes.pose(float(np.arctan2(chord[1], chord[0])),
                                         [mid[0], mid[1], z]))
        return tuple(columns)

    def track(self, i: int, s: np.ndarray, tag: str) -> None:
        d, traj = self.d, self.traj
        h_sl = d.sleeper_height_m
        n_sl = int(round(d.length_m / d.sleeper_spacing_m))
        s_sl = i * d.length_m + (np.arange(n_sl) + 0.5) * d.sleeper_spacing_m
        points, _, normal = traj.frame(s_sl)
        heading = traj.heading(s_sl)
        head, foot, web = d.rail_head_width_m, d.rail_foot_width_m, d.rail_web_width_m
        h_rail = d.rail_height_m
        # Rail as three convex prisms: foot, web, head (an I-shaped section).
        rail_parts = ((foot, 0.0, 0.2 * h_rail), (web, 0.2 * h_rail, 0.75 * h_rail),
                      (head, 0.75 * h_rail, h_rail))
        for t, sign in enumerate((1, -1)):
            u_track = sign * d.track_spacing_m / 2
            centre = points + u_track * normal
            centre[:, 2] += h_sl / 2
            sleeper_poses = np.stack([meshes.pose(h, c) for h, c in zip(heading, centre)])
            self.add(f"sleeper_{tag}_t{t}", PartKind.SLEEPER, i, meshes.boxes(
                (d.sleeper_width_m, d.sleeper_length_m, h_sl), sleeper_poses))
            for side, rsign in (("l", 1), ("r", -1)):
                u = u_track + rsign * (d.gauge_m + head) / 2
                pieces = [self.deck_sweep(s, meshes.rectangle(u - w / 2, u + w / 2,
                                                              h_sl + z0, h_sl + z1))
                          for w, z0, z1 in rail_parts]
                self.add(f"rail_{tag}_t{t}{side}", PartKind.RAIL, i,
                         trimesh.util.concatenate(pieces), side=side)
            for kind, height in (("contact", d.contact_wire_height_m),
                                 ("messenger", d.messenger_wire_height_m)):
                path, across, up = self.along(s, u_track)
                path[:, 2] += h_sl + h_rail + height
                self.add(f"nonstructural_{tag}_wire_{kind}_t{t}", PartKind.WIRE, i,
                         meshes.sweep(meshes.circle(d.wire_radius_m, self.cfg.cylinder_segments),
                                      path, across, up, closed=True, smooth=True, caps=True))

    def fences_and_poles(self, i: int, s: np.ndarray, tag: str) -> None:
        d, traj = self.d, self.traj
        half_w, t_f = d.deck_width_m / 2, d.fence_thickness_m
        for side, sign in (("l", 1), ("r", -1)):
            lo, hi = sorted((sign * half_w, sign * (half_w - t_f)))
            fence = (open_fence(traj, d, s, lo, hi, self.deck_sweep)
                     if self.cfg.fences == "open" else
                     self.deck_sweep(s, meshes.rectangle(lo, hi, 0.0, d.fence_height_m)))
            self.add(f"nonstructural_{tag}_fence_{side}", PartKind.FENCE, i, fence, side=side)
        s_mid = np.array([i * d.length_m + d.length_m / 2])
        points, _, normal = traj.frame(s_mid)
        heading = float(traj.heading(s_mid)[0])
        u_pole = half_w - t_f - d.pole_radius_m - 0.1
        vertical = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, d.pole_height_m]])
        x_axis, y_axis = np.tile([1.0, 0, 0], (2, 1)), np.tile([0, 1.0, 0], (2, 1))
        for side, sign in (("l", 1), ("r", -1)):
            base = points[0] + sign * u_pole * normal[0]
            self.add(f"nonstructural_{tag}_pole_{side}", PartKind.POLE, i,
                     meshes.sweep(meshes.circle(d.pole_radius_m, self.cfg.cylinder_segments),
                                  vertical, x_axis, y_axis, closed=True, smooth=True, caps=True),
                     meshes.pose(0.0, base), side)
        top = points[0].copy()
        top[2] += d.pole_height_m - d.portal_beam_size_m / 2
        self.add(f"nonstructural_{tag}_portal", PartKind.PORTAL, i,
                 meshes.box((d.portal_beam_size_m, 2 * u_pole, d.portal_beam_size_m)),
                 meshes.pose(heading, top))


def build_environment(config: Config, root_seed: int, env_index: int) -> Environment:
    """Environment ``env_index`` of run ``root_seed``: same inputs, identical meshes."""
    rng = make_rng(root_seed, env_index, Stream.GEOMETRY)
    trajectory = generate_trajectory(config.environment, config.design.length_m, rng)
    builder = _Builder(config, trajectory)
    viaducts = tuple(builder.viaduct(i) for i in range(trajectory.n))
    # Imported here: surroundings and others build on this module's parts and sweeps.
    from glsynth.world.others import build_others
    from glsynth.world.surroundings import build_surroundings

    build_surroundings(builder, root_seed, env_index)
    builder.parts += build_others(config, trajectory, viaducts, builder.parts, root_seed,
                                  env_index)
    env = Environment(root_seed, env_index, config, trajectory, viaducts, tuple(builder.parts))
    if config.damage.geometry:
        from glsynth.world.severe import with_severe_damage  # it builds on this module's Part

        env = with_severe_damage(env)
    return env


def ground_parts(parts: Sequence[Part]) -> list[Part]:
    """The ground strips among ``parts`` (what lights the scene from below)."""
    return [p for p in parts if p.kind is PartKind.GROUND]
