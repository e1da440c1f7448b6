"""Tiny test scenes: meshes (plane, box, sphere), cameras, motion, one-call scene builder.

Shared by the test files of every module (import as ``from scenes import ...``
from inside tests/, or ``tests.scenes``).  Everything is small and exact, so
analytic answers are easy to derive.
"""
from __future__ import annotations

import numpy as np

from stpm_core.motion import MotionTransform
from stpm_core.scene import Camera, Instance, Light, Material, Mesh, Scene, World
from stpm_core.shutter import Shutter

__all__ = ["plane_mesh", "box_mesh", "sphere_mesh", "translate", "look_at", "moving",
           "ortho_camera_down", "persp_camera", "make_scene", "point_light"]


# ----------------------------------------------------------------------------
# Meshes
# ----------------------------------------------------------------------------
def plane_mesh(size_x: float = 10.0, size_y: float | None = None, z: float = 0.0, material: int = 0,
               flip: bool = False, name: str = "plane") -> Mesh:
    """Axis-aligned rectangle centred at (0, 0, z), geometric normal +Z (-Z if flip)."""
    sy = size_x if size_y is None else size_y
    hx, hy = 0.5 * size_x, 0.5 * sy
    v = np.array([[-hx, -hy, z], [hx, -hy, z], [hx, hy, z], [-hx, hy, z]], np.float32)
    tri = np.array([[0, 1, 2], [0, 2, 3]], np.int32)
    if flip:
        tri = tri[:, ::-1].copy()
    return Mesh(vertices=v, triangles=tri, material_ids=np.full(2, material, np.int32), name=name)


def box_mesh(lo=(-0.5, -0.5, -0.5), hi=(0.5, 0.5, 0.5), material: int = 0, name: str = "box") -> Mesh:
    """Axis-aligned box with outward-facing triangles (12 triangles)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    c = np.array([[x, y, z] for z in (lo[2], hi[2]) for y in (lo[1], hi[1]) for x in (lo[0], hi[0])], np.float32)
    # corner index = 4*iz + 2*iy + ix
    quads = [(0, 2, 3, 1),  # -z
             (4, 5, 7, 6),  # +z
             (0, 1, 5, 4),  # -y
             (2, 6, 7, 3),  # +y
             (0, 4, 6, 2),  # -x
             (1, 3, 7, 5)]  # +x
    tri = []
    for a, b, cc, d in quads:
        tri += [(a, b, cc), (a, cc, d)]
    return Mesh(vertices=c, triangles=np.array(tri, np.int32),
                material_ids=np.full(12, material, np.int32), name=name)


def sphere_mesh(radius: float = 1.0, n_theta: int = 24, n_phi: int = 48, material: int = 0,
                smooth: bool = True, name: str = "sphere") -> Mesh:
    """UV sphere centred at the origin, outward winding, optional smooth normals."""
    th = np.linspace(0.0, np.pi, n_theta + 1)
    ph = np.linspace(0.0, 2 * np.pi, n_phi, endpoint=False)
    T, P = np.meshgrid(th, ph, indexing="ij")
    v = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1).reshape(-1, 3)
    tri = []
    for i in range(n_theta):
        for j in range(n_phi):
            a, b = i * n_phi + j, i * n_phi + (j + 1) % n_phi
            c, d = a + n_phi, b + n_phi
            if i > 0:
                tri.append((a, c, b))
            if i < n_theta - 1:
                tri.append((b, c, d))
    tri = np.array(tri, np.int32)
    normals = v[tri].astype(np.float32) if smooth else None
    return Mesh(vertices=(radius * v).astype(np.float32), triangles=tri,
                material_ids=np.full(len(tri), material, np.int32), normals=normals, name=name)


# ----------------------------------------------------------------------------
# Transforms
# ----------------------------------------------------------------------------
def translate(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> np.ndarray:
    """4x4 translation matrix."""
    M = np.eye(4)
    M[:3, 3] = (x, y, z)
    return M


def moving(start, end) -> MotionTransform:
    """Translation moving linearly from ``start`` (3,) at t=0 to ``end`` (3,) at t=1."""
    return MotionTransform(times=np.array([0.0, 1.0]), matrices=np.stack([translate(*start), translate(*end)]))


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Camera/light-to-world matrix looking from eye to target (local -Z forward, +Y up)."""
    eye, target, up = (np.asarray(a, float) for a in (eye, target, up))
    f = target - eye
    f /= np.linalg.norm(f)
    if abs(np.dot(f, up)) > 0.999:
        up = np.array([0.0, 1.0, 0.0])
    x = np.cross(f, up)
    x /= np.linalg.norm(x)
    y = np.cross(x, f)
    M = np.eye(4)
    M[:3, 0], M[:3, 1], M[:3, 2], M[:3, 3] = x, y, -f, eye
    return M


def ortho_camera_down(height: float = 5.0, ortho_scale: float = 2.0, center=(0.0, 0.0)) -> Camera:
    """Orthographic camera above (center, height) looking straight down -Z; image +x = world +x, up = world +y."""
    M = translate(center[0], center[1], height)
    return Camera(type="ORTHO", transform=MotionTransform.static(M), ortho_scale=ortho_scale,
                  clip_start=0.01, clip_end=100.0)


def persp_camera(eye, target, lens: float = 50.0, up=(0.0, 0.0, 1.0)) -> Camera:
    """Perspective camera at eye looking at target."""
    return Camera(type="PERSP", transform=MotionTransform.static(look_at(eye, target, up)), lens=lens,
                  clip_start=0.01, clip_end=1000.0)


# ----------------------------------------------------------------------------
# Scenes
# ----------------------------------------------------------------------------
def make_scene(objects, materials, camera: Camera, lights=(), *, world=(0.0, 0.0, 0.0),
               resolution=(32, 32), shutter: Shutter | None = None, metadata=None) -> Scene:
    """Scene from ``objects``: a list of Mesh or (Mesh, MotionTransform | 4x4 matrix) pairs."""
    meshes, instances = [], []
    for obj in objects:
        mesh, tr = (obj, None) if isinstance(obj, Mesh) else obj
        if tr is None:
            tr = MotionTransform.static()
        elif not isinstance(tr, MotionTransform):
            tr = MotionTransform.static(np.asarray(tr, float))
        instances.append(Instance(mesh=len(meshes), transform=tr, name=mesh.name))
        meshes.append(mesh)
    return Scene(meshes=meshes, instances=instances, camera=camera, lights=list(lights),
                 materials=list(materials), world=World(color=np.asarray(world, float), strength=1.0),
                 shutter=shutter or Shutter(1.0, 1.0), resolution=tuple(resolution),
                 metadata=dict(metadata or {}))


def point_light(pos, power: float, color=(1.0, 1.0, 1.0), radius: float = 0.0) -> Light:
    """Point light of ``power`` W at pos (intensity color * power / (4 pi) W/sr)."""
    return Light(type="POINT", color=np.asarray(color, float), power=power,
                 transform=MotionTransform.static(translate(*pos)), radius=radius, use_soft_falloff=False)
