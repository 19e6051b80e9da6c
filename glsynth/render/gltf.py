"""glTF 2.0 binary with the materials glsynth renders: the interchange for other renderers.

Each part is a node (its name, its component in ``extras``) with one primitive, or, for a
member whose damage material has zones (glsynth.appearance.materials.DamageZones), its mesh
cut at the zones' ends: the pieces inside them with the damage material, the pieces outside
with the member's intact concrete (glsynth.render.zone_split), so that the spalling stays in
the hinge zones as the GL renderer confines it (and in the Cycles twin, which imports this
file). Materials are
metallic-roughness: base colour, metallic-roughness (G roughness, B metallic), normal and
emissive textures with their factors, double-sided as the rasterizer draws them. A damaged
column's damage-id mask travels as a texture named in the material's
``extras.glsynth_damage_mask``. Every image is written once, however many materials use it
(the repository's textures are shared by many parts). The sun is a KHR_lights_punctual
directional light.

Conventions: glTF is y-up and glsynth z-up, so each node's matrix includes (x, y, z) ->
(x, z, -y). glTF puts texture coordinate (0, 0) at the image's top-left corner, glsynth at its
bottom-left (as Blender and GL sample it), so v is exported as 1 - v. UVs are multiplied by the
material's uv_scale, as the renderer does, and textures repeat.
"""

import json
import struct
from collections.abc import Mapping, Sequence

import numpy as np
import trimesh

from glsynth.appearance.materials import Material
from glsynth.core.fileio import png_bytes
from glsynth.render.zone_split import intact_material, zone_pieces
from glsynth.world.environment import Part

Z_UP_TO_Y_UP = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]], dtype=float)
_FLOAT, _UINT32 = 5126, 5125
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963
_REPEAT, _LINEAR, _LINEAR_MIPMAP_LINEAR, _NEAREST = 10497, 9729, 9987, 9728


