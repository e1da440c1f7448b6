"""Coloured glass against Cycles (bpy 5.0): the transmission tint of Principled and Glass BSDFs.

Cycles tints a Principled BSDF's refraction by sqrt(Base Color) (svm/closure.h:
``transmission_tint = sqrt(base_color)``) but a Glass BSDF's by its Color itself, so light through
the two faces of a Principled glass slab of base c comes out tinted by c, through a Glass BSDF
slab of colour c by c^2.  A thin coloured slab (smooth and roughness 0.3) stands in front of a
textured wall lit by a sun from the camera's side, as ``test_cycles_frosted_glass.py``: Cycles with
no diffuse bounce and long glossy / transmission chains (caustics off), STPM without photons:
block Z-test (``cycles_ref.block_ztest``).  Before the closure carried its own transmission tint
(``closure.C_TINT_T``, ``Material.transmission_tint``) STPM tinted both by the colour, and the
Principled slab came out much too dark (measured before: smooth |z| max 208, mean ratio 0.935;
roughness 0.3 |z| max 73, 0.934; after: |z| max 2.8 / 3.0, mean ratio 1.000 / 1.001).

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
MEAN_TOL = 0.02
COLOR = (0.8, 0.3, 0.2)


def _glass(kind, roughness):
    mat = bpy.data.materials.new(f"{kind} glass")
    nodes = mat.node_tree.nodes
    if kind == "principled":
        p = nodes["Principled BSDF"]
        p.inputs["Base Color"].default_value = (*COLOR, 1.0)
        p.inputs["Transmission Weight"].default_value = 1.0
        p.inputs["Roughness"].default_value = roughness
        p.inputs["IOR"].default_value = 1.5
    else:
        nodes.remove(nodes["Principled BSDF"])
        g = nodes.new("ShaderNodeBsdfGlass")
        g.inputs["Color"].default_value = (*COLOR, 1.0)
        g.inputs["Roughness"].default_value = roughness
        g.inputs["IOR"].default_value = 1.5
        mat.node_tree.links.new(g.outputs["BSDF"], nodes["Material Output"].inputs["Surface"])
    return mat


def _scene(tmp_path, kind, roughness):
    png = tmp_path / "pattern.png"
    _write_png(png, _pattern())
    scene = fresh()
    scene.render.resolution_x, scene.render.resolution_y = W, H
    set_world((0, 0, 0), 0.0)
    wall_mat, _ = _image_material("Wall", png)
    wall = add_mesh("plane", "Wall", location=(0, 1.5, 1.0), material=wall_mat, size=6.0)
    wall.rotation_euler = (math.radians(90), 0, 0)
    slab = add_mesh("cube", "Slab", location=(0.2, 0.2, 1.1), material=_glass(kind, roughness))
    slab.scale = (0.9, 0.04, 0.6)
    slab.rotation_euler = (0, 0, math.radians(12))
    add_light("SUN", energy=3.0, location=(0, -3, 5), angle=0.0).rotation_euler = (math.radians(60), 0, math.radians(-15))
    add_camera(location=(0, -4.0, 1.0), rotation=(math.radians(90), 0, 0), lens=50)
    return scene


def _srgb(x):
    x = np.clip(x, 0, 1)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


# The Glass BSDF case: its transmission is right (mean ratio 1.001) but Cycles' Glass BSDF also tints
# its *reflection* by Color (svm/closure.h: reflection_tint = color), which STPM's GLASS_R lobe does
# not yet (untinted Fresnel reflection): the slab's sun reflection is too bright (|z| max 8.1, STPM
# brighter; the same before and after the transmission tint)
GLASS_R_UNTINTED = pytest.mark.xfail(reason="Glass BSDF reflection tint (Color) not modelled", strict=False)


@pytest.mark.parametrize("kind, roughness", [("principled", 0.0), ("principled", 0.3),
                                             pytest.param("glass", 0.0, marks=GLASS_R_UNTINTED)])
def test_coloured_glass_slab_in_front_of_a_lit_textured_wall_like_cycles(tmp_path, kind, roughness):
    _scene(tmp_path, kind, roughness)
    cyc = render_cycles_paths(bpy.context.scene, tmp_path, samples=SPP, seeds=(0, 1, 2, 3), diffuse_bounces=0,
                              glossy_bounces=8, transmission_bounces=8, caustics=False)
    stpm, _res = render_stpm(bpy.context.scene, samples=SPP, seeds=(0, 1, 2, 3), max_depth=8, glossy_bounces=8,
                             transmission_bounces=8)
    r = block_ztest(stpm, cyc)
    print(f"coloured {kind} glass roughness {roughness}: {r.summary()}")
    out = os.environ.get("STPM_TEST_PNG_DIR")
    if out:
        side = np.concatenate([stpm.mean(axis=0), np.zeros((H, 2, 3)), cyc.mean(axis=0)], axis=1)
        _write_png(Path(out) / f"tint_{kind}_{roughness}.png", _srgb(side))
    assert r.z_abs_max < Z_MAX, (r.summary(), np.round(r.z, 1))
    assert abs(r.mean_ratio - 1.0) < MEAN_TOL, r.summary()
