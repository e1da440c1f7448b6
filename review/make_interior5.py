"""Scene 6 (artist review 5): an animated kitchen corner built the way an artist would (bpy 5.0.1).

A corner of two tiled walls (a generated tile image and its normal map, Smart UV Project) and a
wood floor; a window cut into the back wall with a Sun outside and an area light marked Portal in
the opening; a wooden table (Bevel, its legs by a Mirror modifier) with a fabric runner (Solidify,
Smart UV) carrying a glass of water (a Screw profile + Solidify, a water body inside: the caustic)
and a fruit bowl whose fruit are scattered by Geometry Nodes (Distribute Points on Faces ->
Instance on Points); a shelf of jars (an Array modifier) above a Subdivision Surface teapot-ish
pot; a pendant lamp with an emissive shade; an area light over the counter and a spot light
(blend 0.6, soft radius) on the table; a napkin whose shape key lifts it across the shutter and a
kettle lid bent by an armature; a camera with depth of field focused on the glass (an Empty), motion
blur on. Film Transparent, Render Region (border) on a part of the frame, resolution 50 %; two view
layers ("Main", "NoFruit" with the Fruit collection excluded); a compositor tree (Glare + Mix);
frame range 1-3. Writes review/out/kitchen5.blend.

Run: PYTHONPATH=. .venv/bin/python review/make_interior5.py
"""
import math

import numpy as np
import bpy
from mathutils import Matrix, Vector

from _review_common import (OUT, bend_rig, box, emission, glass, image_material, lathe, principled, scatter_tree,
                     select_only, smart_uv, start_scene, subdivide, write_image)

scene = start_scene(frame_range=(1, 3))

# --- textures an artist would paint: wood planks, white tiles with grout (+ normal map), linen
rng = np.random.default_rng(3)
yy, xx = np.mgrid[0:256, 0:256].astype(np.float32)
grain = 0.5 + 0.5 * np.sin(xx * 0.35 + 3.0 * np.sin(yy * 0.05) + rng.normal(0, 0.2, (256, 256)))
plank = (yy // 32) % 2
wood = np.stack([0.42 + 0.12 * grain - 0.05 * plank, 0.25 + 0.07 * grain - 0.03 * plank, 0.12 + 0.03 * grain], -1)
write_image(OUT / "k5_wood.png", wood)
grout = ((xx % 64) < 4) | ((yy % 64) < 4)
tiles = np.where(grout[..., None], np.array([0.35, 0.34, 0.32]), np.array([0.85, 0.86, 0.84]))
write_image(OUT / "k5_tiles.png", tiles)
# normal map: grout lines are grooves (tangent-space normals tilt at their edges)
gx = np.where((xx % 64) < 2, -0.6, np.where(((xx % 64) >= 2) & ((xx % 64) < 4), 0.6, 0.0))
gy = np.where((yy % 64) < 2, -0.6, np.where(((yy % 64) >= 2) & ((yy % 64) < 4), 0.6, 0.0))
n = np.stack([gx, gy, np.ones_like(xx)], -1); n /= np.linalg.norm(n, axis=-1, keepdims=True)
write_image(OUT / "k5_tiles_normal.png", 0.5 + 0.5 * n)
weave = 0.5 + 0.5 * np.sign(np.sin(xx * math.pi / 3) * np.sin(yy * math.pi / 3))
write_image(OUT / "k5_linen.png", np.stack([0.55 + 0.15 * weave, 0.12 + 0.05 * weave, 0.10 + 0.04 * weave], -1))


wood_m = image_material("Wood", OUT / "k5_wood.png", scale=2.0, roughness=0.35)
tile_m = image_material("Tiles", OUT / "k5_tiles.png", OUT / "k5_tiles_normal.png", scale=3.0, roughness=0.15,
                        normal_strength=1.0)
linen_m = image_material("Linen", OUT / "k5_linen.png", scale=4.0, roughness=0.9)
plaster_m, _ = principled("Plaster", Base_Color=(0.8, 0.78, 0.74), Roughness=0.9)

# --- the corner: floor, two tiled walls, a ceiling; a window in the back wall (Boolean)
floor = box("Floor", (4, 4, 0.1), (0, 0, -0.05), wood_m); smart_uv(floor)
back = box("WallBack", (4, 0.1, 2.6), (0, 2.05, 1.3), tile_m)
left = box("WallLeft", (0.1, 4, 2.6), (-2.05, 0, 1.3), tile_m)
box("Ceiling", (4, 4, 0.1), (0, 0, 2.65), plaster_m)
cutter = box("WindowCutter", (1.2, 0.5, 0.9), (0.6, 2.05, 1.6)); cutter.hide_render = True; cutter.display_type = "WIRE"
bo = back.modifiers.new("Window", "BOOLEAN"); bo.object = cutter; bo.operation = "DIFFERENCE"
for o in (back, left):
    smart_uv(o)

# sun outside the window and a portal in the opening, a plain blue-grey world
sun_d = bpy.data.lights.new("Sun", "SUN"); sun_d.energy = 10.0; sun_d.angle = math.radians(1.0); sun_d.color = (1.0, 0.9, 0.78)
sun = bpy.data.objects.new("Sun", sun_d); scene.collection.objects.link(sun)
# shines in through the window onto the glass of water on the table (its caustic)
sun.rotation_euler = (Vector((0.0, 0.5, 0.82)) - Vector((0.6, 2.0, 1.6))).to_track_quat("-Z", "Y").to_euler()
pl = bpy.data.lights.new("WindowPortal", "AREA"); pl.shape = "RECTANGLE"; pl.size, pl.size_y = 1.2, 0.9
pl.cycles.is_portal = True
plo = bpy.data.objects.new("WindowPortal", pl); scene.collection.objects.link(plo)
plo.location = (0.6, 2.0, 1.6); plo.rotation_euler = (-math.pi / 2, 0, 0)
world = bpy.data.worlds.new("Daylight"); scene.world = world
world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.45, 0.6, 0.85, 1)
world.node_tree.nodes["Background"].inputs["Strength"].default_value = 1.5

