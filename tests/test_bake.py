"""The baking fallback (addon/export/bake.py): inputs the node interpreter cannot evaluate are baked
by Cycles in a child process, cached, and read back as textures; what cannot be baked is named.

* planning and classification on plain graphs (no bpy);
* a Gabor texture (not in SUPPORTED_NODES) through a ColorRamp into Base Color: baked, then
  rendered by STPM and by Cycles (direct light only) and compared block by block, as
  tests/test_cycles_textures.py does;
* view-dependent inputs (Layer Weight, Fresnel) and an object without UVs are named as not baked;
* the cache: a second bake starts no child, an edit of the subtree makes a new key.
"""
from __future__ import annotations

import numpy as np
import pytest

from stpm_core.nodes import Link, ShaderGraph, compile_graph
from stpm_core.nodes.graph import Node

from addon.export import bake


# ----------------------------------------------------------------------------
# Pure Python: planning and classification
# ----------------------------------------------------------------------------
def _principled(**inputs):
    return Node("ShaderNodeBsdfPrincipled", inputs=dict(inputs), outputs={"BSDF": "SHADER"},
                input_types={k: ("RGBA" if "Color" in k else "VALUE") for k in inputs})


def _graph(nodes: dict, surface="BSDF") -> ShaderGraph:
    return ShaderGraph(nodes=nodes, surface=Link(surface, "BSDF"))


def test_unsupported_subtrees_are_candidates_and_supported_ones_are_not():
    g = _graph({
        "BSDF": _principled(**{"Base Color": Link("Ramp", "Color"), "Roughness": Link("Math", "Value")}),
        "Ramp": Node("ShaderNodeValToRGB", inputs={"Fac": Link("Gabor", "Value")}, outputs={"Color": "RGBA"}),
        "Gabor": Node("ShaderNodeTexGabor", inputs={"Scale": 3.0}, outputs={"Value": "VALUE"}),
        "Math": Node("ShaderNodeMath", props={"operation": "ADD"}, inputs={"Value": 0.2, "Value_001": 0.1},
                     outputs={"Value": "VALUE"}),
    })
    (c,) = bake.find_candidates(g)
    assert (c.consumer, c.socket, c.kind) == ("BSDF", "Base Color", "color")
    assert c.bakeable and not c.world
    assert c.unsupported == [("Gabor", "ShaderNodeTexGabor", "is not supported by the interpreter")]
    assert set(c.nodes) == {"Ramp", "Gabor"}
    assert "node 'Gabor' (ShaderNodeTexGabor) is not supported" in c.cause()


def test_view_dependent_per_instance_animated_and_grouped_inputs_are_blocked():
    g = _graph({
        "BSDF": _principled(**{"Base Color": Link("Mix", "Result_Color"), "Roughness": Link("Fresnel", "Fac"),
                               "Metallic": Link("Group/Gabor", "Value"),
                               "Emission Color": Link("Info", "Color")}),
        "Mix": Node("ShaderNodeMix", props={"data_type": "RGBA", "blend_type": "MIX"},
                    inputs={"Factor_Float": Link("LW", "Facing"), "A_Color": Link("Gabor", "Color"),
                            "B_Color": (1.0, 0.0, 0.0)}, outputs={"Result_Color": "RGBA"}),
        "LW": Node("ShaderNodeLayerWeight", outputs={"Facing": "VALUE"}),
        "Gabor": Node("ShaderNodeTexGabor", outputs={"Color": "RGBA"}),
        "Fresnel": Node("ShaderNodeFresnel", outputs={"Fac": "VALUE"}),
        "Group/Gabor": Node("ShaderNodeTexGabor", outputs={"Value": "VALUE"}),
        "Info": Node("ShaderNodeObjectInfo", outputs={"Color": "RGBA", "Random": "VALUE"}),
    })
    got = {c.socket: c for c in bake.find_candidates(g, extra_blockers={"Group": "node group 'Group' is animated"})}
    # a Fresnel alone is evaluated (no candidate); with an unsupported node it blocks the bake
    assert set(got) == {"Base Color", "Metallic", "Emission Color"}
    assert "'LW' (ShaderNodeLayerWeight) depends on the view direction" in got["Base Color"].blockers[0]
    assert got["Metallic"].blockers == ["node group 'Group' is animated"]
    # Object Info's Colour is per object but bakeable (the transform joins the key); Random is not
    assert got["Emission Color"].bakeable and got["Emission Color"].world
    g.nodes["BSDF"].inputs["Emission Color"] = Link("Info", "Random")
    got = {c.socket: c for c in bake.find_candidates(g)}
    assert "Random output differs per object instance" in got["Emission Color"].blockers[0]
    # A consumer inside a node group is not baked
    (c,) = bake.find_candidates(
        _graph({"G/BSDF": _principled(**{"Base Color": Link("Gabor", "Color")}),
                "Gabor": Node("ShaderNodeTexGabor", outputs={"Color": "RGBA"})}, surface="G/BSDF"),
        grouped={"G/BSDF"})
    assert "inside a node group" in c.blockers[0]


