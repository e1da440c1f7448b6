"""A closed room lit by the world through one window, with or without a light portal in it.

The room is the box [-1, 1] x [-1, 1] x [0, 2] (walls of zero thickness, white diffuse); the wall
x = +1 has a square opening y in [-0.4, 0.4], z in [0.8, 1.6] (the window); the portal is a
0.8 x 0.8 AREA light filling it, shining into the room (-x).  Shared by tests/test_portals.py and
benchmarks/bench_portals.py.
"""
from __future__ import annotations

import numpy as np

from stpm_core.motion import MotionTransform
from stpm_core.scene import Light, Material, Mesh, World

from scenes import make_scene, persp_camera, point_light, sphere_mesh, translate

__all__ = ["WINDOW", "room_mesh", "portal_light", "room_scene", "inside"]

WINDOW = (-0.4, 0.4, 0.8, 1.6)            # y0, y1, z0, z1 of the opening in the wall x = +1


def _quad(v, a, b, c, d):
    return [[v.index(a), v.index(b), v.index(c)], [v.index(a), v.index(c), v.index(d)]]


def room_mesh() -> Mesh:
    """The room's five closed walls and the window wall with its opening (triangles, two-sided)."""
    quads = [
        [(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)],          # floor
        [(-1, -1, 2), (-1, 1, 2), (1, 1, 2), (1, -1, 2)],          # ceiling
        [(-1, -1, 0), (-1, 1, 0), (-1, 1, 2), (-1, -1, 2)],        # x = -1
        [(-1, -1, 0), (-1, -1, 2), (1, -1, 2), (1, -1, 0)],        # y = -1
        [(-1, 1, 0), (1, 1, 0), (1, 1, 2), (-1, 1, 2)],            # y = +1
    ]
    y0, y1, z0, z1 = WINDOW
    # the window wall x = +1: four rectangles around the opening
    for (ya, yb, za, zb) in ((-1, 1, 0, z0), (-1, 1, z1, 2), (-1, y0, z0, z1), (y1, 1, z0, z1)):
        quads.append([(1, ya, za), (1, yb, za), (1, yb, zb), (1, ya, zb)])
    verts, tris = [], []
    for q in quads:
        base = len(verts)
        verts += q
        tris += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    return Mesh(vertices=np.array(verts, np.float32), triangles=np.array(tris, np.int32),
                material_ids=np.zeros(len(tris), np.int32), name="room")


def portal_light(shrink: float = 1.0) -> Light:
    """The portal: a SQUARE AREA light filling the window, its -Z (emitting side) toward -x."""
    y0, y1, z0, z1 = WINDOW
    M = np.eye(4)
    M[:3, 0] = (0.0, 1.0, 0.0)          # local x -> world y
    M[:3, 1] = (0.0, 0.0, 1.0)          # local y -> world z
    M[:3, 2] = (1.0, 0.0, 0.0)          # local z -> world +x: it shines along -x, into the room
    M[:3, 3] = (1.0, 0.5 * (y0 + y1), 0.5 * (z0 + z1))
    return Light(type="AREA", power=0.0, shape="SQUARE", size=(y1 - y0) * shrink,
                 transform=MotionTransform.static(M), name="portal")


def room_scene(*, portal: bool, world=(1.0, 1.0, 1.0), image=None, lamp: float = 0.0, resolution=(32, 24),
               albedo: float = 0.7, metal_ball: float = 0.0, camera=None):
    """The room seen from inside (camera near the wall x = -1, looking at the window wall and the
    floor); constant world ``world`` or an environment image (H, W, 3); ``lamp`` > 0 adds a point
    light of that power under the ceiling; ``metal_ball`` > 0 a rough metal sphere of that roughness
    on the floor (its reflection of the window is found by next-event estimation and by the
    lobe's own samples, weighed by multiple importance sampling); camera: (eye, target, lens) to
    look elsewhere."""
    lights = [point_light((-0.5, 0.3, 1.7), lamp)] if lamp > 0 else []
    objects = [room_mesh()]
    mats = [Material(base_color=np.full(3, albedo), specular=0.0, roughness=1.0)]
    if metal_ball > 0:
        objects.append((sphere_mesh(0.4, material=1, name="ball"), translate(0.1, 0.1, 0.4)))
        mats.append(Material(base_color=np.full(3, 0.9), metallic=1.0, roughness=metal_ball))
    cam = persp_camera(*(camera or ((-0.9, -0.6, 1.3), (1.0, 0.2, 0.7), 18.0)))
    sc = make_scene(objects, mats, cam, lights, world=world, resolution=resolution)
    if image is not None:
        sc.world = World(color=np.ones(3), strength=1.0, image=np.ascontiguousarray(image, np.float32))
    if portal:
        sc.portals = [portal_light()]
    return sc


def inside(pos: np.ndarray) -> np.ndarray:
    """(n,) bool: positions (n, 3) inside the room (walls included)."""
    e = 1e-3
    return ((pos[:, 0] >= -1 - e) & (pos[:, 0] <= 1 + e) & (pos[:, 1] >= -1 - e) & (pos[:, 1] <= 1 + e)
            & (pos[:, 2] >= -e) & (pos[:, 2] <= 2 + e))