# --- table: Bevel on the top, legs through a Mirror modifier (X and Y)
top = box("TableTop", (1.4, 0.8, 0.05), (0.2, 0.6, 0.75), wood_m)
bev = top.modifiers.new("Bevel", "BEVEL"); bev.width = 0.012; bev.segments = 3
smart_uv(top)
leg = box("TableLeg", (0.06, 0.06, 0.72), (0.2 + 0.62, 0.6 + 0.32, 0.36), wood_m)
# legs mirrored about the table's centre: put the leg's origin at the table centre
leg.data.transform(Matrix.Translation((0.62, 0.32, 0))); leg.location = (0.2, 0.6, 0.36)
mir = leg.modifiers.new("Mirror", "MIRROR"); mir.use_axis = (True, True, False)
smart_uv(leg)
# runner cloth: a thin plane thickened by Solidify
bpy.ops.mesh.primitive_plane_add(size=1, location=(0.2, 0.6, 0.777)); runner = bpy.context.object; runner.name = "Runner"
runner.scale = (1.2, 0.3, 1); bpy.ops.object.transform_apply(scale=True)
runner.modifiers.new("Solidify", "SOLIDIFY").thickness = 0.004
runner.data.materials.append(linen_m); smart_uv(runner)

# --- glass of water (caustic on the table): Screw profile + Solidify, water body inside
water_glass = lathe("Glass", [(0.0, 0.0), (0.032, 0.0), (0.034, 0.004), (0.036, 0.11)], (0.0, 0.5, 0.78))
gs = water_glass.modifiers.new("Solidify", "SOLIDIFY"); gs.thickness = 0.0025; gs.offset = -1
water_glass.data.materials.append(glass("GlassMat", ior=1.5))
water = lathe("Water", [(0.0, 0.006), (0.031, 0.006), (0.0325, 0.075), (0.0, 0.075)], (0.0, 0.5, 0.78))
water_m, _ = principled("WaterMat", Base_Color=(0.95, 0.98, 1.0), Roughness=0.0, Transmission_Weight=1.0, IOR=1.333)
water.data.materials.append(water_m)

