"""Runs inside Blender (``blender -b --factory-startup -P blender_job.py -- job.json``), never
imported by glsynth: renders an exported environment from glsynth cameras in Cycles.

The scene: the job's glTF (the importer keeps glsynth's z-up world; a light in the file is
removed), glsynth's sun (a Blender sun lamp of the environment's irradiance and the real sun's
0.526 deg disc) and sky (Blender's Sky Texture of type Preetham, or a uniform Background).
Every render is Cycles on the CPU, seeded, without denoising or adaptive sampling.

job["mode"]:
- "twin": for each camera, colour at its job["samples"] with a 1-pixel box filter (the pixel area,
  as glsynth's multisample resolve), saved as linear float (OpenEXR, read back here and written
  raw); glsynth applies exposure and its tone map.
- "bench": colour (8-bit PNG, Blender's view transform) at each sample count of job["samples"]
  for timing, then one label render: every material becomes an emission of strength =
  component id, 1 sample with a 0.01 px box filter (each pixel sees its centre), no bounces,
  written with the Z pass (distance along the optical axis).
Raw outputs are float32 RGBA, bottom row first, as Debian's Blender has no numpy.

job["cracks"] (both modes): per part with cracks, its crack texture (glsynth/render/
crack_texture.py: an indirection image and an atlas over planes of the part's mesh frame). The
part's surface shader becomes a mix of itself and black by contrast x coverage: its reflected
light (sun and sky, diffuse and specular) darkened as GL's crack pass darkens it.
"""

import json
import math
import sys
import time
from array import array
from pathlib import Path

import bpy
from mathutils import Matrix, Vector


def patch_numpy_for_gltf_importer() -> None:
    """Blender 3.4's glTF importer uses np.bool, which numpy 1.24-1.26 removed (numpy 2 has it
    again); Debian pairs Blender 3.4.1 with numpy 1.24, so the import fails without this."""
    import numpy

    if "bool" not in numpy.__dict__:
        numpy.bool = numpy.bool_


def add_camera(scene: bpy.types.Scene, cam: dict) -> bpy.types.Object:
    data = bpy.data.cameras.new("glsynth")
    data.sensor_fit = "HORIZONTAL"
    data.sensor_width, data.lens = cam["sensor_mm"], cam["focal_mm"]
    data.clip_start, data.clip_end = cam["znear"], cam["zfar"]
    camera = bpy.data.objects.new("glsynth", data)
    camera.matrix_world = Matrix(cam["pose"])  # world-from-camera, looking down -z, as Blender
    scene.collection.objects.link(camera)
    return camera


def add_light(scene: bpy.types.Scene, light: dict) -> None:
    for obj in [o for o in scene.objects if o.type == "LIGHT"]:
        bpy.data.objects.remove(obj)
    if light["sun_irradiance"] > 0:
        sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
        sun.data.energy = light["sun_irradiance"]
        sun.data.angle = math.radians(0.526)
        sun.rotation_euler = (-Vector(light["sun_direction_zup"])).to_track_quat(
            "-Z", "Y").to_euler()
        scene.collection.objects.link(sun)
    world = bpy.data.worlds.new("sky")
    world.use_nodes = True
    nodes = world.node_tree.nodes
    background = nodes["Background"]
    background.inputs["Strength"].default_value = light["sky_strength"]
    if light["sky"] == "preetham":
        sky = nodes.new("ShaderNodeTexSky")
        sky.sky_type = "PREETHAM"
        sky.turbidity = light["preetham_turbidity"]
        sky.sun_direction = light["preetham_sun_direction_zup"]
        world.node_tree.links.new(sky.outputs["Color"], background.inputs["Color"])
    else:
        background.inputs["Color"].default_value = (*light["uniform_sky_rgb_linear"], 1.0)
    scene.world = world


def math_node(tree: bpy.types.NodeTree, operation: str, *inputs) -> bpy.types.NodeSocket:
    """A Math node of ``operation`` on sockets or constants."""
    node = tree.nodes.new("ShaderNodeMath")
    node.operation = operation
    for socket, value in zip(node.inputs, inputs):
        if isinstance(value, bpy.types.NodeSocket):
            tree.links.new(value, socket)
        else:
            socket.default_value = value
    return node.outputs[0]


def dot(tree: bpy.types.NodeTree, vector: bpy.types.NodeSocket, axis: Vector,
        offset: float) -> bpy.types.NodeSocket:
    """vector . axis + offset."""
    node = tree.nodes.new("ShaderNodeVectorMath")
    node.operation = "DOT_PRODUCT"
    tree.links.new(vector, node.inputs[0])
    node.inputs[1].default_value = axis
    return math_node(tree, "ADD", node.outputs["Value"], offset)


