"""Pictures for docs/shader-nodes.md and docs/blender.md: UDIM tiles and a Blender 5 working space,
STPM next to Cycles.

Both scenes are tests/test_cycles_udim_spaces.py's (built with bpy as an artist builds them),
rendered direct-only by both renderers at the same sample count and written side by side (sRGB
preview, pixels enlarged) to docs/images/:

* ``udim_stpm_vs_cycles.png`` -- a plane whose UV map spans UDIM tiles 1001 (a red checker, 8 x 8
  texels), 1002 (green stripes, 6 x 6), 1011 (a blue gradient, 5 x 5; 8-bit sRGB PNGs, Closest) and
  1012 (listed, no file: magenta in both);
* ``working_space_acescg_stpm_vs_cycles.png`` -- an ACEScg file: an sRGB photo under a warm sun and
  an emitter driven by RGB to BW of it; STPM, Cycles, and (right) STPM reading the file as Linear
  Rec.709 (what it did before: no conversion).  Shown through Blender's Standard view (the working
  space converted to Rec.709, then sRGB-encoded).

Run: ``PYTHONPATH=.:tests .venv/bin/python docs/make_udim_image.py [--out DIR] [--spp N] [--quick]``.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]


def _save(path: Path, panels, scale: int, working: str = "REC709") -> None:
    from stpm_core.imageio import write_png
    gap = np.ones((panels[0].shape[0], 2, 3))
    row = [panels[0]]
    for p in panels[1:]:
        row += [gap, p]
    a = np.concatenate(row, axis=1)
    write_png(path, np.repeat(np.repeat(a, scale, axis=0), scale, axis=1), working=working)


def _checker(n, a, b):
    i, j = np.meshgrid(np.arange(n), np.arange(n))
    return np.where(((i + j) % 2 == 0)[..., None], a, b)


def _stripes(n, a, b):
    i, _j = np.meshgrid(np.arange(n), np.arange(n))
    return np.where((i % 2 == 0)[..., None], a, b)


def _gradient(n, a, b):
    i, j = np.meshgrid(np.arange(n), np.arange(n))
    t = ((i + j) / (2.0 * (n - 1)))[..., None]
    return (1.0 - t) * np.asarray(a) + t * np.asarray(b)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "docs" / "images"))
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--quick", action="store_true", help="48 x 48, 8 samples (tests)")
    args = ap.parse_args(argv)
    import bpy
    import cycles_ref
    import test_cycles_udim_spaces as U
    import test_cycles_textures as T
    from addon.export import nodes as node_export
    size, spp, scale = (48, 8, 1) if args.quick else (96, args.spp, 3)
    saved = (T.W, T.H, U._pattern)
    T.W = T.H = size
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    try:
        _render(out, spp, scale, bpy, cycles_ref, U, node_export)
    finally:
        T.W, T.H, U._pattern = saved                     # the test modules as they were
    return 0


def _render(out: Path, spp: int, scale: int, bpy, cycles_ref, U, node_export) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        # UDIM: four tiles, one missing; each tile a pattern of its own (Closest: crisp texels)
        patterns = iter([_checker(8, (0.8, 0.15, 0.1), (0.95, 0.9, 0.8)),
                         _stripes(6, (0.1, 0.6, 0.2), (0.9, 0.95, 0.85)),
                         _gradient(5, (0.1, 0.2, 0.8), (0.7, 0.9, 1.0))])
        U._pattern = lambda n, seed: next(patterns)
        U._top_down_scene()
        U._udim_plane(tmp, "Closest")
        cyc = cycles_ref.render_cycles(bpy.context.scene, tmp, samples=spp, seeds=(0, 1, 2))
        st, _ = cycles_ref.render_stpm(bpy.context.scene, samples=spp, seeds=(0, 1, 2))
        r = cycles_ref.block_ztest(st, cyc)
        _save(out / "udim_stpm_vs_cycles.png", [st[0], cyc[0]], scale)
        print(f"udim: mean ratio STPM / Cycles {r.mean_ratio:.4f}, block |z| max {r.z_abs_max:.2f}")
        # ACEScg working space
        U._working_space_scene(tmp, "ACEScg")
        cyc = cycles_ref.render_cycles(bpy.context.scene, tmp, samples=spp, seeds=(0, 1, 2))
        st, _ = cycles_ref.render_stpm(bpy.context.scene, samples=spp, seeds=(0, 1, 2))
        old = node_export.working_space
        try:
            node_export.working_space = lambda: "REC709"
            as709, _ = cycles_ref.render_stpm(bpy.context.scene, samples=spp, seeds=(0, 1, 2))
        finally:
            node_export.working_space = old
        r, r709 = cycles_ref.block_ztest(st, cyc), cycles_ref.block_ztest(as709, cyc)
        _save(out / "working_space_acescg_stpm_vs_cycles.png", [st[0], cyc[0], as709[0]], scale, working="ACESCG")
        print(f"acescg: mean ratio STPM / Cycles {r.mean_ratio:.4f}, block |z| max {r.z_abs_max:.2f}; "
              f"read as Rec.709: mean ratio {r709.mean_ratio:.4f}, block |z| max {r709.z_abs_max:.2f}")


if __name__ == "__main__":
    sys.exit(main())
