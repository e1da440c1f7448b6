"""A small Cornell-like box for the final-gathering tests (built with bpy, exported by the add-on).

Open toward the camera: floor, ceiling and back wall white (0.7), left wall red, right wall green,
a white block on the floor; a point light (radius 0.05 m, 200 W) 0.5 m under the ceiling; black world.
Most of what the walls show away from the light's direct reach is indirect light (colour bleeding
on the floor and the block), the case final gathering is for.
"""
from __future__ import annotations

import math

import bpy

from test_addon_scenes import add_camera, add_light, add_mesh, diffuse, fresh, set_world


def _coated(name: str, rgb, roughness: float):
    """A Principled BSDF (Blender's default specular: IOR 1.5, Specular IOR Level 0.5) of base colour rgb."""
    mat = bpy.data.materials.new(name)
    tree = mat.node_tree
    p = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    p.inputs["Base Color"].default_value = (*rgb, 1.0)
    p.inputs["Roughness"].default_value = roughness
    return mat


def cornell(width: int = 48, height: int = 36, light_z: float = 1.5, light_radius: float = 0.05,
            coated_floor: bool = False):
    """The box (2 m cube, floor at z = 0) and its camera; returns the bpy scene.

    coated_floor: the floor a black Principled BSDF (roughness 0.3: its rough dielectric coat
    alone reflects) instead of white diffuse, and the light a spot pointing down (60 degree cone),
    so that walls and ceiling are lit by the coat's reflection, light paths L C x with no diffuse
    vertex before them, and what bounces on from there."""
    scene = fresh()
    scene.render.resolution_x, scene.render.resolution_y = width, height
    white, red, green = diffuse("White", (0.7, 0.7, 0.7)), diffuse("Red", (0.7, 0.1, 0.1)), \
        diffuse("Green", (0.1, 0.7, 0.1))
    floor = _coated("Coated", (0.0, 0.0, 0.0), 0.3) if coated_floor else white
    add_mesh("plane", "Floor", (0, 0, 0), floor, size=2)
    add_mesh("plane", "Ceiling", (0, 0, 2), white, size=2, rotation=(math.pi, 0, 0))
    add_mesh("plane", "Back", (0, 1, 1), white, size=2, rotation=(math.pi / 2, 0, 0))
    add_mesh("plane", "Left", (-1, 0, 1), red, size=2, rotation=(0, math.pi / 2, 0))
    add_mesh("plane", "Right", (1, 0, 1), green, size=2, rotation=(0, -math.pi / 2, 0))
    add_mesh("cube", "Block", (0.3, 0.3, 0.35), white, size=0.7)
    if coated_floor:
        add_light("SPOT", "Lamp", (0, 0, light_z), energy=400.0, shadow_soft_size=light_radius,
                  spot_size=math.radians(60.0), spot_blend=0.1)        # (a light points down -Z)
    else:
        add_light("POINT", "Lamp", (0, 0, light_z), energy=200.0, shadow_soft_size=light_radius)
    set_world((0.0, 0.0, 0.0), 0.0)
    add_camera((0, -3.3, 1.0), (math.radians(90), 0, 0), lens=35.0)
    return scene