def image_lookup(tree: bpy.types.NodeTree, path: str, u: bpy.types.NodeSocket,
                 v: bpy.types.NodeSocket, scale: tuple[float, float]) -> bpy.types.NodeSocket:
    """The texel of the image at ``path`` holding (u, v) x scale (nearest, 0 outside), its
    two bytes as R + G / 256."""
    texcoord = tree.nodes.new("ShaderNodeCombineXYZ")
    tree.links.new(math_node(tree, "MULTIPLY", u, scale[0]), texcoord.inputs[0])
    tree.links.new(math_node(tree, "MULTIPLY", v, scale[1]), texcoord.inputs[1])
    image = tree.nodes.new("ShaderNodeTexImage")
    image.image = bpy.data.images.load(path)
    image.image.colorspace_settings.name = "Non-Color"
    image.interpolation, image.extension = "Closest", "CLIP"
    tree.links.new(texcoord.outputs[0], image.inputs["Vector"])
    channels = tree.nodes.new("ShaderNodeSeparateColor")
    tree.links.new(image.outputs["Color"], channels.inputs[0])
    return math_node(tree, "MULTIPLY_ADD", channels.outputs["Green"], 1 / 256,
                     channels.outputs["Red"])


def plane_coordinates(tree: bpy.types.NodeTree, member: dict, mesh_from_object: Matrix
                      ) -> tuple[bpy.types.NodeSocket, ...]:
    """(u, v) in blocks of the indirection image at the shading point, and 1 where the point
    lies on one of the member's planes with cracks (facing its way), else 0 (u = v = 0).

    Each plane's nodes sit in a node group of their own, chained through (u, v, gap): Blender
    re-checks a whole tree at every node and link added, so a curved girder's planes in one
    tree took seconds (docs/design.md, "Cracks"); Cycles inlines groups, the maths is the same."""
    coords = tree.nodes.new("ShaderNodeTexCoord")
    to_object = mesh_from_object.to_3x3().transposed()
    shift = mesh_from_object.translation
    chain = {"u": 0.0, "v": 0.0, "gap": member["tolerance_m"]}
    for g in member["planes"]:
        node = tree.nodes.new("ShaderNodeGroup")
        node.node_tree = plane_group(g, member, to_object, shift)
        tree.links.new(coords.outputs["Object"], node.inputs["point"])
        tree.links.new(coords.outputs["Normal"], node.inputs["normal"])
        for name, value in chain.items():
            if isinstance(value, bpy.types.NodeSocket):
                tree.links.new(value, node.inputs[name])
            else:
                node.inputs[name].default_value = value
        chain = {name: node.outputs[name] for name in chain}
    on = math_node(tree, "LESS_THAN", chain["gap"], member["tolerance_m"])
    return chain["u"], chain["v"], on


def plane_group(g: dict, member: dict, to_object: Matrix, shift: Vector
                ) -> bpy.types.ShaderNodeTree:
    """One plane of a member: (u, v, gap) in, the same out, replaced by this plane's where the
    point lies nearer to it than ``gap`` (the nearest plane within the tolerance wins, as in
    crack_texture.lookup) and the surface faces its way."""
    group = bpy.data.node_groups.new("crack plane", "ShaderNodeTree")
    sockets = [("point", "NodeSocketVector"), ("normal", "NodeSocketVector"),
               ("u", "NodeSocketFloat"), ("v", "NodeSocketFloat"), ("gap", "NodeSocketFloat")]
    for name, kind in sockets:
        _group_socket(group, name, kind, "INPUT")
    for name, kind in sockets[2:]:
        _group_socket(group, name, kind, "OUTPUT")
    inputs = group.nodes.new("NodeGroupInput").outputs
    outputs = group.nodes.new("NodeGroupOutput").inputs
    n, eu, ev = (Vector(g[k]) for k in ("normal", "u_axis", "v_axis"))
    block = member["block_m"]
    point = inputs["point"]
    gap = math_node(group, "ABSOLUTE", dot(group, point, to_object @ n,
                                           shift.dot(n) - g["offset"]))
    facing = math_node(group, "GREATER_THAN", dot(group, inputs["normal"], to_object @ n, 0.0),
                       0.5)
    mine = math_node(group, "MULTIPLY", math_node(group, "LESS_THAN", gap, inputs["gap"]),
                     facing)
    clamp = group.nodes.new("ShaderNodeClamp")
    group.links.new(dot(group, point, to_object @ eu / block,
                        (shift.dot(eu) - g["corner"][0]) / block + g["column"]),
                    clamp.inputs["Value"])
    clamp.inputs["Min"].default_value = g["column"] - 0.5
    clamp.inputs["Max"].default_value = g["column"] + g["blocks"][0] + 0.5
    group.links.new(_choose(group, mine, clamp.outputs[0], inputs["u"]), outputs["u"])
    group.links.new(_choose(group, mine, dot(group, point, to_object @ ev / block,
                                             (shift.dot(ev) - g["corner"][1]) / block),
                            inputs["v"]), outputs["v"])
    group.links.new(_choose(group, mine, gap, inputs["gap"]), outputs["gap"])
    return group


