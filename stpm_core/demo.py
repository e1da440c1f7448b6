"""The demo (``python3 build.py demo`` = ``python -m stpm_core.demo``): a motion-blurred caustic.

A glass sphere slides over a diffuse floor under a small point light during
the shutter; the light focused through the sphere draws a caustic on the
floor that moves with it, which only time-dependent photon mapping renders
both sharp in space and correctly blurred in time.

Where the scene comes from:

1. ``blend_scenes/demo.blend`` through :func:`stpm_core.blend_loader.load_blend`
   (the add-on, Blender's bpy) when both exist, so the demo renders what an
   artist would open;
2. otherwise the same scene built here directly in numpy (:func:`demo_scene`).

Either way it is saved as ``out/demo/demo.stpm`` (the core scene file) and
rendered through the ``stpm render`` command, writing ``out/demo/demo.exr``,
``demo.png`` and ``demo_stats.json``.

Options: ``--core`` forces the numpy scene; ``--out DIR`` changes the output
folder; ``--quick`` renders a small, fast version (for smoke tests).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from .motion import MotionTransform
from .scene import Camera, Instance, Light, Material, Mesh, Scene, World
from .settings import RenderSettings
from .shutter import Shutter

__all__ = ["demo_scene", "demo_settings", "look_at", "uv_sphere", "main"]

ROOT = Path(__file__).resolve().parent.parent
DEMO_BLEND = ROOT / "blend_scenes" / "demo.blend"


# ----------------------------------------------------------------------------
# Geometry helpers
# ----------------------------------------------------------------------------
def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Camera/light-to-world (4, 4) for an object at ``eye`` looking at ``target``.

    Blender convention: the object looks down its local -Z with +Y up, so the
    columns are (right, up, -forward, eye).
    """
    eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
    forward = target - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    true_up = np.cross(right, forward)
    M = np.eye(4)
    M[:3, 0], M[:3, 1], M[:3, 2], M[:3, 3] = right, true_up, -forward, eye
    return M


def translation(x: float, y: float, z: float) -> np.ndarray:
    M = np.eye(4)
    M[:3, 3] = (x, y, z)
    return M


def uv_sphere(radius: float = 1.0, n_lon: int = 48, n_lat: int = 24, material: int = 0) -> Mesh:
    """A UV sphere centred at the origin, outward winding, smooth per-corner normals.

    Returns a Mesh with vertices (V, 3), triangles (F, 3), normals (F, 3, 3).
    """
    theta = np.linspace(0.0, np.pi, n_lat + 1)            # polar angle from +Z
    phi = np.linspace(0.0, 2 * np.pi, n_lon, endpoint=False)
    th, ph = np.meshgrid(theta, phi, indexing="ij")       # (n_lat+1, n_lon)
    n = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1).reshape(-1, 3)
    idx = np.arange((n_lat + 1) * n_lon).reshape(n_lat + 1, n_lon)
    a, b = idx[:-1], np.roll(idx[:-1], -1, axis=1)       # ring i: this and next longitude
    c, d = idx[1:], np.roll(idx[1:], -1, axis=1)          # ring i+1
    # Two triangles per quad, counter-clockwise seen from outside; drop the pole slivers
    t1 = np.stack([a, c, d], -1)[1:].reshape(-1, 3)
    t2 = np.stack([a, d, b], -1)[:-1].reshape(-1, 3)
    tri = np.concatenate([t1, t2]).astype(np.int32)
    V = (radius * n).astype(np.float32)
    N = n[tri].astype(np.float32)
    return Mesh(vertices=V, triangles=tri, material_ids=np.full(len(tri), material, np.int32),
                normals=N, name="sphere")


def quad(size_x: float, size_y: float, material: int = 0, name: str = "floor") -> Mesh:
    """An axis-aligned rectangle in the z = 0 plane facing +Z, centred at the origin."""
    hx, hy = size_x / 2, size_y / 2
    V = np.array([[-hx, -hy, 0], [hx, -hy, 0], [hx, hy, 0], [-hx, hy, 0]], np.float32)
    tri = np.array([[0, 1, 2], [0, 2, 3]], np.int32)
    return Mesh(vertices=V, triangles=tri, material_ids=np.full(2, material, np.int32), name=name)


