"""Scene 7 (artist review 6): an animated outdoor product shot built the way an artist would (bpy 5.0.1).

A wrist watch and a glass of whisky on a turntable on a bevelled stone plinth, outdoors on a
displaced lawn: the watch case is brushed steel (Principled, Metallic 1, Roughness 0.3, Anisotropic
0.6), its dial an image-textured label (Smart UV Project; the image written here), its strap a
Mix Shader of a Diffuse and a Glossy BSDF by Layer Weight Facing; the glass (Glass BSDF) holds
whisky (Principled transmission, amber); the plinth (Bevel) is a Mix Shader by Fresnel of a
stone image (with a normal map, Smart UV) and a Glossy; the ground is a plane with Subdivision and a
Displace modifier (Clouds texture). The turntable turns 90 degrees over frames 1-25 (linear) and
the camera dollies in; motion blur on (shutter 0.5). The world is an HDRI (a Radiance .hdr written
here: a blue sky gradient with a sun spot 20 degrees up); AgX with the Punchy look; Film Transparent
off; STPM's denoise on. 240 x 135, frames 1-3.

Writes review/out/watch6.blend and variants:
  watch6_sky.blend    the world a Sky Texture (Multiple Scattering, sun 20 degrees up); Filmic,
                      Medium High Contrast look
  watch6_alpha.blend  Film Transparent on; the compositor lays the render over a warm grey (Alpha Over)
Run: PYTHONPATH=. .venv/bin/python review/make_review6.py
"""
import math
import sys
from pathlib import Path

import numpy as np
import bpy
import mathutils

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
OUT = HERE / "out"; OUT.mkdir(exist_ok=True)
sys.path.insert(0, str(ROOT))
import addon  # noqa: E402
from _review_common import lathe, principled, smart_uv, write_image  # noqa: E402

bpy.ops.wm.read_factory_settings(use_empty=True)
addon.register()
scene = bpy.context.scene
bpy.context.preferences.edit.keyframe_new_interpolation_type = "LINEAR"
scene.frame_start, scene.frame_end = 1, 3


# --- images an artist would make: an HDRI with a sun, a dial label, a stone texture and its normal map
SUN_ELEV, SUN_AZ = math.radians(20.0), math.radians(40.0)
H, W = 128, 256
v, u = (np.mgrid[0:H, 0:W] + 0.5) / np.array([H, W])[:, None, None]
elev = (0.5 - v) * math.pi
sky = np.where(elev[..., None] > 0,
               np.array([0.25, 0.45, 0.9]) * (1 - 0.6 * np.sin(np.clip(elev, 0, None)))[..., None] + 0.15,
               np.array([0.18, 0.16, 0.12]))
# equirectangular as Cycles reads it: u = -atan2(dir.y, dir.x) / (2 pi) + 0.5
az = (0.5 - u) * 2 * math.pi
d = np.stack([np.cos(elev) * np.cos(az), np.cos(elev) * np.sin(az), np.sin(elev)], -1)
sd = np.array([math.cos(SUN_ELEV) * math.cos(SUN_AZ), math.cos(SUN_ELEV) * math.sin(SUN_AZ), math.sin(SUN_ELEV)])
sun = (d @ sd) > math.cos(math.radians(2.0))
sky = np.where(sun[..., None], np.array([4000.0, 3600.0, 3000.0]), sky)
write_image(OUT / "r6_sky.hdr", sky, "float")