class _Builder:
    """Accumulates the JSON tree and the binary chunk."""

    def __init__(self) -> None:
        self.tree: dict = {"asset": {"version": "2.0", "generator": "glsynth"},
                           "buffers": [], "bufferViews": [], "accessors": [], "images": [],
                           "samplers": [], "textures": [], "materials": [], "meshes": [],
                           "nodes": []}
        self.chunks: list[bytes] = []
        self.offset = 0
        self.images: dict[int, int] = {}
        """id(source array) -> image index."""
        self.sources: list[np.ndarray] = []  # keeps the arrays (and their ids) alive
        self.packed: dict[int, np.ndarray] = {}
        """id(metallic map) -> its metallic-roughness packing."""
        self.samplers: dict[tuple[int, int], int] = {}
        self.textures: dict[tuple[int, int], int] = {}
        """(image, sampler) -> texture index: one texture per pair, however many users."""

    def view(self, data: bytes, target: int | None = None) -> int:
        pad = (-self.offset) % 4
        if pad:
            self.chunks.append(b"\0" * pad)
            self.offset += pad
        view = {"buffer": 0, "byteOffset": self.offset, "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        self.chunks.append(data)
        self.offset += len(data)
        self.tree["bufferViews"].append(view)
        return len(self.tree["bufferViews"]) - 1

    def accessor(self, array: np.ndarray, kind: str, target: int, bounds: bool = False) -> int:
        component = _UINT32 if array.dtype == np.uint32 else _FLOAT
        accessor = {"bufferView": self.view(array.tobytes(), target), "componentType": component,
                    "count": int(array.shape[0]), "type": kind}
        if bounds:
            accessor["min"] = array.min(axis=0).tolist()
            accessor["max"] = array.max(axis=0).tolist()
        self.tree["accessors"].append(accessor)
        return len(self.tree["accessors"]) - 1

    def texture(self, array: np.ndarray, *, nearest: bool = False) -> dict:
        key = id(array)
        if key not in self.images:
            self.tree["images"].append({"bufferView": self.view(png_bytes(array)),
                                        "mimeType": "image/png"})
            self.images[key] = len(self.tree["images"]) - 1
            self.sources.append(array)
        filters = (_NEAREST, _NEAREST) if nearest else (_LINEAR, _LINEAR_MIPMAP_LINEAR)
        if filters not in self.samplers:
            self.tree["samplers"].append({"magFilter": filters[0], "minFilter": filters[1],
                                          "wrapS": _REPEAT, "wrapT": _REPEAT})
            self.samplers[filters] = len(self.tree["samplers"]) - 1
        texture = (self.images[key], self.samplers[filters])
        if texture not in self.textures:
            self.tree["textures"].append({"source": texture[0], "sampler": texture[1]})
            self.textures[texture] = len(self.tree["textures"]) - 1
        return {"index": self.textures[texture]}

    def metallic_roughness(self, metallic: np.ndarray) -> np.ndarray:
        """glTF's packing of a metallic map (G roughness 1, B metallic), made once per map."""
        key = id(metallic)
        if key not in self.packed:
            packed = np.zeros(metallic.shape + (3,), np.uint8)
            packed[..., 1] = 255
            packed[..., 2] = metallic
            self.packed[key] = packed
            self.sources.append(metallic)
        return self.packed[key]

    def material(self, name: str, m: Material) -> int:
        pbr: dict = {"baseColorFactor": [float(c) for c in m.base_color],
                     "metallicFactor": float(m.metallic), "roughnessFactor": float(m.roughness)}
        material: dict = {"name": name, "pbrMetallicRoughness": pbr, "doubleSided": True}
        if m.base_color_map is not None:
            pbr["baseColorTexture"] = self.texture(m.base_color_map)
        if m.metallic_map is not None:
            packed = self.metallic_roughness(m.metallic_map)
            pbr["metallicRoughnessTexture"] = self.texture(packed)
        if m.normal_map is not None:
            material["normalTexture"] = self.texture(m.normal_map)
        if any(m.emissive):
            material["emissiveFactor"] = [float(c) for c in m.emissive]
            if m.emissive_map is not None:
                material["emissiveTexture"] = self.texture(m.emissive_map)
        if m.damage_mask is not None:
            material["extras"] = {"glsynth_damage_mask": self.texture(m.damage_mask,
                                                                      nearest=True)}
        self.tree["materials"].append(material)
        return len(self.tree["materials"]) - 1

    def glb(self) -> bytes:
        binary = b"".join(self.chunks)
        binary += b"\0" * ((-len(binary)) % 4)
        self.tree["buffers"] = [{"byteLength": len(binary)}]
        for key in ("images", "samplers", "textures"):
            if not self.tree[key]:
                del self.tree[key]
        text = json.dumps(self.tree, separators=(",", ":")).encode()
        text += b" " * ((-len(text)) % 4)
        total = 12 + 8 + len(text) + 8 + len(binary)
        return (struct.pack("<4sII", b"glTF", 2, total)
                + struct.pack("<II", len(text), 0x4E4F534A) + text
                + struct.pack("<II", len(binary), 0x004E4942) + binary)


def tangents(vertices: np.ndarray, normals: np.ndarray, uv: np.ndarray,
             faces: np.ndarray) -> np.ndarray:
    """Per-vertex tangents (x, y, z, w) for normal maps: the direction of increasing u, summed
    over the vertex's triangles, made orthogonal to the normal; w = +-1 is the handedness of
    (tangent, bitangent, normal). Where u does not vary, any unit vector orthogonal to the
    normal (a normal map is then flat there anyway)."""
    p = vertices[faces]
    t = uv[faces]
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    d1, d2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    inv = np.divide(1.0, det, out=np.zeros_like(det), where=np.abs(det) > 1e-20)[:, None]
    face_t = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) * inv
    face_b = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) * inv
    tan, bit = np.zeros_like(vertices), np.zeros_like(vertices)
    for corner in range(3):
        np.add.at(tan, faces[:, corner], face_t)
        np.add.at(bit, faces[:, corner], face_b)
    tan -= normals * np.sum(tan * normals, axis=1, keepdims=True)
    length = np.linalg.norm(tan, axis=1, keepdims=True)
    fallback = np.cross(normals, np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0, 0]],
                                          [[0, 1.0, 0]]))
    fallback /= np.linalg.norm(fallback, axis=1, keepdims=True)
    tan = np.where(length > 1e-12, tan / np.maximum(length, 1e-12), fallback)
    w = np.where(np.sum(np.cross(normals, tan) * bit, axis=1) < 0, -1.0, 1.0)
    return np.concatenate([tan, w[:, None]], axis=1)