# --- fruit bowl: fruit scattered by Geometry Nodes onto a disc inside the bowl
fruit_coll = bpy.data.collections.new("Fruit"); scene.collection.children.link(fruit_coll)
bowl = lathe("Bowl", [(0.0, 0.0), (0.06, 0.0), (0.13, 0.05), (0.15, 0.09)], (0.55, 0.7, 0.78))
bowl.modifiers.new("Solidify", "SOLIDIFY").thickness = 0.006
bowl.data.materials.append(principled("Ceramic", Base_Color=(0.2, 0.35, 0.6), Roughness=0.25)[0])
bpy.ops.mesh.primitive_uv_sphere_add(radius=0.035, segments=16, ring_count=8, location=(0, 0, -10))
fruit = bpy.context.object; fruit.name = "Orange"; fruit.hide_render = True
fruit.data.materials.append(principled("Orange", Base_Color=(0.9, 0.35, 0.03), Roughness=0.4)[0])
bpy.ops.object.shade_smooth()
bpy.ops.mesh.primitive_circle_add(vertices=24, radius=0.08, fill_type="NGON", location=(0.55, 0.7, 0.83))
bed = bpy.context.object; bed.name = "FruitBed"
for c in bed.users_collection:
    c.objects.unlink(bed)
fruit_coll.objects.link(bed)
tree, dist = scatter_tree("FruitScatter", fruit)
dist.distribute_method = "POISSON"
dist.inputs["Density Max"].default_value = 400.0; dist.inputs["Distance Min"].default_value = 0.06
bed.modifiers.new("Scatter", "NODES").node_group = tree

# --- shelf with jars (Array modifier) on the left wall; a Subdivision Surface pot on the counter
box("Shelf", (0.25, 1.2, 0.03), (-1.87, 0.5, 1.55), wood_m)
bpy.ops.mesh.primitive_cylinder_add(radius=0.05, depth=0.16, vertices=24, location=(-1.87, 0.05, 1.65))
jar = bpy.context.object; jar.name = "Jars"
arr = jar.modifiers.new("Array", "ARRAY"); arr.count = 6; arr.relative_offset_displace = (0, 0, 0)
arr.use_relative_offset = False; arr.use_constant_offset = True; arr.constant_offset_displace = (0, 0.18, 0)
jar.data.materials.append(principled("JarGlaze", Base_Color=(0.7, 0.75, 0.3), Roughness=0.2)[0])
counter = box("Counter", (0.6, 1.6, 0.9), (-1.7, -0.6, 0.45), plaster_m)
bpy.ops.mesh.primitive_cube_add(size=0.25, location=(-1.7, -0.4, 1.03)); pot = bpy.context.object; pot.name = "Pot"
pot.modifiers.new("Subdivision", "SUBSURF").render_levels = 3
pot.data.materials.append(principled("Copper", Base_Color=(0.95, 0.6, 0.45), Metallic=1.0, Roughness=0.3)[0])
select_only(pot); bpy.ops.object.shade_smooth()

# --- napkin with a shape key that lifts its corner across the frames (deformation blur)
bpy.ops.mesh.primitive_grid_add(x_subdivisions=12, y_subdivisions=12, size=0.3, location=(-0.25, 0.75, 0.781))
napkin = bpy.context.object; napkin.name = "Napkin"
napkin.shape_key_add(name="Basis"); kb = napkin.shape_key_add(name="Lift")
for v, src in zip(kb.data, napkin.data.vertices):
    d = max(0.0, src.co.x + src.co.y)
    v.co = (src.co.x, src.co.y, 0.4 * d * d)
kb.value = 0.0; kb.keyframe_insert("value", frame=1)
kb.value = 1.0; kb.keyframe_insert("value", frame=4)
napkin.data.materials.append(linen_m); smart_uv(napkin)

# --- a kettle with its spout bent by a keyframed armature on the counter
bpy.ops.mesh.primitive_cylinder_add(radius=0.03, depth=0.3, vertices=12, location=(-1.6, -1.0, 1.05))
spout = bpy.context.object; spout.name = "Whisk"
subdivide(spout, 8)
spout.data.materials.append(principled("Steel", Base_Color=(0.8, 0.8, 0.8), Metallic=1.0, Roughness=0.25)[0])
bend_rig(spout, "WhiskRig", (-1.6, -1.0, 0.9), 0.3, ((1, -40.0), (2, 0.0), (3, 40.0), (4, 0.0)))

