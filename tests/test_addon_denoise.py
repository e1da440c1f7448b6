"""Denoising in Blender (issue 17): Cycles' guide passes against Cycles itself, the compositor's
STPM Denoise group, Blender's Denoise node on F12 and on ``stpm render``.

* The guides: Denoising Albedo of a textured plane is its texture, texel for texel, in STPM and in
  Cycles (bpy 5.0, ``denoising_store_passes``); on a scene with a textured Principled floor, rough
  and glossy metal and glass, both passes match Cycles' block by block (normals in Cycles' camera
  space).
* The compositor: ``scene.stpm.denoise`` puts the STPM Denoise group between Render Layers and
  what the image fed, and takes it out again.
* The image: F12 with ``denoise`` writes the denoised image (the compositor's) beside the raw
  Noisy Image; against a converged STPM render its HDR-FLIP is far below the raw one's, and no
  worse on the rough metal sphere (the issue: unguided denoising smeared rough metal).  The full
  criterion (at most half the raw FLIP) is the slow test at 256 x 192, where OpenImageDenoise has
  the context it needs; ``stpm render`` gives the same denoised pixels as F12's compositor.
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
oiio = pytest.importorskip("OpenImageIO")

from test_addon_scenes import add_camera, add_light, add_mesh, fresh, set_world  # noqa: E402
from test_cycles_textures import _empty_material, _pattern, _top_down_scene, _write_png  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def _layers(path) -> dict:
    """Every layer of a multilayer EXR as name -> (H, W, C) float32 (row 0 = top)."""
    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, oiio.geterror()
    out, sub = {}, 0
    while inp.seek_subimage(sub, 0):
        sp = inp.spec()
        px = inp.read_image(sub, 0, 0, sp.nchannels, "float")
        out[sp.getattribute("name")] = np.asarray(px, np.float32).reshape(sp.height, sp.width, sp.nchannels)
        sub += 1
    inp.close()
    return out


def _multilayer(scene, path) -> None:
    s = scene.render.image_settings
    s.media_type = "MULTI_LAYER_IMAGE"
    s.color_depth = "32"
    scene.render.filepath, scene.render.use_file_extension = str(path), False


def _cycles_guides(scene, tmp_path, samples: int) -> dict:
    """Cycles' Denoising Albedo and Normal (CPU, no denoising, no adaptive sampling)."""
    scene.render.engine = "CYCLES"
    cy = scene.cycles
    cy.device, cy.samples, cy.use_denoising, cy.use_adaptive_sampling = "CPU", samples, False, False
    scene.view_layers[0].cycles.denoising_store_passes = True
    _multilayer(scene, tmp_path / "cycles.exr")
    bpy.ops.render.render(write_still=True)
    layers = _layers(tmp_path / "cycles.exr")
    return {n: layers[f"ViewLayer.{n}"][..., :3] for n in ("Denoising Albedo", "Denoising Normal")}


def _stpm_passes(scene, samples: int, **settings) -> dict:
    """STPM's passes of the scene (the add-on's exporter, then the core) with ``denoise``."""
    from addon.export import export_scene
    from stpm_core.render import render
    from stpm_core.settings import RenderSettings
    scene.render.engine = "STPM"
    core, _w = export_scene(bpy.context.evaluated_depsgraph_get(), lambda f, sub: scene.frame_set(f, subframe=sub))[:2]
    kw = dict(samples=samples, seed=0, photons_caustic=0, photons_global=0, denoise=True)
    kw.update(settings)
    return render(core, RenderSettings(**kw)).passes


def _textured_floor(png) -> None:
    """A 6 m plane "Floor" whose Principled Base Color is the image ``png`` (Closest interpolation)."""
    mat, tree, bsdf = _principled("Floor")
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.load(str(png))
    tex.interpolation = "Closest"
    tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    add_mesh("plane", "Floor", material=mat, size=6.0)


