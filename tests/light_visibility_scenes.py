"""Lights with Ray Visibility switches off, direct light only (bpy).

``build(off)``: a grey diffuse floor, a Principled sphere (base 0.8 red, roughness 0.5: a diffuse
base under a rough specular layer) and a rough Glass BSDF sphere (roughness 0.5) beside it, lit by
a radius-0 point light behind and above the spheres (so the glass refracts it toward the camera)
and a second one in front (its glints on both spheres); black world.  ``off``: the light object
Ray Visibility switches turned off on both lights ("diffuse", "glossy", "transmission").

Built by ``tests/test_cycles_light_visibility.py``.
"""
from __future__ import annotations

import math

import bpy
from mathutils import Vector

from direct_light_scenes import _diffuse
from test_addon_scenes import add_camera, add_light, add_mesh, fresh, set_world

__all__ = ["build", "W", "H"]

W, H = 64, 48


def _principled(name):
    mat = bpy.data.materials.new(name)
    p = mat.node_tree.nodes["Principled BSDF"]
    p.inputs["Base Color"].default_value = (0.8, 0.15, 0.1, 1.0)
    p.inputs["Roughness"].default_value = 0.5
    return mat


def _glass(name):
    mat = bpy.data.materials.new(name)
    t = mat.node_tree
    t.nodes.remove(t.nodes["Principled BSDF"])
    g = t.nodes.new("ShaderNodeBsdfGlass")
    g.inputs["Roughness"].default_value = 0.5
    t.links.new(g.outputs["BSDF"], t.nodes["Material Output"].inputs["Surface"])
    return mat


def build(off=(), w: int = W, h: int = H, area: bool = False):
    """The scene above; returns bpy.context.scene.  area: the two lights are 1 m square AREA lights
    facing the spheres (rays leaving a rough lobe can hit them: multiple importance sampling)."""
    scene = fresh()
    scene.render.resolution_x, scene.render.resolution_y = w, h
    set_world((0, 0, 0), 0.0)
    add_mesh("plane", "Floor", material=_diffuse("Floor"), size=8.0)
    add_mesh("sphere", "Ball", location=(-0.7, 0, 0.6), material=_principled("Red"), radius=0.6)
    add_mesh("sphere", "Glass", location=(0.7, 0, 0.6), material=_glass("Glass"), radius=0.6)
    bpy.ops.object.shade_smooth()
    if area:
        lights = [add_light("AREA", "Back", location=(0.5, 2.5, 2.0), energy=400.0, size=1.0),
                  add_light("AREA", "Front", location=(-1.5, -2.5, 2.5), energy=300.0, size=1.0)]
        for obj in lights:
            # -Z toward the spheres' middle (0, 0, 0.6)
            d = Vector((0.0, 0.0, 0.6)) - obj.location
            obj.rotation_euler = (-d).to_track_quat("Z", "Y").to_euler()
    else:
        lights = [add_light("POINT", "Back", location=(0.5, 2.5, 2.0), energy=400.0, shadow_soft_size=0.0),
                  add_light("POINT", "Front", location=(-1.5, -2.5, 2.5), energy=300.0, shadow_soft_size=0.0)]
    for obj in lights:
        for kind in off:
            setattr(obj, f"visible_{kind}", False)
    add_camera(location=(0, -5.0, 1.6), rotation=(math.radians(78), 0, 0), lens=40)
    return scene
