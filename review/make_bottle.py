"""Scene 3: a perfume-bottle product shot built the way an artist would (bpy 5.0.1).

A Subdivision + Solidify glass bottle with a gold cap, a marble plinth (UV-unwrapped, image
texture + normal map written by this script), a Geometry Nodes scatter of collection-instanced
pearls, a gold ring keyframed to spin during the shutter, an emissive neon strip, an area light
coloured by a Blackbody node, a spot light with an IES Texture (file written here), an HDRI world
(float EXR with a sun spot), a moving camera with depth of field, AgX, 50 % of 320x240.

Writes review/out/bottle.blend and variants:
  bottle_sky.blend    Sky Texture world (Multiple Scattering), Filmic
  bottle_film.blend   transparent film, Standard view, a render region (border, no crop)
python review/make_bottle.py   (PYTHONPATH = the checkout; bpy 5.0.1)
"""
import math
import numpy as np
import bpy

from _review_common import (OUT, emission, glass, image_material, principled, scatter_tree, select_only, smart_uv,
                     start_scene, write_image)

scene = start_scene()
TEX = OUT / "bottle_textures"; TEX.mkdir(exist_ok=True)

# --- textures: marble (veins from sines of a warped coordinate), its normal map, an HDRI
rng = np.random.default_rng(3)
h = w = 128
yy, xx = np.mgrid[0:h, 0:w] / 128.0
warp = sum(a * np.sin(2 * np.pi * (f1 * xx + f2 * yy) + p)
           for a, f1, f2, p in zip(rng.uniform(0.05, 0.2, 6), rng.integers(1, 5, 6), rng.integers(1, 5, 6), rng.uniform(0, 6, 6)))
vein = np.abs(np.sin(2 * np.pi * (3 * xx + 2 * yy + warp))) ** 0.25
marble = np.stack([0.85 * vein + 0.1, 0.83 * vein + 0.1, 0.8 * vein + 0.12], -1)
write_image(TEX / "marble.png", marble)
gy, gx = np.gradient(vein)
nrm = np.stack([0.5 - 2.0 * gx, 0.5 - 2.0 * gy, np.ones_like(gx)], -1)
write_image(TEX / "marble_normal.png", nrm)
H, W = 64, 128
v = (np.arange(H) + 0.5) / H
env = np.zeros((H, W, 3), np.float32)
env[:] = (0.3 + 0.6 * (1 - v))[:, None, None] * np.array([0.55, 0.7, 1.0], np.float32)
env[H // 2:] = np.array([0.12, 0.1, 0.09], np.float32)
env[14:17, 80:83] = 300.0
write_image(TEX / "studio.exr", env, "float")
# an IES file: type C, a downlight whose candela falls off with the vertical angle
angles = list(range(0, 181, 10))
cd = [max(0.0, math.cos(math.radians(a))) ** 2 * 1000 + 20 for a in angles]
(TEX / "downlight.ies").write_text(
    "IESNA:LM-63-2002\n[TEST] review\nTILT=NONE\n1 -1 1 %d 1 1 2 0 0 0\n1 1 100\n%s\n0\n%s\n"
    % (len(angles), " ".join(map(str, angles)), " ".join(f"{c:.1f}" for c in cd)))


# --- backdrop: floor + wall as one plane bent upward, subdivided for the curve
bpy.ops.mesh.primitive_plane_add(size=1); back = bpy.context.object; back.name = "Backdrop"
select_only(back); bpy.ops.object.mode_set(mode="EDIT")
bpy.ops.mesh.subdivide(number_cuts=1); bpy.ops.object.mode_set(mode="OBJECT")
me = back.data
for vtx in me.vertices:
    x, y = vtx.co.x * 8, vtx.co.y
    vtx.co = (x, -6.0, 0) if y < 0 else (x, 2.0, 0) if y == 0 else (x, 2.3, 3.5)   # floor, cove, wall
back.modifiers.new("Subd", "SUBSURF").levels = 2
bm, _ = principled("Backdrop", **{"Base Color": (0.3, 0.28, 0.27, 1), "Roughness": 0.8}); me.materials.append(bm)

# --- marble plinth: UV unwrapped, image texture + normal map
bpy.ops.mesh.primitive_cylinder_add(radius=0.9, depth=0.3, vertices=48, location=(0, 0.2, 0.15)); plinth = bpy.context.object
plinth.name = "Plinth"; smart_uv(plinth); bpy.ops.object.shade_smooth()
plinth.data.materials.append(image_material("Marble", TEX / "marble.png", TEX / "marble_normal.png", roughness=0.25,
                                            normal_strength=0.8))

# --- the bottle: a cube rounded by Subdivision, hollowed by Solidify, glass
me = bpy.data.meshes.new("Bottle")
me.from_pydata([(x * 0.175, y * 0.1, z * 0.25) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], [],
               [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)])
