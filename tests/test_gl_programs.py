"""The GL programs' wiring (glsynth.render.gl.programs): variants by flags, texture units handed
out per sampler name, constants shared with GLSL as defines, guarded includes; and the pass
registry (glsynth.render.passes) that the renderer, the viewer's frames and its protocol
read."""

import re

import numpy as np
import pytest
from glhelpers import LIGHT, camera, pixel_plate, render_config, scene_of

from glsynth.appearance.materials import MAX_ZONES, Material
from glsynth.core.labels import Component
from glsynth.render.gl import programs
from glsynth.render.gl.programs import (
    MAX_VIS,
    PROGRAMS,
    TextureUnits,
    Variant,
    shader_source,
    with_defines,
)
from glsynth.render.gl.renderer import PASSES as RENDERED
from glsynth.render.gl.renderer import Renderer
from glsynth.render.passes import PASSES
from glsynth.view import protocol
from glsynth.view.frames import available_passes, legend, pass_image

SAMPLER = re.compile(r"^\s*uniform\s+[iu]?sampler\w*\s+(\w+)\s*;", re.MULTILINE)


@pytest.fixture(scope="module")
def renderer():
    with Renderer(render_config(64, 48)) as r:
        yield r


def test_each_variant_is_compiled_with_its_flags_as_defines(renderer):
    keys = renderer.programs.keys()
    assert ("color", Variant.CRACKS | Variant.SPALL | Variant.DETAIL) in keys
    assert ("labels", Variant.DETAIL) not in keys  # the labels have no concrete detail
    # The ground's detail stands in for concrete's, on parts without cracks or zones.
    assert ("color", Variant.DETAIL | Variant.GROUND) in keys
    assert not {("color", v | Variant.GROUND) for v in (Variant.NONE, Variant.CRACKS,
                                                        Variant.DETAIL | Variant.SPALL)} & set(keys)
    assert Variant.of(cracks=True, detail=True, ground=True) == Variant.DETAIL | Variant.GROUND
    ground = renderer.programs.get("color", Variant.DETAIL | Variant.GROUND)
    assert ground.get("u_detail_seed", None) and ground.get("u_weathering", None) is None
    assert len({id(renderer.programs.get(*key)) for key in keys}) == len(keys)
    # A variant's code is there only with its flag: the crack uniforms, the zones'.
    assert renderer.programs.get("color").get("u_crack_contrast", None) is None
    assert renderer.programs.get("color", Variant.CRACKS).get("u_crack_contrast", None)
    source = with_defines(shader_source("labels.frag"), Variant.of(cracks=True, spall=True))
    assert "#define CRACKS\n#define SPALL\n" in source
    assert source.startswith("#version 330 core\n#define MAX_ZONES")


def test_shared_constants_size_the_shaders_arrays(renderer):
    zones = renderer.programs.get("labels", Variant.SPALL)["u_zones"]
    assert zones.array_length == MAX_ZONES == 4
    assert renderer.programs.get("sky_visibility")["u_vis_dir"].array_length == MAX_VIS == 16
    for name in ("zones.glsl", "sky_visibility.frag"):
        assert not re.search(r"\[\d+\]", shader_source(name))  # no literal lengths left


def test_every_sampler_has_its_own_unit_in_every_program(renderer):
    units = renderer.units
    for name, variant in renderer.programs.keys():
        prog = renderer.programs.get(name, variant)
        vert, frag, _ = PROGRAMS[name]
        samplers = [s for f in (vert, frag) for s in SAMPLER.findall(shader_source(f))
                    if s in prog]
        wired = [prog[s].value for s in samplers]
        assert wired == [units.unit(s) for s in samplers]
        assert len(set(wired)) == len(wired)  # GL forbids a shared unit across types
        assert max(wired, default=0) < renderer.ctx.default_texture_unit


def test_texture_units_refuse_more_names_than_units():
    units = TextureUnits(2)
    assert (units.unit("a"), units.unit("b"), units.unit("a")) == (0, 1, 0)
    with pytest.raises(RuntimeError, match="no texture unit left for 'c'"):
        units.unit("c")


@pytest.fixture
def shader_folder(tmp_path, monkeypatch):
    """A shader folder of the test's own, read instead of glsynth.shaders."""
    monkeypatch.setattr(programs, "shader_dir", lambda: tmp_path)
    shader_source.cache_clear()
    yield tmp_path
    shader_source.cache_clear()


def test_a_file_included_twice_is_compiled_once(renderer, shader_folder):
    (shader_folder / "half.glsl").write_text("float half_of(float x) { return 0.5 * x; }\n")
    (shader_folder / "twice.glsl").write_text(
        '#include "half.glsl"\nfloat quarter(float x) { return half_of(half_of(x)); }\n')
    (shader_folder / "main.frag").write_text(
        '#version 330 core\n#include "half.glsl"\n#include "twice.glsl"\nout vec4 f;\n'
        "void main() { f = vec4(quarter(1.0)); }\n")
    source = shader_source("main.frag")
    assert "#include" not in source and source.count("#ifndef GLSYNTH_HALF_GLSL") == 2
    # Without the guard the second definition of half_of would not compile.
    vert = "#version 330 core\nvoid main() { gl_Position = vec4(0.0); }\n"
    renderer.ctx.program(vertex_shader=vert, fragment_shader=source).release()


def test_a_file_that_includes_itself_is_an_error(shader_folder):
    (shader_folder / "a.glsl").write_text('#include "b.glsl"\n')
    (shader_folder / "b.glsl").write_text('#include "a.glsl"\n')
    with pytest.raises(RuntimeError, match="'a.glsl' includes itself through a.glsl -> b.glsl"):
        shader_source("a.glsl")


def test_one_registry_names_the_passes_everywhere():
    assert protocol.PASS_NAMES == tuple(PASSES)
    assert RENDERED == {n for n, p in PASSES.items() if p.target is not None}
    assert RENDERED == {"color", "component", "damage", "depth"}


def test_every_registered_pass_makes_an_image_of_a_real_render(renderer):
    cam = camera()
    plate = pixel_plate(cam, 5.0)
    renderer.load(scene_of(("column_plate", Component.COLUMN, plate,
                            Material(base_color=(0.6, 0.5, 0.4, 1.0)))), LIGHT)
    out = renderer.render(cam)
    assert available_passes(out) == list(PASSES)  # the damage pass brings crack widths
    for name in PASSES:
        image = pass_image(name, out, cam.fx)
        assert image.shape == (cam.height, cam.width, 3) and image.dtype == np.uint8
        assert isinstance(legend(name), dict)
    # Each pass shows what it names: the colour itself, the column's colour, near depth.
    assert np.array_equal(pass_image("color", out, cam.fx), out.color)
    column = pass_image("component", out, cam.fx)
    assert (column == column[0, 0]).all()
    assert {"label": "column", "rgb": [int(c) for c in column[0, 0]]} in \
        legend("component")["swatches"]
    no_damage = renderer.render(cam, frozenset({"color"}))
    assert "crack_width" not in available_passes(no_damage)
