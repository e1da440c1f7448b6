"""A default Principled wall (roughness 1, Specular IOR Level 0.5) beside a small light, over a
rough metal floor (bpy); and the floor itself (``floor_view``).

The wall's rough dielectric coat is picked by under 2 % of the camera paths that hit it; what that
lobe sees below is the floor's highlight of the light (tens of times the wall's radiance).  Built
by ``tests/test_cycles_coat_fireflies.py`` (issue 14, "no fireflies"); the review's scene
(160 x 120) with the camera raised so that the frame holds the wall alone.
"""
from __future__ import annotations

import math

import bpy

from direct_light_scenes import metal
from test_addon_scenes import add_camera, add_light, add_mesh, fresh, set_world

__all__ = ["SCENES", "build"]

W, H = 80, 60


def _wall_material(name: str, base: float = 0.8):
    """Blender's default Principled BSDF (base 0.8, Specular IOR Level 0.5, IOR 1.5) at roughness 1."""
    mat = bpy.data.materials.new(name)
    p = mat.node_tree.nodes["Principled BSDF"]
    p.inputs["Roughness"].default_value = 1.0
    p.inputs["Base Color"].default_value = (base, base, base, 1.0)
    return mat


def coat_only(scene) -> None:
    """Turn the wall's base colour black: its coat alone, the same lobe (f_c does not depend on the
    base colour), which Cycles then picks on every hit."""
    p = bpy.data.materials["Wall"].node_tree.nodes["Principled BSDF"]
    p.inputs["Base Color"].default_value = (0.0, 0.0, 0.0, 1.0)


def wall(kind: str = "POINT"):
    """The wall 4 m in front of a soft point light of radius 0.3 (or a 0.6 m disc area light) 1.2 m
    above a roughness-0.3 metal floor; the camera 8 m from the wall looks at it level."""
    scene = fresh()
    scene.render.resolution_x, scene.render.resolution_y = W, H
    set_world((0, 0, 0), 0.0)
    add_mesh("plane", "Floor", material=metal("Floor", roughness=0.3, color=(0.8, 0.8, 0.8)), size=10.0)
    add_mesh("plane", "Wall", location=(0.0, 4.0, 2.0), rotation=(math.radians(90), 0, 0),
             material=_wall_material("Wall"), size=10.0)
    if kind == "POINT":
        add_light("POINT", "Bulb", location=(0.0, 1.5, 1.2), energy=200.0, shadow_soft_size=0.3,
                  use_soft_falloff=True)
    else:
        disc = add_light("AREA", "Disc", location=(0.0, 1.5, 1.2), energy=800.0, shape="DISK", size=0.6)
        disc.rotation_euler = (math.radians(90), 0, 0)
    add_camera(location=(0.0, -4.0, 2.2), rotation=(math.radians(90), 0, 0), lens=50)
    return scene


def floor_view(roughness: float = 0.5):
    """The review's camera (looking down at the floor and the wall behind it) over the metal floor
    of that roughness, with a point light of radius 0 (no light randomness: what noise the
    floor's highlight has is the film's and the metal's samples)."""
    scene = fresh()
    scene.render.resolution_x, scene.render.resolution_y = W, H
    set_world((0, 0, 0), 0.0)
    add_mesh("plane", "Floor", material=metal("Floor", roughness=roughness, color=(0.8, 0.8, 0.8)), size=10.0)
    add_mesh("plane", "Wall", location=(0.0, 4.0, 2.0), rotation=(math.radians(90), 0, 0),
             material=_wall_material("Wall"), size=10.0)
    add_light("POINT", "Bulb", location=(0.0, 1.5, 1.2), energy=200.0, shadow_soft_size=0.0)
    add_camera(location=(0.0, -4.0, 1.5), rotation=(math.radians(80), 0, 0))
    return scene


SCENES = {"point": lambda: wall("POINT"), "disc": lambda: wall("AREA")}


def build(name: str):
    return SCENES[name]()