def test_outputs_the_interpreter_does_not_evaluate_and_view_outputs():
    geo = Node("ShaderNodeNewGeometry", outputs={"Pointiness": "VALUE", "Incoming": "VECTOR", "Position": "VECTOR"})
    g = _graph({"BSDF": _principled(Roughness=Link("Geo", "Pointiness")), "Geo": geo})
    (c,) = bake.find_candidates(g)
    assert c.bakeable and c.world and "Pointiness output" in c.unsupported[0][2]
    # Position alone is evaluated: nothing to bake; Incoming into a Gabor: a candidate that is blocked
    g.nodes["BSDF"].inputs["Roughness"] = Link("Geo", "Position")
    assert bake.find_candidates(g) == []
    g.nodes["Gabor"] = Node("ShaderNodeTexGabor", inputs={"Vector": Link("Geo", "Incoming")},
                            outputs={"Value": "VALUE"})
    g.nodes["BSDF"].inputs["Roughness"] = Link("Gabor", "Value")
    (c,) = bake.find_candidates(g)
    assert "Incoming output depends on the view" in c.blockers[0]


def test_normals_bake_through_bump_height_and_normal_map_color_only():
    g = _graph({
        "BSDF": _principled(Normal=Link("Bump", "Normal")),
        "Bump": Node("ShaderNodeBump", inputs={"Height": Link("Gabor", "Value"), "Normal": Link("NMap", "Normal")},
                     outputs={"Normal": "VECTOR"}),
        "NMap": Node("ShaderNodeNormalMap", props={"space": "TANGENT", "uv_map": ""},
                     inputs={"Color": Link("Gabor2", "Color")}, outputs={"Normal": "VECTOR"}),
        "Gabor": Node("ShaderNodeTexGabor", outputs={"Value": "VALUE"}),
        "Gabor2": Node("ShaderNodeTexGabor", outputs={"Color": "RGBA"}),
    })
    got = {(c.consumer, c.socket): c for c in bake.find_candidates(g)}
    assert set(got) == {("Bump", "Height"), ("NMap", "Color")}
    assert got[("Bump", "Height")].kind == "float" and got[("NMap", "Color")].kind == "data"
    assert all(c.bakeable for c in got.values())
    # A normal from an unsupported node is not baked as such
    g.nodes["BSDF"].inputs["Normal"] = Link("Bevel", "Normal")
    g.nodes["Bevel"] = Node("ShaderNodeBevel", outputs={"Normal": "VECTOR"})
    (c,) = bake.find_candidates(g)
    assert c.socket == "Normal" and not c.bakeable and "Bump node's Height" in c.blockers[0]


