"""Material node trees exported as shader graphs, images as textures, meshes with their UV maps.

Materials are built as artists build them (Image Texture from a PNG on disk, Checker through a
Mapping node, Math, Color Ramp, Mix, Mix Shader with a textured Fac, node groups, muted nodes),
exported through the batch path and checked against the graph format the core's compiler reads
(``stpm_core/nodes/graph.py``), the stored texels and the per-corner UVs.  One test evaluates an
exported graph with the interpreter on hits at known points, one renders a checker.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from test_addon_scenes import add_camera, add_mesh, export_now, fresh, node_material  # noqa: E402

from stpm_core.nodes import Link, ShaderGraph  # noqa: E402


# ----------------------------------------------------------------------------
# Helpers
# ----------------------------------------------------------------------------
def write_png(path, rgba_bytes: np.ndarray, *, alpha: bool = True) -> "bpy.types.Image":
    """Save (H, W, 4) uint8 values (row 0 = bottom, as Image.pixels) as an 8-bit PNG with bpy and
    load it back from disk (a clean, file-backed image)."""
    h, w, _ = rgba_bytes.shape
    img = bpy.data.images.new("tmp_png", w, h, alpha=alpha)
    img.pixels.foreach_set((rgba_bytes.astype(np.float32) / 255.0).reshape(-1))
    img.filepath_raw, img.file_format = str(path), "PNG"
    img.save()
    bpy.data.images.remove(img)
    return bpy.data.images.load(str(path))


def surface_material(name: str, shader: str = "ShaderNodeBsdfPrincipled", **inputs):
    """(material, tree, shader node) with ``shader`` on the Material Output's Surface."""
    mat, node = node_material(name, shader, **inputs)
    return mat, mat.node_tree, node


def graph_of(scene, name: str) -> ShaderGraph:
    return next(m for m in scene.materials if m.name == name).graph


def loop_triangle_uvs(me, layer: str) -> np.ndarray:
    """(F, 3, 2) UVs read corner by corner through bpy's own objects (the reference)."""
    me.calc_loop_triangles()
    data = me.uv_layers[layer].data
    return np.array([[tuple(data[loop].uv) for loop in t.loops] for t in me.loop_triangles], np.float32)


RGBA = np.array([[[0, 0, 0, 255], [255, 0, 0, 255], [10, 20, 30, 128]],
                 [[0, 255, 0, 255], [1, 2, 3, 0], [200, 100, 50, 255]]], np.uint8)   # (2, 3, 4) bottom row first
OPAQUE = np.concatenate([RGBA[..., :3], np.full((2, 3, 1), 255, np.uint8)], axis=2)


# ----------------------------------------------------------------------------
# Image textures: graph, texels, colour spaces, UVs
# ----------------------------------------------------------------------------
def test_image_texture_exports_graph_texture_and_uvs(tmp_path):
    fresh()
    img = write_png(tmp_path / "paint.png", RGBA)
    mat, tree, bsdf = surface_material("Painted")
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation, tex.extension = img, "Closest", "EXTEND"
    tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    tree.links.new(tex.outputs["Alpha"], bsdf.inputs["Roughness"])
    plane = add_mesh("plane", "Canvas", material=mat)
    add_camera()
    scene, warnings = export_now()

    g = graph_of(scene, "Painted")
    assert g.surface == Link("Principled BSDF", "BSDF")
    assert set(g.nodes) == {"Principled BSDF", "Image Texture"}
    t, p = g.nodes["Image Texture"], g.nodes["Principled BSDF"]
    assert t.type == "ShaderNodeTexImage" and p.type == "ShaderNodeBsdfPrincipled"
    assert t.props == {"interpolation": "Closest", "extension": "EXTEND", "projection": "FLAT", "image": 0}
    assert t.inputs == {}                                   # Vector unlinked: the implicit UV, no constant
    assert t.outputs == {"Color": "RGBA", "Alpha": "VALUE"}
    assert p.inputs["Base Color"] == Link("Image Texture", "Color")
    assert p.inputs["Roughness"] == Link("Image Texture", "Alpha")
    assert p.inputs["Metallic"] == 0.0 and p.inputs["IOR"] == pytest.approx(1.5)
    assert p.inputs["Emission Color"] == (1.0, 1.0, 1.0)    # RGBA default, alpha dropped
    assert "Normal" not in p.inputs                          # hide_value: implicit
    assert p.input_types["Base Color"] == "RGBA" and p.input_types["Roughness"] == "VALUE"
    assert p.outputs == {"BSDF": "SHADER"}

    assert len(scene.textures) == 1
    tx = scene.textures[0]
    assert tx.pixels.dtype == np.uint8 and tx.pixels.shape == (2, 3, 4) and not tx.half
    np.testing.assert_array_equal(tx.pixels, RGBA)          # exact, row 0 = bottom as Image.pixels
    assert tx.colorspace == "sRGB" and tx.name == "paint.png"
    assert not any("mean colour" in w for w in warnings), warnings

    mesh = scene.meshes[scene.instances[0].mesh]
    assert mesh.uv_render == "UVMap" and list(mesh.uv_layers) == ["UVMap"]
    uv = mesh.uv_layers["UVMap"]
    assert uv.dtype == np.float32 and uv.shape == (mesh.triangles.shape[0], 3, 2)
    np.testing.assert_array_equal(uv, loop_triangle_uvs(plane.data, "UVMap"))
    # the representative constants are still there (the mean colour of the image)
    m = next(m for m in scene.materials if m.name == "Painted")
    srgb = RGBA[..., :3].reshape(-1, 3) / 255.0
    lin = np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)
    np.testing.assert_allclose(m.base_color, lin.mean(axis=0), atol=1e-5)


