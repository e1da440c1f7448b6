"""Build ``hdri_product.blend``: a product shot lit by an HDRI (issue 14's scene).

* ``textures/studio_sun.exr``: a procedural 512 x 256 equirectangular HDRI (half-float RGB,
  Blender's convention: u = (pi - atan2(y, x)) / (2 pi), v = 1 - acos(z) / pi, top row = zenith):
  a blue sky gradient (zenith ~0.3, horizon ~0.47), a warm ground (~0.15), a sun disc of 3 degrees
  angular radius at 35 degrees elevation whose irradiance on a horizontal plane is 3.5 x that of
  the rest of the map, and two softboxes (radiance 5) so reflections show structure.  The map is
  written for the world's Mapping node (Z rotation 30 degrees): features are placed at their
  *world* directions below, rotated into the map.
* a table (a box, scale applied, Smart UV Project) with the plank image (darkened by a Hue/Saturation Value 0.7) and its normal map
  from ``textures/`` (``make_textured_room.py`` writes them; made here when missing);
* a rough copper sphere (Principled, metallic 1, roughness 0.3), a white diffuse sphere,
  a clear glass sphere (Principled, transmission 1, roughness 0), a frosted glass cube
  (transmission 1, roughness 0.3), and a small glass sphere sliding 0.15 m along +X during the
  0.5-frame shutter (motion blur on);
* one small Area light as a fill;
* World: Texture Coordinate (Generated) -> Mapping (Point, Z 30 degrees) -> Environment Texture
  (``//textures/studio_sun.exr``) -> Background (strength 1);
* camera at 320 x 240 looking at the table; Cycles' Filter Glossy set to 0 so a Cycles
  reference keeps the caustics sharp.

    .venv/bin/python blend_scenes/make_hdri_product.py [OUT.blend]
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

import bpy
from _common import add_box, add_sphere, area_light, camera, finish, keyframes, new_scene, out_path
from make_textured_room import _tree, make_images, smart_uv

HDRI_SIZE = (512, 256)
MAP_ROTATION_Z = math.radians(30.0)   # the world's Mapping node: lookup = Rz(30 deg) * direction
SUN_ELEVATION, SUN_AZIMUTH = math.radians(35.0), math.radians(150.0)   # world; azimuth from +X
SUN_RADIUS = math.radians(3.0)
CONTACT_SINK = 1e-6                   # m: the frosted cube's bottom below the table top (build())
SUN_RATIO = 3.5                       # sun irradiance / rest of the map's, on a horizontal plane
ZENITH, HORIZON, GROUND = np.array([0.22, 0.31, 0.55]), np.array([0.42, 0.47, 0.55]), np.array([0.2, 0.15, 0.1])
# softboxes: (world azimuth, world elevation, half width, half height) in degrees; radiance 5
SOFTBOXES = ((-60.0, 35.0, 12.0, 8.0), (200.0, 20.0, 7.0, 10.0))
SOFTBOX_RADIANCE = np.array([5.0, 5.0, 4.8])


def _world_to_map(d: np.ndarray) -> np.ndarray:
    c, s = math.cos(MAP_ROTATION_Z), math.sin(MAP_ROTATION_Z)
    return np.stack([c * d[..., 0] - s * d[..., 1], s * d[..., 0] + c * d[..., 1], d[..., 2]], -1)


def _map_to_world(m: np.ndarray) -> np.ndarray:
    c, s = math.cos(MAP_ROTATION_Z), math.sin(MAP_ROTATION_Z)
    return np.stack([c * m[..., 0] + s * m[..., 1], -s * m[..., 0] + c * m[..., 1], m[..., 2]], -1)


def _dir(azimuth: float, elevation: float) -> np.ndarray:
    return np.array([math.cos(elevation) * math.cos(azimuth), math.cos(elevation) * math.sin(azimuth),
                     math.sin(elevation)])


def hdri_pixels(ss: int = 4) -> tuple[np.ndarray, dict]:
    """(H, W, 3) float32 radiance (row 0 = top = zenith) and a dict of its irradiances on a
    horizontal plane (``ss`` x ``ss`` supersampling per pixel for the sharp edges)."""
    W, H = HDRI_SIZE
    sub = (np.arange(ss) + 0.5) / ss
    u = ((np.arange(W)[:, None] + sub[None, :]) / W).ravel()                 # (W*ss,)
    v = 1.0 - ((np.arange(H)[:, None] + sub[None, :]) / H).ravel()            # (H*ss,), top first
    theta = np.pi * (1.0 - v)[:, None] * np.ones_like(u)[None, :]
    phi = (np.pi - 2.0 * np.pi * u)[None, :] * np.ones_like(v)[:, None]
    m = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)
    d = _map_to_world(m)                                                      # world direction
    el = np.arcsin(np.clip(d[..., 2], -1, 1))
    az = np.arctan2(d[..., 1], d[..., 0])
    # sky: horizon -> zenith gradient, warm ground, a 1.5-degree blend at the horizon
    t = np.clip(el / (np.pi / 2), 0, 1) ** 0.6
    sky = HORIZON + (ZENITH - HORIZON) * t[..., None]
    w = np.clip(0.5 + el / math.radians(1.5), 0, 1)[..., None]
    rest = GROUND * (1 - w) + sky * w
    sun_d = _dir(SUN_AZIMUTH, SUN_ELEVATION)
    ang = np.arccos(np.clip(d @ sun_d, -1, 1))
    rest = rest + w * np.array([0.12, 0.1, 0.07]) * np.exp(-ang / math.radians(10.0))[..., None]   # aureole
    for a0, e0, hw, hh in SOFTBOXES:
        da = (np.degrees(az) - a0 + 180.0) % 360.0 - 180.0
        box = (np.abs(da) < hw) & (np.abs(np.degrees(el) - e0) < hh)
        rest = np.where(box[..., None], SOFTBOX_RADIANCE, rest)
    disc = (ang < SUN_RADIUS).astype(np.float64)
    # irradiance on a horizontal plane (facing +Z): sum L cos(theta) dOmega per subsample
    domega = (2 * np.pi / (W * ss)) * (np.pi / (H * ss)) * np.sin(theta)
    cosz = np.clip(d[..., 2], 0, None) * domega
    e_rest = float(((rest @ np.array([0.2126, 0.7152, 0.0722])) * cosz).sum())
    e_disc_unit = float((disc * cosz).sum())
    sun_l = SUN_RATIO * e_rest / e_disc_unit
    sun_col = np.array([1.0, 0.93, 0.82])
    sun_col = sun_col / (sun_col @ np.array([0.2126, 0.7152, 0.0722]))
    img = rest * (1 - disc[..., None]) + disc[..., None] * sun_l * sun_col
    img = img.reshape(H, ss, W, ss, 3).mean(axis=(1, 3))
    info = {"sun_radiance": sun_l, "E_rest": e_rest, "E_sun": SUN_RATIO * e_rest,
            "sun_solid_angle": 2 * np.pi * (1 - math.cos(SUN_RADIUS))}
    return img.astype(np.float32), info


def write_hdri(path: Path) -> dict:
    import OpenImageIO as oiio
    img, info = hdri_pixels()
    H, W, _ = img.shape
    spec = oiio.ImageSpec(W, H, 3, "half")
    spec.attribute("compression", "zip")
    spec.attribute("DateTime", "2025:01:01 00:00:00")     # fixed: the file is byte-identical on every run
    path.parent.mkdir(parents=True, exist_ok=True)
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), spec)
    out.write_image(img)
    out.close()
    return info


def principled(name: str, **inputs):
    mat = bpy.data.materials.new(name)
    t, out = _tree(mat)
    s = t.nodes.new("ShaderNodeBsdfPrincipled")
    for k, v in inputs.items():
        s.inputs[k].default_value = v
    t.links.new(s.outputs[0], out.inputs["Surface"])
    return mat


def table_material(planks: Path, normal: Path):
    mat = bpy.data.materials.new("TableWood")
    t, out = _tree(mat)
    bsdf = t.nodes.new("ShaderNodeBsdfPrincipled")
    bsdf.inputs["Roughness"].default_value = 0.55
    coord, mapping = t.nodes.new("ShaderNodeTexCoord"), t.nodes.new("ShaderNodeMapping")
    mapping.inputs["Scale"].default_value = (3.0, 3.0, 1.0)
    t.links.new(coord.outputs["UV"], mapping.inputs["Vector"])
    col = t.nodes.new("ShaderNodeTexImage")
    col.image = bpy.data.images.load(str(planks), check_existing=True)
    t.links.new(mapping.outputs["Vector"], col.inputs["Vector"])
    hsv = t.nodes.new("ShaderNodeHueSaturation")          # a darker stain: the sunlit top stays below 1
    hsv.inputs["Value"].default_value = 0.7
    t.links.new(col.outputs["Color"], hsv.inputs["Color"])
    t.links.new(hsv.outputs["Color"], bsdf.inputs["Base Color"])
    ntex = t.nodes.new("ShaderNodeTexImage")
    ntex.image = bpy.data.images.load(str(normal), check_existing=True)
    ntex.image.colorspace_settings.name = "Non-Color"
    t.links.new(mapping.outputs["Vector"], ntex.inputs["Vector"])
    nmap = t.nodes.new("ShaderNodeNormalMap")
    t.links.new(ntex.outputs["Color"], nmap.inputs["Color"])
    t.links.new(nmap.outputs["Normal"], bsdf.inputs["Normal"])
    t.links.new(bsdf.outputs[0], out.inputs["Surface"])
    return mat


def hdri_world(world, exr: Path) -> None:
    t = world.node_tree
    bg = t.nodes.get("Background")
    bg.inputs["Strength"].default_value = 1.0
    coord, mapping = t.nodes.new("ShaderNodeTexCoord"), t.nodes.new("ShaderNodeMapping")
    mapping.vector_type = "POINT"
    mapping.inputs["Rotation"].default_value = (0.0, 0.0, MAP_ROTATION_Z)
    env = t.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(str(exr), check_existing=True)
    t.links.new(coord.outputs["Generated"], mapping.inputs["Vector"])
    t.links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    t.links.new(env.outputs["Color"], bg.inputs["Color"])


def build(path: Path) -> Path:
    scene = new_scene("HdriProduct")
    tex = path.parent / "textures"
    planks, normal = tex / "planks.png", tex / "planks_normal.png"
    if not (planks.exists() and normal.exists()):
        make_images(tex)
    info = write_hdri(tex / "studio_sun.exr")
    print("studio_sun.exr: " + ", ".join(f"{k} {v:.4g}" for k, v in info.items()))

    table = add_box("Table", 1.0, table_material(planks, normal), location=(0.0, -0.05, 0.375))
    table.scale = (1.8, 1.5, 0.75)
    bpy.ops.object.transform_apply(location=False, rotation=False, scale=True)
    smart_uv(table)
    top = 0.75
    copper = principled("Copper", Metallic=1.0, Roughness=0.3, **{"Base Color": (0.95, 0.62, 0.48, 1)})
    add_sphere("CopperSphere", 0.13, copper, location=(0.36, 0.2, top + 0.13))
    add_sphere("WhiteSphere", 0.10, principled("WhiteMatte", Roughness=1.0, **{"Base Color": (0.62, 0.62, 0.6, 1)}),
               location=(-0.5, 0.3, top + 0.10))
    clear = principled("ClearGlass", Roughness=0.0, IOR=1.5, **{"Transmission Weight": 1.0})
    add_sphere("GlassSphere", 0.12, clear, location=(-0.15, 0.05, top + 0.12))
    frosted = principled("FrostedGlass", Roughness=0.3, IOR=1.5, **{"Transmission Weight": 1.0})
    # sunk 1 um into the table: faces that coincide exactly have no defined answer (Cycles' rays
    # die at t = 0 on them and render the table under the cube black; docs/raycast.md,
    # "Surfaces in contact"), so the reference would score a dark band no renderer should copy
    cube = add_box("FrostedCube", 0.16, frosted, location=(0.08, 0.42, top + 0.08 - CONTACT_SINK))
    cube.rotation_euler = (0.0, 0.0, math.radians(25.0))
    mover = add_sphere("MovingGlass", 0.07, clear, location=(-0.4, -0.35, top + 0.07))
    keyframes(mover, "location", [(0, (-0.7, -0.35, top + 0.07)), (2, (-0.1, -0.35, top + 0.07))])  # 0.15 m / shutter
    aim = np.array([0.0, 0.1, top]) - np.array([0.9, -0.9, 1.7])
    rot = (math.atan2(math.hypot(aim[0], aim[1]), -aim[2]), 0.0, math.atan2(aim[1], aim[0]) - math.pi / 2)
    area_light("Fill", 10.0, (0.9, -0.9, 1.7), 0.3, rotation=rot)
    camera((0.0, -1.5, 1.3), (74.0, 0.0, 0.0), lens=35.0)
    finish(scene, path, resolution=(320, 240), photons_caustic=400_000)
    hdri_world(scene.world, tex / "studio_sun.exr")
    scene.cycles.blur_glossy = 0.0                     # sharp caustics in a Cycles reference
    bpy.ops.file.make_paths_relative()                 # //textures/...
    bpy.ops.wm.save_as_mainfile(filepath=str(path), compress=True)
    return path


if __name__ == "__main__":
    print(build(out_path("hdri_product.blend")))