def test_mix_shader_factor_is_a_candidate_and_substitution_compiles_clean():
    g = ShaderGraph(nodes={
        "Mix": Node("ShaderNodeMixShader", inputs={"Fac": Link("Gabor", "Value"), "Shader": Link("A", "BSDF"),
                                                   "Shader_001": Link("B", "BSDF")},
                    outputs={"Shader": "SHADER"}, input_types={"Fac": "VALUE"}),
        "A": Node("ShaderNodeBsdfDiffuse", inputs={"Color": (1.0, 0.0, 0.0)}, outputs={"BSDF": "SHADER"}),
        "B": Node("ShaderNodeBsdfDiffuse", inputs={"Color": Link("Gabor2", "Color")}, outputs={"BSDF": "SHADER"}),
        "Gabor": Node("ShaderNodeTexGabor", outputs={"Value": "VALUE"}),
        "Gabor2": Node("ShaderNodeTexGabor", outputs={"Color": "RGBA"}),
    }, surface=Link("Mix", "Shader"))
    cands = bake.find_candidates(g)
    assert {(c.consumer, c.socket) for c in cands} == {("Mix", "Fac"), ("B", "Color")}
    assert any("not supported by the node interpreter" in m for m in compile_graph(g, n_textures=2).unsupported)
    for i, c in enumerate(cands):
        bake.substitute(g, c, i, "UVMap")
    assert sorted(bake.prune(g)) == ["Gabor", "Gabor2"]
    prog = compile_graph(g, n_textures=2, uv_layers=[])
    assert prog.unsupported == [] and prog.uv_layers == ["UVMap"]
    assert g.nodes["stpm bake/Mix/Fac/image"].props["extension"] == "EXTEND"


