"""Scene 4 (artist review 3): an evening living room built the way an artist would (bpy 5.0.1).

A window cut with a Boolean, an area light marked Portal in it, a Multiple Scattering Sky
Texture with a low sun behind it; a ceiling lamp whose cone shade emits (a mesh light, no lamp
object); a wine glass made with a Screw modifier + Solidify (inner wall normals facing the
cavity) holding wine (a second Screw, its normals as the Screw makes them) on a turntable
keyframed to spin; a TV whose screen is an Emission shader fed by an image; curtains with an
alpha-masked lace PNG; a sofa with Subdivision + Smart UV Project, a weave texture and a normal
map; a brushed-metal floor lamp (Principled Anisotropic 0.8); a camera on a dolly with depth of
field focused on the glass, motion blur on. Writes review/out/interior.blend (frame 12).

Run: PYTHONPATH=. .venv/bin/python review/make_interior.py
"""
import math

import numpy as np
import bpy

from _review_common import (OUT, TEX, box, emission, glass, image_material, lathe, principled, select_only,
                     smart_uv, start_scene, subdivide, write_image)

scene = start_scene()

# --- textures an artist would paint or download
yy, xx = np.mgrid[0:128, 0:128].astype(np.float32)
weave = 0.5 + 0.5 * np.sign(np.sin(xx * math.pi / 4) * np.sin(yy * math.pi / 4))
fabric = np.stack([0.18 + 0.10 * weave, 0.28 + 0.12 * weave, 0.45 + 0.15 * weave], -1)
write_image(OUT / "fabric.png", fabric)
nrm = np.stack([0.5 + 0.25 * np.cos(xx * math.pi / 4), 0.5 + 0.25 * np.cos(yy * math.pi / 4), np.ones_like(xx)], -1)
write_image(OUT / "fabric_normal.png", nrm)
# lace: cream colour, round holes (alpha 0) on a 16-px grid
d = np.hypot((xx % 16) - 8, (yy % 16) - 8)
lace = np.stack([np.full_like(xx, 0.9), np.full_like(xx, 0.85), np.full_like(xx, 0.7), (d > 5).astype(np.float32)], -1)
write_image(OUT / "lace.png", lace)


# --- the room: 6 x 5 x 2.8 m, a window cut into the back wall with a Boolean
wall_m, _ = principled("Wall", Base_Color=(0.75, 0.68, 0.58, 1), Roughness=0.9)
floor_m = image_material("Floor", TEX / "planks.png", roughness=0.45)
floor = box("Floor", (6, 5, 0.1), (0, 0, -0.05), floor_m); smart_uv(floor)
box("Ceiling", (6, 5, 0.1), (0, 0, 2.85), wall_m)
box("WallL", (0.1, 5, 2.8), (-3.05, 0, 1.4), wall_m)
box("WallR", (0.1, 5, 2.8), (3.05, 0, 1.4), wall_m)
box("WallFront", (6, 0.1, 2.8), (0, -2.55, 1.4), wall_m)
back = box("WallBack", (6, 0.1, 2.8), (0, 2.55, 1.4), wall_m)
cutter = box("WindowCutter", (2.0, 0.5, 1.4), (0, 2.55, 1.5)); cutter.hide_render = True; cutter.display_type = "WIRE"
bo = back.modifiers.new("Window", "BOOLEAN"); bo.object = cutter; bo.operation = "DIFFERENCE"

# portal in the window opening, emitting side into the room (-y)
pl = bpy.data.lights.new("WindowPortal", "AREA"); pl.shape = "RECTANGLE"; pl.size, pl.size_y = 2.0, 1.4
pl.cycles.is_portal = True
plo = bpy.data.objects.new("WindowPortal", pl); scene.collection.objects.link(plo)
plo.location = (0, 2.5, 1.5); plo.rotation_euler = (-math.pi / 2, 0, 0)

