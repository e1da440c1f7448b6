"""The caster both backends share: batching, nearest-over-parts, shading.

A scene is split into *parts*, each able to answer "nearest hit in (t0, t1)"
for a batch of rays at their own times:

* the static part: every instance whose transform is static and whose mesh
  is rigid, baked into one world-space structure (pays no motion cost);
* one part per moving instance (rigid motion): rays go to object space with
  the instance's inverse transform at each ray's time;
* one part per instance of a deforming mesh.

:class:`Caster` walks the parts in that order, skipping rays whose current
segment misses a part's swept world bounds, keeps the nearest exact (float64)
hit, then asks the winning part of each ray for normals and material.
Backends (:mod:`.embree_backend`, :mod:`.numba_backend`, :mod:`.numpy_backend`)
only provide parts.

A part has ``bounds`` (world (lo, hi) over the shutter, or None = every ray)
and three methods on a batch of m rays:

* ``cast(o, d, times, t0, t1) -> (t, prim, u, v)``: nearest exact hit with
  t0 < t < t1 (t = inf for a miss; prim, u, v meaningless there);
* ``occluded(o, d, times, t0, t1) -> (m,) bool``;
* ``shade(times, prim, u, v) -> (instance, prim, ng, ns, material)`` for hits.

Optional fused entry points (embree parts with numba, :mod:`.embree_kernels`),
used by the caster when present and not None:

* unbounded part, first in the list (the baked static scene):
  ``intersect_into(o, d, times, tmax, guard, k, fields, tmin, final)`` makes
  the guard, casts and writes every result field of every ray in place
  (misses included: the caster pre-fills nothing), and
  ``occluded_into(o, d, tmax, guard, tmin, blocked)``;
* bounded part: ``cast_all(o, d, times, t0, t1)`` and
  ``occluded_all(o, d, times, t0, t1, skip)`` take every ray of a block and do
  their own swept-box tests (the caster's part-box pass is skipped for them);
  ``shade_rows(rows, prim, times, out)`` writes the shading fields of the
  rays it won straight into the results.
"""
from __future__ import annotations

import os
import time as _time

import numpy as np

from . import Hits
from .geometry import ray_guard, scene_scale, tmin_of
from .pair_bvh import PairBVH, RaySlabs, segments_meet_boxes

__all__ = ["make_caster", "Caster", "BACKENDS"]

BACKENDS = ("auto", "embree", "numba", "numpy")


# Environment override of backend='auto' (render() and the photon tracer build
# their casters with 'auto'): one of BACKENDS, e.g. STPM_RAYCAST_BACKEND=numba
BACKEND_ENV = "STPM_RAYCAST_BACKEND"

# Rays per batch: embree's run() is fastest at 4k-16k rays (design.md), and the
# numpy work around it stays in cache.
CHUNK = 8192

# Above this many bounded parts, rays find theirs through a BVH of the part boxes;
# below it one slab test per part is cheaper (measured: the BVH's gathers cost
# about as much as 20-25 slab tests).
PART_BVH_MIN = 24


def embree_available() -> bool:
    """Can the embreex backend be imported on this platform?"""
    try:
        import embreex.rtcore_scene  # noqa: F401
        import embreex.mesh_construction  # noqa: F401
    except Exception:
        return False
    return True


def numba_available() -> bool:
    """Can the numba backend be imported (numba installed and working)?"""
    try:
        import numba  # noqa: F401
    except Exception:
        return False
    return True