yy, xx = np.mgrid[0:256, 0:256].astype(np.float32)
r = np.hypot(xx - 127.5, yy - 127.5)
dial = np.ones((256, 256, 3)) * np.array([0.9, 0.88, 0.8])
ang = np.arctan2(yy - 127.5, xx - 127.5)
ticks = (r > 100) & (r < 118) & (np.abs(((ang / (2 * math.pi) * 12) + 0.5) % 1 - 0.5) < 0.06)
dial[ticks] = (0.05, 0.05, 0.08)
dial[(np.abs(xx - 127.5) < 3) & (yy > 50) & (yy < 128)] = (0.05, 0.05, 0.08)       # the hands
dial[(np.abs(yy - 127.5) < 3) & (xx > 127) & (xx < 190)] = (0.05, 0.05, 0.08)
dial[r > 122] = (0.6, 0.1, 0.1)
write_image(OUT / "r6_dial.png", dial)
rng = np.random.default_rng(6)
veins = 0.5 + 0.5 * np.sin(xx * 0.05 + 4 * np.sin(yy * 0.03) + rng.normal(0, 0.15, xx.shape))
write_image(OUT / "r6_stone.png", np.stack([0.55 + 0.3 * veins, 0.53 + 0.28 * veins, 0.5 + 0.25 * veins], -1))
hgt = np.sin(xx * 0.05 + 4 * np.sin(yy * 0.03))
gy, gx = np.gradient(hgt)
n = np.stack([-gx * 3, -gy * 3, np.ones_like(xx)], -1); n /= np.linalg.norm(n, axis=-1, keepdims=True)
write_image(OUT / "r6_stone_normal.png", 0.5 + 0.5 * n)


def shader_material(name):
    m = bpy.data.materials.new(name); nt = m.node_tree; nt.nodes.remove(nt.nodes["Principled BSDF"])
    return m, nt, nt.nodes["Material Output"]


# brushed steel (anisotropic)
steel, sb = principled("BrushedSteel", Base_Color=(0.85, 0.85, 0.87), Metallic=1.0, Roughness=0.3, Anisotropic=0.6)
# dial label: image on Smart UV
dial_m, db = principled("Dial", Roughness=0.4)
t = dial_m.node_tree.nodes.new("ShaderNodeTexImage"); t.image = bpy.data.images.load(str(OUT / "r6_dial.png"))
dial_m.node_tree.links.new(t.outputs["Color"], db.inputs["Base Color"])
# leather strap: Diffuse / Glossy mixed by Layer Weight Facing
strap, nt, mo = shader_material("Strap")
dif = nt.nodes.new("ShaderNodeBsdfDiffuse"); dif.inputs["Color"].default_value = (0.12, 0.05, 0.02, 1)
glo = nt.nodes.new("ShaderNodeBsdfGlossy"); glo.inputs["Roughness"].default_value = 0.25
lw = nt.nodes.new("ShaderNodeLayerWeight"); lw.inputs["Blend"].default_value = 0.35
mix = nt.nodes.new("ShaderNodeMixShader")
nt.links.new(lw.outputs["Facing"], mix.inputs["Fac"]); nt.links.new(dif.outputs[0], mix.inputs[1])
nt.links.new(glo.outputs[0], mix.inputs[2]); nt.links.new(mix.outputs[0], mo.inputs["Surface"])
# stone plinth: image + normal map (Diffuse) mixed by Fresnel with a Glossy
stone, nt, mo = shader_material("PolishedStone")
tc = nt.nodes.new("ShaderNodeTexCoord")
ti = nt.nodes.new("ShaderNodeTexImage"); ti.image = bpy.data.images.load(str(OUT / "r6_stone.png"))
tn = nt.nodes.new("ShaderNodeTexImage"); tn.image = bpy.data.images.load(str(OUT / "r6_stone_normal.png"))
tn.image.colorspace_settings.name = "Non-Color"
nm = nt.nodes.new("ShaderNodeNormalMap")
sdif = nt.nodes.new("ShaderNodeBsdfDiffuse"); sglo = nt.nodes.new("ShaderNodeBsdfGlossy")
sglo.inputs["Roughness"].default_value = 0.08
fr = nt.nodes.new("ShaderNodeFresnel"); fr.inputs["IOR"].default_value = 1.5
smix = nt.nodes.new("ShaderNodeMixShader")
for a, b in ((tc.outputs["UV"], ti.inputs["Vector"]), (tc.outputs["UV"], tn.inputs["Vector"]),
             (tn.outputs["Color"], nm.inputs["Color"]), (ti.outputs["Color"], sdif.inputs["Color"]),
             (nm.outputs["Normal"], sdif.inputs["Normal"]), (nm.outputs["Normal"], sglo.inputs["Normal"]),
             (nm.outputs["Normal"], fr.inputs["Normal"]), (fr.outputs["Fac"], smix.inputs["Fac"]),
             (sdif.outputs[0], smix.inputs[1]), (sglo.outputs[0], smix.inputs[2]),
             (smix.outputs[0], mo.inputs["Surface"])):
    nt.links.new(a, b)