def test_smart_project_uvs_and_render_active_layer():
    """Every UV map per loop-triangle corner, in the exported triangles' order; the render-active
    map's name (not the one active for editing)."""
    fresh()
    cube = add_mesh("cube", "Box")
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.uv.smart_project()
    bpy.ops.object.mode_set(mode="OBJECT")
    second = cube.data.uv_layers.new(name="Second")
    second.active_render = True
    uv = np.empty(len(cube.data.loops) * 2, np.float32)
    cube.data.uv_layers["UVMap"].uv.foreach_get("vector", uv)
    second.uv.foreach_set("vector", uv[::-1].copy() * 0.5)  # a different map
    cube.data.uv_layers.active = cube.data.uv_layers["UVMap"]
    add_camera()
    scene, _ = export_now()
    mesh = scene.meshes[0]
    assert list(mesh.uv_layers) == ["UVMap", "Second"] and mesh.uv_render == "Second"
    me = cube.data
    me.calc_loop_triangles()
    np.testing.assert_array_equal(mesh.triangles, np.array([tuple(t.vertices) for t in me.loop_triangles]))
    for name in ("UVMap", "Second"):
        np.testing.assert_array_equal(mesh.uv_layers[name], loop_triangle_uvs(me, name))
    assert not np.array_equal(mesh.uv_layers["UVMap"], mesh.uv_layers["Second"])


def test_one_texture_per_image_and_colour_spaces(tmp_path, monkeypatch):
    """An image used twice is one texture; byte images keep their colour space's name (Non-Color,
    Display P3: the renderer converts them); a space without a formula (Rec.1886: a 2.4 gamma) is
    converted by OpenColorIO with Blender's config into float32 working-space values, and without
    OpenColorIO read as linear, warned; an RGB image keeps 3 channels."""
    fresh()
    img = write_png(tmp_path / "a.png", RGBA)
    data = write_png(tmp_path / "data.png", OPAQUE, alpha=False)
    data.colorspace_settings.name = "Non-Color"
    p3 = write_png(tmp_path / "p3.png", OPAQUE, alpha=False)
    p3.colorspace_settings.name = "Display P3"
    odd = write_png(tmp_path / "odd.png", OPAQUE, alpha=False)
    odd.colorspace_settings.name = "Rec.1886"
    for name, image in (("A", img), ("B", img), ("C", data), ("D", p3), ("E", odd)):
        mat, tree, bsdf = surface_material(name, "ShaderNodeBsdfDiffuse")
        node = tree.nodes.new("ShaderNodeTexImage")
        node.image = image
        tree.links.new(node.outputs["Color"], bsdf.inputs["Color"])
        add_mesh("cube", name, location=(3 * len(bpy.data.objects), 0, 0), material=mat)
    add_camera()
    scene, warnings = export_now()
    idx = {n: graph_of(scene, n).nodes["Image Texture"].props["image"] for n in "ABCDE"}
    assert idx["A"] == idx["B"] and len(set(idx.values())) == 4 and len(scene.textures) == 4
    tc, td, te = scene.textures[idx["C"]], scene.textures[idx["D"]], scene.textures[idx["E"]]
    assert tc.colorspace == "Non-Color" and tc.pixels.shape == (2, 3, 3) and tc.pixels.dtype == np.uint8
    np.testing.assert_array_equal(tc.pixels, RGBA[..., :3])
    assert td.colorspace == "Display P3" and td.pixels.dtype == np.uint8
    assert te.colorspace == "Linear" and te.pixels.dtype == np.float32
    np.testing.assert_allclose(te.pixels, (RGBA[..., :3] / 255.0) ** 2.4, rtol=2e-4, atol=1e-6)
    assert not [w for w in warnings if "odd.png" in w or "p3.png" in w]
    # without OpenColorIO the values are read as linear, and said so
    from addon.export import nodes as node_export
    monkeypatch.setattr(node_export, "_ocio_config", lambda: None)
    scene, warnings = export_now()
    te = scene.textures[graph_of(scene, "E").nodes["Image Texture"].props["image"]]
    assert te.colorspace == "Linear" and te.pixels.dtype == np.uint8
    hits = [w for w in warnings if "'odd.png'" in w]
    assert len(hits) == 1 and "'Rec.1886'" in hits[0] and "linear" in hits[0]


def test_float_half_and_16_bit_images_keep_their_precision(tmp_path):
    """Float images are scene-linear in Blender: a generated float image -> float32, a half EXR ->
    float16 (exact), a 16-bit Non-Color PNG -> uint16 (exact), a grey PNG -> 1 channel."""
    oiio = pytest.importorskip("OpenImageIO")

    def write(path, arr, fmt):
        out = oiio.ImageOutput.create(str(path))
        out.open(str(path), oiio.ImageSpec(arr.shape[1], arr.shape[0], arr.shape[2], fmt))
        out.write_image(arr)
        out.close()
        return bpy.data.images.load(str(path))

    fresh()
    rng = np.random.default_rng(3)
    half = (rng.normal(size=(2, 3, 3)) * 4).astype(np.float16)
    u16 = rng.integers(0, 65536, (3, 2, 3)).astype(np.uint16)
    grey = rng.integers(0, 256, (2, 2, 1)).astype(np.uint8)
    images = {"Half": write(tmp_path / "h.exr", half, "half"), "U16": write(tmp_path / "d.png", u16, "uint16"),
              "Grey": write(tmp_path / "g.png", grey, "uint8")}
    images["U16"].colorspace_settings.name = "Non-Color"
    gen = bpy.data.images.new("GenFloat", 2, 2, float_buffer=True)
    flt = rng.normal(size=16).astype(np.float32) / 3
    gen.pixels.foreach_set(flt)
    images["Float"] = gen
    for name, image in images.items():
        mat, tree, bsdf = surface_material(name, "ShaderNodeEmission")
        node = tree.nodes.new("ShaderNodeTexImage")
        node.image = image
        tree.links.new(node.outputs["Color"], bsdf.inputs["Color"])
        add_mesh("plane", name, location=(3 * len(bpy.data.objects), 0, 0), material=mat)
    add_camera()
    scene, _ = export_now()
    tex = {n: scene.textures[graph_of(scene, n).nodes["Image Texture"].props["image"]] for n in images}
    # OpenImageIO rows are top-down, Blender's (and the Texture's) bottom-up
    assert tex["Half"].half and tex["Half"].colorspace == "Linear" and tex["Half"].pixels.shape == (2, 3, 3)
    np.testing.assert_array_equal(tex["Half"].pixels.view(np.float16), half[::-1])
    assert tex["U16"].pixels.dtype == np.uint16 and not tex["U16"].half and tex["U16"].colorspace == "Linear"
    np.testing.assert_array_equal(tex["U16"].pixels, u16[::-1])
    assert tex["Grey"].pixels.shape == (2, 2, 1) and tex["Grey"].colorspace == "sRGB"
    np.testing.assert_array_equal(tex["Grey"].pixels, grey[::-1])
    assert tex["Float"].pixels.dtype == np.float32 and tex["Float"].pixels.shape == (2, 2, 4)
    np.testing.assert_array_equal(tex["Float"].pixels.reshape(-1), flt)