bottle = bpy.data.objects.new("Bottle", me); scene.collection.objects.link(bottle)
bottle.location = (0, 0.2, 0.3 + 0.25 - 0.035)                      # its base on the plinth (after Subdivision)
sub = bottle.modifiers.new("Subd", "SUBSURF"); sub.levels, sub.render_levels = 2, 3
sol = bottle.modifiers.new("Solidify", "SOLIDIFY"); sol.thickness = 0.03
select_only(bottle); bpy.ops.object.shade_smooth()
bottle.data.materials.append(glass("Glass", color=(0.95, 0.85, 0.7, 1)))

# --- gold cap
bpy.ops.mesh.primitive_cylinder_add(radius=0.09, depth=0.18, vertices=32, location=(0, 0.2, 0.82)); cap = bpy.context.object
cap.name = "Cap"; bpy.ops.object.shade_smooth()
gold, _ = principled("Gold", **{"Base Color": (1.0, 0.77, 0.34, 1), "Metallic": 1.0, "Roughness": 0.3})
cap.data.materials.append(gold)

# --- a gold ring spinning during the shutter (rotation keyframes)
bpy.ops.mesh.primitive_torus_add(major_radius=0.22, minor_radius=0.03, location=(0.75, -0.55, 0.23)); ring = bpy.context.object
ring.name = "Ring"; ring.rotation_euler = (math.radians(70), 0, 0); ring.data.materials.append(gold)
bpy.ops.object.shade_smooth()
ring.keyframe_insert("rotation_euler", frame=1)
ring.rotation_euler.z = math.radians(360 * 4); ring.keyframe_insert("rotation_euler", frame=11)

# --- pearls: a collection instanced by a Geometry Nodes scatter on a pad
col = bpy.data.collections.new("Pearls"); scene.collection.children.link(col)
bpy.ops.mesh.primitive_ico_sphere_add(radius=0.035, subdivisions=3, location=(0, 0, 0)); pearl = bpy.context.object
pearl.name = "Pearl"; bpy.ops.object.shade_smooth()
pm, _ = principled("Pearl", **{"Base Color": (0.95, 0.92, 0.88, 1), "Roughness": 0.15, "Coat Weight": 0.5})
pearl.data.materials.append(pm)
for c in pearl.users_collection: c.objects.unlink(pearl)
col.objects.link(pearl)
bpy.context.view_layer.layer_collection.children["Pearls"].exclude = True
bpy.ops.mesh.primitive_plane_add(size=0.9, location=(-0.9, -0.5, 0.001)); pad = bpy.context.object; pad.name = "PearlPad"
pad.data.materials.append(bm)
ng, dist = scatter_tree("Scatter", col, keep_surface=True); dist.inputs["Density"].default_value = 60
pad.modifiers.new("Scatter", "NODES").node_group = ng

# --- emissive neon strip behind the bottle
bpy.ops.mesh.primitive_cylinder_add(radius=0.02, depth=1.6, location=(0, 1.2, 0.75), rotation=(0, math.radians(90), 0))
neon = bpy.context.object; neon.name = "Neon"
neon.data.materials.append(emission("Neon", (1.0, 0.25, 0.6, 1), 8))

