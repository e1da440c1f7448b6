"""Smallest scene for the bright region under the kitchen's rough metal pot: a rough metal (roughness R)
ellipsoid on a grey plane under a sun -> review/out/rough_pot_R.blend.  python make_rough_pot.py [R] [sun|hdri]"""
import math, sys
from pathlib import Path
import bpy
HERE = Path(__file__).resolve().parent; OUT = HERE / "out"; OUT.mkdir(exist_ok=True)
sys.path.insert(0, str(HERE.parent)); import addon
R = float(sys.argv[1]) if len(sys.argv) > 1 else 0.35
bpy.ops.wm.read_factory_settings(use_empty=True); addon.register(); s = bpy.context.scene
bpy.ops.mesh.primitive_plane_add(size=4); p = bpy.context.object
m = bpy.data.materials.new("Floor"); m.use_nodes = True; m.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.6, 0.6, 0.6, 1)
m.node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value = 0.8; p.data.materials.append(m)
bpy.ops.mesh.primitive_uv_sphere_add(radius=0.4, location=(0, 0, 0.3)); pot = bpy.context.object; pot.scale.z = 0.75
bpy.ops.object.shade_smooth()
pm = bpy.data.materials.new("Pot"); pm.use_nodes = True; b = pm.node_tree.nodes["Principled BSDF"]
b.inputs["Metallic"].default_value = 1.0; b.inputs["Roughness"].default_value = R; b.inputs["Base Color"].default_value = (0.9, 0.6, 0.45, 1)
pot.data.materials.append(pm)
sun = bpy.data.lights.new("Sun", "SUN"); sun.energy = 5; sun.angle = math.radians(2)
so = bpy.data.objects.new("Sun", sun); so.rotation_euler = (math.radians(45), 0, math.radians(30)); s.collection.objects.link(so)
w = bpy.data.worlds.new("W"); s.world = w; w.use_nodes = True; w.node_tree.nodes["Background"].inputs["Color"].default_value = (0.02, 0.02, 0.02, 1)
cam = bpy.data.cameras.new("C"); co = bpy.data.objects.new("C", cam); s.collection.objects.link(co)
co.location = (0, -2.6, 1.6); co.rotation_euler = (math.radians(60), 0, 0); s.camera = co
s.render.resolution_x, s.render.resolution_y = 80, 60; s.render.engine = "STPM"
bpy.ops.wm.save_as_mainfile(filepath=str(OUT / f"rough_pot_{R}.blend"))
