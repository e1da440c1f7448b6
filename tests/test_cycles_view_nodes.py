"""Fresnel and Layer Weight (view-dependent nodes) as Cycles renders them.

A smooth-shaded sphere and a plane seen from a perspective camera, each emitting a Mix Shader of
a red and a green Emission whose factor is a Fresnel (IOR 1.45), a Layer Weight Fresnel output or
a Layer Weight Facing output (Blend 0.3): the rims turn green, the centres red, as the angle to
the view changes across the image.  Emission only, so the image is the factor as each renderer
evaluates it.  Before these nodes were compiled (``nodes.compile._fresnel``, ``_layer_weight``)
the factor read its socket default (0.5) and the whole object was one orange.
Measured (48 x 48, 16 spp, 4 seeds, 8 x 8 blocks): block |z| max 1.20 / 1.18 / 1.19 (Fresnel /
Facing / Layer Weight Fresnel), green / red 0.110 / 0.177 / 0.107 in both renderers; with the
factor at its default (the old code) |z| 11.7 on Facing.
"""
from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytest.importorskip("OpenImageIO")

from cycles_ref import block_ztest, render_cycles, render_stpm  # noqa: E402
from test_addon_scenes import add_camera, fresh, set_world  # noqa: E402

SPP, SEEDS, Z_MAX = 16, (0, 1, 2, 3), 5.0


def _build(factor: str):
    scene = fresh()
    scene.render.resolution_x = scene.render.resolution_y = 48
    set_world((0, 0, 0), 0.0)
    mat = bpy.data.materials.new("View")
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    t = mat.node_tree
    t.nodes.remove(t.nodes["Principled BSDF"])
    red, green, mix = (t.nodes.new(k) for k in ("ShaderNodeEmission", "ShaderNodeEmission", "ShaderNodeMixShader"))
    red.inputs["Color"].default_value = (1.0, 0.05, 0.0, 1.0)
    green.inputs["Color"].default_value = (0.0, 1.0, 0.1, 1.0)
    if factor == "Fresnel":
        f = t.nodes.new("ShaderNodeFresnel")
        f.inputs["IOR"].default_value = 1.45
        out = f.outputs["Fac"]
    else:
        f = t.nodes.new("ShaderNodeLayerWeight")
        f.inputs["Blend"].default_value = 0.3
        out = f.outputs[factor]
    t.links.new(out, mix.inputs["Fac"])
    t.links.new(red.outputs[0], mix.inputs[1])
    t.links.new(green.outputs[0], mix.inputs[2])
    t.links.new(mix.outputs[0], t.nodes["Material Output"].inputs["Surface"])
    bpy.ops.mesh.primitive_uv_sphere_add(segments=48, ring_count=24, radius=0.8, location=(-0.45, 0.0, 0.0))
    bpy.ops.object.shade_smooth()
    bpy.context.object.data.materials.append(mat)
    bpy.ops.mesh.primitive_plane_add(size=3.0, location=(0.0, 0.6, -0.9), rotation=(1.2, 0.0, 0.0))
    bpy.context.object.data.materials.append(mat)
    add_camera(location=(0.0, -4.0, 0.6), rotation=(np.radians(84.0), 0.0, 0.0))
    return scene


@pytest.mark.parametrize("factor", ["Fresnel", "Facing", "LW Fresnel"])
def test_view_dependent_factor_matches_cycles(tmp_path, factor):
    scene = _build("Fresnel" if factor == "LW Fresnel" else factor)
    if factor == "LW Fresnel":
        t = bpy.data.materials["View"].node_tree
        f = t.nodes.new("ShaderNodeLayerWeight")
        f.inputs["Blend"].default_value = 0.3
        t.links.new(f.outputs["Fresnel"], t.nodes["Mix Shader"].inputs["Fac"])
    cyc = render_cycles(scene, tmp_path, samples=SPP, seeds=SEEDS)
    stpm, _ = render_stpm(scene, samples=SPP, seeds=SEEDS, max_depth=1)
    r = block_ztest(stpm, cyc)
    g_over_r = stpm[..., 1].mean() / max(stpm[..., 0].mean(), 1e-9), cyc[..., 1].mean() / max(cyc[..., 0].mean(), 1e-9)
    print(f"{factor}: {r.summary()}; green / red STPM {g_over_r[0]:.3f}, Cycles {g_over_r[1]:.3f}")
    assert r.z_abs_max < Z_MAX, (r.summary(), np.round(r.z, 1))
    assert abs(g_over_r[0] / g_over_r[1] - 1.0) < 0.03, g_over_r
