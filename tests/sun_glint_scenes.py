"""A sun's glint in water, chrome and rough metal (bpy), for ``tests/test_cycles_sun_glint.py``.

A plane at z = 0 (20 m square) under a SUN of angular diameter 5 degrees, 20 degrees above the
horizon straight ahead of the camera; the camera 1 m above the plane looks down by the same 20
degrees, so the mirror direction of the image centre points at the sun's centre.  Black world: the
only light is the sun.  Cycles' rays that leave the plane's lobe and escape within the sun's cone
see its radiance S / (pi sin^2(angle / 2)) (its ``distant_light_intersect``), STPM's too since
2026-12-06.

* ``water``: Principled BSDF, Transmission 1, IOR 1.33, Roughness 0 (a delta reflection and
  refraction; the refracted rays escape downward and see nothing);
* ``chrome``: Principled BSDF, Metallic 1, Roughness 0, base colour 0.9 (a delta reflection);
* ``rough_metal``, ``glossy_metal``: the same metal at Roughness 0.25 and 0.1: its lobe reaches
  the sun and next-event estimation samples it; both are kept, weighed by the power heuristic
  (at 0.1 next-event estimation alone is the noisier of the two);
* ``glossy_bsdf``, ``rough_glossy_bsdf``: a Glossy BSDF node (colour 0.9) at Roughness 0 and 0.25:
  Cycles 5.0 gives it no Fresnel, so at this 70-degree incidence it reflects 0.9 where the
  Principled metal's Schlick gives 0.912 (Cycles: 0.986 of the chrome's glint, measured);
* ``mixed_chrome``: a Mix Shader, Fac 0.5 from a (flat) Checker texture (a per-hit choice; until
  2026-12-06 a constant Fac blended the two shaders' parameters at export), of the chrome and a dark
  Diffuse BSDF (0.1): half the hits mirror the sun.
* ``mixed_chrome_const`` (not in ``SCENES``; ``tests/test_cycles_mix_shader.py``): the same Mix
  Shader with a constant Fac 0.5 (until 2026-12-06 exported as one Principled with every
  parameter blended: roughness 0.5, metallic 0.5, a broad highlight where Cycles has the glint).
"""
from __future__ import annotations

import math

import bpy

from direct_light_scenes import metal
from test_addon_scenes import add_camera, add_light, add_mesh, fresh, set_world

__all__ = ["SCENES", "build", "SUN_ANGLE", "SUN_STRENGTH", "ELEVATION"]

W, H = 64, 48
SUN_ANGLE = math.radians(5.0)         # angular diameter
SUN_STRENGTH = 3.0                     # W/m^2
ELEVATION = math.radians(20.0)         # the sun above the horizon; the camera looks down as much


def _water(name="Water"):
    mat = bpy.data.materials.new(name)
    p = mat.node_tree.nodes["Principled BSDF"]
    p.inputs["Base Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    p.inputs["Transmission Weight"].default_value = 1.0
    p.inputs["IOR"].default_value = 1.33
    p.inputs["Roughness"].default_value = 0.0
    return mat


def _plane(make_material):
    """The plane (its material from make_material(), called after the factory reset), the camera,
    the sun; black world."""
    scene = fresh()
    material = make_material()
    scene.render.resolution_x, scene.render.resolution_y = W, H
    set_world((0, 0, 0), 0.0)
    add_mesh("plane", "Plane", location=(0.0, 6.0, 0.0), material=material, size=20.0)
    add_camera(location=(0.0, -2.0, 1.0), rotation=(math.pi / 2 - ELEVATION, 0, 0), lens=80)
    sun = add_light("SUN", "Sun", location=(0.0, 5.0, 5.0), energy=SUN_STRENGTH, angle=SUN_ANGLE)
    sun.rotation_euler = (-(math.pi / 2 - ELEVATION), 0, 0)   # its +Z (toward the sun): (0, cos e, sin e)
    return scene


def _mixed_chrome(name="MixedChrome", textured=True):
    mat = metal(name, roughness=0.0)
    t = mat.node_tree
    out, p = t.nodes["Material Output"], t.nodes["Principled BSDF"]
    mix = t.nodes.new("ShaderNodeMixShader")
    df = t.nodes.new("ShaderNodeBsdfDiffuse")
    df.inputs["Color"].default_value = (0.1, 0.1, 0.1, 1.0)
    if textured:
        ck = t.nodes.new("ShaderNodeTexChecker")
        ck.inputs["Color1"].default_value = ck.inputs["Color2"].default_value = (0.5, 0.5, 0.5, 1.0)
        t.links.new(ck.outputs["Color"], mix.inputs["Fac"])
    else:
        mix.inputs["Fac"].default_value = 0.5
    t.links.new(df.outputs["BSDF"], mix.inputs[1])
    t.links.new(p.outputs["BSDF"], mix.inputs[2])
    t.links.new(mix.outputs["Shader"], out.inputs["Surface"])
    return mat


def water():
    return _plane(_water)


def chrome():
    return _plane(lambda: metal("Chrome", roughness=0.0))


def mixed_chrome():
    return _plane(_mixed_chrome)


def mixed_chrome_const():
    return _plane(lambda: _mixed_chrome("MixedChromeConst", textured=False))


def rough_metal():
    return _plane(lambda: metal("Rough", roughness=0.25))


def glossy_metal():
    return _plane(lambda: metal("Glossy", roughness=0.1))


def _glossy_bsdf(name, roughness):
    """A Glossy BSDF node (colour 0.9): Cycles 5.0 gives it no Fresnel (its colour at every angle)."""
    mat = bpy.data.materials.new(name)
    t = mat.node_tree
    t.nodes.remove(t.nodes["Principled BSDF"])
    g = t.nodes.new("ShaderNodeBsdfGlossy")
    g.inputs["Color"].default_value = (0.9, 0.9, 0.9, 1.0)
    g.inputs["Roughness"].default_value = roughness
    t.links.new(g.outputs["BSDF"], t.nodes["Material Output"].inputs["Surface"])
    return mat


def glossy_bsdf():
    return _plane(lambda: _glossy_bsdf("GlossyBSDF", 0.0))


def rough_glossy_bsdf():
    return _plane(lambda: _glossy_bsdf("RoughGlossyBSDF", 0.25))


SCENES = {"water": water, "chrome": chrome, "rough_metal": rough_metal, "glossy_metal": glossy_metal,
          "mixed_chrome": mixed_chrome, "glossy_bsdf": glossy_bsdf, "rough_glossy_bsdf": rough_glossy_bsdf}


def build(name: str):
    return SCENES[name]()
