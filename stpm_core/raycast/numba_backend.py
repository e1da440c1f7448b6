"""numba backend: compiled BVH traversal, exact float64 at every ray time.

The same parts as the other backends (see :mod:`.build`):

* :class:`StaticPart` - every static instance of a rigid mesh baked into one
  world-space BVH (``bounds = None``: it sees every ray);
* :class:`NumbaPart` per moving instance - rays mapped to object space with the
  instance's inverse transform at each ray's time (:func:`.geometry.world_to_object`,
  exactly as the numpy backend), cast against an object-space BVH shared by
  all instances of the mesh;
* :class:`NumbaPart` per deforming instance - a BVH over each triangle's box
  swept over *all* vertex steps; the kernel interpolates the candidate
  triangle's corners to the ray's own time, so the answer is exact (unlike the
  embree time buckets).

Kernels: ``@njit(parallel=True, cache=True)``, ``prange`` over blocks of
``_BLOCK`` rays (one traversal stack per block).  Closest hit: front-to-back
traversal (nearer child first, nodes beyond the best hit skipped).  Any hit:
stops at the first hit.  The triangle test is float64 Moeller-Trumbore written
with the same operations as :func:`.geometry.ray_triangle`, so ``t`` matches the
numpy oracle to rounding.  Compiled code is cached on disk (numba's cache,
next to this file or in ``NUMBA_CACHE_DIR``); the first call in a fresh
environment compiles (see docs/raycast.md for the measured times).
"""
from __future__ import annotations

import os

# OpenMP workers sleep instead of spinning between parallel regions: the caster
# launches one region per 8192-ray chunk, and on a loaded machine spinning
# workers cost ~8x in throughput (measured, docs/raycast.md).  Must be set before
# numba's OpenMP pool starts; the user's own setting wins.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np  # noqa: E402
from numba import njit, prange  # noqa: E402

from .bvh_build import build_bvh
from .geometry import (InstanceShading, apply_affine, apply_linear, baked_normals, segment_of,
                       swept_bounds, world_to_object)

__all__ = ["build_parts", "StaticPart", "NumbaPart", "TriangleBVH", "warm_up"]

_BLOCK = 64          # rays per prange block (one stack allocation per block)
_HUGE = 1e300        # stands in for 1/0 in the slab test (0 * _HUGE = 0, no NaN)


# ---------------------------------------------------------------- kernels
@njit(cache=True)
def _enter(lo, hi, k, ox, oy, oz, ix, iy, iz, tmin, tmax):
    """Entry distance of segment [tmin, tmax] of a ray into box k, inf if it misses."""
    ta, tb = (lo[k, 0] - ox) * ix, (hi[k, 0] - ox) * ix
    near, far = min(ta, tb), max(ta, tb)
    ta, tb = (lo[k, 1] - oy) * iy, (hi[k, 1] - oy) * iy
    near, far = max(near, min(ta, tb)), min(far, max(ta, tb))
    ta, tb = (lo[k, 2] - oz) * iz, (hi[k, 2] - oz) * iz
    near, far = max(near, min(ta, tb)), min(far, max(ta, tb))
    near, far = max(near, tmin), min(far, tmax)
    return near if near <= far else np.inf


@njit(cache=True)
def _inv(x):
    """1 / x for the slab test; _HUGE for a zero (or denormal) component, so 0 * inv is 0, not NaN."""
    return 1.0 / x if abs(x) > 1e-290 else _HUGE


@njit(cache=True)
def _corners(P, s, a, j, C):
    """Corners (9,) of leaf-order triangle j at vertex step s + fraction a into C."""
    if P.shape[0] == 1:
        for q in range(9):
            C[q] = P[0, j, q]
    else:
        for q in range(9):
            c0 = P[s, j, q]
            C[q] = c0 + a * (P[s + 1, j, q] - c0)


