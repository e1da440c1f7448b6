"""Pure-numpy backend: float64 Moeller-Trumbore, exact at every ray time.

Same API as the embree backend (one part per instance, see :mod:`.build`).
Each instance's rays are mapped to object space with its inverse transform at
each ray's time; deforming meshes are evaluated at each ray's time.  Every ray
is tested exactly against the triangles of every instance whose swept bounds it
meets: brute force in chunks of about ``_PAIRS`` ray-triangle pairs for meshes
of at most ``BRUTE_MAX`` triangles, else the candidates a :class:`PairBVH` of
swept triangle boxes returns (conservative for every time, so still exact).
The test oracle, and the fallback where embreex has no wheel (macOS arm64,
Linux aarch64).
"""
from __future__ import annotations

import numpy as np

from .geometry import (ExactCastPart, InstanceShading, apply_affine, apply_linear, ray_triangle, segment_of,
                       swept_bounds, world_to_object)
from .pair_bvh import PairBVH

__all__ = ["build_parts", "NumpyPart"]

_PAIRS = 1 << 19   # ray-triangle pairs per chunk (about 100 MB of float64 temporaries)
BRUTE_MAX = 64     # meshes with more triangles go through a PairBVH
_BVH_RAYS = 2048   # rays per BVH traversal batch


class NumpyPart(ExactCastPart):
    """One instance (static, moving or deforming), brute force over its triangles."""

    def __init__(self, scene, i: int):
        inst = scene.instances[i]
        self.index = i
        self.mesh = mesh = scene.meshes[inst.mesh]
        self.transform = inst.transform
        self.shading = InstanceShading(mesh, self.transform)
        self.bounds = swept_bounds(mesh, self.transform)
        F = np.asarray(mesh.triangles, dtype=np.int64)
        V = np.asarray(mesh.vertices, dtype=np.float64)
        # Static instance: triangles baked into world space, rays untouched (works
        # for a singular, zero-scale transform too)
        self.baked = self.transform.is_static
        if self.baked:
            M = self.transform.matrices[0]
            V = V @ M[:3, :3].T + M[:3, 3]
        if mesh.is_deforming:
            self.tk = np.asarray(mesh.vertex_times, dtype=np.float64)
            self.P = V[:, F]                       # (K, F, 3, 3) corners per step
        else:
            self.tk = None
            self.P = (V[0] if V.ndim == 3 else V)[F][None]   # (1, F, 3, 3)
        # Bigger meshes: a BVH over triangle boxes swept over all vertex steps
        self.bvh = None
        if F.shape[0] > BRUTE_MAX:
            self.bvh = PairBVH(self.P.min(axis=(0, 2)), self.P.max(axis=(0, 2)))

    def _nearest(self, o, d, C, t0, t1):
        """Nearest inside hit of rays (R,) over corners C (F,3,3) or (R,F,3,3)."""
        if C.ndim == 3:
            v0, v1, v2 = C[None, :, 0], C[None, :, 1], C[None, :, 2]
        else:
            v0, v1, v2 = C[:, :, 0], C[:, :, 1], C[:, :, 2]
        with np.errstate(invalid="ignore", over="ignore"):
            t, u, v = ray_triangle(o[:, None], d[:, None], v0, v1, v2)
            inside = (u >= 0) & (v >= 0) & (u + v <= 1) & (t > t0[:, None]) & (t < t1[:, None])
        t = np.where(inside, t, np.inf)
        j = np.argmin(t, axis=1)
        r = np.arange(o.shape[0])
        tj = t[r, j]
        hit = np.isfinite(tj)
        return tj, np.where(hit, j, -1), np.where(hit, u[r, j], 0.0), np.where(hit, v[r, j], 0.0)

    def cast(self, o, d, times, t0, t1):
        if self.baked:
            oo, dd = o, d
        else:
            A, b = world_to_object(self.transform, times)
            oo, dd = apply_affine(A, b, o), apply_linear(A, d)
        n = o.shape[0]
        nF = self.P.shape[1]
        t, prim, u, v = np.full(n, np.inf), np.full(n, -1, np.int64), np.zeros(n), np.zeros(n)
        step = max(1, _PAIRS // max(nF, 1))
        if self.tk is None:
            seg, a = np.zeros(n, np.int64), np.zeros(n)
        else:
            seg, a = segment_of(self.tk, times)
        if self.bvh is not None:
            for c in range(0, n, _BVH_RAYS):
                r = slice(c, min(n, c + _BVH_RAYS))
                t[r], prim[r], u[r], v[r] = self._cast_bvh(oo[r], dd[r], t0[r], t1[r], seg[r], a[r])
            return t, prim, u, v
        for s in np.unique(seg):
            rs = np.flatnonzero(seg == s)
            for c in range(0, rs.size, step):
                r = rs[c:c + step]
                if self.tk is None:
                    C = self.P[0]
                else:
                    # Corners at each ray's own time: linear between steps s and s+1
                    C = self.P[s][None] + a[r, None, None, None] * (self.P[s + 1] - self.P[s])[None]
                t[r], prim[r], u[r], v[r] = self._nearest(oo[r], dd[r], C, t0[r], t1[r])
        return t, prim, u, v

    def _cast_bvh(self, o, d, t0, t1, seg, a):
        """Nearest exact hit of rays (m,) over the BVH's candidate triangles."""
        m = o.shape[0]
        t, prim, u, v = np.full(m, np.inf), np.full(m, -1, np.int64), np.zeros(m), np.zeros(m)
        ray, tri = self.bvh.candidates(o, d, t0, t1)
        if ray.size == 0:
            return t, prim, u, v
        # Corners at each ray's own time (linear between vertex steps)
        s = seg[ray]
        C = self.P[s, tri]
        if self.tk is not None:
            C = C + a[ray, None, None] * (self.P[s + 1, tri] - C)
        with np.errstate(invalid="ignore", over="ignore"):
            tt, uu, vv = ray_triangle(o[ray], d[ray], C[:, 0], C[:, 1], C[:, 2])
            inside = (uu >= 0) & (vv >= 0) & (uu + vv <= 1) & (tt > t0[ray]) & (tt < t1[ray])
        tt = np.where(inside, tt, np.inf)
        # Nearest per ray over its candidate list
        best = np.full(m, np.inf)
        np.minimum.at(best, ray, tt)
        w = np.flatnonzero(inside & (tt == best[ray]))
        t[ray[w]], prim[ray[w]], u[ray[w]], v[ray[w]] = tt[w], tri[w], uu[w], vv[w]
        return t, prim, u, v


def build_parts(scene, scale: float) -> list:
    """One :class:`NumpyPart` per instance with triangles."""
    return [NumpyPart(scene, i) for i, inst in enumerate(scene.instances)
            if np.asarray(scene.meshes[inst.mesh].triangles).shape[0] > 0]
