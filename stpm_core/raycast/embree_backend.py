"""embreex backend: float32 embree BVHs, hits refined in float64.

Precision strategy
------------------
* Every embree scene is built from vertices re-centred on their own bounds
  centre (world bounds for the baked static scene, object bounds for a moving
  mesh), and rays are shifted by the same centre in float64 before the cast to
  float32.  A scene 1e5 units from the origin therefore keeps float32's
  relative precision of its own size, not of its distance from the origin.
* embree only picks the triangle.  ``t`` and the barycentrics are recomputed
  by an exact float64 Moeller-Trumbore test on that triangle (at the ray's
  time for deforming meshes); barycentrics are clamped into the triangle since
  embree's float32 inside test may be off by an ulp at an edge.
* Self-intersection guard: a ray starts at ``tmin = TMIN_REL * scale / |d|``
  (origin shifted along the ray before the float32 cast).  If the refined
  float64 ``t`` of the hit is still <= tmin (float32 noise at grazing angles)
  the ray is re-cast from just past that hit, up to 3 times.

Motion
------
Static instances are baked into one world-space scene.  A moving rigid
instance has its mesh's own object-space scene (shared between instances of
that mesh); each ray is mapped to object space with the inverse transform at
its own time, directions not renormalised, so t is the same in both spaces and
the result is exact for every time.  With the fused kernels a ray is paired
with a moving instance only if it meets the instance's box over the ray's
time slice (:func:`slice_bounds`, 1/16 of the shutter), not just its box over
the whole shutter.  Deforming meshes: see :class:`DeformingPart`.
"""
from __future__ import annotations

import hashlib
import threading

import numpy as np
from embreex import rtcore_scene as rtcs
from embreex.mesh_construction import TriangleMesh

from .geometry import (ExactCastPart, InstanceShading, MotionKeys, apply_affine, apply_linear, baked_normals, cross,
                       ray_triangle, swept_bounds, triangles_at, world_to_object)
from .pair_bvh import PairBVH, RaySlabs, segments_meet_boxes

# Fused numba kernels for the work around run() (None: numba missing, numpy path only)
try:
    from . import embree_kernels as _K
except Exception:          # pragma: no cover - depends on the platform
    _K = None

__all__ = ["build_parts", "EmbreeMesh", "StaticPart", "RigidPart", "RigidGroup", "DeformingPart",
           "DEFORM_BUCKETS_MAX", "FUSED_AVAILABLE"]

# Can the parts use the fused numba kernels (embree_kernels)?
FUSED_AVAILABLE = _K is not None

_FAR32 = np.float32(1e37)      # embree's "no tfar" value
_RECASTS = 3                   # re-casts of rays whose refined hit fell inside the guard
_NO_T = np.zeros(1)            # stands for an absent tmax in the kernels


def _writable(a) -> np.ndarray:
    """a as a C-contiguous writable float64 array: numba compiles a kernel once per argument type, and
    a read-only view (np.broadcast_to of an inf tmax or of a still's time) is another type."""
    return np.require(a, np.float64, ("C", "W"))
_SCRATCH_ROWS = 8192           # rows of the per-thread ray buffers (the caster's block size)
_SLACK = 4.0                   # deforming buckets: search margin in units of the shape tolerance

# Moving instances of one mesh: above this many, pairs come from a BVH of their boxes.
_GROUP_BVH_MIN = 24
# (ray, instance) pairs made at once by the fused kernels (about 92 bytes each, per thread)
PAIR_CHUNK = 1 << 18

# Deforming meshes: about this many embree scenes (time buckets) per mesh
# (at least one per vertex step).
DEFORM_BUCKETS_MAX = 16

# Moving instances (fused kernels): per-time-slice boxes over the shutter, this many slices
TIME_SLICES = 16


