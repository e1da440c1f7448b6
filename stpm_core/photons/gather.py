"""Precomputed irradiance for final gathering (Christensen 1999; docs/photon-mapping.md, "Final gathering").

    cache = IrradianceCache.build(maps, caster, stride=4)
    E = cache.lookup(rows, live, hits, d, t)       # (n, 3) W/m^2 at gather hits (kernels.gather)

After the maps are built, every ``stride``-th photon of the global map (records in Morton order,
so the chosen ones are spread evenly) becomes a cache point: its position x_i and time t_i (the
photon's own), the surface's geometric normal and instance there (one short ray cast back along
the photon's incoming direction at t_i), and the irradiance

    E_i = PhotonMaps.estimate('global', x_i, n_i, t_i)         W / m^2

read with the render's own space-time estimator (STANDARD / TEMPORAL / KD4D, k).  With final
gathering the global map holds every photon stored at a non-delta surface within the diffuse
bounce budget -- direct (first-hit) and caustic photons included (``trace_global_map``), so E_i
is the whole irradiance at x_i.  A gather hit then reads ONE cache point (``kernels.gather.cache_lookup``).
"""
from __future__ import annotations

import time as _time

import numpy as np

from ..kernels import gather as _G
from .record import oct_decode

__all__ = ["IrradianceCache", "GATHER_STRIDE", "GATHER_NORMAL_COS", "GATHER_MAX_RING"]

GATHER_STRIDE = 4              # every 4th global photon is a cache point (Christensen's choice)
GATHER_NORMAL_COS = 0.9        # a cache point serves a hit whose normal is within acos(0.9) = 26 deg of its own
GATHER_MAX_RING = 6            # cells searched around a hit: rings 0 .. 6 (then E = 0: no photon near)
GRID_CELL_FRACTION = 0.5       # grid cell side: this fraction of the median estimate radius r_k


class IrradianceCache:
    """Cache points (N of them) sorted by grid cell, and their irradiance.

    Attributes
    ----------
    pos : (N, 3) float64 world positions (m); time : (N,) shutter times; normal : (N, 3) unit
    geometric normals on the side the photon arrived from; instance : (N,) int64; E : (N, 3)
    W/m^2; cells : (C,) int64 occupied cell keys, sorted; starts : (C + 1,) int64 first point of
    each; lo : (3,) grid origin; h : cell side (m); s : space-time scale (m per shutter);
    stats : build seconds and counts.
    """

    def __init__(self, pos, time, normal, instance, E, *, h: float, s: float, stats: dict | None = None):
        pos = np.asarray(pos, np.float64).reshape(-1, 3)
        self.s = float(s)
        self.h = float(h) if h > 0 else 1.0
        self.lo = pos.min(axis=0) - self.h if pos.shape[0] else np.zeros(3)
        n_axis = 1 << _G.GRID_BITS
        c = np.clip(np.floor((pos - self.lo) / self.h).astype(np.int64), 0, n_axis - 1)
        key = c[:, 0] | (c[:, 1] << _G.GRID_BITS) | (c[:, 2] << (2 * _G.GRID_BITS))
        order = np.argsort(key, kind="stable")
        key = key[order]
        self.pos = np.ascontiguousarray(pos[order])
        self.time = np.ascontiguousarray(np.asarray(time, np.float64)[order])
        self.normal = np.ascontiguousarray(np.asarray(normal, np.float64).reshape(-1, 3)[order])
        self.instance = np.ascontiguousarray(np.asarray(instance, np.int64)[order])
        self.E = np.ascontiguousarray(np.asarray(E, np.float64).reshape(-1, 3)[order])
        self.cells, first = np.unique(key, return_index=True)
        self.starts = np.append(first, key.size).astype(np.int64)
        self.stats = dict(stats or {})
        self.stats["gather_cache_points"] = int(self.pos.shape[0])

    @property
    def n(self) -> int:
        return int(self.pos.shape[0])

    @classmethod
    def build(cls, maps, caster, *, stride: int = GATHER_STRIDE, scene_extent: float = 1.0) -> "IrradianceCache":
        """The cache of ``maps`` (a ``PhotonMaps`` whose global map holds every stored photon).

        caster: the scene's ray caster (a point's normal and instance: a ray from x_i + delta wi
        back along -wi at t_i, delta = 1e-4 scene_extent, reaches the surface the photon landed
        on; points whose ray misses are dropped).  scene_extent: the scene's diagonal (m).
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
        if p.shape[0]:
            E, r = maps.estimate("global", p, ns, t, support=True)[:2]
            h = GRID_CELL_FRACTION * float(np.median(r[np.isfinite(r) & (r > 0)])) if np.any(r > 0) else 1.0
        else:
            E, h = np.zeros((0, 3)), 1.0
        stats = {"gather_normals_s": t1 - t0, "gather_estimate_s": _time.perf_counter() - t1,
                 "gather_points_dropped": int((~ok).sum())}
        return cls(p, t, ng, inst, E, h=h, s=maps.time_scale, stats=stats)

    def lookup(self, rows: np.ndarray, live: np.ndarray, hits, d: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Irradiance (n, 3) W/m^2 at the gather hits rows[live] (n,) of ``hits`` (rays d (m, 3) at times t (m,))."""
        out = np.empty((live.shape[0], 3))
        if self.n == 0:
            out[:] = 0.0
            return out
        misses = _G.cache_lookup(rows, live, hits.position, hits.ng, d, t, hits.instance, self.cells, self.starts,
                                 self.pos, self.time, self.normal, self.instance, self.E, self.lo, self.h, self.s,
                                 GATHER_NORMAL_COS, GATHER_MAX_RING, out)
        self.stats["gather_misses"] = self.stats.get("gather_misses", 0) + int(misses)
        return out