def _write_tile(oiio, path, arr, fmt):
    """(H, W, C) values, row 0 at the bottom (as Blender's pixels), to an image file of type fmt."""
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(arr.shape[1], arr.shape[0], arr.shape[2], fmt))
    out.write_image(np.ascontiguousarray(arr[::-1]))
    out.close()


def _udim_image(tmp_path, oiio, rng, space="Non-Color"):
    """A UDIM image on disk: 1001 an 8-bit RGB PNG, 1002 a 16-bit RGB PNG, 1011 a half RGBA EXR; then
    tile 1012 added in Blender without a file.  Returns (image, {tile: written array})."""
    tiles = {1001: rng.integers(0, 256, (3, 4, 3)).astype(np.uint8),
             1002: rng.integers(0, 65536, (2, 5, 3)).astype(np.uint16),
             1011: rng.uniform(0, 2, (4, 2, 4)).astype(np.float16)}
    for t, arr in tiles.items():
        ext = "exr" if arr.dtype == np.float16 else "png"
        fmt = {np.dtype(np.uint8): "uint8", np.dtype(np.uint16): "uint16", np.dtype(np.float16): "half"}[arr.dtype]
        _write_tile(oiio, tmp_path / f"wood.{t}.{ext}", arr, fmt)
    # Blender finds the tiles of one name and extension: the EXR tile gets the PNGs' name pattern
    (tmp_path / "wood.1011.exr").rename(tmp_path / "wood.1011.png")
    img = bpy.data.images.load(str(tmp_path / "wood.1001.png"))
    img.source = "TILED"
    img.colorspace_settings.name = space
    img.tiles.new(1012)
    return img, tiles


def test_udim_tiles_are_read_in_their_stored_type(tmp_path):
    """A UDIM image becomes one texture per tile, each in its file's stored type (uint8, uint16,
    half), rows bottom-up, the image's colour space; the node holds [[tile, texture]] for the tiles
    with pixels, a tile without a file is named once (it reads magenta, as in Cycles); packed tiles
    read the same; "only the first tile" is never said."""
    oiio = pytest.importorskip("OpenImageIO")
    fresh()
    rng = np.random.default_rng(11)
    img, written = _udim_image(tmp_path, oiio, rng)
    mat, tree, bsdf = surface_material("Udim", "ShaderNodeEmission")
    node = tree.nodes.new("ShaderNodeTexImage")
    node.image = img
    tree.links.new(node.outputs["Color"], bsdf.inputs["Color"])
    add_mesh("plane", "P", material=mat)
    add_camera()
    for packed in (False, True):
        if packed:                     # (Blender packs only tiles with files: 1012 goes first)
            img.tiles.remove(img.tiles[-1])
            img.pack()
            for f in tmp_path.glob("wood.*"):
                f.unlink()
        scene, warnings = export_now()
        props = graph_of(scene, "Udim").nodes["Image Texture"].props
        assert [t for t, _i in props["tiles"]] == [1001, 1002, 1011]
        assert props["image"] == props["tiles"][0][1]
        tex = {t: scene.textures[i] for t, i in props["tiles"]}
        assert tex[1001].pixels.dtype == np.uint8 and tex[1001].colorspace == "Non-Color"
        np.testing.assert_array_equal(tex[1001].pixels, written[1001])
        assert tex[1002].pixels.dtype == np.uint16 and not tex[1002].half
        np.testing.assert_array_equal(tex[1002].pixels, written[1002])
        assert tex[1011].half and tex[1011].pixels.shape == (4, 2, 4)
        np.testing.assert_array_equal(tex[1011].pixels.view(np.float16), written[1011])
        assert tex[1011].alpha_mode == img.alpha_mode
        hits = [w for w in warnings if "1012" in w]
        assert len(hits) == (0 if packed else 1) and all("magenta" in h for h in hits), warnings
        assert not [w for w in warnings if "first tile" in w]
        assert sum(t.nbytes for t in scene.textures) == sum(a.nbytes for a in written.values())


def test_udim_tiles_read_as_blender_reads_the_same_files(tmp_path):
    """Each sRGB tile decodes to what Blender's own loader gives for that file as a plain image
    (Image.pixels through image_texture: bytes as bytes, 16-bit linearised floats), and fails
    if the tile were read as another one."""
    oiio = pytest.importorskip("OpenImageIO")
    fresh()
    rng = np.random.default_rng(12)
    img, written = _udim_image(tmp_path, oiio, rng, space="sRGB")
    from addon.export.nodes import image_texture, tile_textures
    warn = []
    tiles = dict(tile_textures(img, warn.append))
    assert tiles[1012] is None and len(warn) == 1
    for t in (1001, 1002):
        single = bpy.data.images.load(str(tmp_path / f"wood.{t}.png"), check_existing=False)
        single.colorspace_settings.name = "sRGB"
        ref = image_texture(single, warn.append)
        # (Blender linearises 16-bit files with OpenColorIO's fast pow: 2.2e-5 relative from the EOTF)
        np.testing.assert_allclose(tiles[t].decoded(), ref.decoded(), rtol=1e-6 if t == 1001 else 5e-5, atol=1e-7,
                                   err_msg=str(t))
    assert tiles[1001].colorspace == "sRGB" and tiles[1001].pixels.dtype == np.uint8
    assert tiles[1001].decoded().shape != tiles[1002].decoded().shape


