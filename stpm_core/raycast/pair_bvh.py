"""A numpy BVH traversed breadth-first over (ray, node) pairs: the numpy backend's
acceleration for meshes too big for brute force.

Build (vectorised, no Python recursion): triangles sorted along a Morton curve
of their box centres, cut into leaves of ``LEAF`` consecutive triangles, and
the tree built bottom-up by merging neighbouring boxes two by two, so node j
of level l has children 2j and 2j+1 on level l+1.

Boxes are *swept*: for a deforming mesh a triangle's box holds its corners at
every vertex step, hence every time in between (positions are linear between
steps), so the candidate set is conservative for every ray time and the exact
float64 test at the ray's time decides.

Traversal keeps an array of (ray, node) pairs per level: pairs whose box the
ray segment misses are dropped, the rest expand to the two children; at the
leaves each pair expands to the leaf's triangles.  No front-to-back order, so
no pruning by the nearest hit; the cost is about (boxes touched per ray) x
(rays), which for surfaces grows like sqrt(triangles).
"""
from __future__ import annotations

import numpy as np

__all__ = ["PairBVH", "LEAF", "RaySlabs", "segments_meet_boxes"]

LEAF = 8       # triangles per leaf
_BLOCK = 8192  # rays per cache-sized block in RaySlabs


def _morton3(q: np.ndarray) -> np.ndarray:
    """Interleave the bits of 10-bit integer coordinates q (n, 3) -> (n,) int64 codes."""
    code = np.zeros(q.shape[0], np.int64)
    for bit in range(10):
        for axis in range(3):
            code |= ((q[:, axis] >> bit) & 1).astype(np.int64) << (3 * bit + axis)
    return code


def segments_meet_boxes(o, inv, lo, hi, t0, t1) -> np.ndarray:
    """(k,) bool per pair: does segment [t0, t1] of ray (o, 1/d) meet box [lo, hi]?

    All arguments are aligned per pair: (k, 3) or (k,).  Conservative: a NaN
    slab (origin on a slab plane, zero direction component) does not reject.
    """
    near, far = t0, t1
    with np.errstate(invalid="ignore"):
        for c in range(3):
            ta = (lo[:, c] - o[:, c]) * inv[:, c]
            tb = (hi[:, c] - o[:, c]) * inv[:, c]
            near = np.fmax(near, np.fmin(ta, tb))
            far = np.fmin(far, np.fmax(ta, tb))
    return near <= far


