"""Direct light against Cycles: per-pixel variance ratio STPM / Cycles at equal samples (issue 14, item 6).

Scenes: ``tests/direct_light_scenes.py`` (a diffuse room corner lit by a rectangle, an emissive
quad, a disc and an ellipse, a sphere light and a spot of radius 0.3, several lights of very
different power).  Direct light only: Cycles with ``max_bounces = 0``, STPM without photons and
``max_depth = 1`` (diffuse walls end the path); ``--spp`` samples, ``--seeds`` seeds each.

Per scene: the block Z-test (``tests/cycles_ref.block_ztest``), the median over lit pixels of
the per-pixel variance over seeds STPM / Cycles (``cycles_ref.lit_variance_ratio``), STPM's render
seconds, and PNGs of seed 0 side by side (``--out``).  Cycles' images are cached in ``--out``
(keyed by scene, spp, seeds) so a change to STPM reruns only STPM.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_direct_light.py --scenes area_rect mesh_panel
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))


def _png(img: np.ndarray, path: Path, exposure: float) -> None:
    from stpm_core.imageio import write_png
    write_png(str(path), img * exposure)


def main(argv=None) -> int:
    import bpy
    import direct_light_scenes as dls
    from cycles_ref import block_ztest, lit_variance_ratio, render_cycles, render_stpm

    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", nargs="*", default=list(dls.SCENES))
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--seeds", type=int, default=6)
    ap.add_argument("--out", default=str(ROOT / "bench_out" / "direct_light"))
    ap.add_argument("--tag", default="")
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    seeds = tuple(range(a.seeds))
    for name in a.scenes:
        dls.build(name)
        scene = bpy.context.scene
        cache = out / f"cycles_{name}_{a.spp}_{a.seeds}.npy"
        if cache.exists():
            cyc = np.load(cache)
        else:
            cyc = render_cycles(scene, out, samples=a.spp, seeds=seeds, max_bounces=0)
            np.save(cache, cyc)
        render_stpm(scene, samples=1, seeds=(0,), max_depth=1)           # kernels loaded
        t0 = time.perf_counter()
        stpm, _ = render_stpm(scene, samples=a.spp, seeds=seeds, max_depth=1)
        sec = (time.perf_counter() - t0) / len(seeds)
        r = block_ztest(stpm, cyc)
        med, n_lit = lit_variance_ratio(stpm, cyc)
        print(f"{name:12s} {a.tag:8s} var ratio median {med:7.2f} ({n_lit} px) | {r.summary()} | "
              f"STPM {sec:.2f} s/seed", flush=True)
        expo = 0.5 / max(float(np.percentile(cyc[0].mean(axis=-1), 95)), 1e-6)
        _png(cyc[0], out / f"{name}_cycles.png", expo)
        _png(stpm[0], out / f"{name}_stpm{a.tag}.png", expo)
        np.save(out / f"stpm_{name}_{a.spp}_{a.seeds}{a.tag}.npy", stpm)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
