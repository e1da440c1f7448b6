"""Export-only probe: is motion blur exported for instances that move with their instancer, for a
moving collection-instance empty, a child of a moving parent, and for a camera zooming (lens
keyframed) during the shutter?  python review/motion_probe.py   (PYTHONPATH = checkout)"""
import math, sys
from pathlib import Path
ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]
import numpy as np, bpy
from test_addon_scenes import fresh, add_camera, add_light, add_mesh, set_world, export_now
from _review_common import scatter_tree


def scatter_group(obj_to_instance):
    ng, d = scatter_tree("Scatter", obj_to_instance); d.inputs["Density"].default_value = 5
    return ng

s = fresh(); add_camera(); add_light(); set_world((0.1, 0.1, 0.1)); s.render.use_motion_blur = True
cone = add_mesh("cube", "Seed", size=0.1); cone.hide_render = True
pad = add_mesh("plane", "Pad", size=2); pad.modifiers.new("S", "NODES").node_group = scatter_group(cone)
pad.keyframe_insert("location", frame=1); pad.location.x = 1.0; pad.keyframe_insert("location", frame=2)
col = bpy.data.collections.new("C"); b = bpy.data.objects.new("Inner", bpy.data.meshes.new("m"))
bpy.ops.mesh.primitive_cube_add(size=0.2); inner = bpy.context.object; inner.name = "Inner"
for c in inner.users_collection: c.objects.unlink(inner)
col.objects.link(inner)
e = bpy.data.objects.new("Empty", None); e.instance_type = "COLLECTION"; e.instance_collection = col; s.collection.objects.link(e)
e.keyframe_insert("location", frame=1); e.location.y = 1.0; e.keyframe_insert("location", frame=2)
par = add_mesh("cube", "Parent", location=(0, 0, 2), size=0.2); ch = add_mesh("cube", "Child", location=(0.5, 0, 2), size=0.2)
ch.parent = par; ch.matrix_parent_inverse = par.matrix_world.inverted()
par.keyframe_insert("rotation_euler", frame=1); par.rotation_euler.z = math.radians(90); par.keyframe_insert("rotation_euler", frame=2)
cam = s.camera.data; cam.keyframe_insert("lens", frame=1); cam.lens = 100; cam.keyframe_insert("lens", frame=2)
s.frame_set(1); s.render.motion_blur_position = "START"; s.render.motion_blur_shutter = 1.0
core, warnings = export_now(s)
for i in core.instances:
    T = i.transform
    moved = None if T.is_static else np.linalg.norm(T.at(np.array([1.0]))[0][:3, 3] - T.at(np.array([0.0]))[0][:3, 3])
    print(f"{i.name:20s} static={T.is_static} moved={moved}")
print("camera static:", core.camera.transform.is_static, "camera fields:", {k: getattr(core.camera, k) for k in vars(core.camera) if 'lens' in k or 'fov' in k or 'focal' in k})
print("warnings", warnings)
