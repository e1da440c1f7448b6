"""Smallest scene for the merge refusal: one UV'd cylinder with Array + Bevel modifiers -> review/out/bevel_min.blend."""
import math, sys
from pathlib import Path
import bpy
HERE = Path(__file__).resolve().parent; OUT = HERE / "out"; OUT.mkdir(exist_ok=True)
sys.path.insert(0, str(HERE.parent)); import addon
bpy.ops.wm.read_factory_settings(use_empty=True); addon.register()
s = bpy.context.scene
bpy.ops.mesh.primitive_cylinder_add(radius=0.3, depth=0.1); ck = bpy.context.object
if "array" in sys.argv:
    a = ck.modifiers.new("Array", "ARRAY"); a.count = 4; a.relative_offset_displace = (1.3, 0, 0)
ck.modifiers.new("Bevel", "BEVEL").width = 0.03
bpy.ops.object.mode_set(mode="EDIT"); bpy.ops.mesh.select_all(action="SELECT"); bpy.ops.uv.smart_project(); bpy.ops.object.mode_set(mode="OBJECT")
l = bpy.data.lights.new("L", "POINT"); l.energy = 500; lo = bpy.data.objects.new("L", l); lo.location = (0, -2, 3); s.collection.objects.link(lo)
cam = bpy.data.cameras.new("C"); co = bpy.data.objects.new("C", cam); s.collection.objects.link(co)
co.location = (1, -4, 2); co.rotation_euler = (math.radians(65), 0, 0); s.camera = co
s.render.resolution_x, s.render.resolution_y = 32, 24; s.render.engine = "STPM"
bpy.ops.wm.save_as_mainfile(filepath=str(OUT / "bevel_min.blend"))
