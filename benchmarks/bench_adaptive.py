"""Adaptive sampling on the HDRI product shot (``bench_product``'s scene and references).

STPM's FINAL preset (64 samples per pixel, fixed) against the same preset with adaptive sampling
(Cycles' Noise Threshold: ``use_adaptive_sampling``, ``adaptive_threshold``,
``adaptive_min_samples``; docs/rendering.md, "Adaptive sampling") at about the same render time,
scored as ``bench_product`` scores: outside the caustic region LDR-FLIP against Cycles 1024 spp;
inside it the 8 x 8-block luminance correlation and the mean against the converged (16384 spp)
crop.  Also each render's wall and CPU seconds (the machine is shared: CPU seconds vary less
with the load) and, with adaptive sampling, the mean samples per pixel over the image and
inside the caustic region.

The references come from ``bench_product``'s cache (``bench_out/cache/product/``): run
``python -m benchmarks product`` once first (it renders them, about 7 min + the converged crop).

    python -m benchmarks adaptive     # 3 STPM renders (and a warm-up) of 1-5 min each, by load
"""
from __future__ import annotations

import json
import resource
import time

import numpy as np

from benchmarks import bench_product as bp
from benchmarks import bench_room as room

#: (tag, settings changed after the FINAL preset); the adaptive ones aim at the fixed render's time
VARIANTS = (
    ("fixed64", {"use_adaptive_sampling": False}),
    ("adaptive", {"use_adaptive_sampling": True, "samples": 1024, "adaptive_threshold": 0.05,
                  "adaptive_min_samples": 32}),
    ("adaptive_cheap", {"use_adaptive_sampling": True, "samples": 1024, "adaptive_threshold": 0.08,
                        "adaptive_min_samples": 16}),
)


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def run() -> dict:
    missing = room.missing_requirements()
    if missing is not None:
        return missing
    if not bp.BLEND.exists():
        return {"skipped": f"{bp.BLEND.name} missing: .venv/bin/python blend_scenes/make_hdri_product.py"}
    ref, index, _ref_s, _ = bp.reference()
    ref = np.asarray(ref, np.float64)
    nc = np.asarray(bp.no_refractive_caustics()[0], np.float64)
    with bp._this_scene():
        room._open()                        # object_names reads the open file's scene
        names = room.object_names()
    caustic = bp.caustic_mask(ref, nc, index == names.index("Table") + 1)
    outside = ~caustic
    conv, (y0, y1, x0, x1), _, _ = bp.converged_crop(caustic)
    conv = np.asarray(conv, np.float64)
    cm = caustic[y0:y1, x0:x1]
    y_conv = conv @ bp.LUMA
    out: dict = {"caustic_px": int(caustic.sum())}
    warm = True
    for tag, over in VARIANTS:
        c0 = _cpu()
        with bp._this_scene():
            img, passes, tim = room.stpm_final(overrides=over, warm=warm)
        warm = False
        out[f"{tag}_render_s"] = tim["render_s"]
        out[f"{tag}_cpu_s"] = _cpu() - c0
        _, fmap = room.flip_ldr(img, ref)
        crop = img[y0:y1, x0:x1]
        out[f"{tag}_flip_ldr_outside"] = float(fmap[outside].mean())
        out[f"{tag}_mean_ratio_outside"] = float(img[outside].mean() / ref[outside].mean())
        out[f"{tag}_caustic_vs_converged_mean_ratio"] = float((crop @ bp.LUMA)[cm].mean() / y_conv[cm].mean())
        out[f"{tag}_caustic_vs_converged_block8_corr"] = bp.masked_block_corr(crop, conv, cm)[0]
        if "Sample Count" in passes:
            n = passes["Sample Count"][..., 0]
            out[f"{tag}_samples_mean"] = float(n.mean())
            out[f"{tag}_samples_caustic_mean"] = float(n[caustic].mean())
    out["variants"] = json.dumps(dict(VARIANTS))
    out["when_utc"] = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    return out


if __name__ == "__main__":
    for k, v in run().items():
        print(f"{k:40s} {v}")