def test_cache_dirs(monkeypatch, tmp_path):
    monkeypatch.delenv("STPM_BAKE_CACHE", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    dirs = bake.cache_dirs(str(tmp_path / "shot" / "scene.blend"))
    assert dirs[0] == str(tmp_path / "shot" / "stpm_bake_cache")
    if bake.sys.platform.startswith("linux"):
        assert dirs[1] == str(tmp_path / "xdg" / "stpm" / "bake")
    assert bake.cache_dirs(None) == dirs[1:]
    monkeypatch.setenv("STPM_BAKE_CACHE", str(tmp_path / "mine"))
    assert bake.cache_dirs(str(tmp_path / "scene.blend")) == [str(tmp_path / "mine")]


# ----------------------------------------------------------------------------
# Blender: bake, render against Cycles, name what cannot be baked, reuse the cache
# ----------------------------------------------------------------------------
W = H = 48
SPP = 32
BAKE_RES = 256


@pytest.fixture
def blender(monkeypatch, tmp_path):
    bpy = pytest.importorskip("bpy")
    monkeypatch.setenv("STPM_BAKE_CACHE", str(tmp_path / "cache"))
    return bpy


def _gabor_scene(bpy, scale: float = 1.5):
    """The top-down 2 x 2 m plane of test_cycles_textures (default UVs, ortho camera, sun from
    above), Base Color = ColorRamp(Gabor texture): the Gabor is not interpreted, Cycles bakes it."""
    from test_addon_scenes import add_camera, add_light, add_mesh, fresh, set_world
    scene = fresh()
    scene.render.resolution_x, scene.render.resolution_y = W, H
    scene.stpm.bake_resolution = BAKE_RES
    add_camera(location=(0, 0, 5), rotation=(0, 0, 0), type="ORTHO", ortho_scale=2.0)
    add_light("SUN", energy=3.0, location=(0, 0, 10), angle=0.0)
    set_world((0, 0, 0), 0.0)
    mat = bpy.data.materials.new("Gabor")
    t = mat.node_tree
    bsdf = t.nodes["Principled BSDF"]
    bsdf.inputs["Specular IOR Level"].default_value = 0.0
    bsdf.inputs["Roughness"].default_value = 1.0
    gabor = t.nodes.new("ShaderNodeTexGabor")
    gabor.inputs["Scale"].default_value = scale
    ramp = t.nodes.new("ShaderNodeValToRGB")
    ramp.color_ramp.elements[0].color = (0.1, 0.3, 0.8, 1.0)
    ramp.color_ramp.elements[1].color = (0.9, 0.6, 0.1, 1.0)
    t.links.new(gabor.outputs["Value"], ramp.inputs["Fac"])
    t.links.new(ramp.outputs["Color"], bsdf.inputs["Base Color"])
    add_mesh("plane", "Floor", material=mat, size=2.0)
    return scene, mat


def _export(bpy):
    from test_addon_scenes import export_now
    return export_now()


def test_baked_gabor_texture_matches_cycles_and_the_cache_is_reused(blender, tmp_path):
    bpy = blender
    from addon import batch
    from cycles_ref import block_ztest, render_cycles, render_stpm
    assert "ShaderNodeTexGabor" not in __import__("stpm_core.nodes", fromlist=["x"]).SUPPORTED_NODES
    scene, mat = _gabor_scene(bpy)
    # Before baking: named, the default used
    _core_scene, warnings = _export(bpy)
    assert any("Base Color of 'Principled BSDF' on object 'Floor' needs a bake" in w
               and "'Gabor Texture' (ShaderNodeTexGabor)" in w for w in warnings), warnings
    runs = bake.STATS["child_runs"]
    report = batch.bake_current(scene)
    assert report["child"] and len(report["baked"]) == 1 and not report["failed"], report
    assert report["statuses"] == {"baked": 1}
    assert bake.STATS["child_runs"] == runs + 1
    print(f"bake: {report['seconds']:.2f} s ({bake.STATS['last']})")
    # The export reads the bake: a texture of the bake resolution, the Gabor gone from the graph
    core_scene, warnings = _export(bpy)
    assert any(f"Base Color of 'Principled BSDF' on object 'Floor' baked to a {BAKE_RES}x{BAKE_RES} texture" in w
               for w in warnings), warnings
    (m,) = [m for m in core_scene.materials if m.name == "Gabor"]
    assert m.graph is not None and "Gabor Texture" not in m.graph.nodes
    assert [t.pixels.shape for t in core_scene.textures] == [(BAKE_RES, BAKE_RES, 3)]
    # Against Cycles rendering the Gabor itself
    cyc = render_cycles(scene, tmp_path, samples=SPP, seeds=(0, 1, 2))
    stpm, _res = render_stpm(scene, samples=SPP, seeds=(0, 1, 2))
    r = block_ztest(stpm, cyc)
    print(f"baked Gabor vs Cycles: {r.summary()}")
    assert r.z_abs_max < 4.5, (r.summary(), np.round(r.z, 1))
    assert abs(r.mean_ratio - 1.0) < 0.01, r.summary()
    assert np.std(r.stpm) > 0.5 * np.std(r.cycles) > 0.0          # the pattern, not one colour
    # The cache: a second bake starts no child; an edit of the subtree makes a new key
    again = batch.bake_current(scene)
    assert not again["child"] and again["baked"] == [] and bake.STATS["child_runs"] == runs + 1
    resolver = bake.BakeResolver(bpy.context.evaluated_depsgraph_get())
    assert bake.plan_jobs(bpy.context.evaluated_depsgraph_get(), resolver) == []
    mat.node_tree.nodes["Gabor Texture"].inputs["Scale"].default_value = 2.5
    mat.node_tree.nodes["Color Ramp"].color_ramp.elements[0].position = 0.1
    resolver = bake.BakeResolver(bpy.context.evaluated_depsgraph_get())
    (job,) = bake.plan_jobs(bpy.context.evaluated_depsgraph_get(), resolver)
    assert job.key not in report["baked"] and job.socket == "Base Color" and job.uv_map == "UVMap"


def test_bake_in_an_acescg_file_matches_cycles(blender, tmp_path):
    """In an ACEScg file the bake holds working-space values (the child writes its EXR in the
    file's working space) and the export reads them unconverted: the baked Gabor still matches
    Cycles; the key differs from the Rec.709 file's, so neither reads the other's bake."""
    bpy = blender
    from addon import batch
    from cycles_ref import block_ztest, render_cycles, render_stpm
    scene, mat = _gabor_scene(bpy)
    resolver = bake.BakeResolver(bpy.context.evaluated_depsgraph_get())
    (job709,) = bake.plan_jobs(bpy.context.evaluated_depsgraph_get(), resolver)
    assert "FINISHED" in bpy.ops.wm.set_working_color_space(convert_colors=True, working_space="ACEScg")
    report = batch.bake_current(scene)
    assert len(report["baked"]) == 1 and not report["failed"] and job709.key not in report["baked"], report
    core_scene, _ = _export(bpy)
    assert core_scene.metadata["working_space"] == "ACESCG"
    cyc = render_cycles(scene, tmp_path, samples=SPP, seeds=(0, 1, 2))
    stpm, _res = render_stpm(scene, samples=SPP, seeds=(0, 1, 2))
    r = block_ztest(stpm, cyc)
    print(f"baked Gabor in ACEScg vs Cycles: {r.summary()}")
    assert r.z_abs_max < 4.5, (r.summary(), np.round(r.z, 1))
    assert abs(r.mean_ratio - 1.0) < 0.01, r.summary()


def test_inputs_that_cannot_be_baked_are_named(blender):
    bpy = blender
    from test_addon_scenes import add_mesh
    scene, mat = _gabor_scene(bpy)
    t = mat.node_tree
    bsdf = t.nodes["Principled BSDF"]
    lw = t.nodes.new("ShaderNodeLayerWeight")
    mix = t.nodes.new("ShaderNodeMix")
    mix.data_type = "FLOAT"
    t.links.new(lw.outputs["Facing"], mix.inputs["Factor"])
    t.links.new(t.nodes["Gabor Texture"].outputs["Value"], mix.inputs["B"])
    t.links.new(mix.outputs["Result"], bsdf.inputs["Roughness"])
    t.links.new(t.nodes.new("ShaderNodeFresnel").outputs["Fac"], bsdf.inputs["Metallic"])
    # The same material on a mesh without UVs
    bare = add_mesh("cube", "Bare", location=(3, 0, 0), material=mat)
    while bare.data.uv_layers:
        bare.data.uv_layers.remove(bare.data.uv_layers[0])
    _scene, warnings = _export(bpy)
    mine = [w for w in warnings if w.startswith("material 'Gabor': ")]
    rough = [w for w in mine if w.startswith("material 'Gabor': Roughness of 'Principled BSDF' cannot be baked")]
    assert len(rough) == 1 and "'Layer Weight' (ShaderNodeLayerWeight) depends on the view direction" in rough[0]
    assert "use their own default values" in rough[0]
    # a Fresnel alone on Metallic is evaluated by the interpreter: nothing to bake, nothing to say
    assert not any("Metallic" in w for w in mine), mine
    assert any("Base Color of 'Principled BSDF' on object 'Bare' cannot be baked" in w
               and "object 'Bare' has no UV map" in w for w in mine), mine
    assert any("Base Color of 'Principled BSDF' on object 'Floor' needs a bake" in w for w in mine), mine
    # Said once each: the compiler's own "not supported" lines for these nodes are replaced
    assert not any("is not supported by the node interpreter" in w for w in mine), mine
    # Only the bakeable one is planned
    dg = bpy.context.evaluated_depsgraph_get()
    (job,) = bake.plan_jobs(dg, bake.BakeResolver(dg))
    assert (job.object, job.socket) == ("Floor", "Base Color")