class EmbreeMesh:
    """One re-centred float32 embree scene of a triangle mesh.

    Parameters
    ----------
    V : (V, 3) float64 vertex positions (world or object space).
    F : (F, 3) int triangle indices.
    """

    def __init__(self, V: np.ndarray, F: np.ndarray, planes: bool = True, fused: bool = False):
        V = np.asarray(V, dtype=np.float64)
        self.fused = fused and FUSED_AVAILABLE
        F = np.ascontiguousarray(F, dtype=np.int32)
        self.empty = F.shape[0] == 0
        self.centre = 0.5 * (V.min(0) + V.max(0)) if V.shape[0] else np.zeros(3)
        self.scene = rtcs.EmbreeScene()
        if not self.empty:
            TriangleMesh(self.scene, np.ascontiguousarray(V - self.centre, dtype=np.float32), F)
        # Float64 planes n . x = w of rigid triangles (n unnormalised), for the refinement
        self.plane_n = self.plane_w = None
        if planes and not self.empty:
            P = V[F]
            self.plane_n = cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
            self.plane_w = np.einsum("ij,ij->i", self.plane_n, P[:, 0])

    def _rays32(self, o, d, start, t1):
        """Shift rays to the centre and to their start point; float32 arrays for run()."""
        if self.fused:
            n = o.shape[0]
            o32, d32, far32 = np.empty((n, 3), np.float32), np.empty((n, 3), np.float32), np.empty(n, np.float32)
            _K.rays32(np.ascontiguousarray(o), np.ascontiguousarray(d), np.ascontiguousarray(start),
                      np.ascontiguousarray(t1), self.centre, o32, d32, far32)
            return o32, d32, far32
        x = start[:, None] * d
        x += o
        x -= self.centre
        o32 = x.astype(np.float32)
        d32 = d.astype(np.float32)
        far = np.maximum(t1 - start, 0.0)
        far32 = np.minimum(far, _FAR32).astype(np.float32)      # inf -> embree's "no limit"
        return o32, d32, far32

    def occluded(self, o, d, t0, t1) -> np.ndarray:
        """(n,) bool: any hit in (t0, t1) (float32 test)."""
        if self.empty or o.shape[0] == 0:
            return np.zeros(o.shape[0], bool)
        o32, d32, far32 = self._rays32(o, d, t0, t1)
        return self.scene.run(o32, d32, dists=far32, query="OCCLUDED") != -1

    def cast(self, o, d, t0, t1, corners=None, slack=None, rays32=None):
        """Nearest hit in (t0, t1) with float64 t.

        Parameters
        ----------
        o, d : (n, 3) float64 rays in this mesh's space.
        t0, t1 : (n,) search interval (t0 = self-intersection guard).
        corners : None for a rigid mesh (t from the triangle's float64 plane,
            u, v from embree), or callable(prim (m,), rays (m,)) -> (m, 3, 3)
            float64 corners of the hit triangles at those rays' times (t, u, v
            from an exact Moeller-Trumbore test).
        slack : (n,) or None: embree searches (t0 - slack, t1 + slack) when its
            float32 shape only approximates the exact one (deforming buckets);
            the exact t must still lie in (t0, t1).
        rays32 : (o32, d32, far32) already made by :func:`.embree_kernels.rigid_pairs`
            (rays starting at t0, no slack) or None.

        Returns
        -------
        t (n,) float64 (inf = miss), prim (n,) int, u, v (n,) float64; prim, u, v
        are meaningless where t is inf.
        """
        n = o.shape[0]
        if self.empty or n == 0:
            return np.full(n, np.inf), np.full(n, -1, np.int64), np.zeros(n), np.zeros(n)
        # First pass over every ray, masks rather than compressed copies
        s0, s1 = (t0, t1) if slack is None else (t0 - slack, t1 + slack)
        o32, d32, far32 = self._rays32(o, d, s0, s1) if rays32 is None else rays32
        r = self.scene.run(o32, d32, dists=far32, output=1)
        p = r["primID"]
        hit = p >= 0
        tt, u, v = self._refine(o, d, np.where(hit, p, 0), s0, r["tfar"], r["u"], r["v"], corners, None)
        ok = hit & (tt > t0) & (tt < t1)
        t = np.where(ok, tt, np.inf)
        prim = p.astype(np.int64)
        # Hits that the exact test puts inside the guard: cast again from past them
        live = np.flatnonzero(hit & (tt <= t0))
        if live.size == 0:
            return t, prim, u, v
        te = s0[live] + r["tfar"][live]                 # embree's t of the rejected hit
        for _ in range(_RECASTS - 1):
            start = te + t0[live]
            o32, d32, far32 = self._rays32(o[live], d[live], start, s1[live])
            r = self.scene.run(o32, d32, dists=far32, output=1)
            h = np.flatnonzero(r["primID"] >= 0)
            rays = live[h]
            p = r["primID"][h].astype(np.int64)
            tt, uu, vv = self._refine(o[rays], d[rays], p, start[h], r["tfar"][h], r["u"][h], r["v"][h],
                                      corners, rays)
            t0r = t0[rays]
            ok = (tt > t0r) & (tt < t1[rays])
            k = rays[ok]
            t[k], prim[k], u[k], v[k] = tt[ok], p[ok], uu[ok], vv[ok]
            again = ~ok & (tt <= t0r)
            live = rays[again]
            if live.size == 0:
                break
            te = start[h][again] + r["tfar"][h][again]
        return t, prim, u, v

    def _refine(self, o, d, p, start, tfar, u32, v32, corners, rays):
        """Float64 t, u, v of rays o, d (m, 3) on triangles p (m,).

        ``start + tfar`` is embree's own t (used where the float64 plane test
        is undefined: a ray parallel to the triangle's plane).
        """
        if corners is None and self.fused:
            # Same plane test, one kernel pass
            tt = np.zeros(o.shape[0])
            _K.refine_plane(np.ascontiguousarray(o), np.ascontiguousarray(d), np.ascontiguousarray(p),
                            np.ascontiguousarray(start), np.ascontiguousarray(tfar), self.plane_n,
                            self.plane_w, tt)
            return tt, u32.astype(np.float64), v32.astype(np.float64)
        if corners is None:
            # t on the triangle's float64 plane; embree's u, v are fine for shading
            nrm = self.plane_n[p]
            with np.errstate(divide="ignore", invalid="ignore"):
                tt = (self.plane_w[p] - np.einsum("ij,ij->i", nrm, o)) / np.einsum("ij,ij->i", nrm, d)
            uu, vv = u32.astype(np.float64), v32.astype(np.float64)
        else:
            # Exact float64 test on the triangle at the ray's time
            C = corners(p, np.arange(o.shape[0]) if rays is None else rays)
            tt, uu, vv = ray_triangle(o, d, C[:, 0], C[:, 1], C[:, 2])
            uu = np.clip(uu, 0.0, 1.0)
            vv = np.clip(vv, 0.0, 1.0 - uu)
        bad = ~np.isfinite(tt)
        if bad.any():
            tt[bad] = start[bad] + tfar[bad]
        return tt, uu, vv


