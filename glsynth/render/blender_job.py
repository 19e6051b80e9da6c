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

job["cracks"] (both modes): per part with cracks, its coverage tiles (glsynth/render/
crack_tiles.py) as images, each placed on a plane of the part's mesh frame. The part's surface
shader becomes a mix of itself and black by contrast x coverage: its reflected light (sun and
sky, diffuse and specular) darkened as GL's crack pass darkens it.
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


PLANE_TOLERANCE_M = 1e-3
"""A point takes a tile's coverage within this distance of the tile's plane: well above the
float32 precision of positions a kilometre from the origin (0.1 mm)."""


def affine(tree: bpy.types.NodeTree, point: bpy.types.NodeSocket, axis: Vector,
           offset: float) -> bpy.types.NodeSocket:
    """A socket computing point . axis + offset."""
    dot = tree.nodes.new("ShaderNodeVectorMath")
    dot.operation = "DOT_PRODUCT"
    tree.links.new(point, dot.inputs[0])
    dot.inputs[1].default_value = axis
    add = tree.nodes.new("ShaderNodeMath")
    add.operation = "ADD"
    tree.links.new(dot.outputs["Value"], add.inputs[0])
    add.inputs[1].default_value = offset
    return add.outputs[0]


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


def tile_coverage(tree: bpy.types.NodeTree, point: bpy.types.NodeSocket,
                  mesh_from_object: Matrix, tile: dict) -> bpy.types.NodeSocket:
    """One tile's coverage at object-space ``point``: 0 off the tile's plane or rectangle
    (the image clips), else its texel's value, decoded as R + G / 256."""
    rotation, shift = mesh_from_object.to_3x3(), mesh_from_object.translation
    to_corner = shift - Vector(tile["origin"])
    size = [tile["texel_m"] * n for n in tile["size"]]
    u, v, n = (Vector(tile[k]) for k in ("u_axis", "v_axis", "normal"))
    texcoord = tree.nodes.new("ShaderNodeCombineXYZ")
    for i, (axis, extent) in enumerate(((u, size[0]), (v, size[1]))):
        tree.links.new(affine(tree, point, rotation.transposed() @ axis / extent,
                              to_corner.dot(axis) / extent), texcoord.inputs[i])
    image = tree.nodes.new("ShaderNodeTexImage")
    image.image = bpy.data.images.load(tile["image"])
    image.image.colorspace_settings.name = "Non-Color"
    image.interpolation, image.extension = "Closest", "CLIP"
    tree.links.new(texcoord.outputs[0], image.inputs["Vector"])
    channels = tree.nodes.new("ShaderNodeSeparateColor")
    tree.links.new(image.outputs["Color"], channels.inputs[0])
    value = math_node(tree, "MULTIPLY_ADD", channels.outputs["Green"], 1 / 256,
                      channels.outputs["Red"])
    off_plane = math_node(tree, "ABSOLUTE", affine(tree, point, rotation.transposed() @ n,
                                                   to_corner.dot(n)))
    return math_node(tree, "MULTIPLY", value,
                     math_node(tree, "LESS_THAN", off_plane, PLANE_TOLERANCE_M))


def add_cracks(scene: bpy.types.Scene, cracks: list[dict]) -> None:
    """Darken each cracked part's surface shader by contrast x coverage (module docstring)."""
    for member in cracks:
        obj = bpy.data.objects.get(member["part"])
        if obj is None or obj.type != "MESH":
            raise SystemExit(f"part {member['part']!r} with cracks is not a mesh of the scene")
        material = obj.material_slots[0].material
        if material.users > 1:  # shared with parts without these cracks
            material = obj.material_slots[0].material = material.copy()
        tree = material.node_tree
        output = next(n for n in tree.nodes
                      if n.type == "OUTPUT_MATERIAL" and n.is_active_output)
        surface = output.inputs["Surface"].links[0].from_socket
        point = tree.nodes.new("ShaderNodeTexCoord").outputs["Object"]
        mesh_from_object = Matrix(member["pose"]).inverted() @ obj.matrix_world
        coverage = None
        for tile in member["tiles"]:
            one = tile_coverage(tree, point, mesh_from_object, tile)
            coverage = one if coverage is None else math_node(tree, "MAXIMUM", coverage, one)
        black = tree.nodes.new("ShaderNodeBsdfDiffuse")
        black.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
        mix = tree.nodes.new("ShaderNodeMixShader")
        tree.links.new(math_node(tree, "MULTIPLY", coverage, member["contrast"]),
                       mix.inputs["Fac"])
        tree.links.new(surface, mix.inputs[1])
        tree.links.new(black.outputs[0], mix.inputs[2])
        tree.links.new(mix.outputs[0], output.inputs["Surface"])


def setup_scene(job: dict) -> bpy.types.Scene:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    patch_numpy_for_gltf_importer()
    bpy.ops.import_scene.gltf(filepath=job["glb"])
    scene = bpy.context.scene
    add_light(scene, job["lighting"])
    add_cracks(scene, job.get("cracks", []))
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
