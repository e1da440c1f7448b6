"""Build ``metal_ring.blend``: a turning half ring of mirror metal throws a cardioid caustic.

The coffee-cup caustic: low sunlight (25 degrees above the horizon) reflects
inside a circular mirror wall and focuses on the floor along a nephroid (a
cardioid for light from a point on the circle).  The ring is a half circle (an open arc, so its
turning is visible) of radius 1 m, 0.35 m high, that turns 40 degrees about
the vertical axis during the 0.5-frame shutter: the caustic sweeps.

    .venv/bin/python blend_scenes/make_metal_ring.py [OUT.blend]
"""
from __future__ import annotations

import math

import bpy

from _common import add_plane, camera, diffuse, finish, keyframes, mesh_object, metal, new_scene, out_path

RADIUS, HEIGHT, SEGMENTS, ARC = 1.0, 0.35, 48, math.pi


def ring_wall():
    """Vertices and quads of an open circular wall (arc ARC, centred on the -Y side)."""
    verts, faces = [], []
    for i in range(SEGMENTS + 1):
        a = -0.5 * math.pi - 0.5 * ARC + ARC * i / SEGMENTS
        x, y = RADIUS * math.cos(a), RADIUS * math.sin(a)
        verts += [(x, y, 0.0), (x, y, HEIGHT)]
    for i in range(SEGMENTS):
        faces.append((2 * i, 2 * i + 2, 2 * i + 3, 2 * i + 1))
    return verts, faces


def build(path):
    scene = new_scene("MetalRing")
    add_plane("Floor", 6.0, diffuse("Floor", (0.7, 0.7, 0.7)))
    verts, faces = ring_wall()
    ring = mesh_object("Ring", verts, faces, metal("Chrome"), smooth=True)
    keyframes(ring, "rotation_euler", [(0, 0.0), (2, math.radians(160.0))], index=2)   # 80 degrees per frame
    sun = bpy.data.lights.new("LowSun", type="SUN")             # from +Y, 25 degrees up: light enters the arc
    sun.energy, sun.angle = 3.0, math.radians(0.5)
    sun_obj = bpy.data.objects.new("LowSun", sun)
    sun_obj.rotation_euler = (math.radians(-65.0), 0.0, 0.0)
    scene.collection.objects.link(sun_obj)
    camera((0.0, 0.0, 4.2), (0.0, 0.0, 0.0), lens=30.0)          # straight down
    return finish(scene, path, motion_steps=5)


if __name__ == "__main__":
    print(build(out_path("metal_ring.blend")))