glass_m, nt, mo = shader_material("Glass")
g = nt.nodes.new("ShaderNodeBsdfGlass"); g.inputs["IOR"].default_value = 1.5
nt.links.new(g.outputs[0], mo.inputs["Surface"])
whisky, _ = principled("Whisky", Base_Color=(0.9, 0.45, 0.1), Roughness=0.0, Transmission_Weight=1.0, IOR=1.33)
lawn, _ = principled("Lawn", Base_Color=(0.12, 0.3, 0.06), Roughness=0.8)

# --- the lawn: Subdivision + Displace (Clouds)
bpy.ops.mesh.primitive_plane_add(size=30, location=(0, 0, 0)); ground = bpy.context.object; ground.name = "Lawn"
ground.data.materials.append(lawn)
sub = ground.modifiers.new("Subdivision", "SUBSURF"); sub.subdivision_type = "SIMPLE"; sub.levels = sub.render_levels = 6
clouds = bpy.data.textures.new("Bumps", "CLOUDS"); clouds.noise_scale = 1.5
dis = ground.modifiers.new("Displace", "DISPLACE"); dis.texture = clouds; dis.strength = 0.25; dis.mid_level = 0.5

# --- the plinth (Bevel), the turntable disc on it, the watch and the glass parented to the disc
bpy.ops.mesh.primitive_cube_add(size=1, location=(0, 0, 0.4)); plinth = bpy.context.object; plinth.name = "Plinth"
plinth.scale = (0.8, 0.8, 0.8); bpy.ops.object.transform_apply(scale=True)
bev = plinth.modifiers.new("Bevel", "BEVEL"); bev.width = 0.02; bev.segments = 4
plinth.data.materials.append(stone); smart_uv(plinth)
bpy.ops.mesh.primitive_cylinder_add(radius=0.35, depth=0.03, vertices=64, location=(0, 0, 0.815))
disc = bpy.context.object; disc.name = "Turntable"; disc.data.materials.append(steel)
disc.rotation_euler.z = 0.0; disc.keyframe_insert("rotation_euler", index=2, frame=1)
disc.rotation_euler.z = math.radians(90); disc.keyframe_insert("rotation_euler", index=2, frame=25)

bpy.ops.mesh.primitive_torus_add(major_radius=0.1, minor_radius=0.018, major_segments=64, minor_segments=16,
                                 location=(-0.08, 0.02, 0.85))
case = bpy.context.object; case.name = "WatchCase"; case.data.materials.append(steel)
case.modifiers.new("Subdivision", "SUBSURF").render_levels = 2
bpy.ops.object.shade_smooth()
bpy.ops.mesh.primitive_cylinder_add(radius=0.095, depth=0.01, vertices=64, location=(-0.08, 0.02, 0.85))
face = bpy.context.object; face.name = "Dial"; face.data.materials.append(dial_m); smart_uv(face)
bpy.ops.mesh.primitive_cube_add(size=1, location=(-0.08, 0.02, 0.835)); band = bpy.context.object; band.name = "Strap"
band.scale = (0.07, 0.5, 0.01); bpy.ops.object.transform_apply(scale=True); band.data.materials.append(strap)
band.modifiers.new("Bevel", "BEVEL").width = 0.004


tumbler = lathe("Tumbler", [(0.0, 0.0), (0.045, 0.0), (0.047, 0.004), (0.05, 0.12)], (0.15, -0.05, 0.83), steps=64)
sol = tumbler.modifiers.new("Solidify", "SOLIDIFY"); sol.thickness = 0.004; sol.offset = -1
tumbler.data.materials.append(glass_m)
drink = lathe("Whisky", [(0.0, 0.012), (0.0445, 0.012), (0.046, 0.06), (0.0, 0.06)], (0.15, -0.05, 0.83), steps=64)
drink.data.materials.append(whisky)
for o in (case, face, band, tumbler, drink):
    o.parent = disc; o.matrix_parent_inverse = disc.matrix_world.inverted()

