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
import sys
from pathlib import Path

import numpy as np
import bpy
import OpenImageIO as oiio

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
OUT = HERE / "out"; OUT.mkdir(exist_ok=True)
sys.path.insert(0, str(ROOT))
import addon  # noqa: E402

bpy.ops.wm.read_factory_settings(use_empty=True)
addon.register()
scene = bpy.context.scene
bpy.context.preferences.edit.keyframe_new_interpolation_type = "LINEAR"


def write_png(path, arr):
    h, w, c = arr.shape
    buf = oiio.ImageBuf(oiio.ImageSpec(w, h, c, "uint8"))
    buf.set_pixels(oiio.ROI(), (np.clip(arr, 0, 1) * 255 + 0.5).astype(np.uint8))
    assert buf.write(str(path)), oiio.geterror()


# --- textures an artist would paint or download
yy, xx = np.mgrid[0:128, 0:128].astype(np.float32)
weave = 0.5 + 0.5 * np.sign(np.sin(xx * math.pi / 4) * np.sin(yy * math.pi / 4))
fabric = np.stack([0.18 + 0.10 * weave, 0.28 + 0.12 * weave, 0.45 + 0.15 * weave], -1)
write_png(OUT / "fabric.png", fabric)
nrm = np.stack([0.5 + 0.25 * np.cos(xx * math.pi / 4), 0.5 + 0.25 * np.cos(yy * math.pi / 4), np.ones_like(xx)], -1)
write_png(OUT / "fabric_normal.png", nrm)
# lace: cream colour, round holes (alpha 0) on a 16-px grid
d = np.hypot((xx % 16) - 8, (yy % 16) - 8)
lace = np.stack([np.full_like(xx, 0.9), np.full_like(xx, 0.85), np.full_like(xx, 0.7), (d > 5).astype(np.float32)], -1)
write_png(OUT / "lace.png", lace)


def obj_active(obj):
    bpy.context.view_layer.objects.active = obj
    for o in bpy.context.view_layer.objects:
        o.select_set(o is obj)


def smart_uv(obj):
    obj_active(obj)
    bpy.ops.object.mode_set(mode="EDIT"); bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.uv.smart_project(); bpy.ops.object.mode_set(mode="OBJECT")


def principled(name, **inputs):
    m = bpy.data.materials.new(name); m.use_nodes = True
    b = m.node_tree.nodes["Principled BSDF"]
    for k, v in inputs.items():
        b.inputs[k.replace("_", " ")].default_value = v
    return m, b


def box(name, size, loc, mat=None):
    bpy.ops.mesh.primitive_cube_add(size=1, location=loc); o = bpy.context.object; o.name = name
    o.scale = size; bpy.ops.object.transform_apply(scale=True)
    if mat:
        o.data.materials.append(mat)
    return o


def lathe(name, profile, loc, steps=48):
    """A mesh from an (r, z) profile line turned by a Screw modifier (as artists lathe glasses)."""
    me = bpy.data.meshes.new(name)
    me.from_pydata([(r, 0, z) for r, z in profile], [(i, i + 1) for i in range(len(profile) - 1)], [])
    o = bpy.data.objects.new(name, me); scene.collection.objects.link(o); o.location = loc
    sc = o.modifiers.new("Screw", "SCREW"); sc.steps = sc.render_steps = steps; sc.use_merge_vertices = True
    sc.use_smooth_shade = True
    return o


# --- the room: 6 x 5 x 2.8 m, a window cut into the back wall with a Boolean
wall_m, _ = principled("Wall", Base_Color=(0.75, 0.68, 0.58, 1), Roughness=0.9)
floor_m, fb = principled("Floor", Roughness=0.45)
ft = floor_m.node_tree
tex = ft.nodes.new("ShaderNodeTexImage"); tex.image = bpy.data.images.load(str(ROOT / "blend_scenes/textures/planks.png"))
ft.links.new(tex.outputs["Color"], fb.inputs["Base Color"])
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
shade_m = bpy.data.materials.new("LampShade"); shade_m.use_nodes = True
snt = shade_m.node_tree; snt.nodes.remove(snt.nodes["Principled BSDF"])
em = snt.nodes.new("ShaderNodeEmission"); em.inputs["Color"].default_value = (1.0, 0.72, 0.42, 1); em.inputs["Strength"].default_value = 25.0
snt.links.new(em.outputs[0], snt.nodes["Material Output"].inputs["Surface"])
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
glass = lathe("WineGlass", glass_profile, (0.08, 0.0, 0.015))
so = glass.modifiers.new("Solidify", "SOLIDIFY"); so.thickness = 0.003; so.offset = -1
glass.modifiers.new("Subdivision", "SUBSURF").render_levels = 1
glass.parent = turn
glass_m = bpy.data.materials.new("Glass"); glass_m.use_nodes = True
gnt = glass_m.node_tree; gnt.nodes.remove(gnt.nodes["Principled BSDF"])
gg = gnt.nodes.new("ShaderNodeBsdfGlass"); gg.inputs["IOR"].default_value = 1.5; gg.inputs["Roughness"].default_value = 0.0
gnt.links.new(gg.outputs[0], gnt.nodes["Material Output"].inputs["Surface"])
glass.data.materials.append(glass_m)
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
tim = tnt.nodes.new("ShaderNodeTexImage"); tim.image = bpy.data.images.load(str(ROOT / "blend_scenes/textures/pool_tiles.png"))
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
    obj_active(cu); bpy.ops.object.mode_set(mode="EDIT"); bpy.ops.mesh.subdivide(number_cuts=24); bpy.ops.object.mode_set(mode="OBJECT")
    for v in cu.data.vertices:
        v.co.y += 0.05 * math.sin(v.co.x * 40.0)
    cu.data.materials.append(lace_m)

