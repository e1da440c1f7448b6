"""A Mix Shader with a constant Fac against Cycles (bpy 5.0): two weighted closures, not one blend.

Cycles evaluates a Mix Shader as its two closures weighted by (1 - Fac, Fac), whatever Fac is.  Until
2026-12-06 STPM's export blended the two shaders' *parameters* when Fac was constant, so a dark
Diffuse mixed 50/50 with a mirror became one Principled BSDF of roughness 0.5 and metallic 0.5: the
sun's sharp glint became a broad highlight.  Now such a material carries its node graph
(``addon.export.nodes.graph_needed``) and the compiled SVM picks one closure per hit with probability
Fac (stratified per pixel on camera paths), as with a textured Fac.  The parameter blend is kept only
where it is exact (``nodes.mix_is_exact_blend``: Diffuse BSDFs differing only in colour, and Emissions): there the material stays on the constant path.

Scenes (64 x 48 px, 64 samples, 8 seeds of each renderer; STPM without photons, max depth 1; Cycles
with one glossy and one transmission bounce and no diffuse bounce):

* ``chrome``: ``sun_glint_scenes.mixed_chrome_const``, Diffuse 0.1 and a roughness-0 metal, Fac 0.5,
  under a 5-degree sun seen at the mirror angle;
* ``glossy``: a Diffuse (0.8, 0.5, 0.3) and a Glossy BSDF (roughness 0.2), Fac 0.7, on a floor under a
  1 m square area light whose highlight the camera sees;
* ``two_diffuse``: a Diffuse red and a Diffuse blue, Fac 0.3, under the same area light (exact blend:
  no graph).

Each scene is also rendered with the old export (the parameter blend forced, by patching
``mix_is_exact_blend`` to True) and that must fail the same test: the test can see the difference.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytest.importorskip("OpenImageIO")

import sun_glint_scenes as sgs  # noqa: E402
from cycles_ref import block_ztest, render_cycles_paths, render_stpm  # noqa: E402
from test_addon_scenes import add_camera, add_light, add_mesh, fresh, set_world  # noqa: E402

SPP = 64
SEEDS = tuple(range(8))        # 4 seeds: a glossy block at |z| 4.1 once (8: 1.7); t-tails
Z_MAX = 4.0
MEAN_TOL = 0.03


def _mix(name, first, second, fac):
    """A material: Mix Shader (constant ``fac``) of the shader nodes made by first(t), second(t)."""
    mat = bpy.data.materials.new(name)
    t = mat.node_tree
    t.nodes.remove(t.nodes["Principled BSDF"])
    mix = t.nodes.new("ShaderNodeMixShader")
    mix.inputs["Fac"].default_value = fac
    t.links.new(first(t).outputs[0], mix.inputs[1])
    t.links.new(second(t).outputs[0], mix.inputs[2])
    t.links.new(mix.outputs["Shader"], t.nodes["Material Output"].inputs["Surface"])
    return mat


def _diffuse_node(color):
    def make(t):
        n = t.nodes.new("ShaderNodeBsdfDiffuse")
        n.inputs["Color"].default_value = (*color, 1.0)
        return n
    return make


def _glossy_node(roughness, color=(0.9, 0.9, 0.9)):
    def make(t):
        n = t.nodes.new("ShaderNodeBsdfGlossy")
        n.inputs["Color"].default_value = (*color, 1.0)
        n.inputs["Roughness"].default_value = roughness
        return n
    return make


def _floor_under_area(make_material):
    """A 6 m floor at z = 0 (its material from make_material()), a 1 m square area light 1.2 m up
    facing down, the camera 2 m up looking at the floor so that the light's highlight is in view."""
    scene = fresh()
    material = make_material()
    scene.render.resolution_x, scene.render.resolution_y = 64, 48
    set_world((0, 0, 0), 0.0)
    add_mesh("plane", "Floor", material=material, size=6.0)
    add_camera(location=(0.0, -2.5, 2.0), rotation=(math.radians(55), 0, 0), lens=30)
    add_light("AREA", "Panel", location=(0.0, 1.2, 1.2), energy=60.0, shape="SQUARE", size=1.0)
    return scene


def glossy():
    return _floor_under_area(lambda: _mix("DiffuseGlossy", _diffuse_node((0.8, 0.5, 0.3)), _glossy_node(0.2), 0.7))


def two_diffuse():
    return _floor_under_area(lambda: _mix("TwoDiffuse", _diffuse_node((0.8, 0.1, 0.1)),
                                          _diffuse_node((0.1, 0.2, 0.8)), 0.3))


SCENES = {"chrome": sgs.mixed_chrome_const, "glossy": glossy, "two_diffuse": two_diffuse}