@njit(cache=True)
def _moller_trumbore(C, ox, oy, oz, dx, dy, dz):
    """(t, u, v) of the ray against corners C (9,); t = inf when det == 0.

    Same operations, in the same order, as geometry.ray_triangle.
    """
    e1x, e1y, e1z = C[3] - C[0], C[4] - C[1], C[5] - C[2]
    e2x, e2y, e2z = C[6] - C[0], C[7] - C[1], C[8] - C[2]
    px, py, pz = dy * e2z - dz * e2y, dz * e2x - dx * e2z, dx * e2y - dy * e2x
    det = e1x * px + e1y * py + e1z * pz
    if det == 0.0:
        return np.inf, 0.0, 0.0
    inv_det = 1.0 / det
    sx, sy, sz = ox - C[0], oy - C[1], oz - C[2]
    u = (sx * px + sy * py + sz * pz) * inv_det
    qx, qy, qz = sy * e1z - sz * e1y, sz * e1x - sx * e1z, sx * e1y - sy * e1x
    v = (dx * qx + dy * qy + dz * qz) * inv_det
    t = (e2x * qx + e2y * qy + e2z * qz) * inv_det
    return t, u, v


@njit(cache=True)
def _closest_rays(lo, hi, child, start, count, P, tri, o, d, t0, t1, seg, a, r0, r1,
                  node_st, near_st, C, t_out, p_out, u_out, v_out):
    """Closest hit of rays r0 .. r1-1 into the output arrays (serial; see :func:`closest_hit`)."""
    for r in range(r0, r1):
        ox, oy, oz = o[r, 0], o[r, 1], o[r, 2]
        dx, dy, dz = d[r, 0], d[r, 1], d[r, 2]
        ix, iy, iz = _inv(dx), _inv(dy), _inv(dz)
        tmin, best = t0[r], t1[r]
        s, f = seg[r], a[r]
        best_p, best_u, best_v = -1, 0.0, 0.0
        sp = 0
        tn = _enter(lo, hi, 0, ox, oy, oz, ix, iy, iz, tmin, best)
        if tn < np.inf:
            node_st[0], near_st[0] = 0, tn
            sp = 1
        while sp > 0:
            sp -= 1
            k = node_st[sp]
            if near_st[sp] > best:
                continue                       # a nearer hit was found since the push
            c = child[k]
            if c < 0:
                # Leaf: exact test of each triangle at the ray's time
                for j in range(start[k], start[k] + count[k]):
                    _corners(P, s, f, j, C)
                    t, u, v = _moller_trumbore(C, ox, oy, oz, dx, dy, dz)
                    if u >= 0.0 and v >= 0.0 and u + v <= 1.0 and t > tmin and t < best:
                        best, best_p, best_u, best_v = t, tri[j], u, v
                continue
            # Interior: push the farther child first so the nearer one is popped next
            ta = _enter(lo, hi, c, ox, oy, oz, ix, iy, iz, tmin, best)
            tb = _enter(lo, hi, c + 1, ox, oy, oz, ix, iy, iz, tmin, best)
            if ta > tb:
                ta, tb = tb, ta
                first, second = c + 1, c
            else:
                first, second = c, c + 1
            if tb < np.inf:
                node_st[sp], near_st[sp] = second, tb
                sp += 1
            if ta < np.inf:
                node_st[sp], near_st[sp] = first, ta
                sp += 1
        if best_p >= 0:
            t_out[r], p_out[r], u_out[r], v_out[r] = best, best_p, best_u, best_v