# --- sofa: Subdivision + Smart UV + fabric texture and normal map
sofa_m, sb = principled("Fabric", Roughness=0.9)
snt2 = sofa_m.node_tree
st_ = snt2.nodes.new("ShaderNodeTexImage"); st_.image = bpy.data.images.load(str(OUT / "fabric.png"))
sn_ = snt2.nodes.new("ShaderNodeTexImage"); sn_.image = bpy.data.images.load(str(OUT / "fabric_normal.png"))
sn_.image.colorspace_settings.name = "Non-Color"
nm = snt2.nodes.new("ShaderNodeNormalMap")
snt2.links.new(st_.outputs["Color"], sb.inputs["Base Color"])
snt2.links.new(sn_.outputs["Color"], nm.inputs["Color"]); snt2.links.new(nm.outputs["Normal"], sb.inputs["Normal"])
for name, size, loc in (("SofaSeat", (2.2, 0.9, 0.45), (0.0, -1.2, 0.25)), ("SofaBack", (2.2, 0.25, 0.6), (0.0, -1.55, 0.75)),
                        ("SofaArmL", (0.25, 0.9, 0.35), (-1.2, -1.2, 0.6)), ("SofaArmR", (0.25, 0.9, 0.35), (1.2, -1.2, 0.6))):
    o = box(name, size, loc, sofa_m)
    o.modifiers.new("Subdivision", "SUBSURF").levels = 2
    smart_uv(o)
    obj_active(o); bpy.ops.object.shade_smooth()

# --- brushed-metal floor lamp (anisotropic)
brushed_m, bb = principled("BrushedMetal", Base_Color=(0.85, 0.82, 0.78, 1), Metallic=1.0, Roughness=0.35)
bb.inputs["Anisotropic"].default_value = 0.8
bpy.ops.mesh.primitive_cylinder_add(radius=0.2, depth=0.03, location=(1.8, 1.2, 0.015)); base = bpy.context.object; base.name = "LampBase"
bpy.ops.mesh.primitive_cylinder_add(radius=0.03, depth=1.5, location=(1.8, 1.2, 0.78)); pole = bpy.context.object; pole.name = "LampPole"
bpy.ops.mesh.primitive_uv_sphere_add(radius=0.18, location=(1.8, 1.2, 1.6)); head = bpy.context.object; head.name = "LampHead"
for o in (base, pole, head):
    o.data.materials.append(brushed_m); obj_active(o); bpy.ops.object.shade_smooth()

# --- camera on a dolly: moves sideways, depth of field on the glass
cam = bpy.data.cameras.new("Camera"); cobj = bpy.data.objects.new("Camera", cam); scene.collection.objects.link(cobj)
cam.lens = 42
cobj.rotation_euler = (math.radians(68), 0, 0)
cobj.location = (-0.5, -2.35, 1.6); cobj.keyframe_insert("location", frame=1)
cobj.location = (0.5, -2.35, 1.6); cobj.keyframe_insert("location", frame=48)
cam.dof.use_dof = True; cam.dof.focus_object = glass; cam.dof.aperture_fstop = 2.8
scene.camera = cobj

scene.render.use_motion_blur = True; scene.render.motion_blur_shutter = 0.5
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 320, 180, 100
scene.frame_set(12)
scene.render.engine = "STPM"
bpy.ops.wm.save_as_mainfile(filepath=str(OUT / "interior.blend"))
print("saved", OUT / "interior.blend")
