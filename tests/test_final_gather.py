"""Final gathering's precomputed irradiance (``photons.gather``, ``kernels.gather``) against numpy oracles.

* every cache point's photon irradiance is the render's estimator at the photon's own position,
  side and time, with the photon-normal test and no height bound (a photon behind the point's
  plane counts only if its stored normal is within acos(NORMAL_COS) of the point's): checked
  against a brute-force k-nearest STANDARD estimate in numpy;
* the cache points are every 4th global photon, at the photon's own time;
* a gather hit reads the nearest cache point in space-time on its own instance with a normal within
  acos(0.9), within the cache's reach (the kd-tree search): checked against a brute-force search in numpy, on a scene with a moving box (so the
  time term decides);
* the direct part, added at render time by next-event estimation at the points, is exact for a
  point light (I cos / d^2 where unshadowed);
* PROGRESSIVE refuses it with a clear message.
Small scenes, 20k photons: a few seconds after the kernels are compiled.
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from scenes import box_mesh, make_scene, moving, ortho_camera_down, plane_mesh, point_light
from stpm_core.errors import SettingsError
from stpm_core.lights import LightSet
from stpm_core.photons.gather import GATHER_NORMAL_COS, GATHER_STRIDE, IrradianceCache
from stpm_core.photons.maps import build_photon_maps
from stpm_core.photons.estimators import NORMAL_COS
from stpm_core.photons.record import NO_NORMAL, oct_decode
from stpm_core.raycast import make_caster
from stpm_core.scene import Material
from stpm_core.settings import RenderSettings
from stpm_core.shutter import Shutter


def _scene(moving_box: bool = False):
    """A floor, a box (sliding 1 m in x over the shutter when moving_box) and a point light above."""
    mats = [Material.diffuse((0.8, 0.8, 0.8)), Material.diffuse((0.5, 0.6, 0.7))]
    box = box_mesh((-0.4, -0.4, 0.0), (0.4, 0.4, 0.8), material=1, name="box")
    tr = moving((-0.5, 0, 0), (0.5, 0, 0)) if moving_box else np.eye(4)
    return make_scene([plane_mesh(6.0, z=0.0, material=0, name="floor"), (box, tr)], mats, ortho_camera_down(),
                      [point_light((0.3, -1.0, 2.0), 200.0)], shutter=Shutter(1.0, 2.0))


def _maps(scene, **kw):
    st = RenderSettings(**dict(dict(photons_global=60_000, photons_caustic=0, k_nearest=20, estimator="STANDARD",
                                    final_gather_samples=4, max_depth=4), **kw))
    caster = make_caster(scene)
    return build_photon_maps(scene, st, caster, LightSet(scene)), caster


def test_precomputed_irradiance_matches_a_brute_force_estimate():
    """E_i = sum_{k-1 nearest, wi . n_i > 0, n_p . n_i >= NORMAL_COS behind x_i's plane} Phi / (pi r_k^2)
    at every cache point (STANDARD, k = 20): the box's top face near its edges has the sides' photons
    behind it, at right angles, which the normal test drops."""
    maps, _ = _maps(_scene())
    cache = maps.gather_cache
    gm = maps.maps["global"]
    rec = gm.records
    assert cache is not None and cache.n > 0.95 * (gm.n // GATHER_STRIDE)
    # the cache points are the 4th photons, at their own times
    sel = rec[::GATHER_STRIDE]
    key = lambda p, t: set(map(tuple, np.round(np.column_stack([p, t]), 5)))  # noqa: E731
    assert key(cache.pos, cache.time) <= key(sel["position"].astype(np.float64) + gm.origin, sel["time"])
    # brute force, in the records' own frame
    P = rec["position"].astype(np.float64)
    wi = oct_decode(rec["wi_oct"]).astype(np.float64)
    Phi = rec["power"].astype(np.float64)
    n_p = oct_decode(rec["ng_oct"]).astype(np.float64)
    has_n = np.all(rec["ng_oct"] != NO_NORMAL, axis=1)
    assert has_n.all()
    dropped = 0
    rng = np.random.default_rng(3)
    pick = rng.choice(cache.n, min(cache.n, 300), replace=False)
    k = 20
    for i in pick:
        x = cache.pos[i] - gm.origin
        d = np.sqrt(((P - x) ** 2).sum(axis=1))
        order = np.argsort(d, kind="stable")
        r = d[order[k - 1]]
        inner = order[:k - 1]
        side = wi[inner] @ cache.normal[i] > 0.0
        behind = (P[inner] - x) @ cache.normal[i] < 0.0
        facing = n_p[inner] @ cache.normal[i] >= NORMAL_COS
        dropped += int((side & behind & ~facing).sum())
        side &= ~behind | facing
        E = Phi[inner][side].sum(axis=0) / (np.pi * r * r)
        np.testing.assert_allclose(cache.E[i], E, rtol=2e-4, atol=1e-9 * max(E.max(), 1.0))
    assert dropped > 0                                             # the normal test was exercised
    assert cache.direct_pending                                    # the direct part comes at render time


def test_direct_part_is_next_event_estimation_at_the_points():
    """The integrator adds E_direct = I cos / d^2 (unshadowed) at every cache point, once: a point
    light has no noise, so the added part is exact; without final gathering there is no cache."""
    from stpm_core.integrator import trace_image
    scene = _scene()
    maps, caster = _maps(scene)
    cache = maps.gather_cache
    before = cache.E.copy()
    settings = RenderSettings(samples=1, photons_global=60_000, photons_caustic=0, k_nearest=20,
                              estimator="STANDARD", final_gather_samples=4, max_depth=4)
    trace_image(scene, settings, caster, LightSet(scene), maps)
    assert not cache.direct_pending
    added = cache.E - before
    light = np.array([0.3, -1.0, 2.0])
    L = light - cache.pos
    dist = np.linalg.norm(L, axis=1)
    w = L / dist[:, None]
    cos = np.einsum("ij,ij->i", cache.normal, w)
    lit = ~np.asarray(caster.occluded(cache.pos + 1e-4 * cache.normal, w, cache.time, dist - 2e-4), bool)
    want = np.where(lit & (cos > 0), 200.0 / (4 * np.pi) * np.maximum(cos, 0) / dist ** 2, 0.0)
    np.testing.assert_allclose(added.mean(axis=1), want, rtol=1e-6, atol=1e-9)
    assert np.ptp(added, axis=1).max() < 1e-12                      # white light, white closure
    E_again = cache.E.copy()
    trace_image(scene, settings, caster, LightSet(scene), maps)      # a second trace adds nothing
    np.testing.assert_array_equal(cache.E, E_again)
    no_fg, _ = _maps(scene, final_gather_samples=0)
    assert no_fg.gather_cache is None


def test_gather_lookup_is_the_nearest_cache_point_in_space_time():
    """cache_lookup = argmin |x - x_c|^2 + (s (t - t_c))^2 over points on the hit's instance, normals within acos(0.9)."""
    scene = _scene(moving_box=True)
    maps, caster = _maps(scene, estimator="TEMPORAL")
    cache = maps.gather_cache
    assert cache.s > 0.5                                           # the box moves 1 m: time matters
    rng = np.random.default_rng(7)
    n = 2000
    o = np.column_stack([rng.uniform(-1.5, 1.5, n), rng.uniform(-1.5, 1.5, n), np.full(n, 3.0)])
    d = np.column_stack([rng.normal(0, 0.3, n), rng.normal(0, 0.3, n), -np.ones(n)])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t = rng.random(n)
    hits = caster.intersect(o, d, t, None)
    live = np.flatnonzero(hits.hit)
    rows = np.arange(n)
    E = cache.lookup(rows, live, hits, d, t)
    found = 0
    assert live.size > 1000 and np.any(hits.instance[live] == 1)
    for j, r in enumerate(live):
        g = hits.ng[r] * (-1.0 if hits.ng[r] @ d[r] > 0 else 1.0)
        ok = (cache.instance == hits.instance[r]) & (cache.normal @ g >= GATHER_NORMAL_COS)
        if not ok.any():
            assert np.all(E[j] == 0.0)
            continue
        c = np.flatnonzero(ok)
        d2 = ((cache.pos[c] - hits.position[r]) ** 2).sum(axis=1) + (cache.s * (cache.time[c] - t[r])) ** 2
        best = c[np.argmin(d2)]
        if d2.min() >= cache.reach ** 2:
            assert np.all(E[j] == 0.0)                             # beyond the reach: a miss
            continue
        np.testing.assert_array_equal(E[j], cache.E[best])
        found += 1
    assert found > 0.9 * live.size


def test_progressive_refuses_final_gathering():
    with pytest.raises(SettingsError, match="final_gather_samples"):
        RenderSettings(method="PROGRESSIVE", passes=4, final_gather_samples=8)


def test_cache_of_an_empty_map_reads_zero():
    cache = IrradianceCache(np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros((0, 3)),
                            s=1.0)
    hits = SimpleNamespace(position=np.zeros((2, 3)), ng=np.zeros((2, 3)), instance=np.zeros(2, np.int64))
    E = cache.lookup(np.arange(2), np.arange(2), hits, np.zeros((2, 3)), np.zeros(2))
    assert np.all(E == 0.0)


def test_one_diffuse_bounce_reads_the_maps_directly():
    """diffuse_bounces = 1: the gather vertex could read no photon, so gathering is off (no cache),
    and the global map is the one the camera reads (the same records as without gathering)."""
    scene = _scene()
    on, _ = _maps(scene, diffuse_bounces=1)
    off, _ = _maps(scene, diffuse_bounces=1, final_gather_samples=0)
    assert on.gather_cache is None
    np.testing.assert_array_equal(on.maps["global"].records, off.maps["global"].records)
