"""Photon look-ups against ray casting: CPU seconds of each in whole renders, and where look-ups go.

Issue 16, item 3: look-up CPU-s over ray-cast CPU-s should be <= 1 (a user saw 215 CPU-s of
look-ups against 15 s of photon tracing on a sunlit pool, FINAL preset).  Scenes, 160 x 120:

* ``demo``: the demo's glass sphere sliding over a floor (``stpm_core.demo.demo_scene``);
* ``pool``: caustic-heavy: a sun through a rippling glass water sheet (64 x 64 grid deforming
  over 5 steps) onto a tiled floor and one wall (:func:`pool_scene`).

Methods (``threads=1``: every CPU second is the calling thread's, ``time.thread_time``):

* PROGRESSIVE with FINAL_PROGRESSIVE's pass (TEMPORAL, k = 20, 1 spp, 200k caustic + 100k global
  photons per pass), PASSES passes, in two variants interleaved over ROUNDS rounds (minimum per
  quantity reported: noise only adds time): ``before`` (each pass's maps built with the k-nearest
  trees of TEMPORAL, as until 2026-12-06) and ``after`` (no trees up front: the default now); a
  third, regions read on a uniform hash grid, measured 1.24-1.34x the tree's range-query time and
  was removed (``photons/hashgrid.py``'s docstring);
* PHOTON with FINAL's maps (TEMPORAL, k = 100, 2M caustic + 1M global photons), FINAL_SPP samples
  per pixel (FINAL has 64 at 320 x 240: 64x the queries, the same per-query cost).

* Sharing (:func:`run_sharing`, keys ``share_...``): FINAL's maps and 64 spp on 80 x 60 pixels of
  FINAL's 320 x 240 size (lens x 4), look-ups shared within f x the pilots' radius for f = 0, 0.1,
  0.25, 0.5 (0: unshared, today's path), interleaved per seed over 3 seeds: queries shared,
  look-up CPU-s (estimates + the grouping) and the image error against unshared.

Reported per scene and method: ``lookup_s`` (CPU s inside the maps' ``estimate``), ``cast_s`` (CPU
s inside the caster during ``trace_image``: camera, bounce and shadow rays), ``cast_all_s`` (also
photon tracing's rays), ``lookup_over_cast`` (the issue's ratio) and ``lookup_over_cast_all``; for
PROGRESSIVE the split of a look-up: ``pilot_s`` (the pilot region at each query:
``Pilot.initial_size``), ``range_s`` (the pass's photons in the regions, the structure's build
included), ``other_s`` (normalisation and array traffic); ``build_s`` (every kd-tree built in the
render, the pilot's included: map building, not look-ups); ``after_over_before_build`` and
``after_over_before_cpu`` (per round and of the minima).

    python -m benchmarks lookups          # about 6-7 minutes on 2 cores (sharing: about 4)
"""
from __future__ import annotations

import time

import numpy as np

from stpm_core.demo import demo_scene, look_at, quad
from stpm_core.motion import MotionTransform
from stpm_core.scene import Camera, Instance, Light, Material, Mesh, Scene, World
from stpm_core.settings import RenderSettings
from stpm_core.shutter import Shutter

from .bench_render import TimingCaster

__all__ = ["run", "pool_scene"]

RESOLUTION = (160, 120)
PASSES = 8
ROUNDS = 2
FINAL_SPP = 4
PROGRESSIVE = dict(method="PROGRESSIVE", estimator="TEMPORAL", samples=1, photons_caustic=200_000,
                   photons_global=100_000, k_nearest=20, passes=PASSES, max_depth=8, seed=1, threads=1)
FINAL = dict(method="PHOTON", estimator="TEMPORAL", samples=FINAL_SPP, photons_caustic=2_000_000,
             photons_global=1_000_000, k_nearest=100, temporal_alpha=0.0, max_depth=8, seed=1, threads=1)


