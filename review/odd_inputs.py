"""Export-only probe of ordinary-but-odd objects (each alone in a tiny scene): what warns, what raises.

python review/odd_inputs.py   (PYTHONPATH=worktree)
"""
import math, sys, traceback
from pathlib import Path
sys.path.insert(0, str(Path(__file__).resolve().parent.parent)); sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
import bpy
from test_addon_scenes import fresh, add_camera, add_light, set_world, export_now

def case(name, build):
    scene = fresh(); add_camera(); add_light(); set_world((0.1, 0.1, 0.1))
    try:
        build(scene)
        core = export_now(scene)
        core = core[0] if isinstance(core, tuple) else core
        w = core.metadata.get("warnings", [])
        print(f"[{name}] OK meshes={len(core.meshes)} tris={sum(len(m.triangles) for m in core.meshes)} warnings={w}")
    except Exception as e:
        print(f"[{name}] RAISED {type(e).__name__}: {e}"); traceback.print_exc(limit=3)

def curve_no_bevel(s):
    bpy.ops.curve.primitive_bezier_curve_add()
def text_no_mat(s):
    bpy.ops.object.text_add(); bpy.context.object.data.extrude = 0.1
def metaball(s):
    bpy.ops.object.metaball_add(type="BALL")
def hair(s):
    bpy.ops.mesh.primitive_plane_add(); o = bpy.context.object
    ps = o.modifiers.new("H", "PARTICLE_SYSTEM").particle_system; ps.settings.type = "HAIR"; ps.settings.count = 50
def boolean(s):
    bpy.ops.mesh.primitive_cube_add(); a = bpy.context.object
    bpy.ops.mesh.primitive_uv_sphere_add(location=(0.5, 0, 0)); b = bpy.context.object; b.hide_render = True
    m = a.modifiers.new("B", "BOOLEAN"); m.object = b
def empty_mesh(s):
    me = bpy.data.meshes.new("E"); s.collection.objects.link(bpy.data.objects.new("E", me))
def point_cloud_gn(s):
    bpy.ops.mesh.primitive_plane_add(); o = bpy.context.object
    ng = bpy.data.node_groups.new("P", "GeometryNodeTree")
    ng.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    ng.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    gi, go = ng.nodes.new("NodeGroupInput"), ng.nodes.new("NodeGroupOutput"); d = ng.nodes.new("GeometryNodeDistributePointsOnFaces")
    ng.links.new(gi.outputs[0], d.inputs[0]); ng.links.new(d.outputs[0], go.inputs[0]); o.modifiers.new("G", "NODES").node_group = ng
def emission_principled(s):
    bpy.ops.mesh.primitive_cube_add(); o = bpy.context.object
    m = bpy.data.materials.new("Em"); m.use_nodes = True; b = m.node_tree.nodes["Principled BSDF"]
    b.inputs["Emission Color"].default_value = (1, 0.5, 0.2, 1); b.inputs["Emission Strength"].default_value = 5
    o.data.materials.append(m)
def light_nodes(s):
    l = bpy.data.lights["Light"]; l.use_nodes = True
    nt = l.node_tree; e = nt.nodes.get("Emission"); t = nt.nodes.new("ShaderNodeTexChecker"); nt.links.new(t.outputs[0], e.inputs["Color"])
def ortho_shift(s):
    c = s.camera.data; c.type = "ORTHO"; c.shift_x = 0.2; c.sensor_fit = "VERTICAL"
    bpy.ops.mesh.primitive_cube_add()
def volume_obj(s):
    bpy.ops.object.volume_add()
def film_transparent(s):
    s.render.film_transparent = True; bpy.ops.mesh.primitive_cube_add()
def mirror_mod_negscale(s):
    bpy.ops.mesh.primitive_cube_add(); o = bpy.context.object; o.scale = (-1, 1, 1); o.modifiers.new("M", "MIRROR")

for n, f in list(globals().items()):
    if callable(f) and getattr(f, "__module__", "") == "__main__" and n not in ("case",):
        case(n, f)
