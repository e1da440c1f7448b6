"""Precomputed irradiance for final gathering (Christensen 1999; docs/photon-mapping.md, "Final gathering").

    cache = IrradianceCache.build(maps, caster, stride=4)
    E = cache.lookup(rows, live, hits, d, t)       # (n, 3) W/m^2 at gather hits (kernels.gather)

After the maps are built, every ``stride``-th photon of the global map (records in Morton order,
so the chosen ones are spread evenly) becomes a cache point: its position x_i and time t_i (the
photon's own), the surface's geometric normal and instance there (one short ray cast back along
the photon's incoming direction at t_i), and the irradiance

    E_i = E_direct(x_i, t_i) + E_caustic(x_i, n_i, t_i) + E_global(x_i, n_i, t_i)        W / m^2

the last two read with the render's own space-time estimator (STANDARD / TEMPORAL / KD4D, k) from
the caustic and global maps with the photon-normal test and no tangent slab (``GATHER_PLANE_BACK``:
a photon behind the point's plane counts only if its stored normal is within acos(``NORMAL_COS``)
of n_i, so the sunlit notch faces of an open outer corner, at right angles behind a wall, add
nothing; the wall behind a curtain still does), the first by next-event estimation at (x_i, t_i)
toward every light (``integrator._cache_direct``, with a white Lambertian closure), so E_i is the
whole irradiance at x_i.  (Direct light from first-hit photons instead -- Jensen's global map -- leaked through
zero-thickness walls: a point inside a room near an edge read the sunlit roof's photons across it,
since a photon record has no normal to tell them apart.)  A gather hit then reads ONE cache point (``kernels.gather.cache_lookup``):
the nearest in space-time on its instance with a normal within acos(``GATHER_NORMAL_COS``), within ``reach``.
"""
from __future__ import annotations

import time as _time

import numpy as np

from ..kernels import gather as _G
from .record import oct_decode

__all__ = ["IrradianceCache", "GATHER_STRIDE", "GATHER_NORMAL_COS", "GATHER_REACH", "GATHER_PLANE_BACK"]

GATHER_STRIDE = 4              # every 4th global photon is a cache point (Christensen's choice)
GATHER_NORMAL_COS = 0.9        # a cache point serves a hit whose normal is within acos(0.9) = 26 deg of its own
GATHER_REACH = 4.0             # a hit reads no cache point farther than 4 x the 95th percentile of the
                               # estimates' radii r_k (then E = 0, counted in gather_misses)
GATHER_PLANE_BACK = 2.0        # the cache's estimates: the tangent slab's back fraction (estimators.PLANE_FRACTION's
                               # stand-in).  Every photon of a search region lies within its radius rho of the
                               # point, so |h| <= rho and any fraction >= 1 bounds nothing (2: clear of rounding):
                               # the photon-normal test (kdtree._facing) alone, which the slab switches on.  The
                               # slab proper darkened curtains under final gathering (docs/photon-mapping.md,
                               # "Tangent slab"); without the normal test an open outer corner leaked (section 9)


