"""Build ``camera_pan_caustic.blend``: the camera pans across a static glass-sphere caustic.

Everything in the scene is still; only the camera turns 6 degrees during the
0.5-frame shutter.  The plan: motion blur yes, caustics yes, time dependent
no -- the lighting is the same at every instant, so the photons need no time
and the STANDARD estimate is exact (the whole image blurs with the pan).

    .venv/bin/python blend_scenes/make_camera_pan_caustic.py [OUT.blend]
"""
from __future__ import annotations

import math

from _common import add_plane, add_sphere, camera, diffuse, finish, glass, keyframes, new_scene, out_path, point_light


def build(path):
    scene = new_scene("CameraPanCaustic")
    add_plane("Floor", 6.0, diffuse("Floor", (0.8, 0.8, 0.8)))
    add_sphere("GlassSphere", 0.5, glass(), location=(0.0, 0.0, 1.0))
    point_light("Key", 300.0, (0.0, 0.0, 3.0), radius=0.05)
    cam = camera((0.0, -5.5, 3.2), (60.0, 0.0, 0.0))
    keyframes(cam, "rotation_euler", [(0, math.radians(-12.0)), (2, math.radians(12.0))], index=2)  # 12 deg/frame
    return finish(scene, path)


if __name__ == "__main__":
    print(build(out_path("camera_pan_caustic.blend")))
