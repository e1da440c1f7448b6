"""Frosted glass against Cycles (bpy 5.0): rough refraction blurs what lies behind a glass slab.

A thin box of Principled glass (Transmission 1, IOR 1.5, Roughness 0.3 / 0.6) stands in front of a
textured wall lit by a sun from the camera's side.  Cycles with no diffuse bounce and long glossy /
transmission chains (the wall's direct light seen through both faces of the slab, caustics off),
STPM without photons and max_depth 8 (its camera path goes on through the glass's rough lobes, both
refraction and reflection, and estimates the wall's direct light there): block Z-test
(``cycles_ref.block_ztest``).  Before rough refraction the slab was a smooth refractor
(a sharp image of the wall) with a rough reflection.

STPM_TEST_PNG_DIR=<dir> writes the two mean images side by side (sRGB PNG) for a look.
"""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytest.importorskip("OpenImageIO")

from test_addon_scenes import add_camera, add_light, add_mesh, fresh, set_world  # noqa: E402
from test_cycles_textures import _image_material, _pattern, _write_png  # noqa: E402
from cycles_ref import block_ztest, render_cycles_paths, render_stpm  # noqa: E402

W, H = 64, 48
SPP = 64
Z_MAX = 4.5
MEAN_TOL = 0.03


def _frosted(name, roughness):
    mat = bpy.data.materials.new(name)
    p = mat.node_tree.nodes["Principled BSDF"]
    p.inputs["Base Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    p.inputs["Transmission Weight"].default_value = 1.0
    p.inputs["Roughness"].default_value = roughness
    p.inputs["IOR"].default_value = 1.5
    return mat


def slab_scene(tmp_path, make_material):
    """A thin box of the material ``make_material()`` makes (called after the scene is reset) in front
    of a textured wall lit by a sun from the camera's side (also the coloured-glass tests' scene,
    tests/test_cycles_glass_tint.py)."""
    png = tmp_path / "pattern.png"
    _write_png(png, _pattern())
    scene = fresh()
    scene.render.resolution_x, scene.render.resolution_y = W, H
    set_world((0, 0, 0), 0.0)
    wall_mat, _ = _image_material("Wall", png)
    wall = add_mesh("plane", "Wall", location=(0, 1.5, 1.0), material=wall_mat, size=6.0)
    wall.rotation_euler = (math.radians(90), 0, 0)
    slab = add_mesh("cube", "Slab", location=(0.2, 0.2, 1.1), material=make_material())
    slab.scale = (0.9, 0.04, 0.6)
    slab.rotation_euler = (0, 0, math.radians(12))
    add_light("SUN", energy=3.0, location=(0, -3, 5), angle=0.0).rotation_euler = (math.radians(60), 0, math.radians(-15))
    add_camera(location=(0, -4.0, 1.0), rotation=(math.radians(90), 0, 0), lens=50)
    return scene


def _srgb(x):
    x = np.clip(x, 0, 1)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def compare_slab(tmp_path, label: str, png_name: str):
    """The current scene with Cycles (no diffuse bounce, 8 glossy + 8 transmission, caustics off) and
    STPM (no photons, the same bounce budgets), 4 seeds each: the block Z-test's result; with
    STPM_TEST_PNG_DIR set, the two mean images side by side as ``png_name``."""
    cyc = render_cycles_paths(bpy.context.scene, tmp_path, samples=SPP, seeds=(0, 1, 2, 3), diffuse_bounces=0,
                              glossy_bounces=8, transmission_bounces=8, caustics=False)
    stpm, _res = render_stpm(bpy.context.scene, samples=SPP, seeds=(0, 1, 2, 3), max_depth=8, glossy_bounces=8,
                             transmission_bounces=8)
    # floor 1 %: the block on the slab's shadow edge (row 3, column 4 of the smooth Glass BSDF slab) is
    # 1.6 % (independent light samples) / 2.1 % (stratified, kernels.paths.light_strata) darker than
    # Cycles in every seed, measured 2026-12-06: a sub-pixel difference in where the hard edge falls,
    # left open (docs/rendering.md, "Stratified light samples"); with 4 seeds of stratified samples its
    # standard error alone is 0.4 %
    r = block_ztest(stpm, cyc, floor=0.01)
    print(f"{label}: {r.summary()}")
    out = os.environ.get("STPM_TEST_PNG_DIR")
    if out:
        side = np.concatenate([stpm.mean(axis=0), np.zeros((H, 2, 3)), cyc.mean(axis=0)], axis=1)
        _write_png(Path(out) / png_name, _srgb(side))
    return r


@pytest.mark.parametrize("roughness", [0.3, 0.6])
def test_frosted_glass_slab_in_front_of_a_lit_textured_wall_like_cycles(tmp_path, roughness):
    slab_scene(tmp_path, lambda: _frosted("Frosted", roughness))
    r = compare_slab(tmp_path, f"frosted glass roughness {roughness}", f"frosted_{roughness}.png")
    # (measured: roughness 0.3 |z| max 1.92, mean ratio 0.993; 0.6 |z| max 3.19, mean ratio 0.991)
    assert r.z_abs_max < Z_MAX, (r.summary(), np.round(r.z, 1))
    assert abs(r.mean_ratio - 1.0) < MEAN_TOL, r.summary()
