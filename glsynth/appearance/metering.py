"""A camera's exposure metered on the face it aims at ([lighting] metering = "face";
docs/design.md, "Metered exposure").

A camera's light meter sets the exposure so that what it sees averages middle grey. A view
aimed at a member's face at 0.3-3 m sees little but that face, so the meter reads the face's
luminance: its albedo times the irradiance it receives over pi (a diffuse surface); its
automatic white balance makes that irradiance white (the ground's green bounce under a deck,
the sky's blue on a face in shade). The irradiance is the sun's where the aimed point sees
the sun, plus the sky's and the lit ground's (the renderer's spherical harmonics) through the
share of the sky that no part hides.
Parts hide light by their triangles, found through their boxes (numpy ray casts,
glsynth.world.visibility): no GL, no ray-cast library.
"""

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from glsynth.appearance.materials import Material, surface_albedo
from glsynth.world.cameras import FaceAim
from glsynth.world.environment import Part, PartKind
from glsynth.world.lighting import LUMINANCE, Lighting, sh_basis
from glsynth.world.visibility import rays_meet_triangles

MID_GREY = 0.18
"""The linear luminance a metered view's aimed face gets (18 % grey, as light meters aim)."""

FACE_NORMALS = {"+x": (1.0, 0.0, 0.0), "-x": (-1.0, 0.0, 0.0), "+y": (0.0, 1.0, 0.0),
                "-y": (0.0, -1.0, 0.0), "-z": (0.0, 0.0, -1.0)}
"""FaceAim.face's outward normal in the member's mesh frame."""

SKY_RAYS = 256
"""Cosine-weighted directions over the face's hemisphere for its openness (a fixed spiral:
no generator, the same directions every time); 1/sqrt(256) = 6 % at most in the share."""

LIFT_M = 0.01
"""Rays start this far off the face, along its normal, so that the member itself hides none."""


def hemisphere(normal: np.ndarray, count: int = SKY_RAYS) -> np.ndarray:
    """``count`` cosine-weighted unit directions about ``normal`` (a Fibonacci spiral on the
    disk, lifted onto the hemisphere: equal weights)."""
    k = np.arange(count) + 0.5
    r, phi = np.sqrt(k / count), k * math.pi * (3.0 - math.sqrt(5.0))
    local = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1.0 - r * r)], 1)
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t = np.cross(normal, helper)
    t /= np.linalg.norm(t)
    return local @ np.stack([t, np.cross(normal, t), normal])


def blocked(origin: np.ndarray, dirs: np.ndarray, parts: Sequence[Part],
            boxes: "PartBoxes | None" = None) -> np.ndarray:
    """(N,) bool: whether each ray from ``origin`` along ``dirs`` (N, 3) meets a part: its
    box in its mesh frame first (slab test, every part's at once), then, for the rays that
    meet the box, its triangles. Boxes alone are no proxy for the parts swept along the track
    (slab, girders, rails, ground): their mesh frame is the world's, so on a track running
    diagonally to the world axes a 40 m slab's box covers a 28 m square and hid the sun from
    every column under it (views metered for shade came out white). ``boxes``: part_boxes
    of ``parts``, where the caller casts several times."""
    hit = np.zeros(len(dirs), bool)
    if not parts:
        return hit
    lo, hi, rotation, shift = boxes or part_boxes(parts)
    o = np.einsum("pji,pj->pi", rotation, origin - shift)  # origin in each mesh frame
    d = np.matmul(dirs, rotation)  # (P, N, 3): dirs in each mesh frame (einsum: 40x the time)
    with np.errstate(divide="ignore", invalid="ignore"):
        t0, t1 = (lo[:, None] - o[:, None]) / d, (hi[:, None] - o[:, None]) / d
    # Over the three slabs, NaN (a ray in a box's side plane: 0 / 0) left out as nanmax and
    # nanmin leave it out, axis by axis: a third of their time on a length-3 axis.
    entry, leave = np.minimum(t0, t1), np.maximum(t0, t1)
    near = np.fmax(np.fmax(entry[..., 0], entry[..., 1]), entry[..., 2])
    far = np.fmin(np.fmin(leave[..., 0], leave[..., 1]), leave[..., 2])
    meets = far >= np.maximum(near, 0.0)  # (P, N)
    for index in np.flatnonzero(meets.any(axis=1)):
        candidates = ~hit & meets[index]
        if candidates.any():
            part = parts[index]
            tri = part.world_vertices()[part.mesh.faces]
            hit[candidates] = rays_meet_triangles(origin, dirs[candidates], tri)
    return hit


