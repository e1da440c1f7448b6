"""PROGRESSIVE's error budget against ACCUMULATION-16: bias^2 and variance over seeds, with the work done.

The scenes of ``bench_progressive`` (96 x 64, each with its exact image).  Each method renders with
SEEDS seeds; per pixel and channel, over the seeds, the mean m and the variance v (ddof 1) of the
estimate against the exact value x give

    MSE = mean (estimate - x)^2 = bias^2 + variance,   variance = mean v,   bias^2 = mean (m - x)^2 - variance / n

(the second term removes the seeds' own noise from the squared bias of their mean).  PROGRESSIVE
(TEMPORAL, ``bench_progressive``'s passes: 12.5k caustic photons, 1 spp, k = 20) is read after passes
16, 64 and 256, ACCUMULATION-16 (16 stills of 250k photons and 16 spp, k = 30) once; each with the
photon paths and camera paths it traced and the CPU seconds it took (``time.process_time``: every
thread of the process).  docs/photon-mapping.md, "Error budget against ACCUMULATION-16", reads it.

    python -m benchmarks budget      # about 5-8 minutes on 2 cores
"""
from __future__ import annotations

import os
import sys
import time

_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(_ROOT, "benchmarks"))
sys.path.insert(0, os.path.join(_ROOT, "tests"))

import numpy as np  # noqa: E402

import bench_progressive as bp  # noqa: E402
from stpm_core.photons.progressive import pilot_photons  # noqa: E402
from stpm_core.render import render  # noqa: E402
from stpm_core.settings import RenderSettings  # noqa: E402

from test_compare import moving_caustic_scene  # noqa: E402  (tests/ on sys.path)

SEEDS = (1, 2, 3, 4)
ACC_SEEDS = (1, 2, 3)
MARKS = (16, 64, 256)


def budget(images, ref) -> dict:
    """{'rmse', 'bias', 'std', 'bias2_share'} of renders (n, H, W, 3) of one method against the exact image."""
    a = np.stack(images).astype(np.float64)
    n = a.shape[0]
    mse = float(np.mean((a - ref) ** 2))
    var = float(np.mean(a.var(axis=0, ddof=1)))
    bias2 = max(float(np.mean((a.mean(axis=0) - ref) ** 2)) - var / n, 0.0)
    return {"rmse": mse ** 0.5, "bias": bias2 ** 0.5, "std": var ** 0.5, "bias2_share": bias2 / mse}


def run_scene(mirror) -> dict:
    scene = moving_caustic_scene(bp.RESOLUTION, mirror=mirror)
    ref = bp._exact(mirror)
    pixels = bp.RESOLUTION[0] * bp.RESOLUTION[1]
    out = {}
    # -- PROGRESSIVE: images after the marked passes, CPU seconds to them --------------------------
    imgs, cpu = {m: [] for m in MARKS}, {m: [] for m in MARKS}
    for seed in SEEDS:
        st = RenderSettings(**{**bp.COMMON, "seed": seed}, method="PROGRESSIVE", passes=max(MARKS),
                            photons_caustic=bp.PASS_PHOTONS, samples=bp.PASS_SAMPLES, k_nearest=bp.PASS_K)
        c0 = time.process_time()

        def on_pass(img, info, c0=c0):
            if info["pass"] in imgs:
                cpu[info["pass"]].append(time.process_time() - c0)
                imgs[info["pass"]].append(img["Combined"][:, :, :3].copy())
        render(scene, st, on_pass=on_pass)
    pilot = pilot_photons(bp.PASS_PHOTONS, bp.PASS_K)
    for m in MARKS:
        b = budget(imgs[m], ref)
        out[f"progressive_{m}"] = (f"rmse {b['rmse']:.4f} bias {b['bias']:.4f} std {b['std']:.4f} "
                                   f"bias^2 share {b['bias2_share']:.2f}; {(m * bp.PASS_PHOTONS + pilot) / 1e6:.2f}M "
                                   f"photons, {m * bp.PASS_SAMPLES * pixels / 1e6:.2f}M camera paths, "
                                   f"{np.median(cpu[m]):.1f} CPU s")
    # -- ACCUMULATION-16 ------------------------------------------------------------------------------
    acc, acc_cpu = [], []
    for seed in ACC_SEEDS:
        c0 = time.process_time()
        r = render(scene, RenderSettings(**{**bp.COMMON, "seed": seed}, method="ACCUMULATION", **bp.ACC16))
        acc_cpu.append(time.process_time() - c0)
        acc.append(r.passes["Combined"][:, :, :3].copy())
    b = budget(acc, ref)
    steps = bp.ACC16["accumulation_steps"]
    out["accumulation_16"] = (f"rmse {b['rmse']:.4f} bias {b['bias']:.4f} std {b['std']:.4f} "
                              f"bias^2 share {b['bias2_share']:.2f}; "
                              f"{steps * bp.ACC16['photons_caustic'] / 1e6:.2f}M photons, "
                              f"{steps * bp.ACC16['samples'] * pixels / 1e6:.2f}M camera paths, "
                              f"{np.median(acc_cpu):.1f} CPU s")
    return out


def run() -> dict:
    t0 = time.perf_counter()
    bp._warm(None)
    out = {"seeds": f"PROGRESSIVE {len(SEEDS)}, ACCUMULATION-16 {len(ACC_SEEDS)}", "load_start": os.getloadavg()[0]}
    for name, mirror in bp.SCENES.items():
        out.update({f"{name}: {k}": v for k, v in run_scene(mirror).items()})
    out["load_end"] = os.getloadavg()[0]
    out["total_s"] = time.perf_counter() - t0
    return out


if __name__ == "__main__":
    for k, v in run().items():
        print(f"{k:40s} {v}")
