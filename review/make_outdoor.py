"""Scene 5 (artist review 4): an outdoor golden-hour shot built the way an artist would (bpy 5.0.1).

A Sky Texture world (Blender 5's default type, sun disc off) with a Sun lamp matched to its sun
direction; a car-paint blob (Principled: metallic flakes from a Noise texture into roughness and a
bump, a clear coat) on a turntable keyframed to spin; a puddle (Principled water, a Wave texture
into a Bump) and a glass bottle (Screw + Solidify) on the ground making a caustic; a flag pole bent
by a keyframed armature (deformation blur); rocks scattered by Geometry Nodes (Distribute Points on
Faces -> Instance on Points) of a UV-mapped, image-textured ico-sphere; a ground of Subdivision +
Displace (an image texture from blend_scenes/textures) with an image material; a camera with depth
of field, motion blur on; a Holdout object, a Shadow Catcher object, a fog cube with a Principled
Volume material, a point light linked to the car only (Blender 4 light linking).

python review/make_outdoor.py [--bad]   (PYTHONPATH = checkout)
--bad adds what artists get wrong: a missing image file, a packed image, a mesh with NaN and huge
coordinates and zero-area faces, a 0-sized object, a negative-scale object, a Shader to RGB setup.
Writes review/out/outdoor.blend (or outdoor_bad.blend), frame 10 of 1-24.
"""
import math
import sys

import bpy

from _review_common import (OUT, TEX, bend_rig, car_body, car_paint, glass, image_material, principled, scatter_tree,
                     select_only, start_scene, subdivide)

BAD = "--bad" in sys.argv
scene = start_scene(frame_range=(1, 24))


# --- world: Blender 5's default Sky Texture, sun disc off, a Sun lamp in its direction
world = bpy.data.worlds.new("Sky"); scene.world = world
wt = world.node_tree
sky = wt.nodes.new("ShaderNodeTexSky")
print("sky type (default):", sky.sky_type)
sky.sun_elevation = math.radians(8.0); sky.sun_rotation = math.radians(215.0)
sky.sun_disc = False
wt.links.new(sky.outputs["Color"], wt.nodes["Background"].inputs["Color"])
wt.nodes["Background"].inputs["Strength"].default_value = 0.3

sun_d = bpy.data.lights.new("Sun", "SUN"); sun_d.energy = 3.0; sun_d.color = (1.0, 0.72, 0.45)
sun_d.angle = math.radians(0.545)
sun = bpy.data.objects.new("Sun", sun_d); scene.collection.objects.link(sun)
# Blender's sky: sun at azimuth sun_rotation (from +Y? the sky's convention: direction
# (sin(rot) cos(el), cos(rot) cos(el), sin(el))); the lamp points along -that
el, rot = sky.sun_elevation, sky.sun_rotation
sun.rotation_euler = (math.pi / 2 - el, 0.0, rot)

# --- ground: Subdivision + Displace by an image, image material
bpy.ops.mesh.primitive_grid_add(x_subdivisions=24, y_subdivisions=24, size=14)
ground = bpy.context.object; ground.name = "Ground"
ground.modifiers.new("Subdiv", "SUBSURF").levels = 2
ground.modifiers["Subdiv"].render_levels = 2
dtex = bpy.data.textures.new("GroundDisp", "IMAGE")
dtex.image = bpy.data.images.load(str(TEX / "pool_tiles.png"), check_existing=True)
disp = ground.modifiers.new("Displace", "DISPLACE"); disp.texture = dtex; disp.strength = 0.06
disp.texture_coords = "UV"
ground.data.materials.append(image_material("GroundMat", TEX / "planks.png", scale=4.0, roughness=0.8))

# --- the car-paint blob on a turntable
bpy.ops.mesh.primitive_cylinder_add(radius=1.1, depth=0.08, location=(0.6, 0.4, 0.04))
turn = bpy.context.object; turn.name = "Turntable"
turn.data.materials.append(principled("TableMetal", Base_Color=(0.2, 0.2, 0.22), Metallic=1.0, Roughness=0.35)[0])
turn.rotation_euler.z = 0.0; turn.keyframe_insert("rotation_euler", index=2, frame=1)
turn.rotation_euler.z = math.pi; turn.keyframe_insert("rotation_euler", index=2, frame=25)
car = car_body((0.6, 0.4, 0.45), car_paint())
car.parent = turn; car.matrix_parent_inverse = turn.matrix_world.inverted()

