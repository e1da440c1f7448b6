"""Scene 1: a kitchen-table still life built the way an artist would (bpy 5.0.1).

UV-unwrapped (Smart UV Project) meshes with Subdivision/Bevel/Array modifiers, a PNG
texture written to disk and loaded, a normal map, a glass with liquid (volume absorption),
a rough metal pot, an HDRI world (float EXR with a sun spot), a spinning fan with motion blur.
Writes review/out/kitchen.blend.
"""
import math
import numpy as np
import bpy
import OpenImageIO as oiio

from _review_common import OUT, image_material, principled, smart_uv, start_scene

scene = start_scene()

# --- textures on disk
h, w = 64, 64
yy, xx = np.mgrid[0:h, 0:w]
checker = (((xx // 8) + (yy // 8)) % 2).astype(np.float32)
img = np.stack([0.6 + 0.3 * checker, 0.35 + 0.2 * checker, 0.2 + 0.1 * checker, np.ones_like(checker)], -1)
buf = oiio.ImageBuf(oiio.ImageSpec(w, h, 4, "uint8")); buf.set_pixels(oiio.ROI(), (img * 255).astype(np.uint8))
buf.write(str(OUT / "wood.png"))
nrm = np.zeros((h, w, 3), np.float32); nrm[..., 0] = 0.5 + 0.3 * np.sin(xx / 3.0); nrm[..., 1] = 0.5; nrm[..., 2] = 1.0
buf = oiio.ImageBuf(oiio.ImageSpec(w, h, 3, "uint8")); buf.set_pixels(oiio.ROI(), (np.clip(nrm, 0, 1) * 255).astype(np.uint8))
buf.write(str(OUT / "wood_normal.png"))
# HDRI: 128x64 lat-long, dim sky gradient + a bright sun spot
H, W = 64, 128
v = (np.arange(H) + 0.5) / H
env = np.zeros((H, W, 3), np.float32)
env[...] = (0.25 + 0.5 * (1 - v))[:, None, None] * np.array([0.6, 0.75, 1.0], np.float32)
env[H // 2:] = np.array([0.15, 0.12, 0.1], np.float32)
env[16:19, 40:43] = 2000.0
buf = oiio.ImageBuf(oiio.ImageSpec(W, H, 3, "float")); buf.set_pixels(oiio.ROI(), env)
buf.write(str(OUT / "sky.exr"))

# --- table: a cube with bevel, wood texture + normal map
bpy.ops.mesh.primitive_cube_add(size=1, location=(0, 0, -0.05)); table = bpy.context.object
table.scale = (3, 2, 0.1); bpy.ops.object.transform_apply(scale=True)
table.modifiers.new("Bevel", "BEVEL").width = 0.03
smart_uv(table)
table.data.materials.append(image_material("Wood", OUT / "wood.png", OUT / "wood_normal.png", roughness=0.5))

# --- glass with liquid
bpy.ops.mesh.primitive_cylinder_add(radius=0.25, depth=0.6, location=(-0.6, 0.2, 0.3)); glass = bpy.context.object
glass.modifiers.new("Solid", "SOLIDIFY").thickness = 0.02
glass.modifiers.new("Sub", "SUBSURF").levels = 1
bpy.ops.object.shade_smooth()
g, gb = principled("Glass", Roughness=0.0); gb.inputs["Transmission Weight"].default_value = 1.0; gb.inputs["IOR"].default_value = 1.5
glass.data.materials.append(g)
bpy.ops.mesh.primitive_cylinder_add(radius=0.22, depth=0.4, location=(-0.6, 0.2, 0.22)); liquid = bpy.context.object
bpy.ops.object.shade_smooth()
lm = bpy.data.materials.new("Juice"); lm.use_nodes = True
lnt = lm.node_tree; lb = lnt.nodes["Principled BSDF"]
lb.inputs["Transmission Weight"].default_value = 1.0; lb.inputs["IOR"].default_value = 1.33; lb.inputs["Roughness"].default_value = 0.0
va = lnt.nodes.new("ShaderNodeVolumeAbsorption"); va.inputs["Color"].default_value = (1.0, 0.4, 0.05, 1); va.inputs["Density"].default_value = 3.0
lnt.links.new(va.outputs[0], lnt.nodes["Material Output"].inputs["Volume"])
liquid.data.materials.append(lm)

# --- rough metal pot
bpy.ops.mesh.primitive_uv_sphere_add(radius=0.4, location=(0.5, 0.3, 0.3)); pot = bpy.context.object
pot.scale.z = 0.75; pot.modifiers.new("Sub", "SUBSURF").levels = 1; bpy.ops.object.shade_smooth()
pm, pb = principled("Pot", Metallic=1.0, Roughness=0.35); pb.inputs["Base Color"].default_value = (0.9, 0.6, 0.45, 1)
pot.data.materials.append(pm)

# --- array of cookies (small beveled cylinders)
bpy.ops.mesh.primitive_cylinder_add(radius=0.08, depth=0.03, location=(-0.2, -0.5, 0.015)); ck = bpy.context.object
arr = ck.modifiers.new("Array", "ARRAY"); arr.count = 4; arr.relative_offset_displace = (1.3, 0, 0)
ck.modifiers.new("Bevel", "BEVEL").width = 0.01
smart_uv(ck)
cm, cb = principled("Cookie", Roughness=0.8); cb.inputs["Base Color"].default_value = (0.7, 0.45, 0.2, 1)
ck.data.materials.append(cm)

# --- a spinning fan: 3 blades, keyframed rotation, motion blur
bpy.ops.object.empty_add(location=(0.9, -0.4, 0.6)); hub = bpy.context.object
fm, fb = principled("Fan", Roughness=0.4); fb.inputs["Base Color"].default_value = (0.1, 0.3, 0.8, 1)
for i in range(3):
    bpy.ops.mesh.primitive_cube_add(size=1); bl = bpy.context.object
    bl.scale = (0.3, 0.06, 0.01); bl.location = (0.15 * math.cos(i * 2.094), 0.15 * math.sin(i * 2.094), 0)
    bl.rotation_euler.z = i * 2.094; bl.parent = hub; bl.data.materials.append(fm)
hub.rotation_euler = (math.radians(80), 0, 0)
scene.frame_start, scene.frame_end = 1, 3
hub.keyframe_insert("rotation_euler", frame=1)
hub.rotation_euler.z = math.radians(180); hub.keyframe_insert("rotation_euler", frame=3)
scene.frame_set(2)
scene.render.use_motion_blur = True; scene.render.motion_blur_shutter = 0.5

# --- world HDRI
world = bpy.data.worlds.new("World"); scene.world = world; world.use_nodes = True
wnt = world.node_tree; envn = wnt.nodes.new("ShaderNodeTexEnvironment"); envn.image = bpy.data.images.load(str(OUT / "sky.exr"))
wnt.links.new(envn.outputs["Color"], wnt.nodes["Background"].inputs["Color"])

# --- camera
cam = bpy.data.cameras.new("Cam"); cobj = bpy.data.objects.new("Cam", cam); scene.collection.objects.link(cobj)
cobj.location = (0, -3.2, 1.6); cobj.rotation_euler = (math.radians(66), 0, 0); cam.lens = 35
scene.camera = cobj
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 160, 120, 100
scene.render.engine = "STPM"
bpy.ops.wm.save_as_mainfile(filepath=str(OUT / "kitchen.blend"))
print("saved", OUT / "kitchen.blend")
