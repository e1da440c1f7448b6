"""Render the picture of docs/lights-and-materials.md, "World": a scene lit by the world alone.

A grey floor, a glass sphere and a diffuse box under a constant white world of radiance 0.8
(no lamp): left, direct light only; right, with world photons (indirect light and the sphere's
soft sky caustic).  Prints each render's mean and seconds.

    .venv/bin/python docs/make_world_image.py      # about 20 s on 2 cores
"""
from __future__ import annotations

import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "tests"))

from scenes import box_mesh, make_scene, persp_camera, plane_mesh, sphere_mesh, translate  # noqa: E402
from stpm_core.imageio import write_png  # noqa: E402
from stpm_core.render import render  # noqa: E402
from stpm_core.scene import Material  # noqa: E402
from stpm_core.settings import RenderSettings  # noqa: E402


def main() -> int:
    mats = [Material.diffuse((0.7, 0.7, 0.7)), Material.glass(1.5), Material.diffuse((0.8, 0.3, 0.2))]
    scene = make_scene([plane_mesh(12.0), (sphere_mesh(0.6, 32, 64, material=1), translate(-0.7, 0.0, 0.6)),
                        (box_mesh((-0.4, -0.4, 0.0), (0.4, 0.4, 0.8), material=2), translate(0.9, 0.3, 0.0))],
                       mats, persp_camera((0.0, -5.0, 2.6), (0.1, 0.0, 0.4), lens=40.0), [],
                       world=(0.8, 0.8, 0.8), resolution=(320, 200))
    panels = []
    for label, kw in (("direct only", dict(photons_caustic=0, photons_global=0, caustics=False, indirect=False)),
                      ("with world photons", dict(photons_caustic=400_000, photons_global=400_000,
                                                  caustics=True, indirect=True))):
        t0 = time.perf_counter()
        r = render(scene, RenderSettings(samples=32, effects="MANUAL", seed=1, **kw))
        rgb = r.passes["Combined"][..., :3]
        print(f"{label:20s} mean {rgb.mean():.4f}  Indirect {r.passes['Indirect'].mean():.4f}  "
              f"Caustic {r.passes['Caustic'].mean():.4f}  {time.perf_counter() - t0:.1f} s")
        panels.append(rgb)
    out = os.path.join(ROOT, "docs", "images", "world_light.png")
    write_png(out, np.hstack(panels))
    print("wrote", out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