def _exported_graph(scene):
    """(does each exported material carry a node graph, the export's warnings)"""
    from addon.export import export_scene
    core, warnings = export_scene(bpy.context.evaluated_depsgraph_get(),
                                  lambda f, sub: scene.frame_set(f, subframe=sub))[:2]
    return [m.graph is not None for m in core.materials], warnings


def _old_export(monkeypatch):
    """The export before 2026-12-06: every constant-Fac Mix Shader blended (no graph for it)."""
    from addon.export import nodes as node_export
    monkeypatch.setattr(node_export, "mix_is_exact_blend", lambda graph, name: True)


@pytest.mark.parametrize("name", sorted(SCENES))
def test_constant_fac_mix_matches_cycles(name, tmp_path, monkeypatch):
    SCENES[name]()
    scene = bpy.context.scene
    cyc = render_cycles_paths(scene, tmp_path, samples=SPP, seeds=SEEDS, diffuse_bounces=0,
                              glossy_bounces=1, transmission_bounces=1, caustics=True)
    stpm, _ = render_stpm(scene, samples=SPP, seeds=SEEDS, max_depth=1)
    r = block_ztest(stpm, cyc)
    print(f"{name}: {r.summary()}; Cycles mean {cyc.mean():.4f}, STPM {stpm.mean():.4f}")
    graphs, warnings = _exported_graph(scene)
    assert not [w for w in warnings if "Mix Shader" in w], warnings   # nothing approximated, nothing to warn
    if name == "two_diffuse":
        assert graphs == [False]                 # the exact fast path: one Diffuse of the blended colour
    else:
        assert graphs == [True]                  # two closures, one per hit
    assert r.z_abs_max < Z_MAX, (r.summary(), np.round(r.z, 1))
    assert abs(r.mean_ratio - 1.0) < MEAN_TOL, r.summary()
    if name == "two_diffuse":
        return                                   # the old export rendered it the same way
    _old_export(monkeypatch)
    assert _exported_graph(scene)[0] == [False]
    old, _ = render_stpm(scene, samples=SPP, seeds=SEEDS, max_depth=1)
    ro = block_ztest(old, cyc)
    print(f"{name}, old export (parameters blended): {ro.summary()}; STPM {old.mean():.4f}")
    assert ro.z_abs_max > 2 * Z_MAX, ro.summary()


#: the room with photons: |z| bound.  The same room all Diffuse (direct_light_scenes.area_rect) measures
#: |z| max 5.3 and 7.0 (seeds 0-3, 4-7; mean 0.981, 0.983): the photon map's own bias at these settings
ROOM_Z_MAX = 8.0


def test_constant_fac_mix_with_photons_matches_cycles(tmp_path, monkeypatch):
    """Full light paths: the area-lit room corner (``direct_light_scenes.area_rect``) with its floor a
    Diffuse 0.8 / Glossy (roughness 0.1) mix, Fac 0.7; Cycles 64 spp with 8 diffuse and 8 glossy
    bounces, STPM 16 spp with 100 000 global and caustic photons (which scatter off the floor by the
    same per-hit closure choice as camera paths), 4 seeds each.  Measured 2026-12-06: |z| max 4.96 /
    4.77, mean 0.987 / 1.001 (seeds 0-3 / 4-7); the old export |z| max 146 (mostly the floor's
    highlight, which it spread), mean 0.952."""
    import direct_light_scenes as dls
    scene = dls.area_rect()
    mat = _mix("FloorMix", _diffuse_node((0.8, 0.8, 0.8)), _glossy_node(0.1), 0.7)
    bpy.data.objects["Floor"].material_slots[0].material = mat
    seeds = (0, 1, 2, 3)
    cyc = render_cycles_paths(scene, tmp_path, samples=64, seeds=seeds, diffuse_bounces=8, glossy_bounces=8,
                              transmission_bounces=0, caustics=True)
    kw = dict(photons_global=100_000, photons_caustic=100_000)
    stpm, _ = render_stpm(scene, samples=16, seeds=seeds, **kw)
    r = block_ztest(stpm, cyc)
    print(f"room: {r.summary()}")
    assert r.z_abs_max < ROOM_Z_MAX, (r.summary(), np.round(r.z, 1))
    assert abs(r.mean_ratio - 1.0) < MEAN_TOL, r.summary()
    _old_export(monkeypatch)
    old, _ = render_stpm(scene, samples=16, seeds=seeds, **kw)
    ro = block_ztest(old, cyc)
    print(f"room, old export (parameters blended): {ro.summary()}")
    assert ro.z_abs_max > 2 * ROOM_Z_MAX, ro.summary()