def _principled(name, **inputs):
    mat, tree, out = _empty_material(name)
    bsdf = tree.nodes.new("ShaderNodeBsdfPrincipled")
    for key, value in inputs.items():
        bsdf.inputs[key].default_value = value
    tree.links.new(bsdf.outputs[0], out.inputs["Surface"])
    return mat, tree, bsdf


def _sphere(name, location, radius, material):
    add_mesh("sphere", name, location=location, material=material, radius=radius, segments=48, ring_count=24)
    bpy.ops.object.shade_smooth()


# ----------------------------------------------------------------------------
# The guide passes against Cycles
# ----------------------------------------------------------------------------
def test_the_albedo_of_a_textured_plane_is_its_texture_as_in_cycles(tmp_path):
    """48 x 48 pixels over 8 x 8 texels (Closest, non-colour: the stored 8-bit values): where the
    1.5-pixel filter stays inside one texel, both albedos are that texel's value; the normal of the
    plane facing the camera is (0, 0, -1) in Cycles' camera space (z into the view)."""
    texels = _pattern()
    png = tmp_path / "pattern.png"
    _write_png(png, texels)
    scene = _top_down_scene()
    mat, tree, out = _empty_material("Tex")
    bsdf = tree.nodes.new("ShaderNodeBsdfDiffuse")
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.load(str(png))
    tex.image.colorspace_settings.name = "Non-Color"
    tex.interpolation = "Closest"
    tree.links.new(tex.outputs["Color"], bsdf.inputs["Color"])
    tree.links.new(bsdf.outputs[0], out.inputs["Surface"])
    add_mesh("plane", "Floor", material=mat, size=2.0)
    cycles = _cycles_guides(scene, tmp_path, samples=16)
    stpm = _stpm_passes(scene, samples=16)
    stored = np.round(np.clip(texels, 0, 1) * 255) / 255          # what the PNG holds
    expected = np.repeat(np.repeat(stored, 6, axis=0), 6, axis=1)   # 6 x 6 pixels per texel, row 0 = top
    inner = np.zeros((48, 48), bool)
    for k in (2, 3):
        inner[k::6, 2::6] = inner[k::6, 3::6] = True
    for name, guides in (("STPM", stpm), ("Cycles", cycles)):
        np.testing.assert_allclose(guides["Denoising Albedo"][inner], expected[inner], atol=2e-5, err_msg=name)
        # (the 2-pixel border: samples of the pixel filter land outside the plane, as in Cycles)
        np.testing.assert_allclose(guides["Denoising Normal"][2:-2, 2:-2].reshape(-1, 3),
                                   np.broadcast_to([0, 0, -1.0], (44 * 44, 3)), atol=1e-5, err_msg=name)
    # the texel edges too, up to the two renderers' own sample positions
    assert np.abs(stpm["Denoising Albedo"] - cycles["Denoising Albedo"]).mean() < 0.01


def _guides_scene(png: Path, size=(64, 48)):
    """A textured Principled floor (roughness 0.5: its specular layer is diffuse-like), a rough metal
    sphere (roughness 0.4: GGX alpha 0.16, diffuse-like), a glossy one (roughness 0.15: alpha 0.023,
    specular-like: the features go on to what it reflects) and clear glass, an area light, a grey world."""
    scene = fresh()
    scene.render.resolution_x, scene.render.resolution_y = size
    add_camera(location=(0, -5.5, 2.6), rotation=(math.radians(68), 0, 0))
    add_light("AREA", energy=300.0, location=(1.5, -1.5, 4.0), size=1.5)
    set_world((0.3, 0.35, 0.4), 1.0)
    _textured_floor(png)
    _sphere("RoughMetal", (-1.3, 0, 0.7), 0.7, _principled("RoughMetal", **{
        "Base Color": (0.9, 0.6, 0.3, 1), "Metallic": 1.0, "Roughness": 0.4})[0])
    _sphere("GlossyMetal", (0.2, 0.6, 0.7), 0.7, _principled("GlossyMetal", **{
        "Base Color": (0.8, 0.8, 0.85, 1), "Metallic": 1.0, "Roughness": 0.15})[0])
    _sphere("Glass", (1.5, -0.4, 0.6), 0.6, _principled("Glass", **{
        "Transmission Weight": 1.0, "Roughness": 0.0, "IOR": 1.45})[0])
    return scene


