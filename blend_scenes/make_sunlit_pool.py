"""Build ``sunlit_pool.blend``: a sunlit pool with a deforming water surface (issue 16's pool).

Built the way an artist builds one:

* a 4 x 4 m basin: a floor and four walls 1.2 m high, each UV-unwrapped with Smart UV Project
  and tiled with ``textures/pool_tiles.png`` (pale blue tiles and grout, generated here,
  Closest interpolation, repeated through a Mapping node);
* the water: a 4 x 4 m grid of 96 x 96 quads, smooth-shaded, a Glass BSDF of IOR 1.33, displaced
  by a Displace modifier reading a Clouds texture (Perlin noise, 0.6 m) through an Empty that
  drifts 3 cm during the shutter, so the surface deforms across it: a moving network of thin
  caustic lines on the floor;
* a sun lamp (2 W/m^2, 5 degrees wide) at 60 degrees elevation; a camera above the water looking
  down through it at the floor.

The water's surface is a single sheet (air above, water below), so light reaches the floor by one
refraction: Cycles' shadow caustics (MNEE: the water is a caustic caster, floor and walls
receivers, the sun a caustic light, all flagged here) can render it, and
``python -m benchmarks pool`` compares the two.

    .venv/bin/python blend_scenes/make_sunlit_pool.py [OUT.blend]
"""
from __future__ import annotations

import math
from pathlib import Path

import bpy
from _common import camera, finish, keyframes, mesh_object, new_scene, out_path
import numpy as np
from make_textured_room import _save_png, _tree, smart_uv

#: the water's Displace: strength (m) and the noise texture's size (m)
WAVE_STRENGTH, WAVE_SIZE = 0.08, 0.6
#: how far the noise drifts during the 0.5-frame shutter (m)
DRIFT = 0.03


def pool_tiles(folder: Path) -> Path:
    """``pool_tiles.png`` (256 x 256 8-bit sRGB): 8 x 8 pale blue tiles, each a little different,
    with grey grout lines 3 px wide."""
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(7)
    n, k = 256, 8
    y, x = np.mgrid[0:n, 0:n]
    cell = (y // (n // k)) * k + x // (n // k)
    shade = rng.uniform(0.9, 1.05, k * k)[cell]
    rgb = np.stack([0.62, 0.78, 0.86]) * shade[..., None]
    grout = ((x % (n // k)) < 3) | ((y % (n // k)) < 3)
    rgb[grout] = (0.30, 0.33, 0.34)
    path = folder / "pool_tiles.png"
    _save_png(path, rgb)
    return path


def tiles_material(path: Path) -> "bpy.types.Material":
    """The tile image through UVs x 2 (Mapping: 16 tiles of 25 cm across the floor), Closest, on a
    matte Principled."""
    mat = bpy.data.materials.new("PoolTiles")
    t, out = _tree(mat)
    bsdf = t.nodes.new("ShaderNodeBsdfPrincipled")
    bsdf.inputs["Roughness"].default_value = 1.0
    spec = bsdf.inputs.get("Specular IOR Level")
    if spec is not None:
        spec.default_value = 0.0                  # matte tiles: the caustic is the point, not their gloss
    tex = t.nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.load(str(path))
    tex.interpolation = "Closest"
    uv = t.nodes.new("ShaderNodeTexCoord")
    mapping = t.nodes.new("ShaderNodeMapping")
    mapping.inputs["Scale"].default_value = (2.0, 2.0, 1.0)
    t.links.new(uv.outputs["UV"], mapping.inputs["Vector"])
    t.links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
    t.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    t.links.new(bsdf.outputs[0], out.inputs["Surface"])
    return mat


def water_material() -> "bpy.types.Material":
    mat = bpy.data.materials.new("Water")
    t, out = _tree(mat)
    glass = t.nodes.new("ShaderNodeBsdfGlass")
    glass.inputs["IOR"].default_value = 1.33
    glass.inputs["Roughness"].default_value = 0.0
    t.links.new(glass.outputs[0], out.inputs["Surface"])
    return mat


def basin(mat):
    """Floor (z = 0) and four walls up to z = 1.2, normals inward; Smart-UV-projected."""
    h, a = 1.2, 2.0
    verts = [(-a, -a, 0), (a, -a, 0), (a, a, 0), (-a, a, 0), (-a, -a, h), (a, -a, h), (a, a, h), (-a, a, h)]
    floor = mesh_object("PoolFloor", verts[:4], [(0, 1, 2, 3)], mat)
    walls = mesh_object("PoolWalls", verts, [(0, 4, 5, 1), (1, 5, 6, 2), (2, 6, 7, 3), (3, 7, 4, 0)], mat)
    for obj in (floor, walls):
        smart_uv(obj)
    return floor, walls


def water(mat):
    """The water sheet at z = 1: a 96 x 96 grid, smooth, displaced by drifting Perlin noise."""
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=96, y_subdivisions=96, size=4.0, location=(0, 0, 1.0))
    obj = bpy.context.object
    obj.name = "Water"
    obj.data.materials.append(mat)
    bpy.ops.object.shade_smooth()
    tex = bpy.data.textures.new("Ripples", type="CLOUDS")
    tex.noise_scale = WAVE_SIZE
    tex.noise_basis = "ORIGINAL_PERLIN"
    tex.noise_depth = 1
    drift = bpy.data.objects.new("WaveDrift", None)
    bpy.context.scene.collection.objects.link(drift)
    # 2 x DRIFT per frame: DRIFT during the 0.5-frame shutter
    keyframes(drift, "location", [(0, (-2 * DRIFT, -DRIFT, 0.0)), (2, (2 * DRIFT, DRIFT, 0.0))])
    mod = obj.modifiers.new("Ripples", type="DISPLACE")
    mod.texture = tex
    mod.texture_coords = "OBJECT"
    mod.texture_coords_object = drift
    mod.direction = "Z"
    mod.strength = WAVE_STRENGTH
    mod.mid_level = 0.5
    obj.cycles.is_caustics_caster = True
    return obj


def build(path: Path) -> Path:
    scene = new_scene("SunlitPool")
    floor, walls = basin(tiles_material(pool_tiles(path.parent / "textures")))
    for obj in (floor, walls):
        obj.cycles.is_caustics_receiver = True
    water(water_material())
    sun = bpy.data.lights.new("Sun", type="SUN")
    sun.energy, sun.angle = 2.0, math.radians(5.0)
    sun.cycles.is_caustics_light = True
    sun_obj = bpy.data.objects.new("Sun", sun)
    sun_obj.rotation_euler = (math.radians(30), 0.0, math.radians(25))     # 60 degrees elevation
    scene.collection.objects.link(sun_obj)
    camera((0.0, -3.3, 3.6), (45.0, 0.0, 0.0), lens=30.0)
    out = finish(scene, path, resolution=(320, 240), world=(0.05, 0.06, 0.08), motion_steps=5,
                 photons_caustic=1_000_000, photons_global=200_000)
    bpy.ops.file.make_paths_relative()                 # the textures travel with the .blend
    bpy.ops.wm.save_as_mainfile(filepath=str(path), compress=True)
    return out


if __name__ == "__main__":
    print(build(out_path("sunlit_pool.blend")))
