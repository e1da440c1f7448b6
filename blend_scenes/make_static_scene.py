"""Build ``static_scene.blend``: nothing moves (a glass sphere and a box on a floor), motion blur on.

The plan: no motion blur, caustics yes, indirect yes (floor and box light
each other), time dependent no -- so the render traces no time-dependent
work: the estimator is STANDARD (exact when nothing moves) and the
motion-blur setting costs nothing (same rays, same photons as with it off).

    .venv/bin/python blend_scenes/make_static_scene.py [OUT.blend]
"""
from __future__ import annotations

from _common import add_box, add_plane, add_sphere, camera, diffuse, finish, glass, new_scene, out_path, point_light


def build(path):
    scene = new_scene("StaticScene")
    add_plane("Floor", 6.0, diffuse("Floor", (0.8, 0.8, 0.8)))
    add_sphere("GlassSphere", 0.5, glass(), location=(-0.4, 0.0, 1.0))
    add_box("Box", 0.7, diffuse("Box", (0.2, 0.4, 0.8)), location=(1.1, 0.4, 0.35))
    point_light("Key", 300.0, (-0.2, -0.3, 3.0), radius=0.05)
    camera((0.0, -5.5, 3.2), (60.0, 0.0, 0.0))
    return finish(scene, path)


if __name__ == "__main__":
    print(build(out_path("static_scene.blend")))