# --- lights: an area light coloured by a Blackbody node, a spot with an IES profile
ar = bpy.data.lights.new("Softbox", "AREA"); ar.size = 1.2; ar.energy = 120
ar.use_nodes = True
lnt = ar.node_tree; bb = lnt.nodes.new("ShaderNodeBlackbody"); bb.inputs["Temperature"].default_value = 4000
lnt.links.new(bb.outputs[0], lnt.nodes["Emission"].inputs["Color"])
ao = bpy.data.objects.new("Softbox", ar); ao.location = (-1.8, -1.2, 2.0)
ao.rotation_euler = (math.radians(45), math.radians(-40), 0); scene.collection.objects.link(ao)
sp = bpy.data.lights.new("Downlight", "SPOT"); sp.energy = 4; sp.spot_size = math.radians(60); sp.shadow_soft_size = 0.05
sp.use_nodes = True
snt = sp.node_tree; ies = snt.nodes.new("ShaderNodeTexIES"); ies.mode = "EXTERNAL"; ies.filepath = str(TEX / "downlight.ies")
snt.links.new(ies.outputs[0], snt.nodes["Emission"].inputs["Strength"])
so = bpy.data.objects.new("Downlight", sp); so.location = (0.6, -0.3, 2.6); scene.collection.objects.link(so)

# --- HDRI world
world = bpy.data.worlds.new("Studio"); scene.world = world
if bpy.app.version < (5, 0, 0): world.use_nodes = True
wnt = world.node_tree; bg = wnt.nodes["Background"]
envn = wnt.nodes.new("ShaderNodeTexEnvironment"); envn.image = bpy.data.images.load(str(TEX / "studio.exr"))
wnt.links.new(envn.outputs["Color"], bg.inputs["Color"]); bg.inputs["Strength"].default_value = 0.6

# --- moving camera with depth of field
cam = bpy.data.cameras.new("Cam"); co = bpy.data.objects.new("Cam", cam); scene.collection.objects.link(co)
co.location = (0.4, -4.0, 1.6); co.rotation_euler = (math.radians(75), 0, math.radians(5.7)); cam.lens = 45
co.keyframe_insert("location", frame=1); co.location.x = 0.6; co.keyframe_insert("location", frame=11)
cam.dof.use_dof = True; cam.dof.focus_object = bottle; cam.dof.aperture_fstop = 2.0
scene.camera = co

r = scene.render
r.resolution_x, r.resolution_y, r.resolution_percentage = 320, 240, 50
r.use_motion_blur = True; r.motion_blur_shutter = 0.5
scene.frame_start, scene.frame_end = 1, 11; scene.frame_set(3)
scene.view_settings.view_transform = "AgX"
r.engine = "STPM"
bpy.ops.stpm.apply_preset(preset="PREVIEW")
bpy.ops.wm.save_as_mainfile(filepath=str(OUT / "bottle.blend")); print("saved bottle.blend")

# --- variant: Sky Texture world, Filmic
sky = bpy.data.worlds.new("Sky"); scene.world = sky
if bpy.app.version < (5, 0, 0): sky.use_nodes = True
snt = sky.node_tree; st = snt.nodes.new("ShaderNodeTexSky"); st.sky_type = "MULTIPLE_SCATTERING"
st.sun_elevation = math.radians(30); st.sun_rotation = math.radians(200)
snt.links.new(st.outputs["Color"], snt.nodes["Background"].inputs["Color"]); snt.nodes["Background"].inputs["Strength"].default_value = 0.3
scene.view_settings.view_transform = "Filmic"
bpy.ops.wm.save_as_mainfile(filepath=str(OUT / "bottle_sky.blend")); print("saved bottle_sky.blend")

# --- variant: transparent film, Standard, render region without crop
scene.world = world
r.film_transparent = True; scene.view_settings.view_transform = "Standard"
r.use_border = True; r.use_crop_to_border = False
r.border_min_x, r.border_max_x, r.border_min_y, r.border_max_y = 0.2, 0.8, 0.1, 0.7
bpy.ops.wm.save_as_mainfile(filepath=str(OUT / "bottle_film.blend")); print("saved bottle_film.blend")