class PairBVH:
    """BVH over boxes lo, hi (F, 3) float64, ``leaf`` boxes per leaf.

    Attributes
    ----------
    order : (F,) int64 triangle ids in leaf order.
    levels : list of (lo (N_l, 3), hi (N_l, 3)), root level first, leaves last.
    """

    def __init__(self, lo: np.ndarray, hi: np.ndarray, leaf: int = LEAF):
        F = lo.shape[0]
        self.leaf = leaf
        # Morton order of the box centres
        c = 0.5 * (lo + hi)
        cmin, cmax = c.min(0), c.max(0)
        q = ((c - cmin) / np.where(cmax > cmin, cmax - cmin, 1.0) * 1023).astype(np.int64)
        self.order = np.argsort(_morton3(q), kind="stable")
        # Leaves: LEAF consecutive triangles each
        starts = np.arange(0, F, leaf)
        level = (np.minimum.reduceat(lo[self.order], starts, axis=0),
                 np.maximum.reduceat(hi[self.order], starts, axis=0))
        levels = [level]
        # Merge neighbours two by two up to the root
        while levels[-1][0].shape[0] > 1:
            L_lo, L_hi = levels[-1]
            n = L_lo.shape[0]
            m = n // 2
            P_lo = np.minimum(L_lo[0:2 * m:2], L_lo[1:2 * m:2])
            P_hi = np.maximum(L_hi[0:2 * m:2], L_hi[1:2 * m:2])
            if n % 2:
                P_lo, P_hi = np.vstack([P_lo, L_lo[-1:]]), np.vstack([P_hi, L_hi[-1:]])
            levels.append((P_lo, P_hi))
        self.levels = levels[::-1]
        self.n_tri = F

    def candidates(self, o: np.ndarray, d: np.ndarray, t0: np.ndarray, t1: np.ndarray):
        """(ray, triangle) pairs whose leaf box the segment [t0, t1] of ray meets.

        o, d : (m, 3) rays in the boxes' space; t0, t1 : (m,).
        Returns ray (k,) int64 and tri (k,) int64 (triangle ids).
        """
        m = o.shape[0]
        with np.errstate(divide="ignore"):
            inv = 1.0 / d
        ray = np.arange(m)
        node = np.zeros(m, np.int64)
        last = len(self.levels) - 1
        for l, (lo, hi) in enumerate(self.levels):
            # Drop pairs whose box the ray segment misses
            keep = segments_meet_boxes(o[ray], inv[ray], lo[node], hi[node], t0[ray], t1[ray])
            ray, node = ray[keep], node[keep]
            if l < last:
                # Expand each surviving pair to the node's children
                n_next = self.levels[l + 1][0].shape[0]
                ray = np.repeat(ray, 2)
                node = (2 * node[:, None] + np.arange(2)).ravel()
                ok = node < n_next
                ray, node = ray[ok], node[ok]
        # Leaves -> their triangles
        slot = (node[:, None] * self.leaf + np.arange(self.leaf)).ravel()
        ray = np.repeat(ray, self.leaf)
        ok = slot < self.n_tri
        return ray[ok], self.order[slot[ok]]


class RaySlabs:
    """Rays prepared for box tests: contiguous origin and inverse-direction columns."""

    def __init__(self, o: np.ndarray, d: np.ndarray):
        self.o = [np.ascontiguousarray(o[:, c]) for c in range(3)]
        with np.errstate(divide="ignore"):
            self.inv = [1.0 / d[:, c] for c in range(3)]

    def meets(self, bounds, t0, t1) -> np.ndarray:
        """(n,) bool: does each ray's segment [t0 (n,), t1 (n,)] meet the box (lo, hi)?

        Conservative: a NaN slab (origin on a slab plane, zero direction
        component) does not reject.
        """
        lo, hi = bounds
        n = t0.shape[0]
        out = np.empty(n, bool)
        # Cache-sized blocks: about 4x faster than whole-array passes
        with np.errstate(invalid="ignore"):
            for a in range(0, n, _BLOCK):
                sl = slice(a, min(n, a + _BLOCK))
                near, far = t0[sl], t1[sl]
                for c in range(3):
                    oc, ic = self.o[c][sl], self.inv[c][sl]
                    ta = (lo[c] - oc) * ic
                    tb = (hi[c] - oc) * ic
                    near = np.fmax(near, np.fmin(ta, tb))
                    far = np.fmin(far, np.fmax(ta, tb))
                out[sl] = near <= far
        return out

    def meets_each(self, lo: np.ndarray, hi: np.ndarray, t0, t1) -> np.ndarray:
        """(P, n) bool: :meth:`meets` for P boxes lo, hi (P, 3) at once.

        Ray blocks outside, boxes inside: a block's columns stay in cache for
        all the boxes.
        """
        P, n = lo.shape[0], t0.shape[0]
        out = np.empty((P, n), bool)
        with np.errstate(invalid="ignore"):
            for a in range(0, n, _BLOCK):
                sl = slice(a, min(n, a + _BLOCK))
                oc = [self.o[c][sl] for c in range(3)]
                ic = [self.inv[c][sl] for c in range(3)]
                for j in range(P):
                    near, far = t0[sl], t1[sl]
                    for c in range(3):
                        ta = (lo[j, c] - oc[c]) * ic[c]
                        tb = (hi[j, c] - oc[c]) * ic[c]
                        near = np.fmax(near, np.fmin(ta, tb))
                        far = np.fmin(far, np.fmax(ta, tb))
                    out[j, sl] = near <= far
        return out
