"""Final gathering's cache near an open outer corner reads no sunlit notch face behind the wall (a leak, fixed).

tests/test_corner_leak.py's synthetic corner (walls A: y = 0 facing +y and B: x = 0 facing +x at
1 W/m^2, the notch face x = 0, y in [-0.1, 0] at 20 W/m^2, its photons arriving from the room
side of A's plane), read through ``photons.gather.IrradianceCache``: every 4th photon a cache
point whose irradiance is the map's estimate there, and gather hits on A 0.02-0.1 m from the
corner reading the nearest cache point on A's instance (``kernels.gather.cache_lookup``).  The
cache's estimates read the maps without the tangent slab; until 2026-12-07 that also meant without
the photon-normal test, so cache points on A near the corner summed the notch's photons and a
gather hit there read (k 100) TEMPORAL 7.62x, STANDARD 4.26x, KD4D 5.67x A's irradiance.  With the
normal test and no height bound (``GATHER_PLANE_BACK``): 1.01x, 1.03x, 1.02x (docs/photon-mapping.md,
section 9, "Open outer corners").  The caster is a stub that knows the three faces.
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from test_corner_leak import E_WALL, corner_map
from stpm_core.photons.gather import IrradianceCache
from stpm_core.photons.maps import PhotonMaps


class _CornerCaster:
    """The faces under a cache point (its short ray starts on them): A (y = 0, instance 0), the
    notch face (x = 0, y < 0: A's box's end, instance 0) and B (x = 0, y > 0, instance 1)."""

    def intersect(self, o, d, t, tmax):
        n = o.shape[0]
        on_a = np.abs(o[:, 1]) < 1e-3
        ng = np.where(on_a[:, None], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0])
        inst = np.where(~on_a & (o[:, 1] > 0.0), 1, 0).astype(np.int32)
        return SimpleNamespace(hit=np.ones(n, bool), ng=ng, ns=ng.copy(), instance=inst, position=o)


@pytest.mark.parametrize("backend", ["numba", "scipy"])
@pytest.mark.parametrize("estimator", ["STANDARD", "TEMPORAL", "KD4D"])
def test_gather_hits_near_an_open_outer_corner_read_no_notch_photons(estimator, backend):
    rng = np.random.default_rng(3)
    m = corner_map(rng, backend=backend)
    maps = PhotonMaps({"global": m}, estimator=estimator, k=100, kernel="BOX", temporal_alpha=0.0,
                      time_scale=m.time_scale)
    cache = IrradianceCache.build(maps, _CornerCaster(), scene_extent=3.0, caustics=False)
    # gather hits on A near the corner, arriving from the room (+y)
    n = 400
    y = np.column_stack([rng.uniform(0.02, 0.1, n), np.zeros(n), rng.uniform(0.5, 1.5, n)])
    hits = SimpleNamespace(position=y, ng=np.tile([0.0, 1.0, 0.0], (n, 1)), instance=np.zeros(n, np.int32))
    d = np.tile([0.0, -1.0, 0.0], (n, 1))
    E = cache.lookup(np.arange(n), np.arange(n), hits, d, rng.random(n))[:, 0]
    assert cache.stats["gather_misses"] == 0
    assert abs(E.mean() / E_WALL - 1.0) < 0.1, E.mean() / E_WALL


@pytest.mark.parametrize("backend", ["numba", "scipy"])
@pytest.mark.parametrize("estimator", ["STANDARD", "TEMPORAL", "KD4D"])
def test_a_back_fraction_of_two_bounds_no_photon(estimator, backend):
    """back >= 1 cuts nothing by height: on the corner map without stored normals (every photon
    passes the normal test) the estimate equals the one without any slab, the notch included."""
    rng = np.random.default_rng(5)
    m = corner_map(rng, no_normals=True, backend=backend)
    n = 300
    q = np.column_stack([rng.uniform(0.0, 0.3, n), np.zeros(n), rng.uniform(0.2, 1.8, n)])
    ns = np.tile([0.0, 1.0, 0.0], (n, 1))
    t = rng.random(n)
    free = m.estimate(q, ns, t, estimator=estimator, k=100)
    two = m.estimate(q, ns, t, estimator=estimator, k=100, ng=ns, back=2.0)
    half = m.estimate(q, ns, t, estimator=estimator, k=100, ng=ns)
    np.testing.assert_array_equal(two, free)
    assert half[:, 0].mean() < 0.95 * free[:, 0].mean()        # the default 0.5 does cut some of it
    with pytest.raises(ValueError, match="back fraction"):
        m.estimate(q, ns, t, estimator=estimator, k=100, ng=ns, back=0.0)