# ----------------------------------------------------------------------------
# The demo scene and settings
# ----------------------------------------------------------------------------
def demo_scene(resolution=(320, 240)) -> Scene:
    """Glass sphere (r = 0.5, IOR 1.5) moving 1 m along +X during the shutter, 0.3 m over a floor.

    Paraxial focus of a ball lens: f = n R / (2 (n - 1)) = 0.75 m from its
    centre, so with the centre 0.8 m up the caustic is nearly focused on the floor.
    """
    materials = [Material.diffuse((0.8, 0.8, 0.8), name="floor"),
                 Material.glass(ior=1.5, name="glass")]
    meshes = [quad(6.0, 6.0, material=0), uv_sphere(0.5, material=1)]
    sphere_motion = MotionTransform(times=np.array([0.0, 1.0]),
                                    matrices=np.stack([translation(-0.5, 0.0, 0.8), translation(0.5, 0.0, 0.8)]))
    instances = [Instance(mesh=0, name="Floor"), Instance(mesh=1, transform=sphere_motion, name="GlassSphere")]
    camera = Camera(type="PERSP", lens=40.0, sensor_width=36.0, sensor_fit="AUTO",
                    transform=MotionTransform.static(look_at((0.0, -4.2, 2.6), (0.0, 0.0, 0.35))),
                    clip_start=0.1, clip_end=100.0)
    light = Light(type="POINT", color=np.ones(3), power=1500.0, radius=0.05,
                  transform=MotionTransform.static(translation(0.0, 0.3, 4.0)), name="Light")
    return Scene(meshes=meshes, instances=instances, camera=camera, lights=[light],
                 materials=materials, world=World(color=np.full(3, 0.03), strength=1.0),
                 shutter=Shutter(open=0.75, close=1.25), resolution=tuple(resolution), frame=1.0,
                 metadata={"source": "stpm_core.demo", "description": "glass sphere moving over a floor"})


def demo_settings(quick: bool = False) -> RenderSettings:
    """Modest settings: the demo finishes in about a minute on 2 cores."""
    if quick:
        return RenderSettings(samples=2, photons_caustic=20_000, photons_global=5_000, k_nearest=20, seed=1)
    return RenderSettings(samples=16, photons_caustic=200_000, photons_global=50_000, k_nearest=50, seed=1)


def _blend_scene():
    """(Scene, RenderSettings) from blend_scenes/demo.blend through the add-on, or None if unavailable."""
    if not DEMO_BLEND.exists():
        return None
    from .blend_loader import BlendSupportMissing, load_blend
    from .command_common import settings_from_dict, stdout_to_stderr
    try:
        with stdout_to_stderr():  # Blender's log lines
            scene, d = load_blend(DEMO_BLEND, 1)
    except BlendSupportMissing:  # no bpy / add-on here: the numpy scene instead
        return None
    return scene, settings_from_dict(d, DEMO_BLEND.name)


# ----------------------------------------------------------------------------
# Entry point
# ----------------------------------------------------------------------------
def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m stpm_core.demo", description=__doc__.splitlines()[0])
    ap.add_argument("--core", action="store_true", help="use the numpy-built scene even if demo.blend exists")
    ap.add_argument("--out", default=str(ROOT / "out" / "demo"), help="output folder (default out/demo)")
    ap.add_argument("--quick", action="store_true", help="tiny render for smoke tests")
    args = ap.parse_args(argv)

    from .cli import main as cli_main
    from .scenefile import save_scene

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    # -- The scene: the .blend through Blender when possible, else numpy ---------------
    loaded = None if args.core else _blend_scene()
    if loaded is not None:
        scene, settings = loaded
        source = str(DEMO_BLEND)
    else:
        scene, settings = demo_scene(), None
        source = "numpy scene (stpm_core.demo.demo_scene)"
    settings = demo_settings(args.quick) if settings is None or args.quick else settings
    if args.quick:
        scene.resolution = (80, 60)
    scene_path = save_scene(scene, out / "demo.stpm", settings=settings)
    print(f"demo scene: {source}")
    print(f"wrote {scene_path}")

    # -- Render through the command line, exactly as a user would -----------------------
    return cli_main(["render", str(scene_path), "--output", str(out / "demo.exr"),
                     "--stats", str(out / "demo_stats.json")])


if __name__ == "__main__":
    sys.exit(main())