class StaticPart:
    """All static rigid instances baked into one world-space embree scene.

    Per baked triangle it keeps its float64 plane (in :class:`EmbreeMesh`), the owning instance
    and mesh-local index, world geometric normal and world per-corner shading
    normals, so shading a hit is a gather.
    """

    bounds = None
    # The fused entry points when the kernels are on (see Caster.intersect / occluded)
    intersect_into = None
    occluded_into = None

    def __init__(self, scene, instances: list[int], fused: bool = False):
        self.fused = fused and FUSED_AVAILABLE
        self.reused_now = False          # the last build_parts took it from the persistent cache
        self._local = threading.local()
        if self.fused:
            self.intersect_into, self.occluded_into = self._intersect_into, self._occluded_into
        Vs, Fs, inst, prim, ng, nsc, mat = [], [], [], [], [], [], []
        nv = 0
        self.smooth = any(scene.meshes[scene.instances[i].mesh].normals is not None for i in instances)
        for i in instances:
            mesh = scene.meshes[scene.instances[i].mesh]
            M = scene.instances[i].transform.matrices[0]
            Vo = np.asarray(mesh.vertices, dtype=np.float64).reshape(-1, 3)
            F = np.asarray(mesh.triangles, dtype=np.int64)
            Vw = Vo @ M[:3, :3].T + M[:3, 3]
            Vs.append(Vw)
            Fs.append(F + nv)
            nv += Vw.shape[0]
            inst.append(np.full(F.shape[0], i, np.int32))
            prim.append(np.arange(F.shape[0], dtype=np.int32))
            # World normals: inverse transpose up to a positive factor (object winding decides the side)
            n_w, ns_w = baked_normals(Vo, F, M, mesh.normals)
            ng.append(n_w)
            nsc.append(ns_w)
            mat.append(np.asarray(mesh.material_ids, dtype=np.int32))
        cat = (lambda a, shape: np.concatenate(a) if a else np.zeros(shape))
        # Instance, mesh-local triangle and material of each baked triangle, one gather
        self.ids = np.stack([cat(inst, (0,)), cat(prim, (0,)), cat(mat, (0,))], axis=1).astype(np.int32)
        self.ng = cat(ng, (0, 3))
        self.ns_corners = cat(nsc, (0, 3, 3)).astype(np.float32)
        self.mesh = EmbreeMesh(cat(Vs, (0, 3)), cat(Fs, (0, 3)), fused=self.fused)

    def cast(self, o, d, times, t0, t1):
        return self.mesh.cast(o, d, t0, t1)

    def _scratch(self, m: int):
        """This thread's float32 ray buffers (o32, d32 (m, 3), far32 (m,)) and index buffer (m,), reused."""
        buf = getattr(self._local, "buf", None)
        if buf is None or buf[2].shape[0] < m:
            cap = max(m, _SCRATCH_ROWS)
            buf = (np.empty((cap, 3), np.float32), np.empty((cap, 3), np.float32), np.empty(cap, np.float32),
                   np.empty(cap, np.int64))
            self._local.buf = buf
        return tuple(b[:m] for b in buf)

    def _intersect_into(self, o, d, times, tmax, guard, k, fields, tmin, final: bool) -> None:
        """Cast m rays as the caster's first part and write every result field in place.

        o, d (m, 3), times (m,) C-contiguous; tmax (m,) or None (+inf);
        guard (1,) or (m,) distances (``geometry.ray_guard``).  ``fields`` = views (m rows, any content) of
        the caster's arrays: best_t, best_part (``k`` where won), part prim, u,
        v, instance, prim, material, ng, ns, position; ``tmin`` (m,) receives
        the guard t.  Rays that miss get the miss values (t = +inf if
        ``final``, else tmax, for the parts that follow).  One kernel makes
        the guard and the float32 rays, one embree call, then
        :func:`.embree_kernels.static_finish`; rays whose refined hit fell
        inside the guard go through :meth:`EmbreeMesh.cast`'s re-cast and
        numpy :meth:`shade` (rare).
        """
        best_t, best_part, prim, u, v, inst, p_out, mat, ng, ns, pos = fields
        m = o.shape[0]
        em = self.mesh
        has_tmax = tmax is not None
        tm = _writable(tmax) if has_tmax else _NO_T
        o32, d32, far32, again = self._scratch(m)
        _K.guard_rays32(o, d, tm, has_tmax, guard, em.centre, tmin, o32, d32, far32)
        if em.empty:
            primID = np.full(m, -1, np.int32)
            r = {"tfar": far32, "primID": primID, "u": far32, "v": far32}
        else:
            r = em.scene.run(o32, d32, dists=far32, output=1)
        n_again = _K.static_finish(o, d, tmin, r["tfar"], r["primID"], r["u"], r["v"], tmin, em.plane_n,
                                   em.plane_w, self.ids, self.ng, self.ns_corners, self.smooth, k, best_t,
                                   best_part, prim, u, v, inst, p_out, mat, ng, ns, pos, again, True, final, tm,
                                   has_tmax)
        if n_again == 0:
            return
        # Guard re-casts: the numpy path for those rays (best_t still holds their tmax)
        a = again[:n_again].copy()
        t_a, p_a, u_a, v_a = em.cast(o[a], d[a], tmin[a], best_t[a])
        won_m = t_a < best_t[a]
        if final:
            best_t[a[~won_m]] = np.inf
        won = np.flatnonzero(won_m)
        if won.size == 0:
            return
        w = a[won]
        i_w, p_w, ng_w, ns_w, mat_w = self.shade(times[w], p_a[won], u_a[won], v_a[won])
        best_t[w], best_part[w], prim[w], u[w], v[w] = t_a[won], k, p_a[won], u_a[won], v_a[won]
        inst[w], p_out[w], mat[w], ng[w], ns[w] = i_w, p_w, mat_w, ng_w, ns_w
        pos[w] = o[w] + t_a[won, None] * d[w]

    def _occluded_into(self, o, d, tmax, guard, tmin, blocked) -> None:
        """Occlusion of m rays as the caster's first part: blocked (m,) bool and the guard tmin (m,) written.

        o, d (m, 3) C-contiguous, tmax (m,); float32 test as :meth:`EmbreeMesh.occluded`.
        """
        m = o.shape[0]
        em = self.mesh
        o32, d32, far32, _ = self._scratch(m)
        tmax = _writable(tmax)
        _K.guard_rays32(o, d, tmax, True, guard, em.centre, tmin, o32, d32, far32)
        if em.empty:
            blocked[:] = False
            return
        _K.occluded_of(em.scene.run(o32, d32, dists=far32, query="OCCLUDED"), blocked)

    def occluded(self, o, d, times, t0, t1):
        return self.mesh.occluded(o, d, t0, t1)

    def shade(self, times, p, u, v):
        ids = self.ids[p]
        ng = self.ng[p]
        if not self.smooth:
            return ids[:, 0], ids[:, 1], ng, ng.copy(), ids[:, 2]
        # Shading normal: barycentric blend of the corner normals (float32 is plenty)
        w = np.stack([1 - u - v, u, v], axis=1).astype(np.float32)
        ns = np.einsum("nk,nkj->nj", w, self.ns_corners[p]).astype(np.float64)
        L = np.sqrt(np.einsum("ij,ij->i", ns, ns))
        zero = L == 0
        ns /= np.where(zero, 1.0, L)[:, None]
        if zero.any():
            ns[zero] = ng[zero]
        return ids[:, 0], ids[:, 1], ng, ns, ids[:, 2]