def _group_socket(group: bpy.types.ShaderNodeTree, name: str, kind: str, in_out: str) -> None:
    """A group input or output socket: Blender 4 names them in ``interface``, 3.x in
    ``inputs`` and ``outputs``."""
    if hasattr(group, "interface"):
        group.interface.new_socket(name, in_out=in_out, socket_type=kind)
    else:
        (group.inputs if in_out == "INPUT" else group.outputs).new(kind, name)


def _choose(tree: bpy.types.NodeTree, pick: bpy.types.NodeSocket, new: bpy.types.NodeSocket,
            old: bpy.types.NodeSocket) -> bpy.types.NodeSocket:
    """``new`` where ``pick`` is 1, ``old`` where it is 0: old + pick (new - old)."""
    return math_node(tree, "MULTIPLY_ADD", pick, math_node(tree, "SUBTRACT", new, old), old)


def crack_coverage(tree: bpy.types.NodeTree, member: dict, mesh_from_object: Matrix
                   ) -> bpy.types.NodeSocket:
    """The member's crack coverage at the shading point: the indirection image gives the
    point's block in the atlas, the atlas its texel (glsynth/render/crack_texture.py)."""
    u, v, on = plane_coordinates(tree, member, mesh_from_object)
    columns, rows = member["indirection_size"]
    # The block index 256 R + G (bytes) from R + G / 256 in 0..1 channel values.
    k = math_node(tree, "ROUND", math_node(tree, "MULTIPLY", image_lookup(
        tree, member["indirection"], u, v, (1 / columns, 1 / rows)), 255.0 * 256.0))
    per_row = member["atlas_blocks"]
    column = math_node(tree, "ADD", math_node(tree, "MODULO", k, per_row),
                       math_node(tree, "FRACT", u))
    row = math_node(tree, "ADD", math_node(tree, "FLOOR", math_node(tree, "DIVIDE", k, per_row)),
                    math_node(tree, "FRACT", v))
    coverage = image_lookup(tree, member["atlas"], column, row, (1 / per_row, 1 / per_row))
    return math_node(tree, "MULTIPLY", coverage, on)


def add_cracks(cracks: list[dict]) -> None:
    """Darken each cracked part's surface shader by contrast x coverage (module docstring)."""
    for member in cracks:
        obj = bpy.data.objects.get(member["part"])
        if obj is None or obj.type != "MESH":
            raise SystemExit(f"part {member['part']!r} with cracks is not a mesh of the scene")
        # A member cut at its damage zones (glsynth.render.zone_split) has a material per piece.
        for slot in obj.material_slots:
            material = slot.material
            if material.users > 1:  # shared with parts without these cracks
                material = slot.material = material.copy()
            darken(material.node_tree, member,
                   Matrix(member["pose"]).inverted() @ obj.matrix_world)


def darken(tree: bpy.types.NodeTree, member: dict, mesh_from_object: Matrix) -> None:
    """Mix the material's surface shader towards black by contrast x crack coverage."""
    output = next(n for n in tree.nodes if n.type == "OUTPUT_MATERIAL" and n.is_active_output)
    surface = output.inputs["Surface"].links[0].from_socket
    coverage = crack_coverage(tree, member, mesh_from_object)
    black = tree.nodes.new("ShaderNodeBsdfDiffuse")
    black.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    mix = tree.nodes.new("ShaderNodeMixShader")
    tree.links.new(math_node(tree, "MULTIPLY", coverage, member["contrast"]), mix.inputs["Fac"])
    tree.links.new(surface, mix.inputs[1])
    tree.links.new(black.outputs[0], mix.inputs[2])
    tree.links.new(mix.outputs[0], output.inputs["Surface"])


def setup_scene(job: dict) -> bpy.types.Scene:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    patch_numpy_for_gltf_importer()
    bpy.ops.import_scene.gltf(filepath=job["glb"])
    scene = bpy.context.scene
    add_light(scene, job["lighting"])
    add_cracks(job.get("cracks", []))
    cam = job["cameras"][0]
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.use_denoising = False
    scene.cycles.use_animated_seed = False
    scene.render.resolution_x, scene.render.resolution_y = cam["width"], cam["height"]
    scene.render.resolution_percentage = 100
    scene.render.threads_mode = "AUTO"
    scene.render.film_transparent = False
    return scene


def read_raw(path: Path) -> tuple[bytes, list[int]]:
    image = bpy.data.images.load(str(path))
    pixels = array("f", bytes(4 * len(image.pixels)))
    image.pixels.foreach_get(pixels)
    size = list(image.size)
    bpy.data.images.remove(image)
    return pixels.tobytes(), size