class IrradianceCache:
    """Cache points (N of them), their irradiance, and a kd-tree over them in (x, y, z, s t).

    Attributes
    ----------
    pos : (N, 3) float64 world positions (m); time : (N,) shutter times; normal : (N, 3) unit
    geometric normals on the side the photon arrived from; instance : (N,) int64; E : (N, 3)
    W/m^2; s : space-time scale (m per shutter); reach : the largest distance a hit reads (m);
    perm, axis, split : the kd-tree (``kernels.gather.cache_tree``); stats : build seconds and counts.
    """

    def __init__(self, pos, time, normal, instance, E, *, s: float, reach: float = np.inf, stats: dict | None = None):
        self.pos = np.ascontiguousarray(np.asarray(pos, np.float64).reshape(-1, 3))
        self.time = np.ascontiguousarray(np.asarray(time, np.float64).reshape(-1))
        self.normal = np.ascontiguousarray(np.asarray(normal, np.float64).reshape(-1, 3))
        self.instance = np.ascontiguousarray(np.asarray(instance, np.int64).reshape(-1))
        self.E = np.ascontiguousarray(np.asarray(E, np.float64).reshape(-1, 3))
        self.s = float(s)
        self.reach = float(reach)
        N = self.pos.shape[0]
        self.perm = np.arange(N, dtype=np.int64)
        M = int(_G.tree_size(max(N, 1)))
        self.axis = np.full(M, -1, np.int64)
        self.split = np.zeros(M)
        if N:
            _G.cache_tree(self.pos, self.time, self.s, self.perm, self.axis, self.split)
        self.stats = dict(stats or {})
        self.stats["gather_cache_points"] = int(N)

    direct_pending = False       # the direct irradiance is still to be added (add_direct)
    shading_normal = None

    def add_direct(self, E_direct: np.ndarray) -> None:
        """Add the direct irradiance (N, 3) W/m^2 at the points (next-event estimation), once."""
        self.E += np.asarray(E_direct, np.float64).reshape(self.E.shape)
        self.direct_pending = False

    @property
    def n(self) -> int:
        return int(self.pos.shape[0])

    @classmethod
    def build(cls, maps, caster, *, stride: int = GATHER_STRIDE, scene_extent: float = 1.0,
              caustics: bool = True) -> "IrradianceCache":
        """The cache of ``maps`` (a ``PhotonMaps`` whose global map holds every stored photon).

        caster: the scene's ray caster (a point's normal and instance: a ray from x_i + delta wi
        back along -wi at t_i, delta = 1e-4 scene_extent, reaches the surface the photon landed
        on; points whose ray misses are dropped).  scene_extent: the scene's diagonal (m).
        caustics: add the caustic map's estimate (False when the diffuse budget leaves no caustic
        photon readable at a gather vertex: ``diffuse_bounces`` < 2).

        E holds the global and caustic maps' estimates; the direct part is added by the
        integrator (:meth:`add_direct`, ``integrator._cache_direct``: next-event estimation at the
        points, which needs the lights), before the first look-up.
        """
        t0 = _time.perf_counter()
        gm = maps.maps["global"]
        rec = gm.records[::max(1, int(stride))]
        wi = oct_decode(rec["wi_oct"]).astype(np.float64)
        wi /= np.maximum(np.linalg.norm(wi, axis=1, keepdims=True), 1e-30)
        p = rec["position"].astype(np.float64) + gm.origin
        t = rec["time"].astype(np.float64)
        # -- The surface under each point: normal and instance ---------------------------------
        delta = 1e-4 * max(float(scene_extent), 1e-9)
        hits = caster.intersect(p + delta * wi, -wi, t, np.full(t.shape, 2.0 * delta))
        ok = np.asarray(hits.hit, bool)
        p, t, wi = p[ok], t[ok], wi[ok]
        ng = np.asarray(hits.ng, np.float64)[ok]
        ng = ng / np.maximum(np.linalg.norm(ng, axis=1, keepdims=True), 1e-30)
        ng *= np.where(np.einsum("ij,ij->i", ng, wi) < 0.0, -1.0, 1.0)[:, None]
        ns = np.asarray(hits.ns, np.float64)[ok]
        ns *= np.where(np.einsum("ij,ij->i", ns, wi) < 0.0, -1.0, 1.0)[:, None]
        inst = np.asarray(hits.instance, np.int64)[ok]
        t1 = _time.perf_counter()
        # -- Irradiance at each point: the render's own space-time estimator ---------------------
        reach = np.inf
        if p.shape[0]:
            # (ng: the photon-normal test against the point's geometric normal, no height bound)
            E, r = maps.estimate("global", p, ns, t, support=True, ng=ng, back=GATHER_PLANE_BACK)[:2]
            E = np.array(E, np.float64)
            if caustics and maps.has("caustic"):
                E += maps.estimate("caustic", p, ns, t, ng=ng, back=GATHER_PLANE_BACK)
            r = np.asarray(r, np.float64)
            r = r[np.isfinite(r) & (r > 0)]
            if r.size:
                reach = GATHER_REACH * float(np.percentile(r, 95))
        else:
            E = np.zeros((0, 3))
        t2 = _time.perf_counter()
        cache = cls(p, t, ng, inst, E, s=maps.time_scale, reach=reach)
        cache.shading_normal = np.ascontiguousarray(ns)        # (N, 3) for next-event estimation (add_direct)
        cache.direct_pending = True
        cache.stats.update({"gather_normals_s": t1 - t0, "gather_estimate_s": t2 - t1,
                            "gather_tree_s": _time.perf_counter() - t2, "gather_points_dropped": int((~ok).sum())})
        return cache

    def lookup(self, rows: np.ndarray, live: np.ndarray, hits, d: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Irradiance (n, 3) W/m^2 at the gather hits rows[live] (n,) of ``hits`` (rays d (m, 3) at times t (m,))."""
        out = np.empty((live.shape[0], 3))
        if self.n == 0:
            out[:] = 0.0
            return out
        misses = _G.cache_lookup(rows, live, hits.position, hits.ng, d, t, hits.instance, self.perm, self.axis,
                                 self.split, self.pos, self.time, self.normal, self.instance, self.E, self.s,
                                 GATHER_NORMAL_COS, self.reach * self.reach, out)
        self.stats["gather_misses"] = self.stats.get("gather_misses", 0) + int(misses)
        return out