def test_missing_image_is_magenta_index_and_warned_once(tmp_path):
    fresh()
    gone = bpy.data.images.new("Gone", 4, 4)
    gone.source, gone.filepath = "FILE", str(tmp_path / "gone.png")
    mat, tree, bsdf = surface_material("Lost", "ShaderNodeBsdfDiffuse")
    node = tree.nodes.new("ShaderNodeTexImage")
    node.image = gone
    tree.links.new(node.outputs["Color"], bsdf.inputs["Color"])
    empty = tree.nodes.new("ShaderNodeTexImage")                # no image at all
    tree.links.new(empty.outputs["Alpha"], bsdf.inputs["Roughness"])
    add_mesh("cube", material=mat)
    add_camera()
    scene, warnings = export_now()
    g = graph_of(scene, "Lost")
    assert g.nodes["Image Texture"].props["image"] == -1 and g.nodes["Image Texture.001"].props["image"] == -1
    assert scene.textures == []
    hits = [w for w in warnings if "'Gone'" in w]
    assert len(hits) == 1 and "missing" in hits[0] and "magenta" in hits[0]
    assert sum("'Image Texture.001' has no image" in w for w in warnings) == 1


# ----------------------------------------------------------------------------
# Procedural chains: Checker through Mapping, Math, Color Ramp, Mix, Mix Shader, RGB Curves
# ----------------------------------------------------------------------------
def test_checker_through_mapping_math_ramp_and_mix():
    fresh()
    mat, tree, bsdf = surface_material("Proc")
    coord = tree.nodes.new("ShaderNodeTexCoord")
    mapping = tree.nodes.new("ShaderNodeMapping")
    mapping.vector_type = "TEXTURE"
    mapping.inputs["Scale"].default_value = (2.0, 3.0, 4.0)
    checker = tree.nodes.new("ShaderNodeTexChecker")
    checker.inputs["Scale"].default_value = 8.0
    checker.inputs["Color1"].default_value = (0.9, 0.1, 0.2, 0.5)
    math_node = tree.nodes.new("ShaderNodeMath")
    math_node.operation, math_node.use_clamp = "MULTIPLY_ADD", True
    math_node.inputs[1].default_value, math_node.inputs[2].default_value = 0.5, 0.25
    ramp = tree.nodes.new("ShaderNodeValToRGB")
    ramp.color_ramp.interpolation = "CONSTANT"
    ramp.color_ramp.elements[0].color = (0.1, 0.2, 0.3, 1.0)
    ramp.color_ramp.elements.new(0.25).color = (1.0, 0.5, 0.0, 0.75)
    mix = tree.nodes.new("ShaderNodeMix")
    mix.data_type, mix.blend_type, mix.clamp_result = "RGBA", "MULTIPLY", True
    mix.inputs["Factor"].default_value = 0.75
    mix.inputs[7].default_value = (1.0, 0.0, 0.0, 1.0)      # B_Color
    links = tree.links
    links.new(coord.outputs["UV"], mapping.inputs["Vector"])
    links.new(mapping.outputs["Vector"], checker.inputs["Vector"])
    links.new(checker.outputs["Fac"], math_node.inputs[0])
    links.new(math_node.outputs[0], ramp.inputs["Fac"])
    links.new(ramp.outputs["Color"], mix.inputs[6])         # A_Color
    links.new(mix.outputs[2], bsdf.inputs["Base Color"])    # Result_Color
    links.new(checker.outputs["Color"], bsdf.inputs["Emission Color"])
    add_mesh("plane", material=mat)
    add_camera()
    scene, warnings = export_now()
    g = graph_of(scene, "Proc")
    n = g.nodes
    assert {k: v.type for k, v in n.items()} == {
        "Principled BSDF": "ShaderNodeBsdfPrincipled", "Texture Coordinate": "ShaderNodeTexCoord",
        "Mapping": "ShaderNodeMapping", "Checker Texture": "ShaderNodeTexChecker", "Math": "ShaderNodeMath",
        "Color Ramp": "ShaderNodeValToRGB", "Mix": "ShaderNodeMix"}
    assert n["Texture Coordinate"].props == {"object": False}
    assert n["Texture Coordinate"].outputs == {"UV": "VECTOR"}       # only what the graph reads
    assert n["Mapping"].props == {"vector_type": "TEXTURE"}
    assert n["Mapping"].inputs["Vector"] == Link("Texture Coordinate", "UV")
    assert n["Mapping"].inputs["Scale"] == (2.0, 3.0, 4.0)
    assert n["Checker Texture"].inputs["Vector"] == Link("Mapping", "Vector")
    assert n["Checker Texture"].inputs["Scale"] == 8.0
    assert n["Checker Texture"].inputs["Color1"] == pytest.approx((0.9, 0.1, 0.2))
    assert n["Checker Texture"].outputs == {"Fac": "VALUE", "Color": "RGBA"}
    assert n["Math"].props == {"operation": "MULTIPLY_ADD", "use_clamp": True}
    assert n["Math"].inputs == {"Value": Link("Checker Texture", "Fac"), "Value_001": 0.5, "Value_002": 0.25}
    r = n["Color Ramp"].props
    assert r["interpolation"] == "CONSTANT" and r["color_mode"] == "RGB"
    assert [e[0] for e in r["elements"]] == pytest.approx([0.0, 0.25, 1.0])
    assert r["elements"][1][1] == pytest.approx((1.0, 0.5, 0.0, 0.75))
    assert n["Mix"].props == {"data_type": "RGBA", "blend_type": "MULTIPLY", "clamp_factor": True,
                              "clamp_result": True, "factor_mode": "UNIFORM"}
    assert n["Mix"].inputs == {"Factor_Float": 0.75, "A_Color": Link("Color Ramp", "Color"),
                               "B_Color": (1.0, 0.0, 0.0)}
    assert n["Mix"].input_types == {"Factor_Float": "VALUE", "A_Color": "RGBA", "B_Color": "RGBA"}
    assert n["Principled BSDF"].inputs["Base Color"] == Link("Mix", "Result_Color")
    assert n["Principled BSDF"].inputs["Emission Color"] == Link("Checker Texture", "Color")
    assert not any("driven by" in w for w in warnings), warnings      # the graph renders them