@njit(cache=True)
def _any_rays(lo, hi, child, start, count, P, tri, o, d, t0, t1, seg, a, r0, r1, node_st, C, out):
    """Any hit of rays r0 .. r1-1 into out (serial; see :func:`any_hit`)."""
    for r in range(r0, r1):
        ox, oy, oz = o[r, 0], o[r, 1], o[r, 2]
        dx, dy, dz = d[r, 0], d[r, 1], d[r, 2]
        ix, iy, iz = _inv(dx), _inv(dy), _inv(dz)
        tmin, tmax = t0[r], t1[r]
        s, f = seg[r], a[r]
        sp = 0
        if _enter(lo, hi, 0, ox, oy, oz, ix, iy, iz, tmin, tmax) < np.inf:
            node_st[0] = 0
            sp = 1
        hit = False
        while sp > 0 and not hit:
            sp -= 1
            k = node_st[sp]
            c = child[k]
            if c < 0:
                for j in range(start[k], start[k] + count[k]):
                    _corners(P, s, f, j, C)
                    t, u, v = _moller_trumbore(C, ox, oy, oz, dx, dy, dz)
                    if u >= 0.0 and v >= 0.0 and u + v <= 1.0 and t > tmin and t < tmax:
                        hit = True
                        break
                continue
            if _enter(lo, hi, c + 1, ox, oy, oz, ix, iy, iz, tmin, tmax) < np.inf:
                node_st[sp] = c + 1
                sp += 1
            if _enter(lo, hi, c, ox, oy, oz, ix, iy, iz, tmin, tmax) < np.inf:
                node_st[sp] = c
                sp += 1
        out[r] = hit


# The parallel kernels are thin prange loops over ray blocks around the serial
# bodies above (one stack per block of _BLOCK rays).
@njit(parallel=True, cache=True)
def closest_hit(lo, hi, child, start, count, P, tri, stack_size, o, d, t0, t1, seg, a):
    """Nearest hit with t0 < t < t1 of each ray (m,) -> t, prim, u, v (m,).

    lo, hi, child, start, count : flat BVH (see bvh_build); P (K, F, 9) float64
    corners in leaf order at K vertex steps; tri (F,) int64 triangle id of each
    leaf slot; o, d (m, 3) rays in the BVH's space; seg (m,) int64 vertex step
    and a (m,) fraction of each ray's time (ignored when K == 1).
    Misses: t = inf, prim = -1, u = v = 0.
    """
    m = o.shape[0]
    t_out = np.full(m, np.inf)
    p_out = np.full(m, -1, np.int64)
    u_out = np.zeros(m)
    v_out = np.zeros(m)
    n_blocks = (m + _BLOCK - 1) // _BLOCK
    for blk in prange(n_blocks):
        _closest_rays(lo, hi, child, start, count, P, tri, o, d, t0, t1, seg, a,
                      blk * _BLOCK, min(m, (blk + 1) * _BLOCK), np.empty(stack_size, np.int64),
                      np.empty(stack_size), np.empty(9), t_out, p_out, u_out, v_out)
    return t_out, p_out, u_out, v_out


@njit(parallel=True, cache=True)
def any_hit(lo, hi, child, start, count, P, tri, stack_size, o, d, t0, t1, seg, a):
    """(m,) bool: does each ray hit anything with t0 < t < t1?  Arguments as :func:`closest_hit`."""
    m = o.shape[0]
    out = np.zeros(m, np.bool_)
    n_blocks = (m + _BLOCK - 1) // _BLOCK
    for blk in prange(n_blocks):
        _any_rays(lo, hi, child, start, count, P, tri, o, d, t0, t1, seg, a,
                  blk * _BLOCK, min(m, (blk + 1) * _BLOCK), np.empty(stack_size, np.int64), np.empty(9), out)
    return out


# ---------------------------------------------------------------- triangle sets
class TriangleBVH:
    """Triangles (K vertex steps) under a flat BVH of their swept boxes.

    corners : (K, F, 3, 3) float64 triangle corners at each vertex step.
    """

    def __init__(self, corners: np.ndarray):
        K, F = corners.shape[:2]
        self.bvh = build_bvh(corners.min(axis=(0, 2)), corners.max(axis=(0, 2)))
        self.tri = np.ascontiguousarray(self.bvh.order, dtype=np.int64)
        # Corners in leaf order, 9 contiguous float64 per triangle and step
        self.P = np.ascontiguousarray(corners[:, self.tri].reshape(K, F, 9))
        self.K = K

    def _args(self):
        b = self.bvh
        return b.lo, b.hi, b.child, b.start, b.count, self.P, self.tri, b.stack

    def cast(self, o, d, t0, t1, seg, a):
        """Nearest hit in (t0, t1) -> t, prim, u, v (m,) (see :func:`closest_hit`)."""
        return closest_hit(*self._args(), *_rays(o, d, t0, t1, seg, a))

    def occluded(self, o, d, t0, t1, seg, a):
        """(m,) bool: any hit in (t0, t1)."""
        return any_hit(*self._args(), *_rays(o, d, t0, t1, seg, a))


