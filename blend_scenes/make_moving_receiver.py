"""Build ``moving_receiver.blend``: a static glass sphere focuses a light onto a box sliding under it.

The receiver moves, the caustic's source does not: photons that landed on the
box at other instants sit elsewhere, so the STANDARD estimate comes out too
dark on the box (about the fraction of the shutter the box spends under the
focus) while TEMPORAL / KD4D stay right.  Frame 1, shutter 0.5 frames
centred; the box travels 0.8 m (-0.4 to +0.4 m) during the shutter, its top
passing 0.25 m under the sphere's focus; a weak area light in front shows
the box inside the sphere's shadow.

    .venv/bin/python blend_scenes/make_moving_receiver.py [OUT.blend]
"""
from __future__ import annotations

import math

from _common import (add_box, add_plane, add_sphere, area_light, camera, diffuse, finish, glass, keyframes, new_scene,
                     out_path, point_light)


def build(path):
    scene = new_scene("MovingReceiver")
    add_plane("Floor", 6.0, diffuse("Floor", (0.3, 0.3, 0.3)))
    add_sphere("GlassSphere", 0.5, glass(), location=(0.0, 0.0, 1.6))
    box = add_box("Box", 0.6, diffuse("Box", (0.8, 0.7, 0.5)), location=(0.0, 0.0, 0.3))
    keyframes(box, "location", [(0, (-1.6, 0.0, 0.3)), (2, (1.6, 0.0, 0.3))])   # 1.6 m per frame along +X
    point_light("Key", 300.0, (0.0, 0.0, 3.5), radius=0.05)
    area_light("Fill", 60.0, (0.0, -2.5, 0.8), 1.0, rotation=(math.radians(90.0), 0.0, 0.0))  # shows the box's front
    camera((0.0, -5.0, 3.0), (60.0, 0.0, 0.0))
    return finish(scene, path)


if __name__ == "__main__":
    print(build(out_path("moving_receiver.blend")))