# --- puddle (water with a Wave bump) and a glass bottle on the ground
bpy.ops.mesh.primitive_circle_add(vertices=48, radius=1.0, fill_type="NGON", location=(-1.3, -0.6, 0.09))
puddle = bpy.context.object; puddle.name = "Puddle"; puddle.scale = (1.3, 0.9, 1)
water, wb = principled("Water", Base_Color=(0.8, 0.9, 1.0), Roughness=0.02, Transmission_Weight=1.0, IOR=1.333)
nt = water.node_tree
wave = nt.nodes.new("ShaderNodeTexWave"); wave.inputs["Scale"].default_value = 6.0
wave.inputs["Distortion"].default_value = 4.0
wbump = nt.nodes.new("ShaderNodeBump"); wbump.inputs["Strength"].default_value = 0.1
nt.links.new(wave.outputs["Fac"], wbump.inputs["Height"]); nt.links.new(wbump.outputs["Normal"], wb.inputs["Normal"])
puddle.data.materials.append(water)

prof = bpy.data.curves.new("BottleProfile", "CURVE"); prof.dimensions = "3D"
sp = prof.splines.new("POLY")
pts = [(0.001, 0, 0), (0.16, 0, 0.0), (0.17, 0, 0.05), (0.17, 0, 0.42), (0.12, 0, 0.55),
       (0.055, 0, 0.62), (0.05, 0, 0.8), (0.055, 0, 0.82)]
sp.points.add(len(pts) - 1)
for p, c in zip(sp.points, pts):
    p.co = (*c, 1.0)
pobj = bpy.data.objects.new("Bottle", prof); scene.collection.objects.link(pobj)
pobj.location = (-0.2, -1.3, 0.06)
scr = pobj.modifiers.new("Screw", "SCREW"); scr.steps = 48; scr.render_steps = 48; scr.use_smooth_shade = True
sol = pobj.modifiers.new("Solidify", "SOLIDIFY"); sol.thickness = 0.01
select_only(pobj); bpy.ops.object.convert(target="MESH"); bottle = bpy.context.object
bottle.data.materials.append(glass("BottleGlass", ior=1.5, color=(0.75, 0.95, 0.8, 1)))

# --- a flag pole bent by a keyframed armature (deformation motion blur)
bpy.ops.mesh.primitive_cylinder_add(radius=0.06, depth=2.0, vertices=16, location=(2.6, -0.6, 1.0))
pole = bpy.context.object; pole.name = "Pole"
subdivide(pole, 12)
pole.data.materials.append(principled("PoleYellow", Base_Color=(0.8, 0.6, 0.05), Roughness=0.4)[0])
bend_rig(pole, "PoleRig", (2.6, -0.6, 0.0), 2.0, ((1, -35.0), (10, 35.0), (19, -35.0), (25, 0.0)))

# --- rocks: Geometry Nodes Distribute Points on Faces -> Instance on Points of a UV-textured ico-sphere
bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=2, radius=0.12, location=(0, 0, -20))
rock = bpy.context.object; rock.name = "Rock"
rock.data.materials.append(image_material("RockMat", TEX / "tiles16.png", roughness=0.8))
rock.hide_render = True  # the source is hidden; its instances render
bpy.ops.mesh.primitive_plane_add(size=5, location=(0.3, 2.2, 0.07))
patch = bpy.context.object; patch.name = "RockPatch"
tree, dist = scatter_tree("Scatter", rock, random_scale=((0.5, 0.5, 0.4), (1.4, 1.2, 0.9)))
dist.inputs["Density"].default_value = 6.0
patch.modifiers.new("Scatter", "NODES").node_group = tree

# --- holdout, shadow catcher, fog volume, a light linked to the car only
bpy.ops.mesh.primitive_cube_add(size=0.4, location=(-2.6, 1.6, 0.3)); ho = bpy.context.object; ho.name = "HoldoutBox"
hm = bpy.data.materials.new("HoldoutMat"); hnt = hm.node_tree; hnt.nodes.remove(hnt.nodes["Principled BSDF"])
hnt.links.new(hnt.nodes.new("ShaderNodeHoldout").outputs[0], hnt.nodes["Material Output"].inputs["Surface"])
ho.data.materials.append(hm)
bpy.ops.mesh.primitive_plane_add(size=1.2, location=(2.0, 1.8, 0.12)); sc = bpy.context.object; sc.name = "CatcherCard"
sc.is_shadow_catcher = True
bpy.ops.mesh.primitive_cube_add(size=1.0, location=(-2.4, 2.6, 0.6)); fog = bpy.context.object; fog.name = "FogCube"
fm = bpy.data.materials.new("Fog"); fnt = fm.node_tree; fnt.nodes.remove(fnt.nodes["Principled BSDF"])
pv = fnt.nodes.new("ShaderNodeVolumePrincipled"); pv.inputs["Density"].default_value = 0.6
fnt.links.new(pv.outputs[0], fnt.nodes["Material Output"].inputs["Volume"])
fog.data.materials.append(fm)
kd = bpy.data.lights.new("CarKey", "POINT"); kd.energy = 150.0; kd.shadow_soft_size = 0.2
key = bpy.data.objects.new("CarKey", kd); scene.collection.objects.link(key); key.location = (1.8, -1.2, 2.0)
carset = bpy.data.collections.new("CarOnly"); carset.objects.link(car)
key.light_linking.receiver_collection = carset