def _rays(o, d, t0, t1, seg, a):
    """Ray arrays as the kernels' one compiled signature wants them: C-contiguous, writable."""
    f64 = lambda x: np.require(x, np.float64, ("C", "W"))
    return f64(o), f64(d), f64(t0), f64(t1), np.require(seg, np.int64, ("C", "W")), f64(a)


def _no_steps(m: int):
    return np.zeros(m, np.int64), np.zeros(m)


# ---------------------------------------------------------------- parts
class StaticPart:
    """Every static instance of a rigid mesh, baked into world space under one BVH.

    Per baked triangle it keeps the owning instance, mesh-local index and
    material, the world geometric normal and the world per-corner shading
    normals (the same maps as :class:`.geometry.InstanceShading`), so shading
    a hit is a gather.
    """

    bounds = None

    def __init__(self, scene, instances: list[int]):
        Ps, ids, ng, nsc = [], [], [], []
        for i in instances:
            mesh = scene.meshes[scene.instances[i].mesh]
            M = scene.instances[i].transform.matrices[0]
            F = np.asarray(mesh.triangles, dtype=np.int64)
            Vo = np.asarray(mesh.vertices, dtype=np.float64).reshape(-1, 3)
            # World corners exactly as the numpy backend bakes them
            Ps.append((Vo @ M[:3, :3].T + M[:3, 3])[F])
            ids.append(np.stack([np.full(len(F), i), np.arange(len(F)),
                                 np.asarray(mesh.material_ids)], axis=1))
            # Normals: cofactor map of the object-space winding normal / corner normals
            n_w, ns_w = baked_normals(Vo, F, M, mesh.normals)
            ng.append(n_w)
            nsc.append(ns_w)
        self.ids = np.concatenate(ids).astype(np.int32)          # (F, 3): instance, prim, material
        self.ng = np.concatenate(ng)
        self.ns_corners = np.concatenate(nsc)
        self.smooth = any(scene.meshes[scene.instances[i].mesh].normals is not None for i in instances)
        self.tris = TriangleBVH(np.concatenate(Ps)[None])

    def cast(self, o, d, times, t0, t1):
        return self.tris.cast(o, d, t0, t1, *_no_steps(o.shape[0]))

    def occluded(self, o, d, times, t0, t1):
        return self.tris.occluded(o, d, t0, t1, *_no_steps(o.shape[0]))

    def shade(self, times, p, u, v):
        ids, ng = self.ids[p], self.ng[p]
        if not self.smooth:
            return ids[:, 0], ids[:, 1], ng, ng.copy(), ids[:, 2]
        # Shading normal: barycentric blend of the world corner normals
        C = self.ns_corners[p]
        ns = (1 - u - v)[:, None] * C[:, 0] + u[:, None] * C[:, 1] + v[:, None] * C[:, 2]
        L = np.sqrt(np.einsum("ij,ij->i", ns, ns))
        zero = L == 0
        ns /= np.where(zero, 1.0, L)[:, None]
        ns[zero] = ng[zero]
        return ids[:, 0], ids[:, 1], ng, ns, ids[:, 2]