def test_mix_shader_with_a_textured_fac():
    fresh()
    mat = bpy.data.materials.new("Blend")
    tree = mat.node_tree
    for node in list(tree.nodes):
        if node.bl_idname != "ShaderNodeOutputMaterial":
            tree.nodes.remove(node)
    out = tree.nodes["Material Output"]
    mix = tree.nodes.new("ShaderNodeMixShader")
    diffuse, glossy = tree.nodes.new("ShaderNodeBsdfDiffuse"), tree.nodes.new("ShaderNodeBsdfGlossy")
    glossy.inputs["Roughness"].default_value = 0.125
    checker = tree.nodes.new("ShaderNodeTexChecker")
    tree.links.new(checker.outputs["Fac"], mix.inputs["Fac"])
    tree.links.new(diffuse.outputs[0], mix.inputs[1])
    tree.links.new(glossy.outputs[0], mix.inputs[2])
    tree.links.new(mix.outputs[0], out.inputs["Surface"])
    add_mesh("cube", material=mat)
    add_camera()
    scene, warnings = export_now()
    g = graph_of(scene, "Blend")
    m = g.nodes["Mix Shader"]
    assert g.surface == Link("Mix Shader", "Shader")
    assert m.inputs == {"Fac": Link("Checker Texture", "Fac"), "Shader": Link("Diffuse BSDF", "BSDF"),
                        "Shader_001": Link("Glossy BSDF", "BSDF")}
    assert m.input_types["Shader"] == "SHADER" and g.nodes["Glossy BSDF"].inputs["Roughness"] == 0.125
    assert g.nodes["Checker Texture"].inputs.keys() == {"Color1", "Color2", "Scale"}   # Vector: implicit
    assert not any("Mix Shader approximated" in w for w in warnings), warnings


def test_rgb_curves_table_applies_the_combined_curve_first():
    fresh()
    mat, tree, bsdf = surface_material("Curved", "ShaderNodeEmission")
    curves = tree.nodes.new("ShaderNodeRGBCurve")
    mapping = curves.mapping
    mapping.curves[3].points[1].location = (1.0, 0.5)      # C: x -> x / 2
    mapping.curves[0].points[0].location = (0.0, 1.0)      # R: x -> 1 - x
    mapping.curves[0].points[1].location = (1.0, 0.0)
    mapping.update()
    tree.links.new(tree.nodes.new("ShaderNodeTexChecker").outputs["Color"], curves.inputs["Color"])
    tree.links.new(curves.outputs["Color"], bsdf.inputs["Color"])
    add_mesh("plane", material=mat)
    add_camera()
    scene, _ = export_now()
    node = graph_of(scene, "Curved").nodes["RGB Curves"]
    table = np.array(node.props["table"])
    assert table.shape == (3, 256) and set(node.props) == {"table"}
    x = np.linspace(0, 1, 256)
    np.testing.assert_allclose(table[0], 1 - x / 2, atol=2e-3)     # R(C(x)), not C(R(x)) = (1 - x) / 2
    np.testing.assert_allclose(table[1], x / 2, atol=2e-3)
    np.testing.assert_allclose(table[2], x / 2, atol=2e-3)


# ----------------------------------------------------------------------------
# Node groups, muted nodes, reroutes; when no graph is exported
# ----------------------------------------------------------------------------
def _group() -> "bpy.types.ShaderNodeTree":
    """A group: Principled whose Roughness = Fac * 2 and whose Base Color is a checker of Col."""
    g = bpy.data.node_groups.new("Rough", "ShaderNodeTree")
    g.interface.new_socket("Fac", in_out="INPUT", socket_type="NodeSocketFloat")
    col = g.interface.new_socket("Col", in_out="INPUT", socket_type="NodeSocketColor")
    col.default_value = (1, 1, 1, 1)
    g.interface.new_socket("BSDF", in_out="OUTPUT", socket_type="NodeSocketShader")
    gin, gout = g.nodes.new("NodeGroupInput"), g.nodes.new("NodeGroupOutput")
    mul = g.nodes.new("ShaderNodeMath")
    mul.operation = "MULTIPLY"
    checker = g.nodes.new("ShaderNodeTexChecker")
    bsdf = g.nodes.new("ShaderNodeBsdfPrincipled")
    g.links.new(gin.outputs["Fac"], mul.inputs[0])
    g.links.new(gin.outputs["Col"], mul.inputs[1])         # a colour into a float: luminance
    g.links.new(gin.outputs["Col"], checker.inputs["Color1"])
    g.links.new(mul.outputs[0], bsdf.inputs["Roughness"])
    g.links.new(checker.outputs["Color"], bsdf.inputs["Base Color"])
    g.links.new(bsdf.outputs[0], gout.inputs["BSDF"])
    return g


