"""Scenes for guided emission (tests/test_photon_guiding.py, benchmarks/bench_guiding.py)."""
from __future__ import annotations

import numpy as np

from scenes import box_mesh, look_at, make_scene, persp_camera, plane_mesh
from stpm_core.motion import MotionTransform
from stpm_core.scene import Light, Material


#: the room's inside (not the window's 0.2 m reveal): a photon whose first hit lies on its faces came through the window
ROOM_INSIDE = ((-2.0, -2.0, 0.0), (2.0, 2.0, 3.0))


def window_room(res=(32, 24), window=(2.0, 1.6), ground=8.0, light: str = "SUN"):
    """A closed 4 x 4 x 3 m room (grey walls 0.2 m thick) with a window (width x height, m) in its
    +x wall, a green ground (ground x ground m) outside and a light outside shining in and down
    (light "SUN": strength 5, angle 0.02 rad; "POINT": 2 kW at (6, 0.3, 4)); the camera inside
    looks at the sunlit floor and the window wall."""
    W = 0.2
    hw, z0 = 0.5 * window[0], 1.6 - 0.5 * window[1]
    z1 = z0 + window[1]
    objs = [plane_mesh(ground, z=-0.2, material=1, name="ground"),
            box_mesh((-2 - W, -2 - W, -W), (2 + W, 2 + W, 0.0), material=0, name="floor"),
            box_mesh((-2 - W, -2 - W, 3.0), (2 + W, 2 + W, 3.0 + W), material=0, name="roof"),
            box_mesh((-2 - W, -2 - W, 0.0), (-2.0, 2 + W, 3.0), material=0, name="wall-x"),
            box_mesh((-2.0, -2 - W, 0.0), (2.0, -2.0, 3.0), material=0, name="wall-y"),
            box_mesh((-2.0, 2.0, 0.0), (2.0, 2 + W, 3.0), material=0, name="wall+y"),
            box_mesh((2.0, -2 - W, 0.0), (2 + W, 2 + W, z0), material=0, name="wall+x-low"),
            box_mesh((2.0, -2 - W, z1), (2 + W, 2 + W, 3.0), material=0, name="wall+x-high"),
            box_mesh((2.0, -2 - W, z0), (2 + W, -hw, z1), material=0, name="wall+x-left"),
            box_mesh((2.0, hw, z0), (2 + W, 2 + W, z1), material=0, name="wall+x-right")]
    mats = [Material(base_color=np.array([0.7, 0.7, 0.7]), roughness=1.0),
            Material(base_color=np.array([0.3, 0.5, 0.2]), roughness=1.0)]
    pose = MotionTransform.static(look_at((6, 0.3, 4.0), (0, 0, 0)))
    if light == "SUN":
        lamp = Light(type="SUN", power=5.0, angle=0.02, transform=pose)
    else:
        lamp = Light(type=light, power=2000.0, transform=pose)
    cam = persp_camera((-1.8, -1.5, 1.6), (1.0, 0.8, 0.6), lens=20.0)
    return make_scene(objs, mats, cam, [lamp], resolution=res)
