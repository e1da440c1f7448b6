"""Soft-falloff point and spot lights over a rough metal strip and a diffuse strip (bpy).

Blender's default for POINT / SPOT lights of radius r > 0 is ``use_soft_falloff``: Cycles then
treats the light as a disc of radius r through its centre facing the point that looks at it (next
event estimation samples that disc; a ray leaving a surface hits the disc facing the ray's origin).
These scenes put such a light (r = 0.3) 1.5 m above a floor whose left half is a roughness-0.5
metal and whose right half is diffuse, so the metal's lobe sees the light and is weighed against
next-event estimation (docs/rendering.md, "Multiple importance sampling").  Built by
``tests/test_cycles_soft_falloff.py``.
"""
from __future__ import annotations

import math

import bpy

from direct_light_scenes import _diffuse, metal as _metal
from test_addon_scenes import add_camera, add_light, add_mesh, fresh, set_world

__all__ = ["SCENES", "build"]

W, H = 64, 48


def floor(w: int = W, h: int = H):
    """Metal (roughness 0.5) for x < 0, diffuse grey 0.8 for x > 0, 6 m deep; camera looking down the floor."""
    scene = fresh()
    scene.render.resolution_x, scene.render.resolution_y = w, h
    set_world((0, 0, 0), 0.0)
    m = add_mesh("plane", "Metal", location=(-1.5, 1.0, 0.0), material=_metal("Metal"), size=3.0)
    m.scale = (1.0, 2.0, 1.0)
    d = add_mesh("plane", "Diffuse", location=(1.5, 1.0, 0.0), material=_diffuse("Diffuse"), size=3.0)
    d.scale = (1.0, 2.0, 1.0)
    add_camera(location=(0.0, -2.6, 1.6), rotation=(math.radians(62), 0, 0), lens=22)
    return scene


def point():
    """A POINT light of radius 0.3 (soft falloff, Blender's default) 1.5 m above the seam."""
    scene = floor()
    add_light("POINT", "Bulb", location=(0.0, 1.2, 1.5), energy=150.0, shadow_soft_size=0.3, use_soft_falloff=True)
    return scene


def spot():
    """A SPOT of radius 0.3 (soft falloff), 1.5 m above the seam, pointing down, 100 degree cone."""
    scene = floor()
    s = add_light("SPOT", "Spot", location=(0.0, 1.2, 1.5), energy=300.0, shadow_soft_size=0.3,
                  use_soft_falloff=True, spot_size=math.radians(100), spot_blend=0.2)
    s.rotation_euler = (math.radians(-15), 0, 0)
    return scene


SCENES = {"point": point, "spot": spot}


def build(name: str):
    return SCENES[name]()
