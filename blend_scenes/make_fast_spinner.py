"""Build ``fast_spinner.blend``: mirror blades spinning one full turn per shutter (critical velocity).

A two-bladed mirror propeller (0.8 m blades tilted 60 degrees, so light from above reflects down) turns 360
degrees about the vertical axis during the 0.5-frame shutter: the blades blur
into a disc and their reflected caustic into a ring.  One turn per shutter is
the critical speed for a renderer that samples motion at few instants: with
3 steps the samples at 0, 180 and 360 degrees make the rotation ambiguous
(slerp takes the shorter arc, 180 degrees has none), with 2 steps the blades
would not move at all.  The file asks for 17 motion steps (22.5 degrees each).

    .venv/bin/python blend_scenes/make_fast_spinner.py [OUT.blend]
"""
from __future__ import annotations

import math

from _common import (add_plane, camera, diffuse, finish, keyframes, mesh_object, metal, new_scene, out_path,
                     point_light)

BLADE, WIDTH, TILT = 0.8, 0.3, math.radians(60.0)


def blades():
    """Two flat blades along +-X, tilted about their long axis (object space)."""
    verts, faces = [], []
    dz, dy = 0.5 * WIDTH * math.sin(TILT), 0.5 * WIDTH * math.cos(TILT)
    for s in (1.0, -1.0):
        i = len(verts)
        verts += [(s * 0.05, -dy, -s * dz), (s * BLADE, -dy, -s * dz), (s * BLADE, dy, s * dz), (s * 0.05, dy, s * dz)]
        faces.append((i, i + 1, i + 2, i + 3) if s > 0 else (i, i + 3, i + 2, i + 1))
    return verts, faces


def build(path):
    scene = new_scene("FastSpinner")
    add_plane("Floor", 6.0, diffuse("Floor", (0.8, 0.8, 0.8)))
    verts, faces = blades()
    rotor = mesh_object("Rotor", verts, faces, metal("Chrome"), location=(0.0, 0.0, 1.0))
    keyframes(rotor, "rotation_euler", [(0, 0.0), (2, 8.0 * math.pi)], index=2)   # 2 turns per frame
    point_light("Key", 250.0, (0.3, -0.2, 3.0), radius=0.03)
    camera((0.0, -4.5, 3.4), (52.0, 0.0, 0.0))
    return finish(scene, path, motion_steps=17)


if __name__ == "__main__":
    print(build(out_path("fast_spinner.blend")))
