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


def test_normal_map_image_matches_cycles(tmp_path):
    """Includes Cycles' bump shadowing term of diffuse closures (bsdf.bump_shadowing): without it
    this map came out 1.0 % bright with block |z| up to 7."""
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
    nmap.inputs["Strength"].default_value = 0.8
    t.links.new(tex.outputs["Color"], nmap.inputs["Color"])
    t.links.new(nmap.outputs["Normal"], bsdf.inputs["Normal"])
    t.links.new(bsdf.outputs[0], out.inputs["Surface"])
    add_mesh("plane", "Floor", material=mat, size=2.0)
    r, *_ = _compare(tmp_path, "normal map")
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