def pool_scene(resolution=RESOLUTION) -> Scene:
    """A sunlit pool: a glass water sheet (IOR 1.33, 4 x 4 m, 64 x 64 quads) rippling 1 m over a tiled
    floor (two travelling waves, 5 deformation steps across the shutter), one wall, a high sun."""
    n, L, K = 64, 4.0, 5
    xs = np.linspace(-L / 2, L / 2, n + 1)
    X, Y = np.meshgrid(xs, xs, indexing="ij")
    steps = np.linspace(0.0, 1.0, K)
    V = np.empty((K, (n + 1) ** 2, 3), np.float32)
    for i, t in enumerate(steps):
        Z = 1.0 + 0.03 * np.sin(3.1 * X + 1.3 * Y - 2.0 * t) + 0.02 * np.sin(-1.7 * X + 4.3 * Y + 3.0 * t)
        V[i] = np.stack([X, Y, Z], -1).reshape(-1, 3)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    tri = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    water = Mesh(vertices=V, triangles=tri.astype(np.int32), material_ids=np.full(len(tri), 1, np.int32),
                 vertex_times=steps, name="water")
    wall_M = np.eye(4)
    wall_M[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
    wall_M[:3, 3] = (0.0, L / 2, 0.7)
    instances = [Instance(0, name="floor"), Instance(1, name="water"),
                 Instance(2, transform=MotionTransform.static(wall_M), name="wall")]
    camera = Camera(type="PERSP", lens=32.0, sensor_width=36.0, sensor_fit="AUTO",
                    transform=MotionTransform.static(look_at((0.0, -4.0, 3.2), (0.0, 0.3, 0.3))),
                    clip_start=0.1, clip_end=100.0)
    sun = Light(type="SUN", power=4.0, angle=0.01,
                transform=MotionTransform.static(look_at((0.6, -0.4, 3.0), (0.0, 0.0, 0.0))))
    return Scene(meshes=[quad(L, L, material=0), water, quad(L, 1.4, material=0, name="wall")],
                 instances=instances, camera=camera, lights=[sun],
                 materials=[Material.diffuse((0.7, 0.75, 0.8), name="tiles"), Material.glass(ior=1.33, name="water")],
                 world=World(color=np.full(3, 0.05), strength=1.0), shutter=Shutter(open=0.75, close=1.25),
                 resolution=tuple(resolution), frame=1.0)


class _Meter:
    """Wraps, for one render, the caster, trace_image, the maps' estimate and the progressive look-up's
    parts with CPU-second counters (this thread's: the render runs with threads=1)."""

    def __init__(self, build_trees: bool = False):
        import stpm_core.progressive as prog
        import stpm_core.render as rnd
        from stpm_core.photons import maps, progressive
        from stpm_core.photons import kdtree
        self.t = {"cast_all_s": 0.0, "cast_s": 0.0, "lookup_s": 0.0, "pilot_s": 0.0, "range_s": 0.0, "build_s": 0.0,
                  "queries": 0}
        self._undo = []
        casters = []

        def patch(obj, name, wrapper):
            old = getattr(obj, name)
            setattr(obj, name, wrapper(old))
            self._undo.append((obj, name, old))

        def counted(key, count=False):
            def wrapper(f):
                def g(*a, **k):
                    t0 = time.thread_time()
                    try:
                        return f(*a, **k)
                    finally:
                        self.t[key] += time.thread_time() - t0
                        if count:
                            self.t["queries"] += len(a[2])
                return g
            return wrapper

        def caster(f):
            def g(*a, **k):
                c = TimingCaster(f(*a, **k))
                casters.append(c)
                return c
            return g

        def traced(f):
            def g(*a, **k):
                c0 = sum(c.seconds for c in casters)
                try:
                    return f(*a, **k)
                finally:
                    self.t["cast_s"] += sum(c.seconds for c in casters) - c0
            return g

        self._casters = casters
        patch(rnd, "make_caster", caster)
        patch(rnd, "trace_image", traced)
        patch(prog, "trace_image", traced)
        patch(maps.PhotonMaps, "estimate", counted("lookup_s", True))
        patch(progressive.ProgressiveMaps, "estimate", counted("lookup_s", True))
        patch(progressive.Pilot, "initial_size", counted("pilot_s"))
        patch(progressive.ProgressiveMaps, "_range_sum", counted("range_s"))
        patch(kdtree.FlatTree, "__init__", counted("build_s"))
        if not build_trees:
            return
        def eager(f):
            return lambda *a, **k: f(*a, **{**k, "build_trees": True})
        patch(prog, "build_photon_maps", eager)

    def close(self) -> dict:
        for obj, name, old in reversed(self._undo):
            setattr(obj, name, old)
        t = dict(self.t)
        t["cast_all_s"] = sum(c.seconds for c in self._casters)
        t["other_s"] = t["lookup_s"] - t["pilot_s"] - t["range_s"]
        t["lookup_over_cast"] = t["lookup_s"] / max(t["cast_s"], 1e-9)
        t["lookup_over_cast_all"] = t["lookup_s"] / max(t["cast_all_s"], 1e-9)
        return t


VARIANTS = {"before": True, "after": False}          # build_trees


def _measure(scene, settings, variant: str = "after") -> dict:
    from stpm_core.render import render
    meter = _Meter(VARIANTS[variant])
    try:
        t0 = time.thread_time()
        render(scene, settings)
        cpu = time.thread_time() - t0
    finally:
        t = meter.close()
    t["cpu_s"] = cpu
    return t


def run(rounds: int = ROUNDS) -> dict:
    scenes = {"demo": demo_scene(RESOLUTION), "pool": pool_scene(RESOLUTION)}
    out: dict = {"resolution": f"{RESOLUTION[0]}x{RESOLUTION[1]}", "passes": PASSES, "rounds": rounds,
                 "final_spp": FINAL_SPP, "threads": 1}
    # -- warm up: load every kernel once (untimed) -----------------------------------------------------
    small = demo_scene((32, 24))
    for variant in VARIANTS:
        _measure(small, RenderSettings(**{**PROGRESSIVE, "passes": 2, "photons_caustic": 5000,
                                           "photons_global": 2000}), variant)
    _measure(small, RenderSettings(**{**FINAL, "photons_caustic": 20_000, "photons_global": 10_000}))
    # -- PROGRESSIVE: the variants, interleaved ---------------------------------------------------
    prog = {(s, v): [] for s in scenes for v in VARIANTS}
    for _ in range(rounds):
        for name, sc in scenes.items():
            for variant in VARIANTS:
                prog[(name, variant)].append(_measure(sc, RenderSettings(**PROGRESSIVE), variant))
    for name in scenes:
        for variant in VARIANTS:
            runs = prog[(name, variant)]
            tag = f"{name}_progressive_{variant}"
            for key in ("lookup_s", "pilot_s", "range_s", "other_s", "build_s", "cast_s", "cast_all_s", "cpu_s"):
                out[f"{tag}_{key}"] = min(r[key] for r in runs)
            out[f"{tag}_queries"] = runs[0]["queries"]
            out[f"{tag}_lookup_over_cast"] = out[f"{tag}_lookup_s"] / out[f"{tag}_cast_s"]
            out[f"{tag}_lookup_over_cast_all"] = out[f"{tag}_lookup_s"] / out[f"{tag}_cast_all_s"]
        ratios = (("after", "before", "build_s", "after_over_before_build"),
                  ("after", "before", "cpu_s", "after_over_before_cpu"))
        for num, den, key, label in ratios:
            a, b = prog[(name, num)], prog[(name, den)]
            out[f"{name}_{label}_per_round"] = [round(x[key] / y[key], 3) for x, y in zip(a, b)]
            out[f"{name}_{label}"] = out[f"{name}_progressive_{num}_{key}"] / out[f"{name}_progressive_{den}_{key}"]
    # -- FINAL's maps (k-nearest TEMPORAL look-ups): the ratio and its cost per query -----------------------
    for name, sc in scenes.items():
        t = _measure(sc, RenderSettings(**FINAL))
        for key in ("lookup_s", "cast_s", "cast_all_s", "queries", "lookup_over_cast", "lookup_over_cast_all"):
            out[f"{name}_final_{key}"] = t[key]
        out[f"{name}_final_us_per_query"] = 1e6 * t["lookup_s"] / max(t["queries"], 1)
    # -- FINAL's maps with a pixel's look-ups shared (photons/sharing.py), fractions interleaved --------
    out.update({f"share_{k}": v for k, v in run_sharing().items()})
    return out


# ---------------------------------------------------------------------------------------------------
# Sharing a pixel's look-ups (photons/sharing.py): FINAL's maps, queries shared, CPU-s and image error
# ---------------------------------------------------------------------------------------------------
SHARE_RESOLUTION = (80, 60)
SHARE_ZOOM = 4.0                     # lens x 4: FINAL's 320 x 240 pixels, the image's central quarter (each axis)
SHARE_SPP = 64                       # FINAL's samples per pixel
SHARE_FRACTIONS = (0.0, 0.1, 0.25, 0.5)
SHARE_SEEDS = (1, 2, 3)
SHARE_BLOCK = 8


def _final_maps(scene, settings):
    """What ``render`` builds before tracing the image (PHOTON): caster, lights, table, maps."""
    from stpm_core.bsdf import MaterialTable
    from stpm_core.lights import LightSet
    from stpm_core.photons import build_photon_maps
    from stpm_core.plan import apply_plan, make_plan
    from stpm_core.raycast import make_caster
    caster = make_caster(scene)
    lights = LightSet(scene)
    ps = apply_plan(settings, make_plan(scene, settings, caster=caster, lights=lights))
    return caster, lights, MaterialTable(scene.materials), build_photon_maps(scene, ps, caster, lights)


def _trace_shared(scene, settings, built, f: float) -> tuple[np.ndarray, dict]:
    """Caustic + Indirect (H, W, 3) of one image traced on ``built`` maps with SHARE_RADIUS_FRACTION = f,
    and CPU seconds (this thread) inside the maps' estimate and in the sharing's own bookkeeping."""
    from stpm_core.integrator import trace_image
    from stpm_core.photons import maps as maps_mod, sharing
    caster, lights, table, pmaps = built
    t = {"estimate_s": 0.0, "share_s": 0.0}
    old_f, old_est, old_share = sharing.SHARE_RADIUS_FRACTION, maps_mod.PhotonMaps.estimate, sharing.shared_estimate

    def est(*a, **k):
        t0 = time.thread_time()
        try:
            return old_est(*a, **k)
        finally:
            t["estimate_s"] += time.thread_time() - t0

    def share(*a, **k):
        t0, e0 = time.thread_time(), t["estimate_s"]
        try:
            return old_share(*a, **k)
        finally:
            t["share_s"] += time.thread_time() - t0 - (t["estimate_s"] - e0)

    sharing.SHARE_RADIUS_FRACTION, maps_mod.PhotonMaps.estimate, sharing.shared_estimate = f, est, share
    try:
        passes, ts = trace_image(scene, settings, caster, lights, pmaps, table=table)
    finally:
        sharing.SHARE_RADIUS_FRACTION, maps_mod.PhotonMaps.estimate, sharing.shared_estimate = \
            old_f, old_est, old_share
    t["lookup_s"] = t["estimate_s"] + t["share_s"]
    t["queries"], t["estimated"] = ts.photon_lookups, ts.photon_estimates
    return passes["Caustic"][..., :3].astype(np.float64) + passes["Indirect"][..., :3], t


def _blocks(img: np.ndarray, b: int = SHARE_BLOCK) -> np.ndarray:
    """Luminance-free block means (H/b, W/b, 3)."""
    H, W = img.shape[0] // b * b, img.shape[1] // b * b
    return img[:H, :W].reshape(H // b, b, W // b, b, 3).mean(axis=(1, 3))


def _zoomed(scene, zoom: float):
    scene.camera.lens *= zoom
    return scene


def run_sharing(fractions=SHARE_FRACTIONS, seeds=SHARE_SEEDS, resolution=SHARE_RESOLUTION, spp=SHARE_SPP,
                zoom=SHARE_ZOOM) -> dict:
    """Per scene (demo, pool) and seed, FINAL's maps traced once (photons of that seed), then the image
    traced with each sharing fraction f, fractions interleaved: queries shared, look-up CPU-s (estimate
    + the grouping; minimum over seeds), and the error against the unshared image: ``rel_rmse_vs_unshared``
    (same seed: same photons and camera samples; RMSE of Caustic + Indirect over its mean) next to
    ``seed_to_seed_rel_rmse`` (two unshared seeds: the image's own noise); ``rel_bias`` (the mean's
    shift); block z (8 x 8 pixel blocks: mean over seeds of shared minus unshared over the standard
    error of the seeds' block means, as for two independent renders)."""
    out: dict = {}
    scenes = {"demo": _zoomed(demo_scene(resolution), zoom), "pool": _zoomed(pool_scene(resolution), zoom)}
    for name, sc in scenes.items():
        img, tm = {}, {}
        for seed in seeds:
            settings = RenderSettings(**{**FINAL, "samples": spp, "seed": seed})
            built = _final_maps(sc, settings)
            if seed == seeds[0]:
                _trace_shared(sc, RenderSettings(**{**settings.__dict__, "samples": 2}), built, 0.1)  # warm-up
            for f in fractions:
                img[(f, seed)], tm[(f, seed)] = _trace_shared(sc, settings, built, f)
        off = np.stack([img[(0.0, s)] for s in seeds])
        scale = float(off.mean())
        noise = [float(np.sqrt(np.mean((off[i] - off[i + 1]) ** 2))) / scale for i in range(len(seeds) - 1)]
        out[f"{name}_seed_to_seed_rel_rmse"] = float(np.mean(noise))
        cap = float(np.percentile(off, 99.5))                 # the same, on images clipped at the unshared
        clip = lambda x: np.minimum(x, cap)                   # 99.5th percentile (fireflies left out)
        out[f"{name}_seed_to_seed_rel_rmse_clipped"] = float(np.mean(
            [np.sqrt(np.mean((clip(off[i]) - clip(off[i + 1])) ** 2)) / scale for i in range(len(seeds) - 1)]))
        for f in fractions:
            tag = f"{name}_f{f}"
            runs = [tm[(f, s)] for s in seeds]
            out[f"{tag}_queries"] = runs[0]["queries"]
            out[f"{tag}_shared_fraction"] = 1.0 - runs[0]["estimated"] / max(runs[0]["queries"], 1)
            for key in ("lookup_s", "estimate_s", "share_s"):
                out[f"{tag}_{key}"] = min(r[key] for r in runs)
            out[f"{tag}_lookup_over_unshared"] = out[f"{tag}_lookup_s"] / out[f"{name}_f{fractions[0]}_lookup_s"]
            if f == 0.0:
                continue
            on = np.stack([img[(f, s)] for s in seeds])
            out[f"{tag}_rel_rmse_vs_unshared"] = float(np.sqrt(np.mean((on - off) ** 2))) / scale
            out[f"{tag}_rel_rmse_vs_unshared_clipped"] = float(np.sqrt(np.mean((clip(on) - clip(off)) ** 2))) / scale
            out[f"{tag}_rel_bias"] = float((on - off).mean()) / scale
            Bon, Boff = np.stack([_blocks(x) for x in on]), np.stack([_blocks(x) for x in off])
            se = np.sqrt((Bon.var(0, ddof=1) + Boff.var(0, ddof=1)) / len(seeds))
            z = (Bon.mean(0) - Boff.mean(0)) / np.maximum(se, 1e-12 * scale)
            out[f"{tag}_block_z_max"] = float(np.abs(z).max())
            out[f"{tag}_block_z_rms"] = float(np.sqrt(np.mean(z ** 2)))
    return out


if __name__ == "__main__":
    for k, v in run().items():
        print(f"{k:48s} {v}")
