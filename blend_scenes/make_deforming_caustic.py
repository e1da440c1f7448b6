"""Build ``deforming_caustic.blend``: a rippling floor (Wave modifier) under a glass-sphere caustic.

The receiver deforms: a subdivided 4 m plane with Blender's Wave modifier
(height 0.25 m, a ripple running outward 0.4 m during the shutter) lies under a
static glass sphere focusing a point light.  Photons land on the surface as it
was at their own instant; deformation blur is exported as vertex positions
per motion step (5 steps).

    .venv/bin/python blend_scenes/make_deforming_caustic.py [OUT.blend]
"""
from __future__ import annotations

import bpy

from _common import add_sphere, camera, diffuse, finish, glass, new_scene, out_path, point_light


def build(path):
    scene = new_scene("DeformingCaustic")
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=48, y_subdivisions=48, size=4.0, location=(0, 0, 0))
    floor = bpy.context.object
    floor.name = "RipplingFloor"
    floor.data.materials.append(diffuse("Floor", (0.8, 0.8, 0.8)))
    wave = floor.modifiers.new("Wave", type="WAVE")
    wave.height, wave.width, wave.speed, wave.narrowness = 0.25, 0.7, 0.8, 1.5
    wave.time_offset = -1.0
    add_sphere("GlassSphere", 0.5, glass(), location=(0.0, 0.0, 1.2))
    point_light("Key", 300.0, (0.0, 0.0, 3.2), radius=0.05)
    camera((0.0, -4.5, 3.0), (56.0, 0.0, 0.0))
    return finish(scene, path, motion_steps=5)


if __name__ == "__main__":
    print(build(out_path("deforming_caustic.blend")))