def make_caster(scene, backend: str = "auto", fused: bool | None = None) -> "Caster":
    """Build a time-aware ray caster for ``scene``.

    backend : 'embree' (embreex, float32 BVH + float64 refinement), 'numba'
        (compiled float64 BVH, exact; for platforms without embreex), 'numpy'
        (exact float64, brute force or a numpy BVH; the test oracle and the
        last fallback) or 'auto': the environment variable
        ``STPM_RAYCAST_BACKEND`` if set, else embree when importable, else
        numba when importable, else numpy.  See docs/raycast.md.
    fused : embree backend only: None (default) = numba kernels around
        embree's ``run()`` whenever numba imports (:mod:`.embree_kernels`);
        False = the numpy path (same results to rounding; tests, benchmarks).
    """
    from ..errors import SettingsError
    if backend == "auto" and os.environ.get(BACKEND_ENV, "").strip():
        backend = os.environ[BACKEND_ENV].strip().lower()
        if backend not in BACKENDS:
            raise SettingsError(f"{BACKEND_ENV} must be one of {', '.join(BACKENDS)}, got {backend!r}")
    if backend not in BACKENDS:
        raise SettingsError(f"ray-casting backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
    if backend == "auto":
        backend = "embree" if embree_available() else "numba" if numba_available() else "numpy"
    if backend == "embree":
        if not embree_available():
            raise SettingsError("ray-casting backend 'embree' needs the embreex package, which is not installed")
        from .embree_backend import build_parts as _embree_parts
        build_parts = (lambda sc, scale: _embree_parts(sc, scale, fused))
    elif backend == "numba":
        if not numba_available():
            raise SettingsError("ray-casting backend 'numba' needs the numba package, which is not installed")
        from .numba_backend import build_parts
    else:
        from .numpy_backend import build_parts
    scale = scene_scale(scene)
    t0 = _time.perf_counter()
    caster = Caster(scene, build_parts(scene, scale), scale, backend)
    caster.stats["build_s"] = _time.perf_counter() - t0
    caster.stats["static_reused"] = bool(caster.parts and getattr(caster.parts[0], "reused_now", False))
    return caster


def _as_rays(origins, dirs, times, tmax):
    """Validate and broadcast ray arrays -> float64 (n,3), (n,3), (n,), (n,)."""
    o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    n = o.shape[0]
    if d.shape[0] != n:
        raise ValueError(f"origins has {n} rays but dirs has {d.shape[0]}")
    try:
        t = np.broadcast_to(np.asarray(times, dtype=np.float64), (n,))
        tm = np.full(n, np.inf) if tmax is None else np.broadcast_to(np.asarray(tmax, dtype=np.float64), (n,))
    except ValueError:
        raise ValueError(f"times and tmax must be scalars or have one value per ray ({n})") from None
    return o, d, t, tm


class Caster:
    """Time-aware caster over a list of parts (see module docstring).

    ``stats``: rays intersected / occlusion-tested and seconds spent.
    """

    def __init__(self, scene, parts, scale: float, backend: str, contacts: bool = True):
        self.scene = scene
        self.parts = parts
        self.scale = scale
        self.backend = backend
        self.stats = {"backend": backend, "rays_intersect": 0, "rays_occluded": 0,
                      "seconds_intersect": 0.0, "seconds_occluded": 0.0}
        # Parts with swept bounds (moving, deforming; every numpy part), under a small BVH
        # so a ray pays for the boxes near it, not for every moving instance
        self.bounded = [k for k, p in enumerate(parts) if p.bounds is not None]
        self._part_lo = np.array([parts[k].bounds[0] for k in self.bounded]).reshape(-1, 3)
        self._part_hi = np.array([parts[k].bounds[1] for k in self.bounded]).reshape(-1, 3)
        self._is_bounded = np.zeros(len(parts) + 1, bool)         # part k (or -1 = none) has bounds?
        self._is_bounded[self.bounded] = True
        many = len(self.bounded) > PART_BVH_MIN
        self._part_bvh = PairBVH(self._part_lo, self._part_hi, leaf=2) if many else None
        # Faces of different static objects lying on each other (:mod:`.contact`); None = rule off
        self.contacts = None
        if contacts:
            from .contact import find_contacts
            first = parts[0] if parts else None
            kept = getattr(first, "contacts", None) if getattr(first, "reused_now", False) else None
            if kept is not None:
                # The persistent static part was reused (same static instances, meshes, matrices):
                # so are its contacts, which depend on nothing else
                kept.rebind(scene)
                self.contacts = kept
            else:
                self.contacts = find_contacts(scene)
                if first is not None and first.bounds is None:
                    first.contacts = self.contacts
            self.stats["contact_faces"] = len(self.contacts)

    def _bounded_rays(self, o, d, t0, t1, subset=None) -> dict:
        """{part index k: ray indices (ascending) whose segment [t0, t1] meets part k's bounds}.

        ``subset`` (m,) restricts the rays considered (indices into o, d, t0, t1).
        """
        out = {}
        if not self.bounded:
            return out
        rays = np.arange(o.shape[0]) if subset is None else subset
        if self._part_bvh is None:
            if subset is None:
                slabs, t0s, t1s = RaySlabs(o, d), t0, t1
            else:
                slabs, t0s, t1s = RaySlabs(o[rays], d[rays]), t0[rays], t1[rays]
            meet = slabs.meets_each(self._part_lo, self._part_hi, t0s, t1s)
            for j, k in enumerate(self.bounded):
                out[k] = rays[meet[j]]
            return out
        # Part BVH in ray blocks: (ray, part) pairs, then each pair against the part's own box
        R, J = [], []
        for a in range(0, rays.size, CHUNK):
            r = rays[a:a + CHUNK]
            oo, dd = o[r], d[r]
            ray, j = self._part_bvh.candidates(oo, dd, t0[r], t1[r])
            with np.errstate(divide="ignore"):
                inv = 1.0 / dd[ray]
            keep = segments_meet_boxes(oo[ray], inv, self._part_lo[j], self._part_hi[j],
                                       t0[r][ray], t1[r][ray])
            R.append(r[ray[keep]])
            J.append(j[keep])
        R, J = np.concatenate(R), np.concatenate(J)
        order = np.lexsort((R, J))
        R, J = R[order], J[order]
        cuts = np.searchsorted(J, np.arange(len(self.bounded) + 1))
        for j, k in enumerate(self.bounded):
            out[k] = R[cuts[j]:cuts[j + 1]]
        return out

    # ------------------------------------------------------------------ intersect
    def intersect(self, origins, dirs, times, tmax=None, guard=None) -> Hits:
        """Nearest hit of each ray at its own time -> :class:`Hits` (see package docstring).

        guard: None (every ray ignores hits closer than TMIN_REL * scale) or (n,) distances, each
        ray's own (capped at that; :func:`~.geometry.ray_guard`).  A ray that leaves an object
        through a face lying on another object's face (a cube resting on a table) hits the other
        object there (:mod:`.contact`)."""
        hits = self._nearest(origins, dirs, times, tmax, guard)
        if self.contacts is not None and len(self.contacts):
            start = _time.perf_counter()
            o, d, times, tmax = _as_rays(origins, dirs, times, tmax)
            self.stats["contact_hits"] = self.stats.get("contact_hits", 0) + \
                self.contacts.resolve(o, d, times, tmax, hits)
            self.stats["seconds_intersect"] += _time.perf_counter() - start
        return hits

    def _nearest(self, origins, dirs, times, tmax=None, guard=None) -> Hits:
        """:meth:`intersect` without the contact rule: the nearest hit over the parts."""
        start = _time.perf_counter()
        n_tmax = tmax
        o, d, times, tmax = _as_rays(origins, dirs, times, tmax)
        n = o.shape[0]
        first = self.parts[0] if self.parts else None
        fast = first is not None and first.bounds is None and getattr(first, "intersect_into", None) is not None
        out = Hits.empty(n)
        if fast:
            # Fused first (static) part: guard, cast, refine and every field in kernels per block,
            # no pre-filled arrays; misses written by the kernel
            only = len(self.parts) == 1
            o, d, times = (np.ascontiguousarray(a) for a in (o, d, times))
            tm = None if n_tmax is None else np.ascontiguousarray(tmax)
            best_t = out.t
            G = ray_guard(self.scale, guard)
            # Part index, part primitive and guard of every ray: needed by the parts that follow,
            # else one block's worth (cache-resident) reused block after block
            rows = min(n, CHUNK) if only else n
            best_part, prim, tmin = np.empty(rows, np.int32), np.empty(rows, np.int64), np.empty(rows)
            for a in range(0, n, CHUNK):
                sl = slice(a, min(n, a + CHUNK))
                bl = slice(0, sl.stop - a) if only else sl
                first.intersect_into(o[sl], d[sl], times[sl], None if tm is None else tm[sl],
                                     G if G.shape[0] == 1 else G[sl], 0,
                                     (best_t[sl], best_part[bl], prim[bl], out.u[sl], out.v[sl],
                                      out.instance[sl], out.prim[sl], out.material[sl], out.ng[sl],
                                      out.ns[sl], out.position[sl]), tmin[bl], only)
            if only:
                self.stats["rays_intersect"] += n
                self.stats["seconds_intersect"] += _time.perf_counter() - start
                return out
            parts = list(enumerate(self.parts))[1:]
        else:
            tmin = tmin_of(d, self.scale, None if guard is None else ray_guard(self.scale, guard))
            out.t[:] = tmax
            out.instance.fill(-1)
            out.prim.fill(-1)
            out.material.fill(-1)
            for f in (out.u, out.v, out.ng, out.ns):
                f.fill(0.0)
            out.position.fill(np.nan)
            best_t = out.t                       # nearest exact hit so far (starts at tmax)
            best_part = np.full(n, -1, np.int32)
            prim = np.full(n, -1, np.int64)      # part-local primitive of the nearest hit
            parts = list(enumerate(self.parts))
        rays = None
        for k, part in parts:
            if part.bounds is None:
                # Parts without bounds (the baked static scene) see every ray and shade
                # their hits at once, in contiguous blocks (a later part may overwrite)
                for a in range(0, n, CHUNK):
                    sl = slice(a, min(n, a + CHUNK))
                    t_k, p_k, u_k, v_k = part.cast(o[sl], d[sl], times[sl], tmin[sl], best_t[sl])
                    won = t_k < best_t[sl]
                    all_won = won.all()
                    inst, p, ng, ns, mat = part.shade(times[sl], p_k if all_won else np.where(won, p_k, 0),
                                                      u_k, v_k)
                    pos = o[sl] + t_k[:, None] * d[sl] if all_won else None
                    fields = ((best_t, t_k), (best_part, k), (prim, p_k), (out.u, u_k), (out.v, v_k),
                              (out.instance, inst), (out.prim, p), (out.material, mat), (out.ng, ng),
                              (out.ns, ns), (out.position, pos))
                    if all_won:
                        # Every ray of the block hit: plain copies (position too, cache-hot)
                        for dst, src in fields:
                            dst[sl] = src
                    else:
                        for dst, src in fields[:-1]:
                            np.copyto(dst[sl], src, where=won if np.ndim(src) < 2 else won[:, None])
                continue
            if self._part_bvh is None and getattr(part, "cast_into", None) is not None:
                # Fused part merging its hits itself: box tests, transforms, refinement, nearest pair
                for a in range(0, n, CHUNK):
                    sl = slice(a, min(n, a + CHUNK))
                    part.cast_into(o[sl], d[sl], times[sl], tmin[sl], k, best_t[sl], best_part[sl], prim[sl],
                                   out.u[sl], out.v[sl])
                continue
            if self._part_bvh is None and getattr(part, "cast_all", None) is not None:
                # Fused part: its kernel does the box tests, every ray in contiguous blocks
                for a in range(0, n, CHUNK):
                    sl = slice(a, min(n, a + CHUNK))
                    t_k, p_k, u_k, v_k = part.cast_all(o[sl], d[sl], times[sl], tmin[sl], best_t[sl])
                    won = t_k < best_t[sl]
                    if won.any():
                        w = a + np.flatnonzero(won)
                        best_t[w], best_part[w], prim[w] = t_k[won], k, p_k[won]
                        out.u[w], out.v[w] = u_k[won], v_k[won]
                continue
            # Other parts: only rays whose segment (tmin, best_t) meets their swept bounds
            if rays is None:
                rays = self._bounded_rays(o, d, tmin, best_t)
            cand = rays[k]
            for a in range(0, cand.size, CHUNK):
                idx = cand[a:a + CHUNK]
                t_k, p_k, u_k, v_k = part.cast(o[idx], d[idx], times[idx], tmin[idx], best_t[idx])
                won = t_k < best_t[idx]
                w = idx[won]
                best_t[w], best_part[w], prim[w], out.u[w], out.v[w] = t_k[won], k, p_k[won], u_k[won], v_k[won]

        # Shading data from the bounded part each ray hit
        for k, part in enumerate(self.parts):
            if part.bounds is None:
                continue
            won = np.flatnonzero(best_part == k)
            if fast and getattr(part, "shade_rows", None) is not None:
                part.shade_rows(won, prim, times, out)             # fused: straight into the results
                continue
            for a in range(0, won.size, CHUNK):
                w = won[a:a + CHUNK]
                inst, p, ng, ns, mat = part.shade(times[w], prim[w], out.u[w], out.v[w])
                out.instance[w], out.prim[w], out.ng[w], out.ns[w], out.material[w] = inst, p, ng, ns, mat
        # Misses: t = inf; hits: the point on the ray (unless a fully-hit static block set it)
        if fast:
            from .embree_kernels import finish_hits
            finish_hits(best_part, self._is_bounded, best_t, o, d, out.position)
            self.stats["rays_intersect"] += n
            self.stats["seconds_intersect"] += _time.perf_counter() - start
            return out
        hit = best_part >= 0
        best_t[~hit] = np.inf
        bounded_won = self._is_bounded[best_part]             # best_part -1: the last entry, False
        todo = np.flatnonzero(hit & (bounded_won | np.isnan(out.position[:, 0])))
        if todo.size:
            out.position[todo] = o[todo] + best_t[todo, None] * d[todo]
        self.stats["rays_intersect"] += n
        self.stats["seconds_intersect"] += _time.perf_counter() - start
        return out

    # ------------------------------------------------------------------ occluded
    def occluded(self, origins, dirs, times, tmax, guard=None) -> np.ndarray:
        """(n,) bool: is anything hit at tmin < t < tmax at the ray's time?  (guard: as :meth:`intersect`)"""
        start = _time.perf_counter()
        o, d, times, tmax = _as_rays(origins, dirs, times, tmax)
        n = o.shape[0]
        first = self.parts[0] if self.parts else None
        near = None
        if first is not None and first.bounds is None and getattr(first, "occluded_into", None) is not None:
            # Fused first (static) part: guard and float32 rays in one kernel per block
            o, d = np.ascontiguousarray(o), np.ascontiguousarray(d)
            tm = np.ascontiguousarray(tmax)
            blocked = np.empty(n, bool)
            only = len(self.parts) == 1
            tmin = np.empty(min(n, CHUNK) if only else n)           # the guard: kept if parts follow
            G = ray_guard(self.scale, guard)
            for a in range(0, n, CHUNK):
                sl = slice(a, min(n, a + CHUNK))
                first.occluded_into(o[sl], d[sl], tm[sl], G if G.shape[0] == 1 else G[sl],
                                    tmin[:sl.stop - a] if only else tmin[sl],
                                    blocked[sl])
            parts = list(enumerate(self.parts))[1:]
        else:
            tmin = tmin_of(d, self.scale, None if guard is None else ray_guard(self.scale, guard))
            blocked = np.zeros(n, bool)
            parts = list(enumerate(self.parts))
        for k, part in parts:
            if part.bounds is None and not blocked.any():
                # First unbounded part: every ray, contiguous blocks
                for a in range(0, n, CHUNK):
                    sl = slice(a, min(n, a + CHUNK))
                    blocked[sl] = part.occluded(o[sl], d[sl], times[sl], tmin[sl], tmax[sl])
                continue
            if part.bounds is not None and self._part_bvh is None \
                    and getattr(part, "occluded_all", None) is not None:
                # Fused part: box tests and transforms in its kernel, unblocked rays of each block
                for a in range(0, n, CHUNK):
                    sl = slice(a, min(n, a + CHUNK))
                    blocked[sl] |= part.occluded_all(o[sl], d[sl], times[sl], tmin[sl], tmax[sl], blocked[sl])
                continue
            if part.bounds is None:
                live = np.flatnonzero(~blocked)
            else:
                # Rays near the part's swept bounds, computed once for all bounded parts
                if near is None:
                    # All rays (contiguous columns beat gathering the unblocked ones)
                    near = self._bounded_rays(o, d, tmin, tmax)
                live = near[k][~blocked[near[k]]]
            for a in range(0, live.size, CHUNK):
                idx = live[a:a + CHUNK]
                blocked[idx[part.occluded(o[idx], d[idx], times[idx], tmin[idx], tmax[idx])]] = True
        self.stats["rays_occluded"] += n
        self.stats["seconds_occluded"] += _time.perf_counter() - start
        return blocked