# --- the world: the HDRI (Environment Texture)
world = bpy.data.worlds.new("HDRI"); scene.world = world
wn = world.node_tree
env = wn.nodes.new("ShaderNodeTexEnvironment"); env.image = bpy.data.images.load(str(OUT / "r6_sky.hdr"))
wn.links.new(env.outputs["Color"], wn.nodes["Background"].inputs["Color"])
wn.nodes["Background"].inputs["Strength"].default_value = 1.0

# --- camera dolly, motion blur
cd = bpy.data.cameras.new("Camera"); cam = bpy.data.objects.new("Camera", cd); scene.collection.objects.link(cam)
scene.camera = cam; cd.lens = 50
target = mathutils.Vector((0.0, 0.0, 0.88))
for f, loc in ((1, (1.1, -0.9, 1.2)), (25, (0.8, -0.65, 1.08))):
    cam.location = loc
    cam.rotation_euler = (target - mathutils.Vector(loc)).to_track_quat("-Z", "Y").to_euler()
    cam.keyframe_insert("location", frame=f); cam.keyframe_insert("rotation_euler", frame=f)
scene.render.use_motion_blur = True; scene.render.motion_blur_shutter = 0.5

# --- output, colour management, STPM settings
rs = scene.render
rs.resolution_x, rs.resolution_y, rs.resolution_percentage = 240, 135, 100
rs.film_transparent = False
scene.view_settings.view_transform = "AgX"; scene.view_settings.look = "AgX - Punchy"
scene.stpm.denoise = True
rs.engine = "STPM"
scene.frame_set(2)
rs.filepath = str(OUT / "watch6_frame_")
bpy.ops.wm.save_as_mainfile(filepath=str(OUT / "watch6.blend"))
print("saved", OUT / "watch6.blend")

# --- variant: a Sky Texture world, Filmic with a look
sky_w = bpy.data.worlds.new("Sky"); scene.world = sky_w
st = sky_w.node_tree.nodes.new("ShaderNodeTexSky"); st.sky_type = "MULTIPLE_SCATTERING"
st.sun_elevation, st.sun_rotation = SUN_ELEV, math.radians(90) - SUN_AZ
sky_w.node_tree.links.new(st.outputs["Color"], sky_w.node_tree.nodes["Background"].inputs["Color"])
sky_w.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.3
scene.view_settings.view_transform = "Filmic"; scene.view_settings.look = "Medium High Contrast"
rs.filepath = str(OUT / "watch6_sky_frame_")
bpy.ops.wm.save_as_mainfile(filepath=str(OUT / "watch6_sky.blend"))
print("saved", OUT / "watch6_sky.blend")

# --- variant: Film Transparent, composited over a warm grey
scene.world = world
scene.view_settings.view_transform = "AgX"; scene.view_settings.look = "AgX - Punchy"
rs.film_transparent = True
ct = bpy.data.node_groups.new("Compositing", "CompositorNodeTree"); scene.compositing_node_group = ct
ct.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
rl = ct.nodes.new("CompositorNodeRLayers")
ao = ct.nodes.new("CompositorNodeAlphaOver")
ao.inputs["Background"].default_value = (0.5, 0.45, 0.4, 1.0)       # the background colour
out = ct.nodes.new("NodeGroupOutput")
ct.links.new(rl.outputs["Image"], ao.inputs["Foreground"]); ct.links.new(ao.outputs["Image"], out.inputs[0])
rs.use_compositing = True
# a new compositor has no STPM Denoise group: Denoise off and on again puts it before the Alpha Over
scene.stpm.denoise = False; scene.stpm.denoise = True
rs.filepath = str(OUT / "watch6_alpha_frame_")
bpy.ops.wm.save_as_mainfile(filepath=str(OUT / "watch6_alpha.blend"))
print("saved", OUT / "watch6_alpha.blend")
