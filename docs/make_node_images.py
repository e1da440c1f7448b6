"""Pictures for docs/shader-nodes.md: STPM (left) next to Cycles (right) on the test scenes.

Each scene is one of tests/test_cycles_textures.py's (built with bpy the way an artist builds it),
rendered direct-only by both renderers at the same sample count, written side by side (linear
values sRGB-encoded and clipped, pixels enlarged 4x) to docs/images/:

* ``textured_emitter_stpm_vs_cycles.png`` -- a red / blue image on an emissive "screen" lights
  the floor red on one side, blue on the other;
* ``alpha_cutout_stpm_vs_cycles.png`` -- a leaf cut out by an image's alpha (Principled Alpha) over
  a checker floor, and its shadow.

Run: ``PYTHONPATH=.:tests .venv/bin/python docs/make_node_images.py [--out DIR] [--spp N]``.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]


def _save(path: Path, stpm: np.ndarray, cycles: np.ndarray) -> None:
    from stpm_core.imageio import write_png
    a = np.concatenate([stpm, cycles], axis=1)
    write_png(path, np.repeat(np.repeat(a, 4, axis=0), 4, axis=1))        # sRGB-encoded, clipped


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "docs" / "images"))
    ap.add_argument("--spp", type=int, default=64)
    args = ap.parse_args(argv)
    import bpy
    import test_cycles_textures as T
    from cycles_ref import block_ztest, render_cycles, render_stpm
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        screen = np.zeros((1, 2, 3))
        screen[0, 0], screen[0, 1] = (1.0, 0.15, 0.1), (0.1, 0.2, 1.0)
        T._write_png(tmp / "screen.png", screen)
        T._cutout_image(tmp / "leaf.png")

        def textured_emitter():
            T._screen_scene(tmp / "screen.png")

        def alpha_cutout():
            T._cutout_scene()
            mat, t, o = T._empty_material("Leaf")
            p, tex = t.nodes.new("ShaderNodeBsdfPrincipled"), t.nodes.new("ShaderNodeTexImage")
            tex.image = bpy.data.images.load(str(tmp / "leaf.png"))
            tex.interpolation = "Closest"
            t.links.new(tex.outputs["Color"], p.inputs["Base Color"])
            t.links.new(tex.outputs["Alpha"], p.inputs["Alpha"])
            t.links.new(p.outputs[0], o.inputs["Surface"])
            T.add_mesh("plane", "Leaf", location=(0.1, -0.1, 0.5), material=mat, size=1.2)

        cases = {"textured_emitter": textured_emitter, "alpha_cutout": alpha_cutout}
        for name, build in cases.items():
            build()
            cyc = render_cycles(bpy.context.scene, tmp, samples=args.spp, seeds=(0,))
            st, _ = render_stpm(bpy.context.scene, samples=args.spp, seeds=(0,))
            r = block_ztest(np.concatenate([st, st]), np.concatenate([cyc, cyc]))
            _save(out / f"{name}_stpm_vs_cycles.png", st[0], cyc[0])
            print(f"{name}: mean ratio STPM / Cycles {r.mean_ratio:.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
