"""Photon tracing and the three irradiance estimates: speed and accuracy.

``run() -> dict`` measures

* photon tracing rate (photons emitted per second, caustic and global maps)
  on the moving-receiver scene (point light, mirror, diffuse box sliding
  through the caustic);
* look-ups per second of every estimator on one 1M-photon map at k = 50
  (synthetic moving receiver: a static caustic of 1 W/m^2 over a box top
  sliding through it), with the scipy and the compiled (numba) search, for
  scattered queries and for a render's density of queries (16 samples per
  pixel footprint); both cores; best of 3 interleaved rounds;
* the TEMPORAL / STANDARD and KD4D / STANDARD cost ratios, per look-up and
  per render (render_s of the traced scene, same photons and k, each backend;
  and the image pass's CPU seconds with one thread, :func:`bench_render_cpu`);
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


def _render_like_queries(n_pixels=12_000, spp=16, footprint=2e-3, seed=12):
    """Box-top queries as a render makes them: per pixel (fixed x, y; footprint in m) spp samples,
    each at its own shutter time, kept where the sliding box top covers the pixel then."""
    from test_estimators import A, H, W, box_center
    rng = np.random.default_rng(seed)
    xy = np.repeat(rng.uniform(-A + 0.02, A - 0.02, (n_pixels, 2)), spp, axis=0)
    xy += rng.uniform(-footprint / 2, footprint / 2, xy.shape)
    t = rng.random(len(xy))
    on = np.abs(xy[:, 0] - box_center(t)) < W / 2 - 0.02
    return np.column_stack([xy[on], np.full(on.sum(), H)]), t[on]


def _box_queries(n, seed=11):
    from test_estimators import box_top_queries
    return box_top_queries(n, margin=0.02, seed=seed)


def _set_backend(name):
    """Force the look-up backend of maps built from now on ('numba' or 'scipy')."""
    from stpm_core.photons import kdtree
    if name == "numba" and not kdtree.AVAILABLE and kdtree._IMPORT_ERROR.startswith("disabled by bench"):
        kdtree.AVAILABLE = True
    elif name == "scipy" and kdtree.AVAILABLE:
        kdtree.disable("disabled by bench")
    return kdtree.AVAILABLE == (name == "numba")


def bench_lookups(n_photons=1_000_000, n_queries=100_000, k=50) -> dict:
    """Look-ups/s of every estimator, scipy and numba backends, on one 1M map, two query sets.

    'scattered': n_queries random box-top points in scanline order (about one query per
    2 mm^2, a few per photon disc); 'render': 6250 pixel footprints x 16 samples (a render's
    density of queries).  Rates: all runs interleaved round-robin, best of 3 rounds.
    """
    from stpm_core.photons.estimators import PhotonMap
    from test_estimators import UP, moving_receiver_map
    base = moving_receiver_map(n_photons, 1)
    maps = {"scipy": PhotonMap(base.records, base.shutter, time_scale=base.time_scale, backend="scipy")}
    out = {"n_photons": n_photons, "k": k, "cpu_count": os.cpu_count(), "load_avg_1min": os.getloadavg()[0]}
    from stpm_core.photons import kdtree
    if kdtree.AVAILABLE:
        t0 = time.perf_counter()
        kdtree.FlatTree(base.records["position"][:1000], base.records["time"][:1000], base._packed[:1000],
                        dims=3, s=1.0)
        out["numba_first_use_s"] = time.perf_counter() - t0      # compile, or load from the cache
        maps["numba"] = PhotonMap(base.records, base.shutter, time_scale=base.time_scale, backend="numba")
    for be, m in maps.items():
        for est in ("STANDARD", "KD4D"):
            t0 = time.perf_counter()
            m.build(est)
            out[f"{be}_tree{'4' if est == 'KD4D' else '3'}_build_s"] = time.perf_counter() - t0
    p, t = _box_queries(n_queries)
    order = np.lexsort((p[:, 0], np.floor(p[:, 1] / 0.02)))          # scanline-coherent like a tile
    qsets = {"scattered": (p[order], t[order]), "render": _render_like_queries()}
    for qname, (p, t) in qsets.items():
        ns = np.tile(UP, (len(p), 1))
        out[f"{qname}_n_queries"] = len(p)
        for name, kw in RUNS:
            est = name.split("_")[0]
            E = maps["scipy"].estimate(p, ns, t, estimator=est, k=k, **kw)[:, 0]
            out[f"{qname}_{name}_error"] = float(E.mean() - 1.0)
            if est == "TEMPORAL":
                out[f"{name}_candidates"] = maps["scipy"].stats["temporal_candidates"]
            if "numba" in maps:
                E2 = maps["numba"].estimate(p, ns, t, estimator=est, k=k, **kw)[:, 0]
                rel = np.abs(E2 - E) / np.maximum(E, 1e-30)
                out[f"{qname}_{name}_numba_vs_scipy_max_rel_diff"] = float(rel.max())
        for _ in range(3):
            for be, m in maps.items():
                for name, kw in RUNS:
                    est = name.split("_")[0]
                    rate = _rate(lambda: m.estimate(p, ns, t, estimator=est, k=k, **kw), len(p))
                    key = f"{qname}_{be}_{name}_lookups_per_s"
                    out[key] = max(out.get(key, 0.0), rate)
        for be in maps:
            for name in ("TEMPORAL", "TEMPORAL_1.5", "KD4D"):
                out[f"{qname}_{be}_{name}_cost_vs_STANDARD"] = (out[f"{qname}_{be}_STANDARD_lookups_per_s"]
                                                              / out[f"{qname}_{be}_{name}_lookups_per_s"])
            if be == "numba":
                for name, _ in RUNS:
                    out[f"{qname}_{name}_speedup_numba_vs_scipy"] = (out[f"{qname}_numba_{name}_lookups_per_s"]
                                                                   / out[f"{qname}_scipy_{name}_lookups_per_s"])
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


def bench_render_cost(resolution=(128, 128), samples=8, n_caustic=400_000, rounds=6) -> dict:
    """render_s of the same render (same photons, k) per estimator and backend.

    Renders interleaved round-robin over (backend, estimator), ``rounds`` times; the
    best round of each counts (the least disturbed one on a shared machine).
    """
    scene = _traced_scene()
    scene.resolution = resolution
    scene.camera.ortho_scale = 4.0
    out = {"resolution": list(resolution), "samples": samples, "photons_caustic": n_caustic, "rounds": rounds,
           "load_avg_1min": os.getloadavg()[0]}
    backends = ["numba", "scipy"] if _set_backend("numba") else ["scipy"]
    for _ in range(rounds):
        for be in backends:
            _set_backend(be)
            for est in ("STANDARD", "TEMPORAL", "KD4D"):
                r = render(scene, RenderSettings(samples=samples, photons_caustic=n_caustic, photons_global=0,
                                                 estimator=est))
                key = f"{be}_{est}_render_s"
                if r.stats["render_s"] < out.get(key, np.inf):
                    out[key] = r.stats["render_s"]
                    out[f"{be}_{est}_lookup_s"] = r.stats["photon_stats"].get("lookup_s", 0.0)
                    out[f"{be}_{est}_lookup_count"] = r.stats["photon_stats"].get("lookup_count", 0)
    for be in backends:
        for est in ("TEMPORAL", "KD4D"):
            out[f"{be}_{est}_render_cost_vs_STANDARD"] = out[f"{be}_{est}_render_s"] / out[f"{be}_STANDARD_render_s"]
    _set_backend("numba")
    return out


def bench_render_cpu(resolution=(128, 128), samples=8, n_caustic=400_000, rounds=3) -> dict:
    """CPU seconds of :func:`bench_render_cost`'s render with ``threads=1``, per estimator (numba).

    ``image_cpu_s``: the image pass (``trace_image``), ``lookup_cpu_s``: the maps' ``estimate``
    calls inside it, both ``time.thread_time`` of the one rendering thread, so other jobs on a
    shared machine slow them less than they do the wall-clock ``render_s`` (which moved by 2x
    between rounds at load 6-8).  After an untimed warm-up render of each, renders interleaved
    over the estimators, ``rounds`` times; the minimum of each counts.
    """
    import stpm_core.render as render_mod
    from stpm_core.photons.estimators import PhotonMap
    scene = _traced_scene()
    scene.resolution = resolution
    scene.camera.ortho_scale = 4.0
    out = {"resolution": list(resolution), "samples": samples, "photons_caustic": n_caustic, "rounds": rounds,
           "load_avg_1min": os.getloadavg()[0]}
    cpu = {"image": 0.0, "lookup": 0.0}
    trace_image, estimate = render_mod.trace_image, PhotonMap.estimate

    def timed_trace_image(*a, **kw):
        t0 = time.thread_time()
        try:
            return trace_image(*a, **kw)
        finally:
            cpu["image"] += time.thread_time() - t0

    def timed_estimate(self, *a, **kw):
        t0 = time.thread_time()
        try:
            return estimate(self, *a, **kw)
        finally:
            cpu["lookup"] += time.thread_time() - t0

    _set_backend("numba")
    # warm-up (untimed): the first render of a process also loads every kernel, which would
    # count against whichever estimator comes first
    small = _traced_scene()
    small.resolution = (16, 16)
    small.camera.ortho_scale = 4.0
    for est in ("STANDARD", "TEMPORAL", "KD4D"):
        render_mod.render(small, RenderSettings(samples=1, photons_caustic=20_000, photons_global=0, estimator=est,
                                                threads=1))
    render_mod.trace_image, PhotonMap.estimate = timed_trace_image, timed_estimate
    try:
        for _ in range(rounds):
            for est in ("STANDARD", "TEMPORAL", "KD4D"):
                cpu["image"] = cpu["lookup"] = 0.0
                render_mod.render(scene, RenderSettings(samples=samples, photons_caustic=n_caustic, photons_global=0,
                                                        estimator=est, threads=1))
                for key in ("image", "lookup"):
                    name = f"{est}_{key}_cpu_s"
                    out[name] = min(out.get(name, np.inf), cpu[key])
    finally:
        render_mod.trace_image, PhotonMap.estimate = trace_image, estimate
    for est in ("TEMPORAL", "KD4D"):
        out[f"{est}_image_cpu_vs_STANDARD"] = out[f"{est}_image_cpu_s"] / out["STANDARD_image_cpu_s"]
        out[f"{est}_lookup_cpu_vs_STANDARD"] = out[f"{est}_lookup_cpu_s"] / out["STANDARD_lookup_cpu_s"]
    return out


def run() -> dict:
    return {"tracing": bench_tracing(), "lookups_1M": bench_lookups(), "traced_errors": bench_traced_errors(),
            "render_cost": bench_render_cost(), "render_cpu": bench_render_cpu()}


if __name__ == "__main__":
    print(json.dumps(run(), indent=2))