class RigidPart:
    """One moving rigid instance: object-space embree scene, rays mapped per time."""

    def __init__(self, scene, i: int, emesh: EmbreeMesh):
        inst = scene.instances[i]
        self.index = i
        self.mesh = scene.meshes[inst.mesh]
        self.transform = inst.transform
        self.emesh = emesh
        self.bounds = swept_bounds(self.mesh, self.transform)
        self.shading = InstanceShading(self.mesh, self.transform)

    def _to_object(self, o, d, times):
        A, b = world_to_object(self.transform, times)
        return apply_affine(A, b, o), apply_linear(A, d)

    def cast(self, o, d, times, t0, t1):
        oo, dd = self._to_object(o, d, times)
        return self.emesh.cast(oo, dd, t0, t1)

    def occluded(self, o, d, times, t0, t1):
        oo, dd = self._to_object(o, d, times)
        return self.emesh.occluded(oo, dd, t0, t1)

    def shade(self, times, p, u, v):
        ng, ns, mat = self.shading.shade(p, u, v, times)
        return np.full(p.shape[0], self.index, np.int32), p.astype(np.int32), ng, ns, mat


class RigidGroup:
    """Several moving instances of one mesh: one transform pass and one embree call.

    Rays are paired with the instances whose swept bounds they meet (a slab
    test per instance, or a :class:`PairBVH` of the instance boxes when there
    are many); every (ray, instance) pair is mapped to the shared object space
    at the ray's time in one vectorised :class:`MotionKeys` pass and cast in one
    embree call; each ray keeps its nearest pair.  ``prim`` returned by
    :meth:`cast` encodes the instance: ``j * F + triangle``.
    """

    def __init__(self, scene, instances: list[int], emesh: EmbreeMesh, fused: bool = False):
        self.instances = np.asarray(instances, dtype=np.int32)
        self.mesh = mesh = scene.meshes[scene.instances[instances[0]].mesh]
        transforms = [scene.instances[i].transform for i in instances]
        self.keys = MotionKeys(transforms)
        self.emesh = emesh
        self.n_tri = np.asarray(mesh.triangles).shape[0]
        boxes = [swept_bounds(mesh, tr) for tr in transforms]
        self.lo = np.array([b[0] for b in boxes])
        self.hi = np.array([b[1] for b in boxes])
        self.bounds = (self.lo.min(0), self.hi.max(0))
        self.bvh = PairBVH(self.lo, self.hi, leaf=2) if len(instances) > _GROUP_BVH_MIN else None
        self.shading = InstanceShading(mesh, None)
        # Fused kernels: box tests (each instance's, or the BVH's) + per-ray transforms in one pass
        self.fused = fused and FUSED_AVAILABLE
        if self.fused:
            # The kernel's BVH: the PairBVH flattened, or for a small group one node (the group
            # box) whose one leaf holds every instance
            lv = self.bvh.levels if self.bvh is not None else [(self.bounds[0][None], self.bounds[1][None])]
            self._bvh_flat = (np.ascontiguousarray(np.concatenate([a for a, _ in lv]), np.float64),
                              np.ascontiguousarray(np.concatenate([b for _, b in lv]), np.float64),
                              np.cumsum([0] + [a.shape[0] for a, _ in lv]).astype(np.int64),
                              int(self.bvh.leaf) if self.bvh is not None else len(instances),
                              np.ascontiguousarray(self.bvh.order if self.bvh is not None
                                                   else np.arange(len(instances)), np.int64))
        self._local = threading.local()
        if self.fused:
            k = self.keys
            c = np.ascontiguousarray
            Q, first, last = c(k.Q, np.float64), c(k.first, np.int64), c(k.last, np.int64)
            arc = np.zeros((Q.shape[0], 3))
            _K.slerp_table(Q, first, last, arc)
            self._keys = (c(k.T, np.float64), Q, c(k.S, np.float64), arc, c(k.knots, np.float64), first, last)
            V = np.asarray(mesh.vertices, dtype=np.float64)
            self._V = c(V[0] if V.ndim == 3 else V)
            self._F = c(np.asarray(mesh.triangles), np.int64)
            N = self.shading.normals
            self._N = c(N if N is not None else np.zeros((0, 3, 3)), np.float64)
            self._box = (c(self.bounds[0], np.float64), c(self.bounds[1], np.float64))
            self._slices = slice_bounds(mesh, transforms, self.lo, self.hi)
            self.cast_all, self.occluded_all = self._cast_all, self._occluded_all
            self.shade_rows, self.cast_into = self._shade_rows, self._cast_into

    def _pairs(self, o, d, t0, t1):
        """(ray, j) pairs (k,) whose segment [t0, t1] meets instance j's swept box."""
        if self.bvh is None:
            meet = RaySlabs(o, d).meets_each(self.lo, self.hi, t0, t1)       # (P, m)
            j, ray = np.nonzero(meet)
            return ray, j
        ray, j = self.bvh.candidates(o, d, t0, t1)
        with np.errstate(divide="ignore"):
            inv = 1.0 / d[ray]
        keep = segments_meet_boxes(o[ray], inv, self.lo[j], self.hi[j], t0[ray], t1[ray])
        return ray[keep], j[keep]

    def _to_object(self, o, d, times, ray, j):
        A, b = self.keys.world_to_object(j, times[ray])
        return apply_affine(A, b, o[ray]), apply_linear(A, d[ray])

    def cast(self, o, d, times, t0, t1):
        m = o.shape[0]
        t, prim, u, v = np.full(m, np.inf), np.full(m, -1, np.int64), np.zeros(m), np.zeros(m)
        ray, j = self._pairs(o, d, t0, t1)
        if ray.size == 0:
            return t, prim, u, v
        oo, dd = self._to_object(o, d, times, ray, j)
        tp, pp, up, vp = self.emesh.cast(oo, dd, t0[ray], t1[ray])
        # Nearest pair per ray
        np.minimum.at(t, ray, tp)
        w = np.flatnonzero(np.isfinite(tp) & (tp == t[ray]))
        prim[ray[w]] = j[w] * self.n_tri + pp[w]
        u[ray[w]], v[ray[w]] = up[w], vp[w]
        return t, prim, u, v

    def occluded(self, o, d, times, t0, t1):
        blocked = np.zeros(o.shape[0], bool)
        ray, j = self._pairs(o, d, t0, t1)
        if ray.size:
            oo, dd = self._to_object(o, d, times, ray, j)
            blocked[ray[self.emesh.occluded(oo, dd, t0[ray], t1[ray])]] = True
        return blocked

    # ------------------------------------------------ fused (numba) path
    def _fused_pairs(self, o, d, times, t0, t1, skip, full: bool):
        """Pairs of m rays in chunks: yields (ray, j, o64, d64, (o32, d32, far32)) per chunk.

        Kernel :func:`.embree_kernels.rigid_pairs` (through the instance BVH, or
        one node for a small group); a chunk holds every pair of its rays, and the
        rays of successive chunks follow each other, so callers can finish one
        chunk before the next is made.  The buffers hold at most
        ``max(J, PAIR_CHUNK)`` pairs (J instances): about 92 bytes a pair.
        """
        m = o.shape[0]
        J = self.lo.shape[0]
        cap = max(J, min(m * J, PAIR_CHUNK))
        # This thread's pair buffers, reused between calls (valid until its next call)
        buf = getattr(self._local, "pairs", None)
        if buf is None or buf[0].shape[0] < cap:
            buf = (np.empty(cap, np.int64), np.empty(cap, np.int64), np.empty((cap, 3)), np.empty((cap, 3)),
                   np.empty((cap, 3), np.float32), np.empty((cap, 3), np.float32), np.empty(cap, np.float32))
            self._local.pairs = buf
        ray, j, o64, d64, o32, d32, far32 = (b[:cap] for b in buf)
        if not full:
            o64, d64 = o64[:0], d64[:0]
        c = _writable
        o, d, times, t0, t1 = c(o), c(d), c(times), c(t0), c(t1)
        start = 0
        while start < m:
            n, start = _K.rigid_pairs(o, d, times, t0, t1, skip, start, *self._bvh_flat, self.lo, self.hi,
                                      *self._slices, *self._keys, self.emesh.centre, ray, j, o64, d64, o32, d32,
                                      far32)
            if n:
                yield ray[:n], j[:n], o64[:n], d64[:n], (o32[:n], d32[:n], far32[:n])

    def _cast_all(self, o, d, times, t0, t1):
        """:meth:`cast` over every ray (m,), box tests included (the caster skips its own)."""
        m = o.shape[0]
        t, prim, u, v = np.full(m, np.inf), np.full(m, -1, np.int64), np.zeros(m), np.zeros(m)
        for ray, j, oo, dd, r32 in self._fused_pairs(o, d, times, t0, t1, np.zeros(m, np.bool_), True):
            tp, pp, up, vp = self.emesh.cast(oo, dd, t0[ray], t1[ray], rays32=r32)
            if self.lo.shape[0] == 1:
                # One instance: at most one pair per ray, a plain scatter
                t[ray], prim[ray], u[ray], v[ray] = tp, pp, up, vp
                continue
            # Nearest pair per ray (a ray's pairs are all in one chunk)
            np.minimum.at(t, ray, tp)
            w = np.flatnonzero(np.isfinite(tp) & (tp == t[ray]))
            prim[ray[w]] = j[w] * self.n_tri + pp[w]
            u[ray[w]], v[ray[w]] = up[w], vp[w]
        return t, prim, u, v

    def _cast_into(self, o, d, times, t0, k, best_t, best_part, prim, u, v) -> None:
        """:meth:`cast_all` merged straight into the caster's arrays (m rows each, contiguous).

        best_t (m,) is read as t1 and lowered where a pair wins; best_part (set to ``k``), prim
        (``j * F + triangle``), u, v written there.  One kernel pass after embree's call per
        chunk of pairs (:func:`.embree_kernels.group_finish`); a chunk with a hit inside the
        guard goes through :meth:`cast_all`'s numpy path instead (re-casts; rare).
        """
        m = o.shape[0]
        buf = getattr(self._local, "blk", None)
        if buf is None or buf[0].shape[0] < m:
            buf = (np.empty(m), np.empty(m, np.int64), np.empty(m), np.empty(m))
            self._local.blk = buf
        em = self.emesh
        for ray, j, oo, dd, (o32, d32, far32) in self._fused_pairs(o, d, times, t0, best_t,
                                                                   np.zeros(m, np.bool_), True):
            far_in = far32.copy()                   # run() overwrites it with tfar
            r = em.scene.run(o32, d32, dists=far32, output=1)
            if _K.group_finish(oo, dd, ray, j, t0, best_t, r["tfar"], r["primID"], r["u"], r["v"], em.plane_n,
                               em.plane_w, self.n_tri, k, *(b[:m] for b in buf), best_t, best_part, prim, u, v):
                continue
            # Guard re-casts: the numpy path on the same pairs (as cast_all, then the caster's merge)
            t_k, p_k, u_k, v_k = np.full(m, np.inf), np.full(m, -1, np.int64), np.zeros(m), np.zeros(m)
            tp, pp, up, vp = em.cast(oo, dd, t0[ray], best_t[ray], rays32=(o32, d32, far_in))
            if self.lo.shape[0] == 1:
                t_k[ray], p_k[ray], u_k[ray], v_k[ray] = tp, pp, up, vp
            else:
                np.minimum.at(t_k, ray, tp)
                w = np.flatnonzero(np.isfinite(tp) & (tp == t_k[ray]))
                p_k[ray[w]] = j[w] * self.n_tri + pp[w]
                u_k[ray[w]], v_k[ray[w]] = up[w], vp[w]
            won = np.flatnonzero(t_k < best_t)
            best_t[won], best_part[won], prim[won], u[won], v[won] = t_k[won], k, p_k[won], u_k[won], v_k[won]

    def _occluded_all(self, o, d, times, t0, t1, skip):
        """(m,) bool over every ray, rays with ``skip`` (m,) bool ignored (left False)."""
        blocked = np.zeros(o.shape[0], bool)
        for ray, _, _, _, (o32, d32, far32) in self._fused_pairs(o, d, times, t0, t1, np.ascontiguousarray(skip),
                                                                 False):
            blocked[ray[self.emesh.scene.run(o32, d32, dists=far32, query="OCCLUDED") != -1]] = True
        return blocked

    def _shade_rows(self, rows, prim, times, out) -> None:
        """:meth:`shade` of the rays ``rows`` (k,) this group won, written into ``out`` (:class:`Hits`, n rows).

        prim (n,) int64 group primitives (``j * F + triangle``), times (n,); u, v read from ``out``.
        """
        _K.rigid_shade_rows(rows, prim, self.n_tri, out.u, out.v, times, self.instances, *self._keys, self._V,
                            self._F, self._N, self.shading.material_ids, out.instance, out.prim, out.ng, out.ns,
                            out.material)

    def shade(self, times, p, u, v):
        j, tri = np.divmod(p, self.n_tri)
        if self.fused:
            m = p.shape[0]
            ng, ns, mat = np.empty((m, 3)), np.empty((m, 3)), np.empty(m, np.int32)
            c = np.ascontiguousarray
            _K.rigid_shade(c(j, np.int64), c(tri, np.int64), c(u, np.float64), c(v, np.float64),
                           c(times, np.float64), *self._keys, self._V, self._F, self._N,
                           self.shading.material_ids, ng, ns, mat)
            return self.instances[j], tri.astype(np.int32), ng, ns, mat
        A, _ = self.keys.world_to_object(j, times)
        ng, ns, mat = self.shading.shade(tri, u, v, times, A)
        return self.instances[j], tri.astype(np.int32), ng, ns, mat