def render_twin(scene: bpy.types.Scene, job: dict, out: Path) -> dict:
    # Keep the synchronised scene (BVH, images) between this job's renders.
    scene.render.use_persistent_data = True
    scene.cycles.pixel_filter_type = "BOX"
    scene.cycles.filter_width = 1.0
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.render.image_settings.color_mode = "RGBA"
    times, sizes = [], []
    for i, (cam, seed, samples) in enumerate(zip(job["cameras"], job["seeds"],
                                                 job["samples"])):
        scene.camera = add_camera(scene, cam)
        scene.cycles.seed = seed
        scene.cycles.samples = samples
        path = out / f"cycles_{i}.exr"
        scene.render.filepath = str(path)
        t0 = time.perf_counter()
        bpy.ops.render.render(write_still=True)
        times.append(time.perf_counter() - t0)
        data, size = read_raw(path)
        (out / f"cycles_{i}.f32").write_bytes(data)
        sizes.append(size)
        path.unlink()
    return {"colour_s": times, "sizes": sizes}


def render_colour(scene: bpy.types.Scene, samples: int, path: Path) -> float:
    scene.cycles.samples = samples
    scene.render.image_settings.file_format = "PNG"
    scene.render.filepath = str(path)
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    return time.perf_counter() - t0


def emission_material(strength: float) -> bpy.types.Material:
    mat = bpy.data.materials.new(f"glsynth_label_{strength:g}")
    mat.use_nodes = True
    nodes = mat.node_tree.nodes
    nodes.clear()
    emission = nodes.new("ShaderNodeEmission")
    emission.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    emission.inputs["Strength"].default_value = strength
    output = nodes.new("ShaderNodeOutputMaterial")
    mat.node_tree.links.new(emission.outputs["Emission"], output.inputs["Surface"])
    return mat


def label_materials(scene: bpy.types.Scene) -> None:
    """Every mesh emits with strength = its component id, read from the glTF node's extras
    (the importer keeps them as the object's custom properties); a mesh without one fails."""
    made: dict[int, bpy.types.Material] = {}
    for obj in scene.objects:
        if obj.type != "MESH":
            continue
        if "component_id" not in obj:
            raise SystemExit(f"object {obj.name!r} has no component_id in its glTF extras")
        cid = int(obj["component_id"])
        if cid not in made:
            made[cid] = emission_material(float(cid))
        obj.data.materials.clear()
        obj.data.materials.append(made[cid])


def render_labels(scene: bpy.types.Scene, out: Path) -> dict:
    label_materials(scene)
    scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.cycles.samples = 1
    scene.cycles.max_bounces = 0
    scene.cycles.pixel_filter_type = "BOX"
    scene.cycles.filter_width = 0.01
    scene.render.dither_intensity = 0.0
    scene.view_settings.view_transform = "Standard"
    scene.view_layers[0].use_pass_z = True
    scene.use_nodes = True
    tree = scene.node_tree
    tree.nodes.clear()
    layers = tree.nodes.new("CompositorNodeRLayers")
    files = tree.nodes.new("CompositorNodeOutputFile")
    files.base_path = str(out)
    files.format.file_format = "OPEN_EXR"
    files.format.color_depth = "32"
    files.file_slots.clear()
    for name, socket in (("labels", "Image"), ("depth", "Depth")):
        files.file_slots.new(name)
        tree.links.new(layers.outputs[socket], files.inputs[name])
    t0 = time.perf_counter()
    bpy.ops.render.render()  # the File Output node writes the EXRs
    elapsed = time.perf_counter() - t0
    frame = scene.frame_current
    sizes = {}
    for name in ("labels", "depth"):
        path = out / f"{name}{frame:04d}.exr"
        data, sizes[name] = read_raw(path)
        (out / f"blender_{name}.f32").write_bytes(data)
        path.unlink()
    return {"labels_depth_s": elapsed, "sizes": sizes}


def main() -> None:
    job = json.loads(Path(sys.argv[sys.argv.index("--") + 1]).read_text())
    out = Path(job["out"])
    t0 = time.perf_counter()
    scene = setup_scene(job)
    times = {"blender": f"Blender {bpy.app.version_string}",
             "import_s": time.perf_counter() - t0}
    if job["mode"] == "twin":
        times.update(render_twin(scene, job, out))
    else:
        scene.camera = add_camera(scene, job["cameras"][0])
        scene.cycles.seed = job["seeds"][0]
        times["colour_s"] = {str(n): render_colour(scene, n, out / f"blender_{n}spp.png")
                             for n in job["samples"]}
        times.update(render_labels(scene, out))
    (out / "blender_times.json").write_text(json.dumps(times))


main()