PartBoxes = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
"""(P, 3) box corners low and high in each part's mesh frame, (P, 3, 3) each frame's
rotation and (P, 3) its origin (world)."""


def part_boxes(parts: Sequence[Part]) -> PartBoxes:
    """The boxes that ``blocked`` tests first, gathered once for several casts."""
    bounds = np.array([p.mesh.bounds for p in parts], float)
    return (bounds[:, 0], bounds[:, 1], np.array([p.pose[:3, :3] for p in parts], float),
            np.array([p.pose[:3, 3] for p in parts], float))


def face_irradiance(aim: FaceAim, parts: Sequence[Part], lighting: Lighting,
                    boxes: PartBoxes | None = None) -> np.ndarray:
    """Linear RGB irradiance (3,) on the aimed face at its aimed point: the sun's (white)
    where it is not hidden, and the sky's and ground's through the face's unhidden share.
    ``boxes``: part_boxes of ``parts``, where the caller meters several faces."""
    member = next(p for p in parts if p.name == aim.member)
    normal = member.pose[:3, :3] @ np.array(FACE_NORMALS[aim.face])
    origin = np.asarray(aim.point, float) + LIFT_M * normal
    # The far terrain is left out, as the sky-visibility maps leave it out (its hills lie
    # under a few degrees of the horizon); the town's merged strips hide light by their
    # triangles like every other part.
    keep = np.array([p.name != aim.member and p.kind is not PartKind.TERRAIN for p in parts],
                    bool)
    others = [p for p, k in zip(parts, keep, strict=True) if k]
    boxes = part_boxes(parts) if boxes is None else boxes
    sun = lighting.sun_direction
    sun_share = lighting.sun_irradiance * max(float(sun @ normal), 0.0)
    seen = hemisphere(normal)
    seen = seen[seen[:, 2] > 0.0]  # the sky the face sees (none from a soffit)
    # One cast for the sun, the face's sky and the point's: a part's triangles are gathered
    # and met once, whichever rays reach its box.
    hidden = blocked(origin, np.concatenate([sun[None], seen, hemisphere(np.array(
        [0.0, 0.0, 1.0]))]), others, tuple(a[keep] for a in boxes) if others else None)
    if sun_share > 0.0 and hidden[0]:
        sun_share = 0.0
    face_open = 1.0 - float(hidden[1:1 + len(seen)].mean()) if len(seen) else 0.0
    point_open = 1.0 - float(hidden[1 + len(seen):].mean())
    sky_sh, ground_sh = lighting.irradiance_sh()
    basis = sh_basis(normal[None])[0]
    # As shaders/color.frag weighs them: the sky through the share the face sees open, the
    # ground's light through the point's openness to the whole sky, but at least a quarter.
    ambient = (np.maximum(basis @ sky_sh, 0.0) * face_open
               + np.maximum(basis @ ground_sh, 0.0) * (0.25 + 0.75 * point_open))
    return sun_share + ambient


def face_albedo(member: Part, material: Material) -> float:
    """Luminance of the member's mean linear base colour, weathering tint included."""
    albedo = surface_albedo([member], {member.name: material})
    return float(albedo * np.asarray(material.weathering_tint or (1.0, 1.0, 1.0)) @ LUMINANCE)


def metered(lighting: Lighting, aim: FaceAim, parts: Sequence[Part], albedo: float,
            boxes: PartBoxes | None = None) -> Lighting:
    """``lighting`` with the exposure that puts the aimed face, of luminance albedo
    ``albedo`` (face_albedo), at MID_GREY (as a diffuse surface, its radiance is its albedo
    times its irradiance over pi), and the white balance that makes the light on it white,
    as a camera's automatic white balance does for a grey scene. ``boxes``: part_boxes of
    ``parts``, gathered once where the caller meters several faces."""
    irradiance = np.maximum(face_irradiance(aim, parts, lighting, boxes), 1e-9)
    luminance = float(irradiance @ LUMINANCE)
    balance = tuple(float(v) for v in luminance / irradiance)  # the light grey, as bright
    # A face in full shade under a closed deck: an exposure of at most 1000.
    exposure = MID_GREY / max(albedo * luminance / math.pi, MID_GREY / 1000.0)
    return replace(lighting, exposure=exposure, white_balance=balance)
