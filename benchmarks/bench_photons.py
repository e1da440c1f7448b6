"""Photon tracing and the three irradiance estimates: speed and accuracy.

``run() -> dict`` measures

* photon tracing rate (photons emitted per second, caustic and global maps)
  on the moving-receiver scene (point light, mirror, diffuse box sliding
  through the caustic);
* look-ups per second of every estimator on one 1M-photon map at k = 50
  (synthetic moving receiver: a static caustic of 1 W/m^2 over a box top
  sliding through it), queries in image-like coherent order, median of 3;
* the TEMPORAL / STANDARD and KD4D / STANDARD cost ratios, per look-up and
  per render (render_s of a small render of the traced scene);
* relative error of the mean irradiance on the moving box top against the
  analytic answer, for the synthetic 1M map and the traced scene.

Run: ``.venv/bin/python benchmarks/bench_photons.py`` (prints JSON).
"""
from __future__ import annotations

import json
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))

from stpm_core.lights import LightSet  # noqa: E402
from stpm_core.photons import build_photon_maps  # noqa: E402
from stpm_core.raycast import make_caster  # noqa: E402
from stpm_core.render import render  # noqa: E402
from stpm_core.settings import RenderSettings  # noqa: E402

RUNS = [("STANDARD", {}), ("TEMPORAL", {}), ("TEMPORAL_1.5", {"temporal_alpha": 1.5}), ("KD4D", {})]


def _rate(fn, n):
    """Calls of fn per second, times n (look-ups per second)."""
    t0 = time.perf_counter()
    fn()
    return n / (time.perf_counter() - t0)


def _traced_scene():
    from scenes import box_mesh, moving
    from test_photons import BOX_H, BOX_HALF, mirror_scene
    box = (box_mesh(lo=(-BOX_HALF, -BOX_HALF, 0.0), hi=(BOX_HALF, BOX_HALF, BOX_H), material=0, name="box"),
           moving((-1.0, 0, 0), (1.0, 0, 0)))
    return mirror_scene(box=box)


def bench_tracing(n_caustic=200_000, n_global=200_000) -> dict:
    scene = _traced_scene()
    caster, lights = make_caster(scene), LightSet(scene)
    maps = build_photon_maps(scene, RenderSettings(photons_caustic=n_caustic, photons_global=n_global),
                             caster, lights)
    st = maps.stats
    return {"photons_emitted": st["photons_emitted"], "photon_trace_s": st["photon_trace_s"],
            "photons_traced_per_s": st["photons_per_s"], "stored_caustic": st["photons_caustic"],
            "stored_global": st["photons_global"], "tree_build_s": st["tree_build_s"],
            "caster": getattr(caster, "backend", type(caster).__name__)}


def bench_lookups(n_photons=1_000_000, n_queries=100_000, k=50) -> dict:
    from test_estimators import UP, box_top_queries, moving_receiver_map
    m = moving_receiver_map(n_photons, 1)
    t0 = time.perf_counter()
    m.tree3()
    build3 = time.perf_counter() - t0
    t0 = time.perf_counter()
    m.tree4()
    build4 = time.perf_counter() - t0
    p, t = box_top_queries(n_queries, margin=0.02)
    order = np.lexsort((p[:, 0], np.floor(p[:, 1] / 0.02)))          # scanline-coherent like a tile
    p, t = p[order], t[order]
    ns = np.tile(UP, (len(p), 1))
    out = {"n_photons": n_photons, "n_queries": len(p), "k": k, "tree3_build_s": build3, "tree4_build_s": build4,
           "cpu_count": os.cpu_count()}
    for name, kw in RUNS:
        est = name.split("_")[0]
        E = m.estimate(p, ns, t, estimator=est, k=k, **kw)[:, 0]
        out[f"{name}_error"] = float(E.mean() - 1.0)
        if est == "TEMPORAL":
            out[f"{name}_candidates"] = m.stats["temporal_candidates"]
    # Rates: estimators interleaved round-robin, best of 3 rounds (the machine is shared:
    # the best round is the least disturbed one)
    for _ in range(3):
        for name, kw in RUNS:
            est = name.split("_")[0]
            rate = _rate(lambda: m.estimate(p, ns, t, estimator=est, k=k, **kw), len(p))
            out[f"{name}_lookups_per_s"] = max(out.get(f"{name}_lookups_per_s", 0.0), rate)
    for name in ("TEMPORAL", "TEMPORAL_1.5", "KD4D"):
        out[f"{name}_cost_vs_STANDARD"] = out["STANDARD_lookups_per_s"] / out[f"{name}_lookups_per_s"]
    return out


def bench_traced_errors(n_caustic=400_000, n_queries=8000) -> dict:
    from test_photons import UP, _box_top_points, caustic_irradiance
    scene = _traced_scene()
    maps = build_photon_maps(scene, RenderSettings(photons_caustic=n_caustic, photons_global=0),
                             make_caster(scene), LightSet(scene))
    p, t = _box_top_points(np.random.default_rng(3), n_queries)
    ns = np.tile(UP, (len(p), 1))
    E_true = caustic_irradiance(p).mean()
    out = {"photons_caustic_emitted": n_caustic, "photons_caustic_stored": maps.stats["photons_caustic"],
           "time_scale": maps.time_scale}
    for name, kw in RUNS:
        E = maps.estimate("caustic", p, ns, t, estimator=name.split("_")[0], **kw)[:, 0]
        out[f"{name}_error"] = float(E.mean() / E_true - 1)
    return out


def bench_render_cost(resolution=(96, 96), samples=8, n_caustic=200_000) -> dict:
    scene = _traced_scene()
    scene.resolution = resolution
    scene.camera.ortho_scale = 4.0
    out = {"resolution": list(resolution), "samples": samples}
    for est in ("STANDARD", "TEMPORAL", "KD4D"):
        r = render(scene, RenderSettings(samples=samples, photons_caustic=n_caustic, photons_global=0,
                                         estimator=est))
        out[f"{est}_render_s"] = r.stats["render_s"]
        out[f"{est}_lookup_s"] = r.stats["photon_stats"].get("lookup_s", 0.0)
    for est in ("TEMPORAL", "KD4D"):
        out[f"{est}_render_cost_vs_STANDARD"] = out[f"{est}_render_s"] / out["STANDARD_render_s"]
    return out


def run() -> dict:
    return {"tracing": bench_tracing(), "lookups_1M": bench_lookups(), "traced_errors": bench_traced_errors(),
            "render_cost": bench_render_cost()}


if __name__ == "__main__":
    print(json.dumps(run(), indent=2))