def test_node_groups_are_inlined():
    fresh()
    mat = bpy.data.materials.new("Grouped")
    tree = mat.node_tree
    for node in list(tree.nodes):
        if node.bl_idname != "ShaderNodeOutputMaterial":
            tree.nodes.remove(node)
    group = tree.nodes.new("ShaderNodeGroup")
    group.node_tree = _group()
    group.name = "Grp"
    group.inputs["Col"].default_value = (0.2, 0.4, 0.6, 1.0)
    outer = tree.nodes.new("ShaderNodeTexGradient")
    outer.gradient_type = "RADIAL"
    reroute = tree.nodes.new("NodeReroute")
    tree.links.new(outer.outputs["Fac"], reroute.inputs[0])
    tree.links.new(reroute.outputs[0], group.inputs["Fac"])
    tree.links.new(group.outputs["BSDF"], tree.nodes["Material Output"].inputs["Surface"])
    add_mesh("cube", material=mat)
    add_camera()
    scene, warnings = export_now()
    g = graph_of(scene, "Grouped")
    assert set(g.nodes) == {"Grp/Principled BSDF", "Grp/Math", "Grp/Checker Texture", "Gradient Texture"}
    assert g.surface == Link("Grp/Principled BSDF", "BSDF")
    assert g.nodes["Gradient Texture"].props == {"gradient_type": "RADIAL"}
    mul = g.nodes["Grp/Math"]
    assert mul.inputs["Value"] == Link("Gradient Texture", "Fac")           # through the reroute and the group
    assert mul.inputs["Value_001"] == pytest.approx(0.2126 * 0.2 + 0.7152 * 0.4 + 0.0722 * 0.6)
    assert g.nodes["Grp/Checker Texture"].inputs["Color1"] == pytest.approx((0.2, 0.4, 0.6))
    p = g.nodes["Grp/Principled BSDF"].inputs
    assert p["Roughness"] == Link("Grp/Math", "Value") and p["Base Color"] == Link("Grp/Checker Texture", "Color")
    assert not any("ShaderNodeGroup" in w for w in warnings), warnings


def test_muted_nodes_pass_their_input_and_muted_links_are_unlinked():
    fresh()
    mat, tree, bsdf = surface_material("Muted")
    checker = tree.nodes.new("ShaderNodeTexChecker")
    muted = tree.nodes.new("ShaderNodeMath")
    muted.operation, muted.mute = "POWER", True
    tree.links.new(checker.outputs["Fac"], muted.inputs[0])
    tree.links.new(muted.outputs[0], bsdf.inputs["Roughness"])
    gradient = tree.nodes.new("ShaderNodeTexGradient")
    tree.links.new(gradient.outputs["Color"], bsdf.inputs["Base Color"]).is_muted = True
    lonely = tree.nodes.new("ShaderNodeMath")                 # muted, its passed input unlinked: its value
    lonely.mute = True
    lonely.inputs[0].default_value = 0.375
    tree.links.new(lonely.outputs[0], bsdf.inputs["Metallic"])
    add_mesh("cube", material=mat)
    add_camera()
    scene, _ = export_now()
    p = graph_of(scene, "Muted").nodes["Principled BSDF"]
    assert p.inputs["Roughness"] == Link("Checker Texture", "Fac")
    assert p.inputs["Base Color"] == pytest.approx((0.8, 0.8, 0.8))      # the socket's own value
    assert p.inputs["Metallic"] == 0.375
    assert set(graph_of(scene, "Muted").nodes) == {"Principled BSDF", "Checker Texture"}


def test_constant_trees_keep_the_constant_path():
    """Principled / Diffuse / Mix Shader trees with constant or Value / RGB inputs: no graph."""
    fresh()
    mat, tree, bsdf = surface_material("Const")
    rgb, value = tree.nodes.new("ShaderNodeRGB"), tree.nodes.new("ShaderNodeValue")
    rgb.outputs[0].default_value = (0.1, 0.2, 0.3, 1.0)
    value.outputs[0].default_value = 0.25
    tree.links.new(rgb.outputs[0], bsdf.inputs["Base Color"])
    tree.links.new(value.outputs[0], bsdf.inputs["Roughness"])
    add_mesh("cube", "A", material=mat)
    mix_mat = bpy.data.materials.new("Mixed")
    t2 = mix_mat.node_tree
    t2.nodes.remove(t2.nodes["Principled BSDF"])
    mix = t2.nodes.new("ShaderNodeMixShader")
    mix.inputs["Fac"].default_value = 0.3
    t2.links.new(t2.nodes.new("ShaderNodeBsdfDiffuse").outputs[0], mix.inputs[1])
    t2.links.new(t2.nodes.new("ShaderNodeEmission").outputs[0], mix.inputs[2])
    t2.links.new(mix.outputs[0], t2.nodes["Material Output"].inputs["Surface"])
    add_mesh("cube", "B", location=(3, 0, 0), material=mix_mat)
    add_camera()
    scene, warnings = export_now()
    assert all(m.graph is None for m in scene.materials)
    assert scene.textures == []
    m = next(m for m in scene.materials if m.name == "Const")
    np.testing.assert_allclose(m.base_color, (0.1, 0.2, 0.3), atol=1e-6)
    assert m.roughness == pytest.approx(0.25)
    # Diffuse + Emission: the blend of the colours and emission is exactly the two closures' mix
    assert not any("Mix Shader" in w for w in warnings), warnings