# evening sky: Multiple Scattering, sun 4 degrees up, roughly behind the window
world = bpy.data.worlds.new("Evening"); scene.world = world; world.use_nodes = True
wnt = world.node_tree
sky = wnt.nodes.new("ShaderNodeTexSky"); sky.sky_type = "MULTIPLE_SCATTERING"
sky.sun_elevation = math.radians(4.0); sky.sun_rotation = math.radians(200.0)
wnt.links.new(sky.outputs["Color"], wnt.nodes["Background"].inputs["Color"])
wnt.nodes["Background"].inputs["Strength"].default_value = 0.3

# --- ceiling lamp: an open cone shade that emits (a mesh light); warm
shade_m = emission("LampShade", (1.0, 0.72, 0.42), 25.0)
bpy.ops.mesh.primitive_cone_add(vertices=32, radius1=0.35, radius2=0.12, depth=0.3, end_fill_type="NOTHING", location=(0.3, 0.2, 2.2))
shade = bpy.context.object; shade.name = "LampShade"; shade.data.materials.append(shade_m)
box("LampCord", (0.01, 0.01, 0.45), (0.3, 0.2, 2.57), wall_m)

# --- coffee table and turntable with a wine glass
wood_m, _ = principled("DarkWood", Base_Color=(0.12, 0.06, 0.03, 1), Roughness=0.3)
box("CoffeeTable", (1.2, 0.7, 0.05), (0.0, 0.3, 0.42), wood_m)
for sx in (-1, 1):
    for sy in (-1, 1):
        box("TableLeg", (0.05, 0.05, 0.4), (0.55 * sx, 0.3 + 0.3 * sy, 0.2), wood_m)
bpy.ops.mesh.primitive_cylinder_add(radius=0.22, depth=0.03, location=(0.1, 0.3, 0.46))
turn = bpy.context.object; turn.name = "Turntable"
metal_m, _ = principled("Turntable", Base_Color=(0.8, 0.8, 0.8, 1), Metallic=1.0, Roughness=0.2)
turn.data.materials.append(metal_m)
scene.frame_start, scene.frame_end = 1, 48
turn.rotation_euler.z = 0.0; turn.keyframe_insert("rotation_euler", index=2, frame=1)
turn.rotation_euler.z = 2 * math.pi; turn.keyframe_insert("rotation_euler", index=2, frame=49)

glass_profile = [(0.0, 0.0), (0.035, 0.0), (0.036, 0.004), (0.006, 0.01), (0.004, 0.08), (0.02, 0.095),
                 (0.038, 0.12), (0.042, 0.16), (0.036, 0.2)]
wine_glass = lathe("WineGlass", glass_profile, (0.08, 0.0, 0.015))
so = wine_glass.modifiers.new("Solidify", "SOLIDIFY"); so.thickness = 0.003; so.offset = -1
wine_glass.modifiers.new("Subdivision", "SUBSURF").render_levels = 1
wine_glass.parent = turn
wine_glass.data.materials.append(glass("Glass", ior=1.5))
wine_profile = [(0.0, 0.099), (0.021, 0.099), (0.036, 0.12), (0.0385, 0.14), (0.0, 0.14)]
wine = lathe("Wine", wine_profile, (0.08, 0.0, 0.015))
wine.parent = turn
wine_m, _ = principled("Wine", Base_Color=(0.5, 0.02, 0.05, 1), Roughness=0.0, Transmission_Weight=1.0, IOR=1.33)
wine.data.materials.append(wine_m)

# --- TV on the left wall: emissive image screen
box("TVBody", (0.06, 1.1, 0.65), (-2.95, -0.2, 1.3), wood_m)
bpy.ops.mesh.primitive_plane_add(size=1, location=(-2.915, -0.2, 1.3), rotation=(0, math.pi / 2, 0))
tv = bpy.context.object; tv.name = "TVScreen"; tv.scale = (0.6, 1.0, 1); bpy.ops.object.transform_apply(scale=True)
tv_m = bpy.data.materials.new("TVScreen"); tv_m.use_nodes = True
tnt = tv_m.node_tree; tnt.nodes.remove(tnt.nodes["Principled BSDF"])
tim = tnt.nodes.new("ShaderNodeTexImage"); tim.image = bpy.data.images.load(str(TEX / "pool_tiles.png"))
tem = tnt.nodes.new("ShaderNodeEmission"); tem.inputs["Strength"].default_value = 4.0
tnt.links.new(tim.outputs["Color"], tem.inputs["Color"]); tnt.links.new(tem.outputs[0], tnt.nodes["Material Output"].inputs["Surface"])
tv.data.materials.append(tv_m)