# --- pendant lamp with an emissive shade; an area light over the counter; a spot on the table
shade_m = emission("ShadeGlow", (1.0, 0.75, 0.45), 12.0)
bpy.ops.mesh.primitive_cone_add(vertices=32, radius1=0.18, radius2=0.06, depth=0.18, end_fill_type="NOTHING",
                                location=(0.2, 0.6, 1.9))
shade = bpy.context.object; shade.name = "PendantShade"; shade.data.materials.append(shade_m)
box("PendantCord", (0.008, 0.008, 0.65), (0.2, 0.6, 2.3), plaster_m)
ad = bpy.data.lights.new("CounterArea", "AREA"); ad.shape = "RECTANGLE"; ad.size, ad.size_y = 0.5, 1.2
ad.energy = 60.0; ad.color = (1.0, 0.95, 0.9)
ao = bpy.data.objects.new("CounterArea", ad); scene.collection.objects.link(ao); ao.location = (-1.7, -0.6, 2.4)
sd = bpy.data.lights.new("TableSpot", "SPOT"); sd.energy = 120.0; sd.spot_size = math.radians(40)
sd.spot_blend = 0.6; sd.shadow_soft_size = 0.08
so = bpy.data.objects.new("TableSpot", sd); scene.collection.objects.link(so)
so.location = (1.4, -0.6, 2.3)
dvec = Vector((0.2, 0.6, 0.78)) - so.location
so.rotation_euler = dvec.to_track_quat("-Z", "Y").to_euler()

# --- camera: depth of field on the glass (via an Empty), slight dolly, motion blur
focus = bpy.data.objects.new("FocusTarget", None); scene.collection.objects.link(focus); focus.location = (0.0, 0.5, 0.84)
cd = bpy.data.cameras.new("Camera"); cam = bpy.data.objects.new("Camera", cd); scene.collection.objects.link(cam)
scene.camera = cam; cd.lens = 32
cam.location = (1.45, -1.75, 1.45); cam.keyframe_insert("location", frame=1)
cam.location = (1.5, -1.7, 1.45); cam.keyframe_insert("location", frame=4)
tv = Vector((-0.2, 0.7, 0.9)) - Vector((1.45, -1.75, 1.45))
cam.rotation_euler = tv.to_track_quat("-Z", "Y").to_euler()
cd.dof.use_dof = True; cd.dof.focus_object = focus; cd.dof.aperture_fstop = 2.0
scene.render.use_motion_blur = True; scene.render.motion_blur_shutter = 0.5

# --- output: 50 % of 640 x 360, Film Transparent, a render region; two view layers; compositor
r = scene.render
r.resolution_x, r.resolution_y, r.resolution_percentage = 640, 360, 50
r.film_transparent = True
r.use_border = True; r.use_crop_to_border = False
r.border_min_x, r.border_max_x, r.border_min_y, r.border_max_y = 0.1, 0.9, 0.1, 0.95
vl_main = scene.view_layers[0]; vl_main.name = "Main"
vl2 = scene.view_layers.new("NoFruit")
vl2.layer_collection.children["Fruit"].exclude = True
ct = bpy.data.node_groups.new("Compositing", "CompositorNodeTree"); scene.compositing_node_group = ct
ct.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
rl = ct.nodes.new("CompositorNodeRLayers"); rl.layer = "Main"
glare = ct.nodes.new("CompositorNodeGlare")
out = ct.nodes.new("NodeGroupOutput")
ct.links.new(rl.outputs["Image"], glare.inputs["Image"]); ct.links.new(glare.outputs["Image"], out.inputs[0])
r.use_compositing = True
scene.frame_set(2)
r.engine = "STPM"
r.filepath = str(OUT / "kitchen5_frame_")
bpy.ops.wm.save_as_mainfile(filepath=str(OUT / "kitchen5.blend"))
print("saved", OUT / "kitchen5.blend")
