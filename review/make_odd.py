"""Scene 2: less common but ordinary features (bpy 5.0.1) -> review/out/odd.blend.

A text object with bevel and extrude, a bevelled Bezier curve, a Geometry Nodes scatter of
instanced cones on a plane, a collection instance, a Mix Shader driven by Layer Weight (Fresnel),
a Principled with Sheen and Coat, a Principled with Subsurface, a spot light with a size and blend,
an area light DISK, a camera with depth of field.
"""
import math
import bpy
from _review_common import OUT, principled, scatter_tree, start_scene
scene = start_scene()

# floor
bpy.ops.mesh.primitive_plane_add(size=6); floor = bpy.context.object
fm, _ = principled("Floor", **{"Base Color": (0.6, 0.6, 0.6, 1), "Roughness": 0.7}); floor.data.materials.append(fm)
# GN scatter of cones on a small plane
bpy.ops.mesh.primitive_plane_add(size=1.2, location=(1.3, 0.8, 0.001)); pad = bpy.context.object
pad.data.materials.append(fm)
bpy.ops.mesh.primitive_cone_add(radius1=0.05, depth=0.15, location=(0, 0, -10)); cone = bpy.context.object
cm, _ = principled("Cone", **{"Base Color": (0.1, 0.7, 0.2, 1)}); cone.data.materials.append(cm)
cone.hide_render = True
ng, dist = scatter_tree("Scatter", cone, keep_surface=True); dist.inputs["Density"].default_value = 20
pad.modifiers.new("Scatter", "NODES").node_group = ng
# text with bevel, Mix(Layer Weight) material
bpy.ops.object.text_add(location=(-1.6, 0.3, 0.0)); txt = bpy.context.object
txt.data.body = "STPM"; txt.data.extrude = 0.08; txt.data.bevel_depth = 0.02; txt.data.size = 0.7
txt.rotation_euler.x = math.radians(90)
m = bpy.data.materials.new("Fres"); m.use_nodes = True; nt = m.node_tree
out = nt.nodes["Material Output"]; nt.nodes.remove(nt.nodes["Principled BSDF"])
d = nt.nodes.new("ShaderNodeBsdfDiffuse"); d.inputs["Color"].default_value = (0.8, 0.1, 0.1, 1)
gl = nt.nodes.new("ShaderNodeBsdfGlossy"); gl.inputs["Roughness"].default_value = 0.1
lw = nt.nodes.new("ShaderNodeLayerWeight"); lw.inputs["Blend"].default_value = 0.3
mix = nt.nodes.new("ShaderNodeMixShader")
nt.links.new(lw.outputs["Fresnel"], mix.inputs[0]); nt.links.new(d.outputs[0], mix.inputs[1]); nt.links.new(gl.outputs[0], mix.inputs[2])
nt.links.new(mix.outputs[0], out.inputs["Surface"])
txt.data.materials.append(m)
# bevelled curve
bpy.ops.curve.primitive_bezier_circle_add(radius=0.4, location=(0.0, -0.6, 0.05)); crv = bpy.context.object
crv.data.bevel_depth = 0.05; crv.data.bevel_resolution = 3
sm, _ = principled("Sheen", **{"Base Color": (0.2, 0.2, 0.6, 1), "Sheen Weight": 1.0, "Coat Weight": 1.0, "Roughness": 0.6}); crv.data.materials.append(sm)
# subsurface sphere, in a collection instanced twice
col = bpy.data.collections.new("Props"); bpy.context.scene.collection.children.link(col)
bpy.ops.mesh.primitive_uv_sphere_add(radius=0.3, location=(0, 0, 0.3)); sph = bpy.context.object
bpy.ops.object.shade_smooth()
ss, _ = principled("Skin", **{"Base Color": (0.8, 0.5, 0.4, 1), "Subsurface Weight": 1.0, "Subsurface Scale": 0.1})
sph.data.materials.append(ss)
for c in sph.users_collection: c.objects.unlink(sph)
col.objects.link(sph)
col.hide_render = False
bpy.context.view_layer.layer_collection.children["Props"].exclude = True
for x in (0.3, 1.0):
    e = bpy.data.objects.new(f"Inst{x}", None); e.instance_type = "COLLECTION"; e.instance_collection = col
    e.location = (x, 0.2, 0); scene.collection.objects.link(e)
# lights: spot with size, area disk
sp = bpy.data.lights.new("Spot", "SPOT"); sp.energy = 300; sp.shadow_soft_size = 0.3; sp.spot_size = math.radians(50); sp.spot_blend = 0.3
so = bpy.data.objects.new("Spot", sp); so.location = (0.5, -1.5, 3); so.rotation_euler = (math.radians(30), 0, 0); scene.collection.objects.link(so)
ar = bpy.data.lights.new("Disk", "AREA"); ar.shape = "DISK"; ar.size = 1.0; ar.energy = 150
ao = bpy.data.objects.new("Disk", ar); ao.location = (-1.5, -1, 2.5); ao.rotation_euler = (math.radians(30), math.radians(-30), 0); scene.collection.objects.link(ao)
world = bpy.data.worlds.new("W"); scene.world = world; world.use_nodes = True
world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.05, 0.05, 0.06, 1)
# camera with DOF
cam = bpy.data.cameras.new("Cam"); co = bpy.data.objects.new("Cam", cam); scene.collection.objects.link(co)
co.location = (0, -4.5, 1.8); co.rotation_euler = (math.radians(72), 0, 0); cam.lens = 40
cam.dof.use_dof = True; cam.dof.focus_distance = 4.5; cam.dof.aperture_fstop = 1.4
scene.camera = co
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 160, 120, 100
scene.render.engine = "STPM"
bpy.ops.wm.save_as_mainfile(filepath=str(OUT / "odd.blend")); print("saved")