# --- curtains: wavy planes either side of the window, alpha-masked lace
lace_m, lb = principled("Lace", Roughness=0.8)
lnt = lace_m.node_tree
lim = lnt.nodes.new("ShaderNodeTexImage"); lim.image = bpy.data.images.load(str(OUT / "lace.png"))
lnt.links.new(lim.outputs["Color"], lb.inputs["Base Color"]); lnt.links.new(lim.outputs["Alpha"], lb.inputs["Alpha"])
for sx in (-1, 1):
    bpy.ops.mesh.primitive_plane_add(size=1, location=(sx * 0.75, 2.4, 1.45), rotation=(math.pi / 2, 0, 0))
    cu = bpy.context.object; cu.name = "Curtain"; cu.scale = (0.8, 2.3, 1); bpy.ops.object.transform_apply(scale=True)
    subdivide(cu, 24)
    for v in cu.data.vertices:
        v.co.y += 0.05 * math.sin(v.co.x * 40.0)
    cu.data.materials.append(lace_m)

# --- sofa: Subdivision + Smart UV + fabric texture and normal map
sofa_m = image_material("Fabric", OUT / "fabric.png", OUT / "fabric_normal.png", roughness=0.9)
for name, size, loc in (("SofaSeat", (2.2, 0.9, 0.45), (0.0, -1.2, 0.25)), ("SofaBack", (2.2, 0.25, 0.6), (0.0, -1.55, 0.75)),
                        ("SofaArmL", (0.25, 0.9, 0.35), (-1.2, -1.2, 0.6)), ("SofaArmR", (0.25, 0.9, 0.35), (1.2, -1.2, 0.6))):
    o = box(name, size, loc, sofa_m)
    o.modifiers.new("Subdivision", "SUBSURF").levels = 2
    smart_uv(o)
    select_only(o); bpy.ops.object.shade_smooth()

# --- brushed-metal floor lamp (anisotropic)
brushed_m, bb = principled("BrushedMetal", Base_Color=(0.85, 0.82, 0.78, 1), Metallic=1.0, Roughness=0.35)
bb.inputs["Anisotropic"].default_value = 0.8
bpy.ops.mesh.primitive_cylinder_add(radius=0.2, depth=0.03, location=(1.8, 1.2, 0.015)); base = bpy.context.object; base.name = "LampBase"
bpy.ops.mesh.primitive_cylinder_add(radius=0.03, depth=1.5, location=(1.8, 1.2, 0.78)); pole = bpy.context.object; pole.name = "LampPole"
bpy.ops.mesh.primitive_uv_sphere_add(radius=0.18, location=(1.8, 1.2, 1.6)); head = bpy.context.object; head.name = "LampHead"
for o in (base, pole, head):
    o.data.materials.append(brushed_m); select_only(o); bpy.ops.object.shade_smooth()

# --- camera on a dolly: moves sideways, depth of field on the glass
cam = bpy.data.cameras.new("Camera"); cobj = bpy.data.objects.new("Camera", cam); scene.collection.objects.link(cobj)
cam.lens = 42
cobj.rotation_euler = (math.radians(68), 0, 0)
cobj.location = (-0.5, -2.35, 1.6); cobj.keyframe_insert("location", frame=1)
cobj.location = (0.5, -2.35, 1.6); cobj.keyframe_insert("location", frame=48)
cam.dof.use_dof = True; cam.dof.focus_object = wine_glass; cam.dof.aperture_fstop = 2.8
scene.camera = cobj

scene.render.use_motion_blur = True; scene.render.motion_blur_shutter = 0.5
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 320, 180, 100
scene.frame_set(12)
scene.render.engine = "STPM"
bpy.ops.wm.save_as_mainfile(filepath=str(OUT / "interior.blend"))
print("saved", OUT / "interior.blend")
