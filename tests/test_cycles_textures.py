"""Textures and shader nodes against Cycles (bpy 5.0): direct-only renders compared block by block.

Each scene is built the way an artist builds it (UV-unwrapped meshes, image textures from files on
disk, node trees), rendered by Cycles (``max_bounces = 0``, several seeds) and by STPM through the
add-on's exporter (no photons: Combined = Emit + Direct, several seeds), and compared with the
block Z-test of ``cycles_ref.block_ztest``.  Small images and sample counts: a few seconds each.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytest.importorskip("OpenImageIO")

from test_addon_scenes import add_camera, add_light, add_mesh, fresh, set_world  # noqa: E402
from cycles_ref import block_ztest, render_cycles, render_stpm  # noqa: E402

W, H = 48, 48
SPP = 32
Z_MAX = 4.5              # per block; 36 blocks per image
MEAN_TOL = 0.01


def _write_png(path, rgba: np.ndarray, bits: int = 8) -> None:
    """Write (h, w, c) values in [0, 1] (row 0 = top) to a PNG file of ``bits`` bits per channel."""
    import OpenImageIO as oiio
    h, w, c = rgba.shape
    spec = oiio.ImageSpec(w, h, c, "uint8" if bits == 8 else "uint16")
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), spec)
    scale = 255.0 if bits == 8 else 65535.0
    out.write_image(np.round(np.clip(rgba, 0, 1) * scale).astype(np.uint8 if bits == 8 else np.uint16))
    out.close()


def _pattern(n: int = 8, seed: int = 3) -> np.ndarray:
    """An n x n RGB image of random saturated texels (big texels: sharp, verifiable edges)."""
    rng = np.random.default_rng(seed)
    return rng.uniform(0.05, 0.95, (n, n, 3))


def _top_down_scene():
    """A 2 x 2 m plane (Blender's default UVs: [0, 1]^2) seen from straight above, ortho camera
    framing it exactly, a sun from straight above (strength 3), black world."""
    scene = fresh()
    scene.render.resolution_x, scene.render.resolution_y = W, H
    add_camera(location=(0, 0, 5), rotation=(0, 0, 0), type="ORTHO", ortho_scale=2.0)
    add_light("SUN", energy=3.0, location=(0, 0, 10), angle=0.0)
    set_world((0, 0, 0), 0.0)
    return scene


def _empty_material(name: str):
    """A new material with only its Material Output: (material, node tree, output node)."""
    mat = bpy.data.materials.new(name)
    tree = mat.node_tree
    for n in list(tree.nodes):
        if n.bl_idname != "ShaderNodeOutputMaterial":
            tree.nodes.remove(n)
    return mat, tree, next(n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial")


def _image_material(name, path, colorspace="sRGB", interpolation="Linear", extension="REPEAT", mapping=None):
    """Diffuse surface coloured by an Image Texture of the file at path (Vector: UV, or a Mapping)."""
    mat, tree, out = _empty_material(name)
    bsdf = tree.nodes.new("ShaderNodeBsdfDiffuse")
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.load(str(path))
    tex.image.colorspace_settings.name = colorspace
    tex.interpolation, tex.extension = interpolation, extension
    if mapping is not None:
        coord = tree.nodes.new("ShaderNodeTexCoord")
        mp = tree.nodes.new("ShaderNodeMapping")
        mp.inputs["Location"].default_value = mapping.get("location", (0, 0, 0))
        mp.inputs["Rotation"].default_value = mapping.get("rotation", (0, 0, 0))
        mp.inputs["Scale"].default_value = mapping.get("scale", (1, 1, 1))
        tree.links.new(coord.outputs["UV"], mp.inputs["Vector"])
        tree.links.new(mp.outputs["Vector"], tex.inputs["Vector"])
    tree.links.new(tex.outputs["Color"], bsdf.inputs["Color"])
    tree.links.new(bsdf.outputs[0], out.inputs["Surface"])
    return mat, tree


def _compare(tmp_path, label: str, spp: int = SPP):
    cyc = render_cycles(bpy.context.scene, tmp_path, samples=spp, seeds=(0, 1, 2))
    stpm, _res = render_stpm(bpy.context.scene, samples=spp, seeds=(0, 1, 2))
    r = block_ztest(stpm, cyc)
    print(f"{label}: {r.summary()}")
    return r, stpm, cyc


def _assert_matches(r, label):
    assert r.z_abs_max < Z_MAX, (label, r.summary(), np.round(r.z, 1))
    assert abs(r.mean_ratio - 1.0) < MEAN_TOL, (label, r.summary())


@pytest.mark.parametrize("colorspace", ["sRGB", "Non-Color"])
@pytest.mark.parametrize("interpolation", ["Closest", "Linear", "Cubic"])
def test_uv_image_texture_matches_cycles(tmp_path, colorspace, interpolation):
    png = tmp_path / "pattern.png"
    _write_png(png, _pattern())
    _top_down_scene()
    mat, _ = _image_material("Tex", png, colorspace=colorspace, interpolation=interpolation)
    add_mesh("plane", "Floor", material=mat, size=2.0)
    r, stpm, cyc = _compare(tmp_path, f"image {colorspace} {interpolation}")
    _assert_matches(r, "image")
    # Not one mean colour: the blocks spread as widely as Cycles' do
    assert np.std(r.stpm) > 0.5 * np.std(r.cycles) > 0.0


def test_mapped_image_16bit_repeat_and_mirror_match_cycles(tmp_path):
    png = tmp_path / "pattern16.png"
    _write_png(png, _pattern(6, seed=5), bits=16)
    _top_down_scene()
    mat, _ = _image_material("Tex16", png, interpolation="Closest", extension="MIRROR",
                             mapping={"scale": (2.5, 1.5, 1.0), "rotation": (0, 0, math.radians(20)),
                                      "location": (0.1, -0.2, 0)})
    add_mesh("plane", "Floor", material=mat, size=2.0)
    r, *_ = _compare(tmp_path, "16-bit mirror mapped")
    _assert_matches(r, "16-bit mirror")


def _procedural_material(name: str):
    """Checker (Object coordinates, scaled) -> ColorRamp of a Gradient mixed by Multiply, through
    Hue/Saturation, Invert, Math and Bright/Contrast: many nodes in one tree."""
    mat, t, out = _empty_material(name)
    bsdf = t.nodes.new("ShaderNodeBsdfPrincipled")
    coord = t.nodes.new("ShaderNodeTexCoord")
    checker = t.nodes.new("ShaderNodeTexChecker")
    checker.inputs["Scale"].default_value = 3.0
    checker.inputs["Color1"].default_value = (0.9, 0.3, 0.1, 1)
    checker.inputs["Color2"].default_value = (0.1, 0.4, 0.8, 1)
    t.links.new(coord.outputs["Object"], checker.inputs["Vector"])
    grad = t.nodes.new("ShaderNodeTexGradient")
    t.links.new(coord.outputs["Generated"], grad.inputs["Vector"])
    ramp = t.nodes.new("ShaderNodeValToRGB")
    ramp.color_ramp.elements[0].color = (0.2, 0.9, 0.2, 1)
    ramp.color_ramp.elements[1].color = (1.0, 1.0, 0.3, 1)
    ramp.color_ramp.elements.new(0.5).color = (0.9, 0.1, 0.6, 1)
    t.links.new(grad.outputs["Fac"], ramp.inputs["Fac"])
    mix = t.nodes.new("ShaderNodeMix")
    mix.data_type, mix.blend_type = "RGBA", "MULTIPLY"
    mix.inputs["Factor"].default_value = 0.8
    t.links.new(checker.outputs["Color"], mix.inputs[6])          # A_Color, B_Color: inputs 6, 7
    t.links.new(ramp.outputs["Color"], mix.inputs[7])
    hsv = t.nodes.new("ShaderNodeHueSaturation")
    hsv.inputs["Hue"].default_value = 0.6
    t.links.new(mix.outputs[2], hsv.inputs["Color"])
    inv = t.nodes.new("ShaderNodeInvert")
    inv.inputs["Fac"].default_value = 0.3
    t.links.new(hsv.outputs["Color"], inv.inputs["Color"])
    bc = t.nodes.new("ShaderNodeBrightContrast")
    bc.inputs["Contrast"].default_value = 0.2
    t.links.new(inv.outputs["Color"], bc.inputs["Color"])
    t.links.new(bc.outputs["Color"], bsdf.inputs["Base Color"])
    bsdf.inputs["Specular IOR Level"].default_value = 0.0
    bsdf.inputs["Roughness"].default_value = 1.0
    t.links.new(bsdf.outputs[0], out.inputs["Surface"])
    return mat


def test_procedural_node_tree_matches_cycles(tmp_path):
    _top_down_scene()
    add_mesh("plane", "Floor", material=_procedural_material("Proc"), size=2.0)
    r, *_ = _compare(tmp_path, "procedural tree")
    _assert_matches(r, "procedural")


def test_mix_shader_with_a_textured_factor_matches_cycles(tmp_path):
    png = tmp_path / "mask.png"
    _write_png(png, np.repeat(_pattern(4, seed=9)[..., :1], 3, axis=2))
    _top_down_scene()
    mat, t, out = _empty_material("MixTex")
    red, blue = t.nodes.new("ShaderNodeBsdfDiffuse"), t.nodes.new("ShaderNodeBsdfDiffuse")
    red.inputs["Color"].default_value = (0.8, 0.1, 0.1, 1)
    blue.inputs["Color"].default_value = (0.1, 0.2, 0.9, 1)
    tex = t.nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.load(str(png))
    tex.image.colorspace_settings.name = "Non-Color"
    tex.interpolation = "Closest"
    mix = t.nodes.new("ShaderNodeMixShader")
    t.links.new(tex.outputs["Color"], mix.inputs["Fac"])
    t.links.new(red.outputs[0], mix.inputs[1])
    t.links.new(blue.outputs[0], mix.inputs[2])
    t.links.new(mix.outputs[0], out.inputs["Surface"])
    add_mesh("plane", "Floor", material=mat, size=2.0)
    r, *_ = _compare(tmp_path, "mix shader", spp=64)
    _assert_matches(r, "mix shader")


def _slanted_sun_scene():
    """The top-down plane under a sun 40 degrees from the zenith (normal changes show)."""
    scene = _top_down_scene()
    bpy.data.objects["Light"].rotation_euler = (math.radians(40), 0.0, math.radians(30))
    return scene


@pytest.mark.parametrize("strength", [0.8, 3.0])
def test_normal_map_image_matches_cycles(tmp_path, strength):
    """Includes Cycles' bump shadowing term of diffuse closures (bsdf.bump_shadowing): without it
    this map came out 1.0 % bright with block |z| up to 7.  Strength 3: applied in tangent space
    as Cycles does (blending the normals instead came out 17 % off)."""
    # A tangent-space normal map of smooth bumps (a Non-Color 8-bit PNG) on a UV plane
    n = 32
    y, x = np.mgrid[0:n, 0:n] / n
    h = np.sin(2 * np.pi * 2 * x) * np.cos(2 * np.pi * 2 * y)
    dx = np.gradient(h, axis=1) * n / 8.0
    dy = -np.gradient(h, axis=0) * n / 8.0          # image rows go down, v goes up
    nrm = np.stack([-dx, -dy, np.ones_like(h)], -1)
    nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
    png = tmp_path / "normal.png"
    _write_png(png, 0.5 * nrm + 0.5)
    _slanted_sun_scene()
    mat, t, out = _empty_material("Bumpy")
    bsdf = t.nodes.new("ShaderNodeBsdfDiffuse")
    tex = t.nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.load(str(png))
    tex.image.colorspace_settings.name = "Non-Color"
    nmap = t.nodes.new("ShaderNodeNormalMap")
    nmap.inputs["Strength"].default_value = strength
    t.links.new(tex.outputs["Color"], nmap.inputs["Color"])
    t.links.new(nmap.outputs["Normal"], bsdf.inputs["Normal"])
    t.links.new(bsdf.outputs[0], out.inputs["Surface"])
    add_mesh("plane", "Floor", material=mat, size=2.0)
    r, *_ = _compare(tmp_path, f"normal map strength {strength}")
    _assert_matches(r, "normal map")
    assert np.std(r.cycles) > 0.02            # the map does show


def test_noise_voronoi_and_bump_match_cycles(tmp_path):
    # Noise (3D fBM) mixed with Voronoi F1 distance into the colour, and a Noise height bumping
    # the normal: procedural textures with Blender's formulas, and the Bump node
    _slanted_sun_scene()
    mat, t, out = _empty_material("Procedural")
    bsdf = t.nodes.new("ShaderNodeBsdfDiffuse")
    noise = t.nodes.new("ShaderNodeTexNoise")
    noise.inputs["Scale"].default_value = 3.0
    vor = t.nodes.new("ShaderNodeTexVoronoi")
    vor.inputs["Scale"].default_value = 4.0
    mix = t.nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    mix.inputs["Factor"].default_value = 0.5
    t.links.new(noise.outputs["Color"], mix.inputs[6])
    t.links.new(vor.outputs["Color"], mix.inputs[7])
    t.links.new(mix.outputs[2], bsdf.inputs["Color"])
    bump_noise = t.nodes.new("ShaderNodeTexNoise")
    bump_noise.inputs["Scale"].default_value = 1.5
    bump_noise.inputs["Detail"].default_value = 0.0
    bump = t.nodes.new("ShaderNodeBump")
    bump.inputs["Distance"].default_value = 0.2
    bump.inputs["Strength"].default_value = 0.6
    t.links.new(bump_noise.outputs["Fac"], bump.inputs["Height"])
    t.links.new(bump.outputs["Normal"], bsdf.inputs["Normal"])
    t.links.new(bsdf.outputs[0], out.inputs["Surface"])
    add_mesh("plane", "Floor", material=mat, size=2.0)
    r, *_ = _compare(tmp_path, "noise + voronoi + bump")
    _assert_matches(r, "procedural + bump")


# ----------------------------------------------------------------------------
# Textured emitters: the light they cast follows their texture
# ----------------------------------------------------------------------------
def _screen_scene(png):
    """A white floor (2 x 2 m) lit only by a "screen": a 2 x 1 m plane standing at its back edge,
    facing the floor, emitting an image (left half red, right half blue) at strength 4; black world,
    perspective camera in front.  The floor's light is red on one side, blue on the other."""
    scene = fresh()
    scene.render.resolution_x, scene.render.resolution_y = W, H
    add_camera(location=(0, -3.2, 2.2), rotation=(math.radians(58), 0, 0), lens=30)
    set_world((0, 0, 0), 0.0)
    floor_mat, t, out = _empty_material("Floor")
    d = t.nodes.new("ShaderNodeBsdfDiffuse")
    d.inputs["Color"].default_value = (0.8, 0.8, 0.8, 1)
    t.links.new(d.outputs[0], out.inputs["Surface"])
    add_mesh("plane", "Floor", material=floor_mat, size=2.0)
    mat, t, out = _empty_material("Screen")
    em = t.nodes.new("ShaderNodeEmission")
    em.inputs["Strength"].default_value = 4.0
    tex = t.nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.load(str(png))
    tex.interpolation = "Closest"
    t.links.new(tex.outputs["Color"], em.inputs["Color"])
    t.links.new(em.outputs[0], out.inputs["Surface"])
    screen = add_mesh("plane", "Screen", location=(0, 1.0, 0.5), material=mat, size=1.0,
                      rotation=(math.radians(90), 0, 0))
    screen.scale = (2.0, 1.0, 1.0)
    return scene


def test_textured_emitter_casts_its_texture_like_cycles(tmp_path):
    png = tmp_path / "screen.png"
    img = np.zeros((1, 2, 3))
    img[0, 0] = (1.0, 0.15, 0.1)       # left: red
    img[0, 1] = (0.1, 0.2, 1.0)        # right: blue
    _write_png(png, img)
    _screen_scene(png)
    r, stpm, cyc = _compare(tmp_path, "textured emitter", spp=64)
    _assert_matches(r, "textured emitter")
    # The floor in front of the screen's left half is lit red, the right half blue (not one mean colour)
    floor = stpm.mean(axis=0)[int(0.55 * H):int(0.68 * H)]       # the floor just in front of the screen
    left, right = floor[:, int(0.25 * W):int(0.45 * W)].mean(axis=(0, 1)), floor[:, int(0.55 * W):int(0.75 * W)].mean(axis=(0, 1))
    assert left[0] > 1.3 * left[2] and right[2] > 1.3 * right[0], (left, right)


def test_textured_emitter_photons_and_light_samples_carry_its_texture(tmp_path):
    """Photon emission and next-event samples of a textured emitter: the flux is 2 pi A times the
    mean emitted radiance (the image's two halves, sRGB decoded), and each photon's colour is its
    own point's (red left of the screen's centre, blue right)."""
    from addon.export import export_scene
    from stpm_core.lights import LightSet
    png = tmp_path / "screen.png"
    img = np.zeros((1, 2, 3))
    img[0, 0] = (1.0, 0.15, 0.1)
    img[0, 1] = (0.1, 0.2, 1.0)
    _write_png(png, img)
    _screen_scene(png)
    bl = bpy.context.scene
    core = export_scene(bpy.context.evaluated_depsgraph_get(), lambda f, sub: bl.frame_set(f, subframe=sub))[0]
    lights = LightSet(core)
    li = [i for i, l in enumerate(lights.lights) if l.type == "MESH"]
    assert len(li) == 1 and lights.lights[li[0]].textured
    li = li[0]

    def srgb(c):
        c = np.round(np.asarray(c) * 255) / 255
        return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    Le_mean = 4.0 * 0.5 * (srgb(img[0, 0]) + srgb(img[0, 1]))
    flux = 2.0 * np.pi * 2.0 * Le_mean                              # both sides, A = 2 m^2
    np.testing.assert_allclose(lights.flux(li), flux, rtol=0.02)
    o, d, P = lights.emit(li, 40000, np.full(1, 0.5), np.random.default_rng(1))
    np.testing.assert_allclose(P.sum(axis=0), flux, rtol=0.02)
    left, right = o[:, 0] < -0.05, o[:, 0] > 0.05
    np.testing.assert_allclose(P[left].mean(axis=0) / P[left].mean(axis=0).sum(),
                               srgb(img[0, 0]) / srgb(img[0, 0]).sum(), atol=1e-6)
    np.testing.assert_allclose(P[right].mean(axis=0) / P[right].mean(axis=0).sum(),
                               srgb(img[0, 1]) / srgb(img[0, 1]).sum(), atol=1e-6)
    # Next-event samples from a floor point: E[weight * cos] = irradiance; its colour follows the halves
    p = np.tile([[-0.8, 0.6, 0.0]], (20000, 1))
    wi, dist, w = lights.sample_direct(li, p, np.full(20000, 0.5), np.random.default_rng(2).random((20000, 2)))
    hit_left = (p + dist[:, None] * wi)[:, 0] < 0.0
    assert w[hit_left, 0].mean() > 3 * w[hit_left, 2].mean()
    assert w[~hit_left, 2].mean() > 3 * w[~hit_left, 0].mean()


# ----------------------------------------------------------------------------
# Transparency: alpha cut-outs, Transparent BSDF, Add Shader
# ----------------------------------------------------------------------------
def _cutout_scene():
    """The top-down view of a checker floor (2 x 2 m) under a slanted sun, with a 1.2 m square
    "leaf" 0.5 m above it: what the leaf lets through shows the floor and lets the sun reach it."""
    scene = _slanted_sun_scene()
    add_mesh("plane", "Floor", material=_procedural_material("Floor"), size=2.0)
    return scene


def _cutout_image(path, n: int = 6, seed: int = 4) -> None:
    """An n x n RGBA PNG: random green-ish texels, alpha 0 on about half of them (holes)."""
    rng = np.random.default_rng(seed)
    px = np.empty((n, n, 4))
    px[..., 0] = rng.uniform(0.1, 0.4, (n, n))
    px[..., 1] = rng.uniform(0.5, 0.9, (n, n))
    px[..., 2] = rng.uniform(0.1, 0.3, (n, n))
    px[..., 3] = (rng.random((n, n)) < 0.5).astype(float)
    _write_png(path, px)


def test_alpha_cutout_and_its_shadow_match_cycles(tmp_path):
    png = tmp_path / "leaf.png"
    _cutout_image(png)
    _cutout_scene()
    mat, t, out = _empty_material("Leaf")
    p = t.nodes.new("ShaderNodeBsdfPrincipled")
    tex = t.nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.load(str(png))
    tex.interpolation = "Closest"
    t.links.new(tex.outputs["Color"], p.inputs["Base Color"])
    t.links.new(tex.outputs["Alpha"], p.inputs["Alpha"])
    t.links.new(p.outputs[0], out.inputs["Surface"])
    add_mesh("plane", "Leaf", location=(0.1, -0.1, 0.5), material=mat, size=1.2)
    r, stpm, cyc = _compare(tmp_path, "alpha cut-out", spp=64)
    _assert_matches(r, "alpha cut-out")


def test_transparent_mix_and_add_shader_match_cycles(tmp_path):
    """A tinted Transparent BSDF mixed 50/50 with a diffuse (what lies behind shows through, tinted,
    and its shadow is tinted), beside an Add Shader of an emission and a diffuse."""
    _cutout_scene()
    mat, t, out = _empty_material("Veil")
    tr, d = t.nodes.new("ShaderNodeBsdfTransparent"), t.nodes.new("ShaderNodeBsdfDiffuse")
    tr.inputs["Color"].default_value = (1.0, 0.5, 0.2, 1)
    d.inputs["Color"].default_value = (0.2, 0.3, 0.9, 1)
    mix = t.nodes.new("ShaderNodeMixShader")
    mix.inputs["Fac"].default_value = 0.5
    t.links.new(tr.outputs[0], mix.inputs[1])
    t.links.new(d.outputs[0], mix.inputs[2])
    t.links.new(mix.outputs[0], out.inputs["Surface"])
    add_mesh("plane", "Veil", location=(-0.45, 0.0, 0.5), material=mat, size=0.8)
    mat2, t2, out2 = _empty_material("Glow")
    em, d2 = t2.nodes.new("ShaderNodeEmission"), t2.nodes.new("ShaderNodeBsdfDiffuse")
    em.inputs["Color"].default_value = (0.9, 0.4, 0.1, 1)
    em.inputs["Strength"].default_value = 0.5
    d2.inputs["Color"].default_value = (0.3, 0.8, 0.3, 1)
    add = t2.nodes.new("ShaderNodeAddShader")
    t2.links.new(em.outputs[0], add.inputs[0])
    t2.links.new(d2.outputs[0], add.inputs[1])
    t2.links.new(add.outputs[0], out2.inputs["Surface"])
    add_mesh("plane", "Glow", location=(0.5, 0.3, 0.3), material=mat2, size=0.6)
    r, stpm, cyc = _compare(tmp_path, "transparent mix + add", spp=64)
    _assert_matches(r, "transparent mix + add")


# ----------------------------------------------------------------------------
# Colour attributes
# ----------------------------------------------------------------------------
@pytest.mark.parametrize("domain, dtype", [("CORNER", "BYTE_COLOR"), ("POINT", "FLOAT_COLOR")])
def test_color_attribute_matches_cycles(tmp_path, domain, dtype):
    """A subdivided plane with a random colour attribute (painted per corner or per vertex, byte or
    float) read by a Color Attribute node (the render-active one) into a Diffuse, and by name
    through an Attribute node's Fac into a Mix."""
    _top_down_scene()
    mat, t, out = _empty_material("Painted")
    vc = t.nodes.new("ShaderNodeVertexColor")
    attr = t.nodes.new("ShaderNodeAttribute")
    attr.attribute_name = "Wear"
    mix = t.nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    mix.inputs["B"].default_value = (0.9, 0.9, 0.2, 1.0)
    d = t.nodes.new("ShaderNodeBsdfDiffuse")
    t.links.new(attr.outputs["Fac"], mix.inputs["Factor"])
    t.links.new(vc.outputs["Color"], mix.inputs["A"])
    t.links.new(mix.outputs["Result"], d.inputs["Color"])
    t.links.new(d.outputs[0], out.inputs["Surface"])
    obj = add_mesh("plane", "Floor", material=mat, size=2.0)
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.subdivide(number_cuts=3)
    bpy.ops.object.mode_set(mode="OBJECT")
    me = obj.data
    rng = np.random.default_rng(7)
    for name in ("Paint", "Wear"):
        a = me.color_attributes.new(name, dtype, domain)
        vals = rng.uniform(0.0, 1.0, (len(a.data), 4))
        vals[:, 3] = 1.0
        a.data.foreach_set("color", vals.astype(np.float32).ravel())
    me.color_attributes.render_color_index = me.color_attributes.find("Paint")
    me.color_attributes.active_color = me.color_attributes["Paint"]
    r, stpm, cyc = _compare(tmp_path, f"colour attribute {domain} {dtype}")
    _assert_matches(r, "colour attribute")
    assert np.std(r.stpm) > 0.5 * np.std(r.cycles) > 0.0


# ----------------------------------------------------------------------------
# The Principled BSDF's rough dielectric layer (kernels/bsdf.py: COAT energy and layering)
# ----------------------------------------------------------------------------
@pytest.mark.parametrize("roughness, base", [(1.0, 0.8), (0.5, 0.8), (1.0, 0.0)])
def test_rough_principled_matches_cycles(tmp_path, roughness, base):
    """A uniform Principled plane under the slanted sun: Cycles' energy-preserving dielectric layer
    and its layering weight 1 - albedo (before: 2.8 % dark at roughness 1, 8 % on the specular
    alone)."""
    _slanted_sun_scene()
    mat, t, out = _empty_material("Rough")
    p = t.nodes.new("ShaderNodeBsdfPrincipled")
    p.inputs["Roughness"].default_value = roughness
    p.inputs["Base Color"].default_value = (base, base, base, 1.0)
    t.links.new(p.outputs[0], out.inputs["Surface"])
    add_mesh("plane", "Floor", material=mat, size=2.0)
    r, *_ = _compare(tmp_path, f"principled roughness {roughness} base {base}")
    _assert_matches(r, "principled")
