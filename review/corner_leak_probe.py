"""A sunlit concave corner against Cycles: which photons a wall's look-ups read near the corner.

python review/corner_leak_probe.py [FRONT ...] [--window | --thick T [--sealed]] [--back B] [--fg N] [--spp N]

Default: two perpendicular 4 x 2.5 m planes (A: y = 0, facing +y; B: x = 0, facing +x) on a 4 x 4 m
floor, grey diffuse (0.8, roughness 1, no specular), black world; a sun from toward (0.05, 1, 0.8)
lights A at cos 0.78 and B at grazing cos 0.039.  --window: a room corner of planes (a ceiling at
2.5 m, a 1.2 x 0.9 m window in A) lit by the sun through the window onto the floor.  --thick T: the
same room built as the kitchen (review/make_interior5.py) is, of boxes: walls T thick meeting at the
inner corner line, the outer corner's T x T notch open (--sealed: B's box fills it), floor and
ceiling boxes not covering the walls; the sun lights the outside and comes in through the window.
The camera looks into the corner: the image's left half is A, its right half B, the corner the
middle column.  Cycles 256 spp (12 bounces, one render, cached in review/out/corner_cycles_<tag>.npy);
STPM TEMPORAL, k 100, 400 k global photons, 16 spp, seeds 0-2 averaged, once per FRONT value
(estimators.PLANE_FRONT; inf = main's one-sided slab), --back B: estimators.PLANE_FRACTION.
Prints STPM / Cycles of 4-column bands over rows 10-60 (the walls); measured numbers in
docs/photon-mapping.md, "Tangent slab" ("Open outer corners").
"""
import math
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE.parent / "tests"))
import bpy  # noqa: E402
from mathutils import Vector  # noqa: E402

from test_addon_scenes import add_camera, add_light, add_mesh, fresh, set_world  # noqa: E402
from cycles_ref import render_cycles, render_stpm  # noqa: E402
from stpm_core.photons import estimators  # noqa: E402

W, H = 128, 96
SEEDS = (0, 1, 2)                  # STPM renders averaged (each its own photons)
SEALED = "--sealed" in sys.argv       # box walls: B's box fills the outer corner's notch
SUN_TO = (0.05, 1.0, 0.8)


def rect(name, mat, centre, size, normal_axis):
    """An axis-aligned rectangle: centre (3,), size (2,) along the two other axes in x, y, z order."""
    rot = {"z": (0, 0, 0), "y": (math.radians(90), 0, 0), "x": (0, math.radians(90), 0)}[normal_axis]
    # local (x, y) of the plane -> world: z-normal (x, y); y-normal (x, z); x-normal (-z, y)
    scale = {"z": (size[0], size[1], 1), "y": (size[0], size[1], 1), "x": (size[1], size[0], 1)}[normal_axis]
    o = add_mesh("plane", name, location=centre, material=mat, size=1.0)
    o.scale, o.rotation_euler = scale, rot
    return o


def box(name, mat, lo, hi):
    """An axis-aligned box from corner lo to corner hi (m)."""
    o = add_mesh("cube", name, location=tuple((a + b) / 2 for a, b in zip(lo, hi)), material=mat, size=1.0)
    o.scale = tuple(b - a for a, b in zip(lo, hi))
    return o