def _sun_rotation(sun: np.ndarray) -> list[float]:
    """Quaternion (x, y, z, w) turning a light's -Z onto the sunlight's direction of travel,
    in glTF's y-up frame; ``sun`` points towards the sun in glsynth's z-up world."""
    travel = Z_UP_TO_Y_UP[:3, :3] @ -np.asarray(sun, float)
    travel /= np.linalg.norm(travel)
    minus_z = np.array([0.0, 0.0, -1.0])
    axis = np.cross(minus_z, travel)
    s, c = np.linalg.norm(axis), float(minus_z @ travel)
    if s < 1e-12:  # straight down -Z already, or the opposite: half a turn about x
        return [0.0, 0.0, 0.0, 1.0] if c > 0 else [1.0, 0.0, 0.0, 0.0]
    half = np.arctan2(s, c) / 2
    return (*(axis / s * np.sin(half)).tolist(), float(np.cos(half)))


def _primitive(b: _Builder, mesh: trimesh.Trimesh, m: Material, material: int) -> dict:
    """A primitive of ``mesh`` (its own frame) drawn with ``m`` (material index ``material``):
    UVs times its uv_scale, tangents where it has a normal map."""
    uv = mesh.visual.uv * m.uv_scale
    uv = np.stack([uv[:, 0], 1.0 - uv[:, 1]], axis=1)
    normals = np.asarray(mesh.vertex_normals, np.float64)
    attributes = {
        "POSITION": b.accessor(np.ascontiguousarray(mesh.vertices, np.float32), "VEC3",
                               _ARRAY_BUFFER, bounds=True),
        "NORMAL": b.accessor(np.ascontiguousarray(normals, np.float32), "VEC3", _ARRAY_BUFFER),
        "TEXCOORD_0": b.accessor(np.ascontiguousarray(uv, np.float32), "VEC2", _ARRAY_BUFFER)}
    if m.normal_map is not None:  # glTF viewers read the normal map in this frame
        attributes["TANGENT"] = b.accessor(np.ascontiguousarray(
            tangents(np.asarray(mesh.vertices, np.float64), normals, uv, mesh.faces),
            np.float32), "VEC4", _ARRAY_BUFFER)
    indices = b.accessor(np.ascontiguousarray(mesh.faces.reshape(-1), np.uint32), "SCALAR",
                         _ELEMENT_ARRAY_BUFFER)
    return {"attributes": attributes, "indices": indices, "material": material}


def gltf_binary(parts: Sequence[Part], materials: Mapping[str, Material],
                sun: np.ndarray | None = None, sun_irradiance: float = 1.0) -> bytes:
    """The .glb bytes of ``parts`` dressed with ``materials`` (by part name), lit by a sun
    towards ``sun`` (z-up world) of the given intensity (glsynth's radiance units); no light
    when ``sun`` is None."""
    b = _Builder()
    # id(material) -> (material, index): holding the material keeps its id from being reused by
    # a later one (a deferred material is built anew on every read and dropped after).
    material_index: dict[int, tuple[Material, int]] = {}
    nodes = []
    for part in parts:
        m = materials[part.name]
        pieces = [(part.mesh, m)]
        if m.zones is not None:  # the damage material inside the zones, concrete outside
            inside, outside = zone_pieces(part.mesh, m.zones)
            intact = intact_material(m)
            pieces = [(p, m) for p in inside] + [(p, intact) for p in outside]
        primitives = []
        for mesh, material in pieces:
            if id(material) not in material_index:
                name = part.name if material is m else f"{part.name} intact"
                material_index[id(material)] = (material, b.material(name, material))
            primitives.append(_primitive(b, mesh, material, material_index[id(material)][1]))
        b.tree["meshes"].append({"name": part.name, "primitives": primitives})
        b.tree["nodes"].append({
            "name": part.name, "mesh": len(b.tree["meshes"]) - 1,
            "matrix": (Z_UP_TO_Y_UP @ part.pose).T.reshape(-1).tolist(),
            "extras": {"component": part.component.name.lower(),
                       "component_id": int(part.component)}})
        nodes.append(len(b.tree["nodes"]) - 1)
    if sun is not None:
        b.tree["extensionsUsed"] = ["KHR_lights_punctual"]
        b.tree["extensions"] = {"KHR_lights_punctual": {"lights": [
            {"name": "sun", "type": "directional", "color": [1.0, 1.0, 1.0],
             "intensity": float(sun_irradiance)}]}}
        b.tree["nodes"].append({"name": "sun", "rotation": _sun_rotation(sun),
                                "extensions": {"KHR_lights_punctual": {"light": 0}}})
        nodes.append(len(b.tree["nodes"]) - 1)
    b.tree["scenes"] = [{"nodes": nodes}]
    b.tree["scene"] = 0
    return b.glb()
