"""Regenerate the progressive-rendering picture of README.md and docs/blender.md, and print its numbers.

``blend_scenes/moving_receiver.blend`` (a box sliding under a glass sphere's caustic) rendered with
method PROGRESSIVE; the image after passes 1, 4, 16 and 64 side by side, plus the Caustic pass of the
same four at x4 exposure.  Each pass: 100k caustic photons, 2 samples per pixel, k = 10 (the
progressive presets' k).  Writes

* ``docs/images/progressive_passes.png``: Combined after passes 1, 4, 16, 64, left to right;
* ``docs/images/progressive_passes_caustic.png``: their Caustic pass, x4 exposure;

and prints, per shown pass, the seconds so far, the estimated noise and the kernel radius scale.

Run (needs bpy, the ``test`` extra; about 1-2 minutes on 2 cores)::

    .venv/bin/python docs/make_progressive_images.py [--quick]
"""
from __future__ import annotations

import argparse
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from stpm_core.cli import load_any_scene  # noqa: E402
from stpm_core.imageio import write_png  # noqa: E402
from stpm_core.photons.progressive import auto_shrink_alpha, kernel_dims, shrink_ratio  # noqa: E402
from stpm_core.render import render  # noqa: E402

BLEND = os.path.join(ROOT, "blend_scenes", "moving_receiver.blend")
OUT = os.path.join(ROOT, "docs", "images")
SHOWN = (1, 4, 16, 64)
CAUSTIC_EXPOSURE = 4.0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small and fast (a check that the script runs)")
    ap.add_argument("--out", default=OUT, help="directory for the PNGs (default docs/images)")
    args = ap.parse_args(argv)
    scene, settings, _ = load_any_scene(BLEND, 1)
    shown = SHOWN[:3] if args.quick else SHOWN
    if args.quick:
        scene.resolution, base = (60, 45), dict(samples=1, photons_caustic=10_000, photons_global=0)
    else:
        scene.resolution, base = (240, 180), dict(samples=2, photons_caustic=100_000, photons_global=0)
    st = settings.replace(method="PROGRESSIVE", estimator="TEMPORAL", passes=shown[-1], k_nearest=10,
                          time_limit=0.0, noise_threshold=0.0, **base)
    combined, caustic, rows = [], [], []

    def on_pass(img, info):
        if info["pass"] in shown:
            combined.append(img["Combined"][:, :, :3].copy())
            caustic.append(img["Caustic"][:, :, :3].copy())
            rows.append((info["pass"], info["elapsed_s"], info["noise_p95"]))
    result = render(scene, st, on_pass=on_pass)
    os.makedirs(args.out, exist_ok=True)
    write_png(os.path.join(args.out, "progressive_passes.png"), np.hstack(combined))
    write_png(os.path.join(args.out, "progressive_passes_caustic.png"), CAUSTIC_EXPOSURE * np.hstack(caustic))
    a, d = auto_shrink_alpha(result.stats["estimator"]), kernel_dims(result.stats["estimator"])
    print(f"{scene.resolution[0]}x{scene.resolution[1]}, per pass {base['samples']} spp and "
          f"{base['photons_caustic']} caustic photons, k = 10, estimator {result.stats['estimator']}")
    for i, t, noise in rows:
        noise_text = "-" if noise is None or noise > 1e30 else f"{noise:.4f}"
        print(f"pass {i:3d}  {t:6.1f} s  noise {noise_text}  kernel radius x{shrink_ratio(i, a) ** (1 / d):.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
