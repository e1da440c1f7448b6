"""Build ``cornell_moving_cube.blend``: a Cornell box whose cube slides during the shutter (indirect light).

A 2 m room open toward the camera: white floor, ceiling and back wall, red
left and green right walls, a small area light under the ceiling.  A white
cube moves 0.4 m along +X during the 0.5-frame shutter: its motion blur shows
in direct light, in its colour bleeding, and in the indirect light it blocks.

    .venv/bin/python blend_scenes/make_cornell_moving_cube.py [OUT.blend]
"""
from __future__ import annotations

import math

from _common import add_box, add_plane, area_light, camera, diffuse, finish, keyframes, new_scene, out_path


def build(path):
    scene = new_scene("CornellMovingCube")
    white, red, green = diffuse("White", (0.75, 0.75, 0.75)), diffuse("Red", (0.7, 0.1, 0.1)), diffuse("Green", (0.1, 0.6, 0.1))
    add_plane("Floor", 2.0, white, location=(0, 0, 0))
    add_plane("Ceiling", 2.0, white, location=(0, 0, 2), rotation=(math.pi, 0, 0))
    add_plane("Back", 2.0, white, location=(0, 1, 1), rotation=(math.pi / 2, 0, 0))
    add_plane("Left", 2.0, red, location=(-1, 0, 1), rotation=(0, math.pi / 2, 0))
    add_plane("Right", 2.0, green, location=(1, 0, 1), rotation=(0, -math.pi / 2, 0))
    cube = add_box("Cube", 0.5, white, location=(0.0, 0.1, 0.25))
    cube.rotation_euler[2] = math.radians(20)
    keyframes(cube, "location", [(0, (-0.8, 0.1, 0.25)), (2, (0.8, 0.1, 0.25))])   # 0.8 m per frame
    area_light("Lamp", 60.0, (0, 0, 1.98), 0.5)                  # faces down (-Z)
    camera((0.0, -3.4, 1.0), (90.0, 0.0, 0.0), lens=35.0)
    return finish(scene, path, resolution=(240, 240), world=(0.0, 0.0, 0.0))


if __name__ == "__main__":
    print(build(out_path("cornell_moving_cube.blend")))
