"""Fixes from the fifth artist review (an animated kitchen corner, review/make_interior5.py), through
the real bpy module: what ``stpm render`` of a .blend leaves out that ``blender -b -f`` renders (a
second view layer, the compositor) is named; geometry-nodes instances are named after their mesh.
"""
from __future__ import annotations

import pytest

bpy = pytest.importorskip("bpy")

from test_addon_scenes import add_camera, add_light, add_mesh, export_now, fresh  # noqa: E402

import addon  # noqa: E402
from addon import batch  # noqa: E402

addon.register()


def _save_layered(tmp_path, *, second_layer: bool, glare: bool, use_first: bool = True):
    """A floor, a cube, a camera and a light; optionally a second view layer (with a collection
    excluded, as the review's) and a compositor with a Glare node; saved, its path returned."""
    scene = fresh()
    add_camera()
    add_light("POINT", energy=300.0, location=(1, -1, 3))
    add_mesh("plane", "Floor", size=6)
    cube = add_mesh("cube", "Fruit", location=(0, 0, 1))
    coll = bpy.data.collections.new("FruitColl")
    scene.collection.children.link(coll)
    for c in cube.users_collection:
        c.objects.unlink(cube)
    coll.objects.link(cube)
    scene.view_layers[0].name = "Main"
    scene.view_layers[0].use = use_first
    if second_layer:
        vl = scene.view_layers.new("NoFruit")
        vl.layer_collection.children["FruitColl"].exclude = True
    if glare:
        tree = bpy.data.node_groups.new("Compositing", "CompositorNodeTree")
        scene.compositing_node_group = tree
        tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
        rl, gl, out = (tree.nodes.new(t) for t in ("CompositorNodeRLayers", "CompositorNodeGlare", "NodeGroupOutput"))
        tree.links.new(rl.outputs["Image"], gl.inputs["Image"])
        tree.links.new(gl.outputs["Image"], out.inputs[0])
        scene.render.use_compositing = True
    path = tmp_path / "layered.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


@pytest.mark.parametrize("second_layer, glare, use_first, expect", [
    (False, False, True, ()),
    (True, False, True, ("view layers: Blender renders 2 of this file ('Main', 'NoFruit'); stpm exports the active "
                         "one, 'Main', alone",)),
    (False, True, True, ("compositor: its nodes (Glare) are not run by stpm",)),
    (True, False, False, ("view layers: Blender renders 1 of this file ('NoFruit'); stpm exports the active one, "
                          "'Main', alone",)),
])
def test_command_line_names_what_blender_would_render_besides(tmp_path, second_layer, glare, use_first, expect):
    # The review's kitchen (two view layers, a Glare compositor) came out of `stpm render` as one
    # layer named ViewLayer, without the glare, and without a word
    path = _save_layered(tmp_path, second_layer=second_layer, glare=glare, use_first=use_first)
    scene, _settings = batch.load_blend(path, 1)
    warnings = scene.metadata["warnings"]
    notes = [w for w in warnings if w.startswith(("view layers:", "compositor:"))]
    assert len(notes) == len(expect), warnings
    for text in expect:
        assert sum(w.startswith(text) for w in notes) == 1, warnings
    # the excluded collection stays in the exported (active) layer
    assert {i.name for i in scene.instances} == {"Floor", "Fruit"}


def test_geometry_nodes_instances_are_named_after_their_mesh():
    # The review's fruit scatter (Object Info, As Instance off -> Instance on Points) was listed by
    # the effects plan as 'FruitBed@FruitBed' four times
    fresh()
    add_camera()
    add_light()
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.1, location=(0, 0, -5))
    orange = bpy.context.object
    orange.name, orange.data.name = "Orange", "OrangeMesh"
    orange.hide_render = True
    bed = add_mesh("plane", "FruitBed", size=1)
    tree = bpy.data.node_groups.new("Scatter", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    gi, go = tree.nodes.new("NodeGroupInput"), tree.nodes.new("NodeGroupOutput")
    inst = tree.nodes.new("GeometryNodeInstanceOnPoints")
    info = tree.nodes.new("GeometryNodeObjectInfo")
    info.inputs["Object"].default_value = orange
    tree.links.new(gi.outputs[0], inst.inputs["Points"])      # the plane's 4 vertices
    tree.links.new(info.outputs["Geometry"], inst.inputs["Instance"])
    tree.links.new(inst.outputs["Instances"], go.inputs[0])
    bed.modifiers.new("Scatter", "NODES").node_group = tree
    out, _warnings = export_now()
    names = sorted(i.name for i in out.instances if "@" in i.name)      # (the source sphere is 'Orange')
    assert names == ["OrangeMesh@FruitBed"] * 4, names
