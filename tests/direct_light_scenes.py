"""Direct-light scenes for measuring next-event estimation against Cycles (bpy).

A corner of a diffuse room (floor, back wall, left wall; Diffuse BSDF, grey 0.8) seen by one
camera, lit by one kind of light per scene, black world.  Built by the Cycles comparison test
(``tests/test_cycles_direct_light.py``) and the measurement script
(``benchmarks/bench_direct_light.py``).  Each builder starts from an empty scene.
"""
from __future__ import annotations

import math

import bpy

from test_addon_scenes import add_camera, add_light, add_mesh, fresh, set_world

__all__ = ["SCENES", "build"]


def _diffuse(name, color=(0.8, 0.8, 0.8)):
    mat = bpy.data.materials.new(name)
    t = mat.node_tree
    t.nodes.remove(t.nodes["Principled BSDF"])
    df = t.nodes.new("ShaderNodeBsdfDiffuse")
    df.inputs["Color"].default_value = (*color, 1.0)
    t.links.new(df.outputs["BSDF"], t.nodes["Material Output"].inputs["Surface"])
    return mat


def metal(name, roughness=0.5, color=(0.9, 0.9, 0.9)):
    """A Principled BSDF metal (Metallic 1) of that roughness and base colour (also the soft-falloff
    and glossy comparisons' metal)."""
    mat = bpy.data.materials.new(name)
    p = mat.node_tree.nodes["Principled BSDF"]
    p.inputs["Base Color"].default_value = (*color, 1.0)
    p.inputs["Metallic"].default_value = 1.0
    p.inputs["Roughness"].default_value = roughness
    return mat


def _emission(name, strength, color=(1.0, 0.9, 0.7)):
    mat = bpy.data.materials.new(name)
    t = mat.node_tree
    t.nodes.remove(t.nodes["Principled BSDF"])
    em = t.nodes.new("ShaderNodeEmission")
    em.inputs["Color"].default_value = (*color, 1.0)
    em.inputs["Strength"].default_value = strength
    t.links.new(em.outputs["Emission"], t.nodes["Material Output"].inputs["Surface"])
    return mat


def room(w: int = 64, h: int = 48):
    """Floor z = 0, back wall y = 2, left wall x = -2 (planes 6 m wide), camera looking into the corner."""
    scene = fresh()
    scene.render.resolution_x, scene.render.resolution_y = w, h
    set_world((0, 0, 0), 0.0)
    mat = _diffuse("Wall")
    add_mesh("plane", "Floor", material=mat, size=6.0)
    back = add_mesh("plane", "Back", location=(0, 2, 3), material=mat, size=6.0)
    back.rotation_euler = (math.radians(90), 0, 0)
    left = add_mesh("plane", "Left", location=(-2, 0, 3), material=mat, size=6.0)
    left.rotation_euler = (0, math.radians(90), 0)
    add_camera(location=(1.2, -3.2, 1.5), rotation=(math.radians(78), 0, math.radians(18)), lens=24)
    return scene


def area_rect():
    """(a) A 1.0 x 0.4 m rectangle 0.25 m from the back wall, tilted toward the room."""
    scene = room()
    a = add_light("AREA", "Rect", location=(-0.6, 1.75, 1.4), energy=80.0, shape="RECTANGLE", size=1.0, size_y=0.4)
    a.rotation_euler = (math.radians(-30), 0, 0)
    return scene


def mesh_panel():
    """(b) An emissive quad (two triangles, Emission 6) 0.5 m above the floor, tilted 60 degrees."""
    scene = room()
    p = add_mesh("plane", "Panel", location=(-0.4, 1.0, 0.5), material=_emission("Panel", 6.0), size=0.7)
    p.rotation_euler = (math.radians(60), 0, 0)
    return scene


def area_disk():
    """(c) A disc (0.8 m) near the left wall and an ellipse (1.0 x 0.3 m) near the back wall."""
    scene = room()
    d = add_light("AREA", "Disk", location=(-1.6, 0.6, 1.0), energy=50.0, shape="DISK", size=0.8)
    d.rotation_euler = (0, math.radians(-60), 0)
    e = add_light("AREA", "Ellipse", location=(0.4, 1.7, 0.9), energy=40.0, shape="ELLIPSE", size=1.0, size_y=0.3)
    e.rotation_euler = (math.radians(-40), 0, 0)
    return scene


def sphere_spot():
    """(d) A point light of radius 0.3 0.45 m from the left wall and a spot of radius 0.3 near the back wall."""
    scene = room()
    add_light("POINT", "Sphere", location=(-1.55, 0.4, 0.9), energy=60.0, shadow_soft_size=0.3)
    s = add_light("SPOT", "Spot", location=(0.5, 1.5, 1.6), energy=120.0, shadow_soft_size=0.3,
                  spot_size=math.radians(70))
    s.rotation_euler = (math.radians(-35), 0, math.radians(10))
    return scene


def many_lights():
    """(e) Lights of very different power and distance: a strong far area light, a faint near bulb,
    a middle spot sphere and a small emissive triangle pair."""
    scene = room()
    a = add_light("AREA", "Far", location=(2.5, -1.5, 4.5), energy=800.0, shape="SQUARE", size=0.5)
    a.rotation_euler = (math.radians(25), math.radians(25), 0)
    add_light("POINT", "Faint", location=(-1.7, 1.7, 0.3), energy=2.0, shadow_soft_size=0.1)
    add_light("POINT", "Mid", location=(0.3, 0.8, 1.8), energy=30.0, shadow_soft_size=0.2)
    p = add_mesh("plane", "Tile", location=(-1.0, 1.9, 2.0), material=_emission("Tile", 3.0), size=0.3)
    p.rotation_euler = (math.radians(90), 0, 0)
    return scene


SCENES = {"area_rect": area_rect, "mesh_panel": mesh_panel, "area_disk": area_disk, "sphere_spot": sphere_spot,
          "many_lights": many_lights}


def build(name: str):
    return SCENES[name]()