def corner_scene(window=False, thick=0.0):
    """window=False: the open corner lit by a grazing sun (SUN_TO).  window=True: a room corner
    (floor, ceiling at 2.5 m, walls A and B) with a 1.2 x 0.9 m window in A; the sun comes in
    through it onto the floor in the middle of the room, the corner lit indirectly (the kitchen)."""
    scene = fresh()
    scene.render.resolution_x, scene.render.resolution_y = W, H
    set_world((0.0, 0.0, 0.0), 0.0)
    grey = bpy.data.materials.new("Grey")
    p = grey.node_tree.nodes["Principled BSDF"]
    p.inputs["Base Color"].default_value = (0.8, 0.8, 0.8, 1.0)
    p.inputs["Roughness"].default_value = 1.0
    p.inputs["Specular IOR Level"].default_value = 0.0
    if thick > 0.0:
        # the kitchen's build: box walls meeting at the inner corner line, the outer corner's
        # thick x thick notch open (x, y in [-thick, 0]); the sun comes in through the window in A
        # and lights A's outer face and the notch's faces
        t = thick
        box("Floor", grey, (0, 0, -0.1), (4, 4, 0))
        box("Ceiling", grey, (0, 0, 2.5), (4, 4, 2.6))
        box("WallB", grey, (-t, -t if SEALED else 0, 0), (0, 4, 2.5))
        box("WallA0", grey, (0, -t, 0), (1.8, 0, 2.5))
        box("WallA1", grey, (3.0, -t, 0), (4, 0, 2.5))
        box("WallA2", grey, (1.8, -t, 0), (3.0, 0, 1.0))
        box("WallA3", grey, (1.8, -t, 1.9), (3.0, 0, 2.5))
        to = Vector((0.6, -1.5, 0.78))
        window = None
    else:
        rect("Floor", grey, (2, 2, 0), (4, 4), "z")
        rect("WallB", grey, (0, 2, 1.25), (4, 2.5), "x")
    if window is None:
        pass
    elif window:
        rect("Ceiling", grey, (2, 2, 2.5), (4, 4), "z")
        rect("WallA0", grey, (0.9, 0, 1.25), (1.8, 2.5), "y")
        rect("WallA1", grey, (3.5, 0, 1.25), (1.0, 2.5), "y")
        rect("WallA2", grey, (2.4, 0, 0.5), (1.2, 1.0), "y")
        rect("WallA3", grey, (2.4, 0, 2.2), (1.2, 0.6), "y")
        to = Vector((0.5, -1.0, 0.8))
    else:
        rect("WallA", grey, (2, 0, 1.25), (4, 2.5), "y")
        to = Vector(SUN_TO)
    sun = add_light("SUN", "Sun", location=(1, 3, 3), energy=3.0 if window is False else 10.0, angle=math.radians(1))
    sun.rotation_euler = to.normalized().to_track_quat("Z", "Y").to_euler()
    eye = Vector((3.0, 3.0, 1.3))
    cam = add_camera(location=tuple(eye), lens=24)
    cam.rotation_euler = (Vector((0, 0, 1.0)) - eye).to_track_quat("-Z", "Y").to_euler()
    return scene


def bands(img, ref, cols=4):
    """(STPM / Cycles) of cols-wide column bands over rows 10 .. 60 (walls above the floor)."""
    x, c = img[..., 10:60, :, :].mean(axis=(0, 1, 3)), ref[..., 10:60, :, :].mean(axis=(0, 1, 3))
    n = W // cols
    return x[:n * cols].reshape(n, cols).mean(1) / c[:n * cols].reshape(n, cols).mean(1)


def main():
    args = sys.argv[1:]
    fg = int(args[args.index("--fg") + 1]) if "--fg" in args else 0
    spp = int(args[args.index("--spp") + 1]) if "--spp" in args else 16
    fronts = [float(a) for i, a in enumerate(args) if not a.startswith("--") and (i == 0 or args[i - 1] not in ("--fg", "--spp", "--thick", "--back"))]
    fronts = fronts or [np.inf]
    out = HERE / "out"
    out.mkdir(exist_ok=True)
    window = "--window" in args
    thick = float(args[args.index("--thick") + 1]) if "--thick" in args else 0.0
    tag = f"boxes{thick}" if thick else "window" if window else "open"
    scene = corner_scene(window, thick)
    cpath = out / f"corner_cycles_{tag}{'_sealed' * SEALED}.npy"
    if cpath.exists():
        ref = np.load(cpath)
    else:
        t = time.time()
        ref = render_cycles(scene, out, samples=256, seeds=(0,), max_bounces=12)
        np.save(cpath, ref)
        print(f"cycles {time.time() - t:.0f} s")
    mid = W // 8
    back = float(args[args.index("--back") + 1]) if "--back" in args else estimators.PLANE_FRACTION
    estimators.PLANE_FRACTION = back
    tag += "_sealed" * SEALED + f"_back{back}"
    for f in fronts:
        estimators.PLANE_FRONT = f
        scene = corner_scene(window, thick)
        t = time.time()
        img, _ = render_stpm(scene, samples=spp, seeds=SEEDS, photons_global=400_000, k_nearest=100,
                             estimator="TEMPORAL", final_gather_samples=fg, diffuse_bounces=12)
        np.save(out / f"corner_stpm_{tag}_{f}_fg{fg}.npy", img)
        r = bands(img, ref)
        np.set_printoptions(linewidth=200, precision=2, suppress=True)
        print(f"FRONT {f} fg {fg}: {time.time() - t:.0f} s; whole {img.mean() / ref.mean():.3f}; "
              f"A left of corner {r[:mid].round(2)}; B right {r[mid:].round(2)}", flush=True)


if __name__ == "__main__":
    main()