class DeformingPart(ExactCastPart):
    """One instance of a deforming mesh: time buckets of embree scenes + exact refinement.

    Each vertex-time segment is split into buckets (more where vertices move
    more, about :data:`DEFORM_BUCKETS_MAX` in all); a bucket's embree scene
    holds the mesh at the bucket's mid time.  A ray is cast, in object space,
    into the bucket containing its time, searching ``(t0 - s, t1 + s)`` with
    ``s = 4 tolerance / |d|``; the triangle found is then intersected exactly
    (float64) at the ray's own time, and if the exact hit falls outside it, the
    triangles sharing a vertex with it (1-ring) are tested exactly instead.
    ``tolerance`` is the largest vertex motion within half a bucket (object
    units).  Hits farther than about 4 tolerance from a silhouette or border
    (and from the ray origin) are exact; nearer ones may hit / miss wrongly.
    See docs/raycast.md for measured error rates.  ``occluded`` uses the exact
    (refined) cast, not the bucket's float32 shape (:class:`ExactCastPart`).
    """

    def __init__(self, scene, i: int):
        inst = scene.instances[i]
        self.index = i
        self.mesh = mesh = scene.meshes[inst.mesh]
        self.transform = inst.transform
        self.bounds = swept_bounds(mesh, self.transform)
        self.shading = InstanceShading(mesh, self.transform)
        self.V = V = np.asarray(mesh.vertices, dtype=np.float64)
        tk = np.asarray(mesh.vertex_times, dtype=np.float64)
        F = np.asarray(mesh.triangles)
        # Buckets per segment, in proportion to the largest vertex displacement
        disp = np.linalg.norm(np.diff(V, axis=0), axis=2).max(axis=1)            # (K-1,)
        nseg = disp.shape[0]
        budget = max(DEFORM_BUCKETS_MAX, nseg)
        share = disp / disp.sum() if disp.sum() > 0 else np.full(nseg, 1.0 / nseg)
        per_seg = np.maximum(1, np.floor(share * budget)).astype(int)
        edges = [tk[0]]
        for s in range(nseg):
            edges.extend(np.linspace(tk[s], tk[s + 1], per_seg[s] + 1)[1:])
        self.edges = np.asarray(edges)
        mids = 0.5 * (self.edges[:-1] + self.edges[1:])
        self.buckets = [EmbreeMesh(mesh.vertices_at(m), F, planes=False) for m in mids]
        self.tk = tk
        # Largest corner motion within half a bucket: the accuracy bound (object units)
        half = [disp[s] / (2 * per_seg[s]) for s in range(nseg)]
        self.tolerance = float(max(half)) if half else 0.0
        # Vertex -> incident triangles (CSR) for the 1-ring search
        self.F = F = np.asarray(F, dtype=np.int64)
        corner_vertex = F.ravel()
        order = np.argsort(corner_vertex, kind="stable")
        self.inc_tri = order // 3
        self.valence = np.bincount(corner_vertex, minlength=V.shape[1])
        self.inc_start = np.concatenate([[0], np.cumsum(self.valence)[:-1]])

    def _to_object(self, o, d, times):
        A, b = world_to_object(self.transform, times)
        return apply_affine(A, b, o), apply_linear(A, d)

    def cast(self, o, d, times, t0, t1):
        oo, dd = self._to_object(o, d, times)
        n = o.shape[0]
        t, prim, u, v = np.full(n, np.inf), np.full(n, -1, np.int64), np.zeros(n), np.zeros(n)
        bucket = np.clip(np.searchsorted(self.edges, times, side="right") - 1, 0, len(self.buckets) - 1)
        # Search margin along the ray: the bucket's shape is off by up to `tolerance`
        slack = _SLACK * self.tolerance / np.maximum(np.linalg.norm(dd, axis=1), 1e-300)
        for k, em in enumerate(self.buckets):
            r = np.flatnonzero(bucket == k)
            if r.size == 0:
                continue
            tr = times[r]
            corners = lambda p, rays, tr=tr: triangles_at(self.mesh, p, tr[rays], self.V)
            t[r], prim[r], u[r], v[r] = em.cast(oo[r], dd[r], t0[r], t1[r], corners, slack[r])
        # Hit outside its triangle at the ray's time: take the nearest of the 1-ring
        h = np.flatnonzero(np.isfinite(t))
        C = triangles_at(self.mesh, prim[h], times[h], self.V)
        _, uu, vv = ray_triangle(oo[h], dd[h], C[:, 0], C[:, 1], C[:, 2])
        eps = 1e-9
        off = h[(uu < -eps) | (vv < -eps) | (uu + vv > 1 + eps)]
        if off.size:
            t[off], prim[off], u[off], v[off] = self._ring_search(oo[off], dd[off], times[off], t0[off],
                                                                  t1[off], prim[off])
        return t, prim, u, v

    def _ring_search(self, o, d, times, t0, t1, p):
        """Nearest exact hit among the triangles sharing a vertex with triangles p (m,)."""
        m = p.shape[0]
        vs = self.F[p].ravel()                                  # (3m,) corner vertices
        counts = self.valence[vs]
        ray = np.repeat(np.arange(3 * m) // 3, counts)
        first = np.repeat(self.inc_start[vs] - np.cumsum(counts) + counts, counts)
        tri = self.inc_tri[first + np.arange(ray.size)]
        C = triangles_at(self.mesh, tri, times[ray], self.V)
        tt, uu, vv = ray_triangle(o[ray], d[ray], C[:, 0], C[:, 1], C[:, 2])
        ok = (uu >= 0) & (vv >= 0) & (uu + vv <= 1) & (tt > t0[ray]) & (tt < t1[ray])
        tt = np.where(ok, tt, np.inf)
        # Per ray minimum over its variable-length candidate list
        order = np.lexsort((tt, ray))
        ray_s, t_s = ray[order], tt[order]
        lead = np.flatnonzero(np.r_[True, ray_s[1:] != ray_s[:-1]])
        best = order[lead]
        t = np.full(m, np.inf)
        prim = np.full(m, -1, np.int64)
        u, v = np.zeros(m), np.zeros(m)
        r = ray_s[lead]
        hit = np.isfinite(t_s[lead])
        t[r[hit]], prim[r[hit]] = t_s[lead][hit], tri[best][hit]
        u[r[hit]], v[r[hit]] = uu[best][hit], vv[best][hit]
        return t, prim, u, v


def slice_bounds(mesh, transforms, lo, hi, slices: int = TIME_SLICES, samples: int = 9):
    """World boxes of moving instances per shutter time slice -> slice_lo, slice_hi (J, slices, 3).

    Slice l covers normalised times [l / slices, (l + 1) / slices]: the
    object box's corners are transformed at ``samples`` times spread over it
    (plus the transform's key times inside it) and the box of those points
    is padded by 2 % of the instance's whole swept box diagonal (lo, hi
    (J, 3), from :func:`.geometry.swept_bounds`), the pad that box itself got
    from 33 samples over the whole shutter: the slice samples are 4x denser,
    so the slice box is at least as safe.  Rays at times in [0, 1] are tested
    against the slice box of their time (:func:`.embree_kernels.rigid_pairs`).
    """
    V = np.asarray(mesh.vertices, dtype=np.float64).reshape(-1, 3)
    a, b = V.min(0), V.max(0)
    corners = np.array([[x, y, z] for x in (a[0], b[0]) for y in (a[1], b[1]) for z in (a[2], b[2])])
    J = len(transforms)
    s_lo, s_hi = np.empty((J, slices, 3)), np.empty((J, slices, 3))
    for j, tr in enumerate(transforms):
        pad = 0.02 * float(np.linalg.norm(hi[j] - lo[j])) + 1e-300
        knots = np.asarray(tr.times, dtype=np.float64)
        # Every slice's sample times in one transform evaluation; slice l's rows start at starts[l]
        ts, starts = [], []
        for l in range(slices):
            t_a, t_b = l / slices, (l + 1) / slices
            starts.append(sum(x.size for x in ts))
            ts.append(np.concatenate([np.linspace(t_a, t_b, samples), knots[(knots > t_a) & (knots < t_b)]]))
        M = tr.at(np.concatenate(ts))
        pts = np.einsum("kij,cj->kci", M[:, :3, :3], corners) + M[:, None, :3, 3]      # (K, 8, 3)
        s_lo[j] = np.minimum.reduceat(pts.min(1), starts, axis=0) - pad
        s_hi[j] = np.maximum.reduceat(pts.max(1), starts, axis=0) + pad
    return s_lo, s_hi


# ---------------------------------------------------------------- persistent static part
_PERSIST_LOCK = threading.Lock()
_PERSIST = {"on": False, "key": None, "part": None}


def set_persistent_static(on: bool) -> None:
    """Keep the last static part between renders (Blender's "Persistent Data"; the CLI's frame ranges).

    When on, :func:`build_parts` reuses the previous render's baked static scene
    if the static instances are the same (:func:`_static_key`), saving the bake
    (about 1.2 us per triangle: 2.7 s for 2.3M triangles).  Turning it off frees
    the kept part.
    """
    with _PERSIST_LOCK:
        _PERSIST["on"] = bool(on)
        if not on:
            _PERSIST["key"] = _PERSIST["part"] = None


def _static_key(scene, static: list[int], fused: bool) -> bytes:
    """Digest of everything a StaticPart is baked from: instance indices, mesh contents, matrices."""
    h = hashlib.blake2b(digest_size=16)
    h.update(b"fused" if fused else b"numpy")
    for i in static:
        inst = scene.instances[i]
        h.update(np.int64(i).tobytes())
        h.update(scene.meshes[inst.mesh].content_digest())
        h.update(np.ascontiguousarray(inst.transform.matrices[0], np.float64).tobytes())
    return h.digest()


def _static_part(scene, static: list[int], fused: bool) -> "StaticPart":
    """The static part, reused from the previous build when persistence is on and nothing static changed."""
    with _PERSIST_LOCK:
        if _PERSIST["part"] is not None:
            _PERSIST["part"].reused_now = False
        if not _PERSIST["on"]:
            return StaticPart(scene, static, fused)
        key = _static_key(scene, static, fused)
        if _PERSIST["key"] == key:
            part = _PERSIST["part"]
            part.reused_now = True
            return part
        _PERSIST["key"] = _PERSIST["part"] = None          # free the old bake before making the new one
        part = StaticPart(scene, static, fused)
        _PERSIST["key"], _PERSIST["part"] = key, part
        return part


def build_parts(scene, scale: float, fused: bool | None = None) -> list:
    """Static part first (cheapest, shrinks t1 for the rest), then moving, then deforming.

    fused : use the numba kernels of :mod:`.embree_kernels` around embree
        (None = whenever numba imports; False = the numpy path, same results
        to rounding).  Fused, a single moving instance is a one-member
        :class:`RigidGroup`.
    """
    fused = FUSED_AVAILABLE if fused is None else (fused and FUSED_AVAILABLE)
    static, rigid, deforming = [], [], []
    for i, inst in enumerate(scene.instances):
        mesh = scene.meshes[inst.mesh]
        if np.asarray(mesh.triangles).shape[0] == 0:
            continue
        if mesh.is_deforming:
            deforming.append(i)
        elif inst.transform.is_static:
            static.append(i)
        else:
            rigid.append(i)
    parts = []
    if static:
        parts.append(_static_part(scene, static, fused))
    # Moving rigid instances: one object-space embree scene per distinct mesh; several
    # moving instances of one mesh -- or of equal copies of it (duplicated objects are
    # exported as separate meshes) -- form one group (one transform pass, one embree call)
    by_mesh: dict[bytes, list[int]] = {}
    for i in rigid:
        by_mesh.setdefault(scene.meshes[scene.instances[i].mesh].content_digest(), []).append(i)
    for members in by_mesh.values():
        m = scene.instances[members[0]].mesh
        V = np.asarray(scene.meshes[m].vertices, dtype=np.float64).reshape(-1, 3)
        emesh = EmbreeMesh(V, scene.meshes[m].triangles, fused=fused)
        if len(members) == 1 and not fused:
            parts.append(RigidPart(scene, members[0], emesh))
        else:
            parts.append(RigidGroup(scene, members, emesh, fused))
    parts.extend(DeformingPart(scene, i) for i in deforming)
    return parts
