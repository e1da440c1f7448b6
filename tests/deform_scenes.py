"""A smooth-shaded UV sphere squashed by an animated shape key across the shutter (bpy).

``build()``: a 12 x 6 UV sphere (radius 1, Shade Smooth, diffuse grey) with a shape key
"Squash" (x 1.35, z 0.6) whose value goes 0 -> 1 linearly over frames 4 -> 6; frame 5 with motion
blur on and a shutter of 1 frame, so the shutter sees the values 0.25 -> 0.75 (Cycles: 3 motion
steps, ``Object.cycles.motion_steps = 1``; STPM's export: 3).  Lit from the side by a radius-0
point light at (-4, -3, 1) in a black world, so the terminator crosses the sphere, seen from the
front.  Few faces on purpose: flat shading shows every facet.

``show_normals()`` swaps the material for an emission of 0.5 + 0.5 N (Geometry > Normal): a
Cycles render then holds its shading normals averaged over the shutter.

Built by ``tests/test_cycles_deforming_normals.py``.
"""
from __future__ import annotations

import math

import bpy

import normal_scenes
from direct_light_scenes import _diffuse
from test_addon_scenes import add_camera, add_light, fresh, linear_keys, set_world

__all__ = ["build", "show_normals", "W", "H"]

W, H = 64, 48


def build(w: int = W, h: int = H):
    """The scene above; returns bpy.context.scene (frame 5)."""
    scene = fresh()
    scene.render.resolution_x, scene.render.resolution_y = w, h
    set_world((0, 0, 0), 0.0)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=12, ring_count=6, radius=1.0, location=(0.0, 0.0, 0.0))
    obj = bpy.context.object
    obj.name = "Blob"
    obj.data.materials.append(_diffuse("Grey"))
    bpy.ops.object.shade_smooth()
    obj.shape_key_add(name="Basis")
    key = obj.shape_key_add(name="Squash")
    for p in key.data:
        p.co.x *= 1.35
        p.co.z *= 0.6
    for f, v in ((4, 0.0), (6, 1.0)):
        key.value = v
        key.keyframe_insert("value", frame=f)
    linear_keys(obj.data.shape_keys)
    add_light("POINT", "Key", location=(-4.0, -3.0, 1.0), energy=1000.0, shadow_soft_size=0.0)
    add_camera(location=(0.0, -5.0, 1.5), rotation=(math.radians(75), 0, 0), lens=50)
    scene.render.use_motion_blur, scene.render.motion_blur_shutter = True, 1.0
    scene.frame_set(5)
    return scene


def show_normals():
    """Make the sphere emit 0.5 + 0.5 N (Geometry > Normal, world space), nothing else."""
    normal_scenes.show_normals("Blob")
