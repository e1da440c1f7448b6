"""Blender's Principled Coat against Cycles (bpy 5.0): the coat layer over the rest of the BSDF.

Cycles' Principled BSDF (svm/closure.h) puts a GGX dielectric layer of weight Coat Weight, roughness
Coat Roughness and Fresnel of Coat IOR on top of every other lobe, and weighs what lies below by
(1 - Coat Weight x the layer's albedo at wo) times mix(1, Coat Tint^(1 / cos_t), Coat Weight)
(``kernels.bsdf``, lobe CLEARCOAT; docs/lights-and-materials.md).  A smooth-shaded sphere of a dark
red base (roughness 0.5) under a coat of roughness 0.05 / 0.3, lit by a square area light and a
constant grey world; one with a warm Coat Tint over a light grey base.  Cycles with one glossy
bounce and no diffuse bounce (the coat's reflection of the light and the world), STPM without
photons (its camera path goes on through the rough lobes): block Z-test (``cycles_ref.block_ztest``)
and the mean.  Until 2026-12-07 STPM ignored the coat ("Coat Weight is not rendered"): measured
then (this file, 4 seeds x 64 samples, 64 x 48, 2026-12-07, load average 9-11) |z| max 98.0 / 160.6 /
326.1, mean ratio 0.956 / 0.958 / 1.327 (roughness 0.05 / 0.3 / tinted); with the coat layer |z| max
1.81 / 2.06 / 1.53, mean ratio 1.0021 / 1.0003 / 1.0004.

STPM_TEST_PNG_DIR=<dir> writes the two mean images side by side (sRGB PNG) for a look.
"""
from __future__ import annotations

import math
import os

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytest.importorskip("OpenImageIO")

from test_addon_scenes import add_camera, add_light, add_mesh, fresh, set_world  # noqa: E402
from cycles_ref import block_ztest, render_cycles_paths, render_stpm  # noqa: E402

W, H = 64, 48
SPP = 64
SEEDS = (0, 1, 2, 3)
Z_MAX = 4.5
MEAN_TOL = 0.02


def coated(name, base, coat_roughness, coat_tint=(1.0, 1.0, 1.0), coat_ior=1.5):
    """A Principled BSDF (roughness 0.5) with Coat Weight 1 of this roughness, tint and IOR."""
    mat = bpy.data.materials.new(name)
    p = mat.node_tree.nodes["Principled BSDF"]
    p.inputs["Base Color"].default_value = (*base, 1.0)
    p.inputs["Roughness"].default_value = 0.5
    p.inputs["Coat Weight"].default_value = 1.0
    p.inputs["Coat Roughness"].default_value = coat_roughness
    p.inputs["Coat IOR"].default_value = coat_ior
    p.inputs["Coat Tint"].default_value = (*coat_tint, 1.0)
    return mat


def coated_sphere_scene(make_material):
    """The coated sphere (material: make_material(), called after the scene is reset) under a square
    area light (front left, above) and a grey world."""
    scene = fresh()
    scene.render.resolution_x, scene.render.resolution_y = W, H
    set_world((0.25, 0.25, 0.25), 1.0)
    add_mesh("sphere", "Ball", location=(0, 0, 0), material=make_material(), radius=1.0, segments=64, ring_count=32)
    bpy.ops.object.shade_smooth()
    lamp = add_light("AREA", location=(-1.5, -2.5, 2.5), energy=150.0, size=1.0)
    lamp.rotation_euler = (math.radians(45), math.radians(-25), 0)
    add_camera(location=(0, -4.5, 0.0), rotation=(math.radians(90), 0, 0), lens=45)
    return scene


def _to_png(path, *imgs):
    import OpenImageIO as oiio
    x = np.concatenate(imgs, axis=1)
    x = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(np.clip(x, 0.0031308, None), 1 / 2.4) - 0.055)
    x = (np.clip(x, 0, 1) * 255 + 0.5).astype(np.uint8)
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(x.shape[1], x.shape[0], 3, "uint8"))
    out.write_image(x)
    out.close()


def compare(tmp_path, label, png_name):
    cyc = render_cycles_paths(bpy.context.scene, tmp_path, samples=SPP, seeds=SEEDS, diffuse_bounces=0,
                              glossy_bounces=1, transmission_bounces=0, caustics=False)
    stpm, _ = render_stpm(bpy.context.scene, samples=SPP, seeds=SEEDS, max_depth=1)
    r = block_ztest(stpm, cyc)
    print(f"{label}: {r.summary()}")
    d = os.environ.get("STPM_TEST_PNG_DIR")
    if d:
        _to_png(os.path.join(d, png_name), stpm.mean(axis=0), cyc.mean(axis=0))
    return r


@pytest.mark.parametrize("coat_roughness", [0.05, 0.3])
def test_coated_red_sphere_under_an_area_light_like_cycles(tmp_path, coat_roughness):
    coated_sphere_scene(lambda: coated("Car paint", (0.3, 0.02, 0.02), coat_roughness))
    r = compare(tmp_path, f"coat roughness {coat_roughness}", f"coat_{coat_roughness}.png")
    assert r.z_abs_max < Z_MAX, (r.summary(), np.round(r.z, 1))
    assert abs(r.mean_ratio - 1.0) < MEAN_TOL, r.summary()


def test_tinted_coat_like_cycles(tmp_path):
    coated_sphere_scene(lambda: coated("Varnish", (0.7, 0.7, 0.7), 0.3, coat_tint=(0.9, 0.55, 0.2)))
    r = compare(tmp_path, "tinted coat", "coat_tint.png")
    assert r.z_abs_max < Z_MAX, (r.summary(), np.round(r.z, 1))
    assert abs(r.mean_ratio - 1.0) < MEAN_TOL, r.summary()


def test_a_coated_principled_exports_its_graph_without_a_coat_warning():
    """The exporter keeps the node graph of a material with a Coat Weight (``nodes.graph_needed``: only
    the interpreter fills the coat's columns) and says nothing about the coat (it said "Coat Weight
    is not rendered" before); emission under a coat is still named (not dimmed by it)."""
    from addon.export import export_scene
    coated_sphere_scene(lambda: coated("Car paint", (0.3, 0.02, 0.02), 0.05))
    core, warnings = export_scene(bpy.context.evaluated_depsgraph_get(),
                                  lambda f, sub: bpy.context.scene.frame_set(f, subframe=sub))[:2]
    assert core.materials[0].graph is not None
    assert not any("Coat" in str(w) for w in warnings), warnings
    p = bpy.data.materials["Car paint"].node_tree.nodes["Principled BSDF"]
    p.inputs["Emission Strength"].default_value = 1.0
    p.inputs["Emission Color"].default_value = (1.0, 0.5, 0.2, 1.0)
    _, warnings = export_scene(bpy.context.evaluated_depsgraph_get(),
                               lambda f, sub: bpy.context.scene.frame_set(f, subframe=sub))[:2]
    assert any("Emission under a Coat" in str(w) for w in warnings), warnings
