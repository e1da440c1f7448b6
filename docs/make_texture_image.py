"""Render the textured-room picture of the README and docs/blender.md: STPM next to Cycles.

Opens ``blend_scenes/textured_room.blend`` with bpy, renders it with Cycles (CPU, 256 samples,
no denoising) and with STPM through the add-on's exporter (16 samples, 200k caustic + 200k global
photons), both at 200 x 150, and writes ``docs/images/textured_room_stpm_vs_cycles.png`` (STPM left,
Cycles right, Standard view transform: the sRGB curve of the clipped linear image, shown 2x).
Prints each render's seconds and image mean.

    .venv/bin/python docs/make_texture_image.py      # about a minute on 2 cores
"""
from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "tests"))

W, H = 200, 150


def _standard(x: np.ndarray) -> np.ndarray:
    """Blender's Standard view transform without the sRGB curve: clipped linear values
    (``write_png`` applies the curve; applying it here too washed the picture out)."""
    return np.clip(x, 0.0, 1.0)


def main() -> int:
    import bpy
    import addon
    from cycles_ref import render_cycles, render_stpm
    from stpm_core.imageio import write_png
    addon.register()
    bpy.ops.wm.open_mainfile(filepath=os.path.join(ROOT, "blend_scenes", "textured_room.blend"))
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = W, H, 100
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        cyc = render_cycles(scene, Path(tmp), samples=256, seeds=(0,), max_bounces=12)[0]
        t_cyc = time.perf_counter() - t0
    t0 = time.perf_counter()
    stpm, res = render_stpm(scene, samples=16, seeds=(0,), photons_global=200_000, photons_caustic=200_000)
    t_stpm = time.perf_counter() - t0
    stpm = stpm[0]
    print(f"Cycles 256 spp: {t_cyc:.1f} s, mean RGB {np.round(cyc.mean(axis=(0, 1)), 4)}")
    print(f"STPM 16 spp + photons: {t_stpm:.1f} s, mean RGB {np.round(stpm.mean(axis=(0, 1)), 4)}; "
          f"warnings: {res.warnings}")
    side = np.concatenate([_standard(stpm), np.ones((H, 4, 3)), _standard(cyc)], axis=1)
    side = np.repeat(np.repeat(side, 2, axis=0), 2, axis=1)
    out = os.path.join(ROOT, "docs", "images", "textured_room_stpm_vs_cycles.png")
    write_png(out, side.astype(np.float32))
    print(out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