def _blocks(x: np.ndarray, b: int = 8) -> np.ndarray:
    H, W, C = x.shape
    return x[:H // b * b, :W // b * b].reshape(H // b, b, W // b, b, C).mean(axis=(1, 3))


def test_the_guide_passes_match_cycles(tmp_path):
    """8 x 8-block means of both passes against Cycles' (64 samples each, 64 x 48).  Measured: normals
    within 0.01 in 90 % of the blocks; through the glass sphere 0.09 (Cycles writes the floor's
    features behind it for about 12 % fewer paths: its normal there is 0.83 long against STPM's
    0.94, its albedo 8 % lower); albedo within 0.03 in 90 % of the blocks, 0.07 at most (Schlick
    against Cycles' F82 metal, STPM's tabulated rough-coat albedo, the glass) except where the glossy sphere mirrors the area light, whose
    emission both carry into the albedo (Cycles weighs it by MIS, STPM fully)."""
    png = tmp_path / "pattern.png"
    _write_png(png, _pattern())
    scene = _guides_scene(png)
    cycles = _cycles_guides(scene, tmp_path, samples=64)
    stpm = _stpm_passes(scene, samples=64)
    n_c, n_s = _blocks(cycles["Denoising Normal"]), _blocks(stpm["Denoising Normal"])
    n_diff = np.abs(n_s - n_c).max(axis=2)
    assert np.quantile(n_diff, 0.9) < 0.02 and n_diff.max() < 0.12, np.round(n_diff, 3)
    a_c, a_s = _blocks(cycles["Denoising Albedo"]), _blocks(stpm["Denoising Albedo"])
    ordinary = a_c.max(axis=2) < 1.0                                  # no light seen in the block
    assert ordinary.sum() >= 0.9 * ordinary.size
    diff = np.abs(a_s - a_c).max(axis=2)
    assert np.quantile(diff[ordinary], 0.9) < 0.03 and diff[ordinary].max() < 0.1, np.round(diff, 2)
    assert (a_s.max(axis=2) > 1.0).any() and not (a_s.max(axis=2) > 1.0)[ordinary].any()   # the highlight is there
    # the rough metal is diffuse-like: its albedo is its reflectance, not what it reflects
    assert np.abs(stpm["Denoising Albedo"][20:28, 10:16].mean(axis=(0, 1)) - [0.9, 0.6, 0.3]).max() < 0.1


# ----------------------------------------------------------------------------
# The compositor group
# ----------------------------------------------------------------------------
def _links(tree) -> set:
    return {(l.from_node.name, l.from_socket.name, l.to_node.name, l.to_socket.name) for l in tree.links}


def test_denoise_adds_and_removes_the_compositor_group():
    from addon.denoise import GROUP, compositor_problem
    scene = fresh()
    scene.render.engine = "STPM"
    add_camera()
    # a compositor of the user's: Render Layers -> Glare -> output
    tree = bpy.data.node_groups.new("Mine", "CompositorNodeTree")
    tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
    scene.compositing_node_group = tree
    rl, glare, out = (tree.nodes.new(t) for t in ("CompositorNodeRLayers", "CompositorNodeGlare", "NodeGroupOutput"))
    tree.links.new(rl.outputs["Image"], glare.inputs["Image"])
    tree.links.new(glare.outputs["Image"], out.inputs[0])
    before = _links(tree)
    scene.stpm.denoise = True
    assert compositor_problem(scene) is None and scene.render.use_compositing
    links = _links(tree)
    assert {(rl.name, "Image", GROUP, "Image"), (rl.name, "Denoising Albedo", GROUP, "Albedo"),
            (rl.name, "Denoising Normal", GROUP, "Normal"), (GROUP, "Image", glare.name, "Image")} <= links
    assert (rl.name, "Image", glare.name, "Image") not in links
    group = tree.nodes[GROUP].node_tree
    assert any(n.bl_idname == "CompositorNodeDenoise" for n in group.nodes)
    scene.stpm.denoise = False
    assert _links(tree) == before and GROUP not in tree.nodes
    scene.stpm.denoise = True
    scene.stpm.denoise = True
    assert sum(n.name.startswith(GROUP) for n in tree.nodes) == 1
    # a scene without a compositor gets one: Render Layers -> STPM Denoise -> output
    other = bpy.data.scenes.new("Other")
    other.render.engine = "STPM"
    other.stpm.denoise = True
    assert other.compositing_node_group is not None and compositor_problem(other) is None
    # and one whose group was deleted is named in the render report
    from addon.engine import LAST_RENDER
    tree.nodes.remove(tree.nodes[GROUP])
    assert "STPM Denoise" in compositor_problem(scene)
    scene.render.resolution_x, scene.render.resolution_y, scene.stpm.samples = 8, 6, 1
    bpy.ops.render.render()
    assert any("'STPM Denoise' group" in w for w in LAST_RENDER["warnings"])


# ----------------------------------------------------------------------------
# The denoised image
# ----------------------------------------------------------------------------
def _flip_scene(tmp_path, size):
    """A look-dev set-up: a grey-blue sky and a small area light over a textured Principled floor, a
    rough metal sphere (roughness 0.35) and a white one; direct light only (no photons), so that a
    high-sample render converges.  Returns (scene, the metal sphere's pixels)."""
    png = tmp_path / "pattern.png"
    _write_png(png, _pattern(4))
    scene = fresh()
    scene.render.resolution_x, scene.render.resolution_y = size
    cam = add_camera(location=(0, -5.5, 2.6), rotation=(math.radians(68), 0, 0))
    add_light("AREA", energy=120.0, location=(1.5, -1.0, 3.5), size=0.5)
    set_world((0.5, 0.55, 0.6), 1.0)
    _textured_floor(png)
    metal = (-0.9, 0.2, 0.8)
    _sphere("Metal", metal, 0.8, _principled("Metal", **{
        "Base Color": (0.95, 0.65, 0.45, 1), "Metallic": 1.0, "Roughness": 0.35})[0])
    _sphere("White", (1.1, -0.3, 0.6), 0.6, _principled("White", **{"Base Color": (0.8, 0.8, 0.8, 1)})[0])
    scene.render.engine = "STPM"
    st = scene.stpm
    st.effects, st.caustics, st.indirect, st.photons_global, st.photons_caustic = "MANUAL", False, False, 0, 0
    # the metal sphere's pixels: its projected disc, shrunk to stay off the silhouette
    from bpy_extras.object_utils import world_to_camera_view
    from mathutils import Vector
    c = world_to_camera_view(scene, cam, Vector(metal))
    e = world_to_camera_view(scene, cam, Vector(metal) + 0.8 * cam.matrix_world.to_3x3() @ Vector((1, 0, 0)))
    w, h = size
    yy, xx = np.mgrid[0:h, 0:w]
    cx, cy, r = c.x * w, (1 - c.y) * h, abs(e.x - c.x) * w
    mask = (xx + 0.5 - cx) ** 2 + (yy + 0.5 - cy) ** 2 < (0.8 * r) ** 2
    return scene, mask


def _flip_map(ref: np.ndarray, img: np.ndarray) -> np.ndarray:
    import flip_evaluator as flip
    emap, _mean, _ = flip.evaluate(np.ascontiguousarray(ref, np.float32), np.ascontiguousarray(img, np.float32), "HDR",
                                   applyMagma=False)
    return np.asarray(emap, np.float64).reshape(ref.shape[:2])


def _denoised_and_raw(tmp_path, size, raw_spp: int, ref_spp: int):
    """(denoised, raw, reference, metal mask): F12 with denoise (the compositor's image and Noisy
    Image from Blender's multilayer EXR) and a converged render without it."""
    pytest.importorskip("flip_evaluator")
    scene, mask = _flip_scene(tmp_path, size)
    scene.stpm.denoise, scene.stpm.samples = True, raw_spp
    _multilayer(scene, tmp_path / "noisy.exr")
    bpy.ops.render.render(write_still=True)
    noisy = _layers(tmp_path / "noisy.exr")
    scene.stpm.denoise, scene.stpm.samples = False, ref_spp
    _multilayer(scene, tmp_path / "ref.exr")
    bpy.ops.render.render(write_still=True)
    ref = _layers(tmp_path / "ref.exr")["ViewLayer.Combined"][..., :3]
    return noisy["Composite.Combined"][..., :3], noisy["ViewLayer.Noisy Image"][..., :3], ref, mask


def _check_denoised(den, raw, ref, mask, max_ratio: float) -> str:
    f_raw, f_den = _flip_map(ref, raw), _flip_map(ref, den)
    report = (f"FLIP raw {f_raw.mean():.4f}, denoised {f_den.mean():.4f} (ratio {f_den.mean() / f_raw.mean():.3f}); "
              f"rough metal {f_raw[mask].mean():.4f} -> {f_den[mask].mean():.4f}; mean {den.mean() / ref.mean():.4f}")
    print(report)
    assert f_den.mean() <= max_ratio * f_raw.mean(), report
    assert f_den[mask].mean() <= f_raw[mask].mean(), report
    assert abs(den.mean() / ref.mean() - 1.0) < 0.02, report             # the denoiser keeps the brightness
    assert not np.array_equal(den, raw)
    return report


def test_f12_with_denoise_writes_the_denoised_image_and_keeps_the_noisy_one(tmp_path):
    """96 x 72, 1 sample per pixel against 256: measured HDR-FLIP raw 0.211, denoised 0.122 (ratio
    0.58; the rough metal 0.242 -> 0.158).  At this size OpenImageDenoise has too little context for
    half; the slow test below has it."""
    den, raw, ref, mask = _denoised_and_raw(tmp_path, (96, 72), raw_spp=1, ref_spp=256)
    assert mask.sum() > 150
    _check_denoised(den, raw, ref, mask, max_ratio=0.75)


@pytest.mark.slow
def test_denoised_flip_is_at_most_half_of_the_raw_one(tmp_path):
    """Issue 17's criterion at 256 x 192: 1 sample per pixel, denoised, against 512 samples (measured:
    FLIP raw 0.199, denoised 0.077, ratio 0.39; rough metal lower too)."""
    den, raw, ref, mask = _denoised_and_raw(tmp_path, (256, 192), raw_spp=1, ref_spp=512)
    _check_denoised(den, raw, ref, mask, max_ratio=0.5)


def test_stpm_render_denoises_a_blend_as_f12_does(tmp_path):
    """``stpm render`` on a .blend saved with denoise: the EXR holds the guide passes, the raw image
    as Noisy Image and, as Combined, what the STPM Denoise group makes of them (the same pixels
    as ``addon.denoise.denoise_passes`` here, which F12's compositor runs too)."""
    from addon.denoise import denoise_passes
    from stpm_core.imageio import read_exr
    scene, _mask = _flip_scene(tmp_path, (64, 48))
    scene.stpm.denoise, scene.stpm.samples = True, 2
    blend = tmp_path / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-m", "stpm_core.cli", "render", str(blend), "--output",
                          str(tmp_path / "out.exr"), "--stats", str(tmp_path / "stats.json"), "--quiet"],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    assert "Saved:" not in out.stderr and "stpm_denoise_" not in out.stderr, out.stderr   # no temp-file chatter
    exr = sorted(tmp_path.glob("out*.exr"))[0]
    passes = read_exr(exr)
    assert {"Combined", "Denoising Albedo", "Denoising Normal", "Noisy Image"} <= set(passes)
    assert not np.array_equal(passes["Combined"], passes["Noisy Image"])
    np.testing.assert_array_equal(passes["Combined"], denoise_passes(passes))
    stats = json.loads(sorted(tmp_path.glob("stats*.json"))[0].read_text())
    assert stats["denoise_s"] > 0 and stats["settings"]["denoise"] is True