class NumbaPart:
    """One moving or deforming instance (or a static instance of a deforming mesh).

    Rays go to object space with the inverse transform at each ray's time
    (static transforms are baked instead, as in the numpy backend); deforming
    meshes are intersected at each ray's time exactly.
    """

    def __init__(self, scene, i: int, tris: TriangleBVH):
        inst = scene.instances[i]
        self.index = i
        self.mesh = mesh = scene.meshes[inst.mesh]
        self.transform = inst.transform
        self.baked = self.transform.is_static
        self.tris = tris
        self.tk = np.asarray(mesh.vertex_times, dtype=np.float64) if mesh.is_deforming else None
        self.bounds = swept_bounds(mesh, self.transform)
        self.shading = InstanceShading(mesh, self.transform)

    def _rays(self, o, d, times):
        """Rays in the BVH's space and each ray's vertex step and fraction."""
        if not self.baked:
            A, b = world_to_object(self.transform, times)
            o, d = apply_affine(A, b, o), apply_linear(A, d)
        if self.tk is None:
            seg, a = _no_steps(o.shape[0])
        else:
            seg, a = segment_of(self.tk, times)
            seg = seg.astype(np.int64)
        return o, d, seg, a

    def cast(self, o, d, times, t0, t1):
        oo, dd, seg, a = self._rays(o, d, times)
        return self.tris.cast(oo, dd, t0, t1, seg, a)

    def occluded(self, o, d, times, t0, t1):
        oo, dd, seg, a = self._rays(o, d, times)
        return self.tris.occluded(oo, dd, t0, t1, seg, a)

    def shade(self, times, p, u, v):
        ng, ns, mat = self.shading.shade(p, u, v, times)
        return np.full(p.shape[0], self.index, np.int32), p.astype(np.int32), ng, ns, mat


def _corners_of(mesh, M=None) -> np.ndarray:
    """(K, F, 3, 3) float64 corners of a mesh (K = 1 if rigid), baked by M (4, 4) if given."""
    V = np.asarray(mesh.vertices, dtype=np.float64)
    if M is not None:
        V = V @ M[:3, :3].T + M[:3, 3]
    F = np.asarray(mesh.triangles, dtype=np.int64)
    return V[:, F] if mesh.is_deforming else V.reshape(-1, 3)[F][None]


def build_parts(scene, scale: float) -> list:
    """Static part first (shrinks t1 for the rest), then one part per other instance."""
    static, other = [], []
    for i, inst in enumerate(scene.instances):
        mesh = scene.meshes[inst.mesh]
        if np.asarray(mesh.triangles).shape[0] == 0:
            continue
        (static if inst.transform.is_static and not mesh.is_deforming else other).append(i)
    parts = [StaticPart(scene, static)] if static else []
    shared: dict[int, TriangleBVH] = {}      # object-space BVH per mesh, shared by its moving instances
    for i in other:
        inst = scene.instances[i]
        mesh = scene.meshes[inst.mesh]
        if inst.transform.is_static:
            tris = TriangleBVH(_corners_of(mesh, inst.transform.matrices[0]))
        else:
            if inst.mesh not in shared:
                shared[inst.mesh] = TriangleBVH(_corners_of(mesh))
            tris = shared[inst.mesh]
        parts.append(NumbaPart(scene, i, tris))
    return parts


def warm_up() -> float:
    """Compile (or load from the on-disk cache) every kernel of this backend and the embree
    backend's fused kernels (:mod:`.embree_kernels`); seconds taken.

    For an installer or an add-on to call once in the background, so the first
    render does not pay the JIT compilation (about 10-15 CPU seconds, see
    docs/raycast.md).
    """
    import time
    start = time.perf_counter()
    corners = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 0, 1], [1, 0, 1], [0, 1, 1]]], float)[None]
    tris = TriangleBVH(corners)
    o, d = np.array([[0.2, 0.2, -1.0]]), np.array([[0.0, 0.0, 1.0]])
    seg, a = _no_steps(1)
    tris.cast(o, d, np.zeros(1), np.full(1, np.inf), seg, a)
    tris.occluded(o, d, np.zeros(1), np.full(1, np.inf), seg, a)
    # The embree backend's fused kernels too (they need numba, not this backend)
    from .embree_kernels import warm_up as warm_embree
    warm_embree()
    return time.perf_counter() - start