def test_unsupported_nodes_warn_once_and_need_no_graph_alone():
    """A node the interpreter does not support renders its consumer's own value on both paths:
    alone it exports no graph (the constant path warns); in a graph the compiler's message names
    it, and the node keeps its own settings as props.  With baking (the default export), the one
    message is the bake report's instead: to be baked (world-unit Wireframe) or why it cannot be
    (pixel-unit Wireframe: view-dependent); tests/test_bake.py covers baking itself."""
    from stpm_core.nodes import SUPPORTED_NODES
    kind = "ShaderNodeWireframe"                               # a ray-traced node: not interpreted
    assert kind not in SUPPORTED_NODES
    fresh()
    mat, tree, bsdf = surface_material("Wired")
    tree.links.new(tree.nodes.new(kind).outputs["Fac"], bsdf.inputs["Roughness"])
    add_mesh("cube", "A", material=mat)
    mat2, tree2, bsdf2 = surface_material("WiredChecker")
    wire = tree2.nodes.new(kind)
    wire.use_pixel_size = True
    tree2.links.new(wire.outputs["Fac"], bsdf2.inputs["Roughness"])
    tree2.links.new(tree2.nodes.new("ShaderNodeTexChecker").outputs["Color"], bsdf2.inputs["Base Color"])
    add_mesh("cube", "B", location=(3, 0, 0), material=mat2)
    add_camera()
    from addon.export import export_scene
    scene = bpy.context.scene
    for bakes in (None, "default"):
        out, warnings = export_scene(bpy.context.evaluated_depsgraph_get(),
                                     lambda f, sub: scene.frame_set(f, subframe=sub), bakes=bakes)
        assert graph_of(out, "Wired") is None
        hits = [w for w in warnings if w.startswith("material 'Wired': ")]
        if bakes is None:
            assert hits == [f"material 'Wired': Principled BSDF.Roughness driven by {kind} is not supported, "
                            "using its value"], warnings
        else:
            assert len(hits) == 1 and "Roughness of 'Principled BSDF' on object 'A' needs a bake" in hits[0] \
                and f"'Wireframe' ({kind}) is not supported" in hits[0] and "default values" in hits[0], hits
        g = graph_of(out, "WiredChecker")
        assert g.nodes["Wireframe"].type == kind and g.nodes["Wireframe"].props == {"use_pixel_size": True}
        hits = [w for w in warnings if w.startswith("material 'WiredChecker': ")]
        assert len(hits) == 1 and f"'Wireframe' ({kind})" in hits[0] and "not supported" in hits[0], hits
        if bakes is not None:
            assert "cannot be baked" in hits[0] and "width in pixels" in hits[0], hits


def test_normal_map_exports_a_graph_and_tangents():
    """A tangent-space Normal Map: the graph carries it (space, UV map) and the mesh its
    MikkTSpace tangents, as Blender computes them, per loop-triangle corner."""
    fresh()
    mat, tree, bsdf = surface_material("Bumpy")
    nmap = tree.nodes.new("ShaderNodeNormalMap")
    nmap.inputs["Strength"].default_value = 0.5
    tree.links.new(tree.nodes.new("ShaderNodeTexChecker").outputs["Color"], nmap.inputs["Color"])
    tree.links.new(nmap.outputs["Normal"], bsdf.inputs["Normal"])
    sphere = add_mesh("sphere", "Ball", material=mat, segments=8, ring_count=4)
    add_camera()
    scene, warnings = export_now()
    g = graph_of(scene, "Bumpy")
    assert g.nodes["Normal Map"].props == {"space": "TANGENT", "uv_map": ""}
    assert g.nodes["Principled BSDF"].inputs["Normal"] == Link("Normal Map", "Normal")
    assert not any("is ignored (no bump" in w for w in warnings), warnings
    mesh = scene.meshes[0]
    assert list(mesh.tangents) == ["UVMap"]
    tan = mesh.tangents["UVMap"]
    assert tan.dtype == np.float32 and tan.shape == (mesh.triangles.shape[0], 3, 4)
    me = sphere.data
    me.calc_tangents(uvmap="UVMap")
    me.calc_loop_triangles()
    want = np.array([[tuple(me.loops[i].tangent) + (me.loops[i].bitangent_sign,) for i in t.loops]
                     for t in me.loop_triangles], np.float32)
    np.testing.assert_allclose(tan, want, atol=1e-6)
    assert set(np.unique(tan[..., 3])) <= {-1.0, 1.0}


def test_tangents_of_an_ngon_mesh_come_from_its_triangles():
    fresh()
    mat, tree, bsdf = surface_material("Flat")
    nmap = tree.nodes.new("ShaderNodeNormalMap")
    tree.links.new(nmap.outputs["Normal"], bsdf.inputs["Normal"])
    bpy.ops.mesh.primitive_circle_add(vertices=6, fill_type="NGON")
    disc = bpy.context.object
    disc.data.materials.append(mat)
    me = disc.data
    layer = me.uv_layers.new(name="UVMap")
    for loop in me.loops:                                     # planar map: u = x, v = y (rescaled)
        co = me.vertices[loop.vertex_index].co
        layer.uv[loop.index].vector = (0.5 + 0.5 * co.x, 0.5 + 0.5 * co.y)
    with pytest.raises(RuntimeError, match="tris/quads"):
        me.calc_tangents(uvmap="UVMap")                        # what Blender itself refuses
    add_camera()
    scene, warnings = export_now()
    tan = scene.meshes[0].tangents["UVMap"]
    assert tan.shape == (4, 3, 4)
    np.testing.assert_allclose(tan.reshape(-1, 4), np.tile([1.0, 0.0, 0.0, 1.0], (12, 1)), atol=1e-6)
    assert not any("tangents" in w for w in warnings), warnings


