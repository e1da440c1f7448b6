"""Final gathering against direct visualisation of the global map on the room, at equal time (issue 16, deliverable 2).

Scene, reference and metrics are ``bench_room``'s (``blend_scenes/textured_room.blend``, Cycles at
1024 spp cached in ``bench_out/cache/room/``, LDR-FLIP after the Standard view, mean ratio, 8 x 8
block correlation), STPM through the add-on's path with the FINAL preset (``bench_room.stpm_final``):

* **direct**: FINAL as it is (``final_gather_samples = 0``: the camera's first diffuse vertex reads
  the global map);
* **gather**: FINAL with ``final_gather_samples = GATHER`` and the camera samples lowered so that
  its wall time (export + render) matches direct's: guessed from a first render at
  ``GATHER_SPP0`` samples, rescaled once by the measured time when more than 15 % off, the closer
  kept;
* **gather_full**: FINAL's own 64 samples with final gathering (its time is what the quality costs
  at FINAL's noise level in Direct and Caustic).

FLIP per region (bench_room's object masks) for the walls and floor, where the blotches live.
Pictures in ``bench_out/gather/``: direct | gather (equal time) | Cycles 1024, Standard view, and
the Indirect passes side by side.

    python -m benchmarks gather      # ~5-8 min on the shared 2-core machine (reference cached)
"""
from __future__ import annotations

import time

import numpy as np

from . import bench_room as room

GATHER = 8                 # final_gather_samples
GATHER_SPP0 = 16           # first guess of the camera samples at equal time
OUT = room.ROOT / "bench_out" / "gather"
REGIONS = ("Floor shade", "Floor sunlit", "Walls", "Wall", "Ceiling", "window/world")


def _measure(tag: str, img: np.ndarray, ref: np.ndarray, regions: dict, out: dict) -> np.ndarray:
    f, fmap = room.flip_ldr(img, ref)
    out[f"{tag}_flip_ldr"] = f
    out[f"{tag}_mean_ratio"] = float(img.mean() / ref.mean())
    out[f"{tag}_block8_corr"] = room.block_corr(img, ref)
    for name, m in regions.items():
        if any(name.startswith(r) for r in REGIONS):
            s = room.region_stats(img, ref, fmap, m)
            out[f"{tag}_{name.replace(' ', '_').replace('/', '_')}_flip"] = s["flip"]
            out[f"{tag}_{name.replace(' ', '_').replace('/', '_')}_rest"] = s["rest"]
    return fmap


def run() -> dict:
    try:
        import bpy  # noqa: F401
        import flip_evaluator  # noqa: F401
    except ImportError:
        return {"skipped": "needs bpy and flip-evaluator"}
    OUT.mkdir(parents=True, exist_ok=True)
    ref, index, ref_s, cached = room.reference()
    ref = np.asarray(ref, np.float64)
    out: dict = {"reference_spp": room.REF_SPP, "reference_cached": cached, "final_gather_samples": GATHER,
                 "sources_sha": room.sources_digest()}
    # -- Direct visualisation (FINAL as it is) ---------------------------------------------------
    img_d, pas_d, tim_d = room.stpm_final(warm=True)
    t_d = tim_d["export_s"] + tim_d["render_s"]
    out.update({"direct_s": t_d, "direct_spp": 64})
    # -- Final gathering at equal time -----------------------------------------------------------
    spp = GATHER_SPP0
    best = None
    for _ in range(2):
        img, pas, tim = room.stpm_final(warm=best is None, overrides={"final_gather_samples": GATHER, "samples": spp})
        t = tim["export_s"] + tim["render_s"]
        print(f"bench_gather: gather {GATHER} at {spp} spp: {t:.1f} s (direct {t_d:.1f} s)", flush=True)
        if best is None or abs(np.log(t / t_d)) < abs(np.log(best[3] / t_d)):
            best = (img, pas, spp, t, tim)
        if abs(t / t_d - 1.0) <= 0.15:
            break
        spp = int(np.clip(round(spp * t_d / t), 1, 256))
    img_g, pas_g, spp_g, t_g, tim_g = best
    out.update({"gather_s": t_g, "gather_spp": spp_g, "gather_rays": tim_g.get("gather_rays", 0),
                "gather_photon_map_build_s": tim_g.get("photon_map_build_s")})
    ps = tim_g.get("photon_stats") or {}
    for k in ("gather_cache_points", "gather_normals_s", "gather_estimate_s", "gather_misses", "photons_global"):
        if k in ps:
            out[f"gather_{k}" if not k.startswith("gather") else k] = ps[k]
    # -- Final gathering at FINAL's samples --------------------------------------------------------
    img_f, pas_f, tim_f = room.stpm_final(warm=False, overrides={"final_gather_samples": GATHER})
    out["gather_full_s"] = tim_f["export_s"] + tim_f["render_s"]
    out["gather_full_spp"] = 64
    # -- Metrics and pictures -----------------------------------------------------------------------
    regions = room.regions(index, room.object_names(), ref)        # (the room file is open)
    maps = {tag: _measure(tag, im, ref, regions, out)
            for tag, im in (("direct", img_d), ("gather", img_g), ("gather_full", img_f))}
    row = np.concatenate([room.standard_view(img_d), room.standard_view(img_g), room.standard_view(ref)], axis=1)
    room._write_display(OUT / "direct_gather_cycles1024.png", row)
    ind = [np.asarray(p["Indirect"][..., :3], np.float64) for p in (pas_d, pas_g, pas_f)]
    scale = 1.0 / max(np.percentile(ind[0], 99), 1e-12)
    room._write_display(OUT / "indirect_direct_gather_gatherfull.png",
                        np.concatenate([room.standard_view(np.clip(x * scale, 0, 1)) for x in ind], axis=1))
    room._write_display(OUT / "flip_direct_gather.png",
                        np.repeat(np.concatenate([maps["direct"], maps["gather"]], axis=1)[..., None], 3, axis=-1))
    out["when_utc"] = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    return out