if BAD:
    # a missing image file
    mm, mb = principled("MissingTex")
    t = mm.node_tree.nodes.new("ShaderNodeTexImage")
    im = bpy.data.images.new("rust.png", 4, 4); im.source = "FILE"; im.filepath = str(OUT / "no_such_rust.png"); t.image = im
    mm.node_tree.links.new(t.outputs[0], mb.inputs["Base Color"])
    bpy.ops.mesh.primitive_cube_add(size=0.3, location=(-0.9, 1.0, 0.25)); bpy.context.object.name = "RustyBox"
    bpy.context.object.data.materials.append(mm)
    # a packed image
    pk = bpy.data.images.load(str(TEX / "tiles16.png")); pk.pack()
    pm, pbp = principled("PackedTex"); t = pm.node_tree.nodes.new("ShaderNodeTexImage"); t.image = pk
    pm.node_tree.links.new(t.outputs[0], pbp.inputs["Base Color"])
    bpy.ops.mesh.primitive_cube_add(size=0.3, location=(-0.4, 1.2, 0.25)); bpy.context.object.name = "PackedBox"
    bpy.context.object.data.materials.append(pm)
    # a mesh with NaN, huge coordinates and zero-area faces
    me = bpy.data.meshes.new("Broken")
    v = [(0, 0, 0.3), (0.3, 0, 0.3), (0, 0.3, 0.3), (float("nan"), 0, 0.3), (1e30, 0, 0.3), (0, 1e30, 0.3),
         (0.6, 0, 0.3), (0.9, 0, 0.3), (1.2, 0, 0.3)]
    me.from_pydata(v, [], [(0, 1, 2), (0, 1, 3), (0, 4, 5), (6, 7, 8)]); me.update()
    bo = bpy.data.objects.new("Broken", me); scene.collection.objects.link(bo); bo.location = (1.0, -2.0, 0)
    # a 0-sized object and a negative-scale one
    bpy.ops.mesh.primitive_cube_add(size=0.3, location=(1.6, -1.6, 0.3)); bpy.context.object.name = "ZeroSized"
    bpy.context.object.scale = (0, 0, 0)
    bpy.ops.mesh.primitive_monkey_add(size=0.4, location=(-1.6, 0.6, 0.35)); neg = bpy.context.object; neg.name = "Mirrored"
    neg.scale = (-1, 1, 1); neg.data.materials.append(principled("Suzanne", Base_Color=(0.2, 0.5, 0.8))[0])
    # an unsupported node setup: Shader to RGB (an EEVEE-only node) feeding an Emission
    um = bpy.data.materials.new("ToonTrick"); unt = um.node_tree
    d = unt.nodes.new("ShaderNodeBsdfDiffuse"); s2r = unt.nodes.new("ShaderNodeShaderToRGB")
    em = unt.nodes.new("ShaderNodeEmission")
    unt.links.new(d.outputs[0], s2r.inputs[0]); unt.links.new(s2r.outputs["Color"], em.inputs["Color"])
    unt.links.new(em.outputs[0], unt.nodes["Material Output"].inputs["Surface"])
    bpy.ops.mesh.primitive_cylinder_add(radius=0.15, depth=0.4, location=(-2.0, -0.2, 0.25)); bpy.context.object.name = "Toon"
    bpy.context.object.data.materials.append(um)

# --- camera: depth of field on the car, moving slightly, motion blur on
cd = bpy.data.cameras.new("Cam"); cam = bpy.data.objects.new("Cam", cd); scene.collection.objects.link(cam)
scene.camera = cam; cd.lens = 40
cam.location = (0.2, -7.5, 1.6); cam.rotation_euler = (math.radians(82), 0, math.radians(3))
cam.keyframe_insert("location", frame=1)
cam.location = (0.6, -7.3, 1.6); cam.keyframe_insert("location", frame=25)
cd.dof.use_dof = True; cd.dof.focus_object = car; cd.dof.aperture_fstop = 4.0
scene.render.use_motion_blur = True; scene.render.motion_blur_shutter = 0.5
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 240, 135, 100
scene.frame_set(10)
scene.render.engine = "STPM"
name = "outdoor_bad.blend" if BAD else "outdoor.blend"
bpy.ops.wm.save_as_mainfile(filepath=str(OUT / name))
print("saved", OUT / name)