def test_scene_file_round_trip_of_an_exported_scene(tmp_path):
    from stpm_core.scenefile import load_scene, save_scene
    fresh()
    img = write_png(tmp_path / "p.png", RGBA)
    mat, tree, bsdf = surface_material("Painted")
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = img
    tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    ramp = tree.nodes.new("ShaderNodeValToRGB")
    tree.links.new(tex.outputs["Alpha"], ramp.inputs["Fac"])
    tree.links.new(ramp.outputs["Color"], bsdf.inputs["Emission Color"])
    curves = tree.nodes.new("ShaderNodeRGBCurve")
    tree.links.new(ramp.outputs["Color"], curves.inputs["Color"])
    tree.links.new(curves.outputs["Color"], bsdf.inputs["Coat Tint"])
    add_mesh("plane", material=mat)
    add_camera()
    scene, _ = export_now()
    loaded = load_scene(save_scene(scene, tmp_path / "s.stpm"))
    assert json_round(loaded.materials[0].graph.to_json()) == json_round(scene.materials[0].graph.to_json())
    np.testing.assert_array_equal(loaded.textures[0].pixels, scene.textures[0].pixels)
    assert loaded.meshes[0].uv_render == "UVMap"
    np.testing.assert_array_equal(loaded.meshes[0].uv_layers["UVMap"], scene.meshes[0].uv_layers["UVMap"])


def json_round(d):
    import json
    return json.loads(json.dumps(d))


# ----------------------------------------------------------------------------
# End to end: the interpreter evaluates the exported graph
# ----------------------------------------------------------------------------
def test_exported_image_graph_shades_hits_with_their_texels(tmp_path):
    """Rays cast down onto the exported plane: each hit's closure has the texel under its UV
    (Closest), interpolated from the exported corner UVs at the hit's barycentrics."""
    from stpm_core.kernels import svm
    from stpm_core.kernels.closure import C_BASE, N_CLOSURE
    from stpm_core.raycast import make_caster
    from stpm_core.shading import hit_geometry, shading_data
    from stpm_core.textures import srgb_to_linear
    fresh()
    img = write_png(tmp_path / "p.png", OPAQUE)             # opaque: colours are the texels (no alpha)
    mat, tree, bsdf = surface_material("Painted", "ShaderNodeBsdfDiffuse")
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation = img, "Closest"
    tree.links.new(tex.outputs["Color"], bsdf.inputs["Color"])
    add_mesh("plane", material=mat)                          # 2 m x 2 m at the origin, UVs 0..1
    add_camera()
    scene, _ = export_now()
    rng = np.random.default_rng(5)
    n = 64
    o = np.column_stack([rng.uniform(-0.98, 0.98, (n, 2)), np.full(n, 1.0)])
    d = np.tile([0.0, 0.0, -1.0], (n, 1))
    times = np.full(n, 0.5)
    hits = make_caster(scene).intersect(o, d, times)
    assert np.all(hits.hit)
    sd = shading_data(scene)
    assert sd.uses_programs and sd.unsupported == []
    C = np.zeros((n, N_CLOSURE))
    svm.shade(sd, hits.material, hit_geometry(hits, d, sd=sd, times=times), 0, C)
    mesh = scene.meshes[0]
    uv = mesh.uv_layers[mesh.uv_render].astype(np.float64)[hits.prim]          # (n, 3, 2)
    w = np.column_stack([1.0 - hits.u - hits.v, hits.u, hits.v])
    st = np.einsum("nk,nkj->nj", w, uv)
    np.testing.assert_allclose(st, (o[:, :2] + 1.0) / 2.0, atol=1e-6)          # the plane's UVs: (x, y) mapped
    H, W = RGBA.shape[:2]
    col = np.clip((st[:, 0] * W).astype(int), 0, W - 1)
    row = np.clip((st[:, 1] * H).astype(int), 0, H - 1)
    assert scene.textures[0].pixels.shape == (2, 3, 3)
    want = srgb_to_linear(OPAQUE[row, col, :3] / 255.0)
    edge = (np.abs(st[:, 0] * W - np.rint(st[:, 0] * W)) < 1e-4) | (np.abs(st[:, 1] * H - np.rint(st[:, 1] * H)) < 1e-4)
    np.testing.assert_allclose(C[~edge, C_BASE:C_BASE + 3], want[~edge], atol=1e-6)
    assert len({tuple(np.round(c, 6)) for c in C[:, :3]}) >= 4     # texels, not one mean colour


def test_rendered_checker_has_two_colours_not_its_mean():
    from stpm_core.render import render
    from stpm_core.settings import RenderSettings
    fresh()
    scene_bpy = bpy.context.scene
    scene_bpy.render.resolution_x = scene_bpy.render.resolution_y = 8
    mat, tree, emit = surface_material("Check", "ShaderNodeEmission")
    checker = tree.nodes.new("ShaderNodeTexChecker")
    checker.inputs["Scale"].default_value = 2.0
    checker.inputs["Color1"].default_value = (1.0, 0.0, 0.0, 1.0)
    checker.inputs["Color2"].default_value = (0.0, 0.0, 1.0, 1.0)
    coord = tree.nodes.new("ShaderNodeTexCoord")
    tree.links.new(coord.outputs["UV"], checker.inputs["Vector"])
    tree.links.new(checker.outputs["Color"], emit.inputs["Color"])
    add_mesh("plane", material=mat, size=2.0)
    add_camera(location=(0, 0, 5), rotation=(0, 0, 0), type="ORTHO", ortho_scale=2.0)
    scene, _ = export_now()
    settings = RenderSettings(method="PHOTON", estimator="STANDARD", samples=4, photons_global=0,
                              photons_caustic=0, seed=1, max_depth=1)
    img = render(scene, settings).passes["Combined"][..., :3]
    corners = {"top-left": img[1, 1], "top-right": img[1, 6], "bottom-left": img[6, 1], "bottom-right": img[6, 6]}
    red, blue = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])
    # UV (0, 0) is the plane's bottom-left: checker cells alternate, the diagonal ones match
    np.testing.assert_allclose(corners["bottom-left"], corners["top-right"], atol=0.05)
    np.testing.assert_allclose(corners["top-left"], corners["bottom-right"], atol=0.05)
    assert {tuple(np.round(corners[k], 1)) for k in corners} == {tuple(red), tuple(blue)}
    assert math.isclose(float(img.mean()), float(np.mean([red, blue])), abs_tol=0.1)
