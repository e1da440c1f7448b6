"""Regenerate the moving-receiver pictures of README.md and docs/photon-mapping.md, and print their numbers.

A box slides under the static caustic of a glass sphere (``blend_scenes/moving_receiver.blend``).
Three renders with the same photons and samples: STANDARD (time ignored), TEMPORAL (the default
estimator) and the accumulation buffer of 16 stills. Writes

* ``docs/images/moving_receiver_standard_temporal_accumulation.png``: Combined, left to right;
* ``docs/images/moving_receiver_caustic_pass.png``: the Caustic pass, same order, x4 exposure;

and prints each render's mean Caustic pass, its ratio to the accumulation buffer, and its
render seconds (one run, all cores).

Run (needs bpy, the ``test`` extra; about 3 minutes on 2 cores)::

    .venv/bin/python docs/make_images.py [--quick]
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from stpm_core.cli import load_any_scene  # noqa: E402
from stpm_core.imageio import write_png  # noqa: E402
from stpm_core.render import render  # noqa: E402

BLEND = os.path.join(ROOT, "blend_scenes", "moving_receiver.blend")
OUT = os.path.join(ROOT, "docs", "images")
CAUSTIC_EXPOSURE = 4.0
RUNS = (("STANDARD", dict(estimator="STANDARD")),
        ("TEMPORAL", dict(estimator="TEMPORAL")),
        ("ACCUMULATION 16", dict(method="ACCUMULATION", accumulation_steps=16, estimator="STANDARD")))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small and fast (a check that the script runs)")
    ap.add_argument("--out", default=OUT, help="directory for the PNGs (default docs/images)")
    args = ap.parse_args(argv)
    scene, settings, _ = load_any_scene(BLEND, 1)
    if args.quick:
        scene.resolution, base = (60, 45), dict(samples=2, photons_caustic=20_000, photons_global=0)
    else:
        scene.resolution, base = (240, 180), dict(samples=16, photons_caustic=400_000, photons_global=0)
    combined, caustic, rows = [], [], []
    for name, kw in RUNS:
        t0 = time.perf_counter()
        r = render(scene, settings.replace(**base, **kw))
        wall = time.perf_counter() - t0
        combined.append(r.passes["Combined"][:, :, :3])
        caustic.append(r.passes["Caustic"][:, :, :3])
        rows.append((name, float(r.passes["Caustic"][:, :, :3].mean()), wall))
    os.makedirs(args.out, exist_ok=True)
    write_png(os.path.join(args.out, "moving_receiver_standard_temporal_accumulation.png"), np.hstack(combined))
    write_png(os.path.join(args.out, "moving_receiver_caustic_pass.png"), CAUSTIC_EXPOSURE * np.hstack(caustic))
    ref = rows[-1][1]
    print(f"{scene.resolution[0]}x{scene.resolution[1]}, {base['samples']} spp, "
          f"{base['photons_caustic']} caustic photons")
    for name, mean, wall in rows:
        print(f"{name:16s} Caustic mean {mean:.4f} ({mean / ref:.3f} of accumulation)  {wall:6.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
