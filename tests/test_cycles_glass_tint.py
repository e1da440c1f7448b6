"""Coloured glass against Cycles (bpy 5.0): the transmission and reflection tints of Principled and
Glass BSDFs.

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

Cycles' Glass BSDF also tints its *reflection* by Color (svm/closure.h: ``reflection_tint =
color``; Principled: the specular tint, white).  Before the closure carried a reflection tint
(``closure.C_TINT_R``, ``Material.reflection_tint``) the Glass BSDF slab's sun reflection was too
bright (smooth |z| max 8.1, mean ratio 1.001; roughness 0.3 |z| max 7.8, 1.007; after: 3.1 / 3.8,
1.000 / 0.999).

STPM_TEST_PNG_DIR=<dir> writes the two mean images side by side (sRGB PNG) for a look.
"""
from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytest.importorskip("OpenImageIO")

from test_cycles_frosted_glass import compare_slab, slab_scene  # noqa: E402

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


@pytest.mark.parametrize("kind, roughness", [("principled", 0.0), ("principled", 0.3), ("glass", 0.0), ("glass", 0.3)])
def test_coloured_glass_slab_in_front_of_a_lit_textured_wall_like_cycles(tmp_path, kind, roughness):
    slab_scene(tmp_path, lambda: _glass(kind, roughness))
    r = compare_slab(tmp_path, f"coloured {kind} glass roughness {roughness}", f"tint_{kind}_{roughness}.png")
    assert r.z_abs_max < Z_MAX, (r.summary(), np.round(r.z, 1))
    assert abs(r.mean_ratio - 1.0) < MEAN_TOL, r.summary()
