"""Binned-SAH BVH over boxes, built by a numba kernel into flat arrays.

Used by :mod:`.numba_backend`.  The tree is stored as flat arrays (no Python
objects per node), the layout the numba traversal kernels read:

* ``lo, hi`` (N, 3) float64: node boxes, padded outward by 1e-12 of the
  root diagonal so the float64 slab test never rejects a box the exact triangle
  test would hit;
* ``child`` (N,) int32: index of the left child (the right one is
  ``child + 1``), -1 for a leaf;
* ``start, count`` (N,) int32: a leaf's primitives are ``order[start:start+count]``;
* ``order`` (F,) int64: primitive ids in leaf order;
* ``depth``: deepest node level (the traversal stack needs ``depth + 2``).

Build: top-down, an explicit stack instead of recursion.  Each node with more
than ``LEAF_MAX`` primitives is split where the surface-area heuristic is
smallest over ``N_BINS`` centroid bins on each axis; when every centroid
coincides (no bin split exists) the node is split at its middle primitive.
Boxes may be *swept* (a deforming triangle's box over all its vertex steps),
so the tree is conservative for every ray time.
"""
from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["FlatBVH", "build_bvh", "LEAF_MAX", "N_BINS"]

LEAF_MAX = 4   # primitives per leaf at most
N_BINS = 12    # SAH bins per axis


@njit(cache=True)
def _area(lx, ly, lz, hx, hy, hz):
    dx, dy, dz = hx - lx, hy - ly, hz - lz
    return dx * dy + dy * dz + dz * dx


@njit(cache=True)
def _build(lo, hi, leaf_max, n_bins):
    """Binned-SAH build over boxes lo, hi (F, 3) -> flat arrays (see module docstring)."""
    F = lo.shape[0]
    cen = 0.5 * (lo + hi)
    order = np.arange(F)
    cap = max(1, 2 * F)
    n_lo = np.empty((cap, 3))
    n_hi = np.empty((cap, 3))
    child = np.full(cap, -1, np.int32)
    start = np.zeros(cap, np.int32)
    count = np.zeros(cap, np.int32)
    # Work stack of (node, begin, end, level)
    st_node = np.empty(cap + 2, np.int64)
    st_b = np.empty(cap + 2, np.int64)
    st_e = np.empty(cap + 2, np.int64)
    st_l = np.empty(cap + 2, np.int64)
    sp = 1
    st_node[0], st_b[0], st_e[0], st_l[0] = 0, 0, F, 0
    n_nodes = 1
    depth = 0
    # Per-bin accumulators
    b_cnt = np.zeros(n_bins, np.int64)
    b_lo = np.empty((n_bins, 3))
    b_hi = np.empty((n_bins, 3))
    r_area = np.empty(n_bins)
    r_cnt = np.empty(n_bins, np.int64)
    while sp > 0:
        sp -= 1
        node, b, e, lev = st_node[sp], st_b[sp], st_e[sp], st_l[sp]
        depth = max(depth, lev)
        # -- node box and centroid box
        lx = ly = lz = np.inf
        hx = hy = hz = -np.inf
        cl = np.full(3, np.inf)
        ch = np.full(3, -np.inf)
        for i in range(b, e):
            p = order[i]
            lx, ly, lz = min(lx, lo[p, 0]), min(ly, lo[p, 1]), min(lz, lo[p, 2])
            hx, hy, hz = max(hx, hi[p, 0]), max(hy, hi[p, 1]), max(hz, hi[p, 2])
            for c in range(3):
                cl[c] = min(cl[c], cen[p, c])
                ch[c] = max(ch[c], cen[p, c])
        n_lo[node, 0], n_lo[node, 1], n_lo[node, 2] = lx, ly, lz
        n_hi[node, 0], n_hi[node, 1], n_hi[node, 2] = hx, hy, hz
        n = e - b
        if n <= leaf_max:
            start[node], count[node] = b, n
            continue
        # -- best SAH split over the bins of each axis
        best_cost, best_axis, best_bin = np.inf, -1, -1
        for c in range(3):
            ext = ch[c] - cl[c]
            if not ext > 0:
                continue
            scale = n_bins / ext
            b_cnt[:] = 0
            b_lo[:] = np.inf
            b_hi[:] = -np.inf
            for i in range(b, e):
                p = order[i]
                k = min(n_bins - 1, int((cen[p, c] - cl[c]) * scale))
                b_cnt[k] += 1
                for q in range(3):
                    b_lo[k, q] = min(b_lo[k, q], lo[p, q])
                    b_hi[k, q] = max(b_hi[k, q], hi[p, q])
            # Right-hand sweep: area and count of bins k+1 .. end
            ax = ay = az = np.inf
            bx = by = bz = -np.inf
            cnt = 0
            for k in range(n_bins - 1, 0, -1):
                if b_cnt[k] > 0:
                    ax, ay, az = min(ax, b_lo[k, 0]), min(ay, b_lo[k, 1]), min(az, b_lo[k, 2])
                    bx, by, bz = max(bx, b_hi[k, 0]), max(by, b_hi[k, 1]), max(bz, b_hi[k, 2])
                    cnt += b_cnt[k]
                r_cnt[k - 1] = cnt
                r_area[k - 1] = _area(ax, ay, az, bx, by, bz) if cnt > 0 else 0.0
            # Left-hand sweep and cost of splitting after bin k
            ax = ay = az = np.inf
            bx = by = bz = -np.inf
            cnt = 0
            for k in range(n_bins - 1):
                if b_cnt[k] > 0:
                    ax, ay, az = min(ax, b_lo[k, 0]), min(ay, b_lo[k, 1]), min(az, b_lo[k, 2])
                    bx, by, bz = max(bx, b_hi[k, 0]), max(by, b_hi[k, 1]), max(bz, b_hi[k, 2])
                    cnt += b_cnt[k]
                if cnt == 0 or r_cnt[k] == 0:
                    continue
                cost = _area(ax, ay, az, bx, by, bz) * cnt + r_area[k] * r_cnt[k]
                if cost < best_cost:
                    best_cost, best_axis, best_bin = cost, c, k
        # -- partition order[b:e] (bins <= best_bin first), else split at the middle
        mid = b + n // 2
        if best_axis >= 0:
            c = best_axis
            scale = n_bins / (ch[c] - cl[c])
            i, j = b, e - 1
            while i <= j:
                k = min(n_bins - 1, int((cen[order[i], c] - cl[c]) * scale))
                if k <= best_bin:
                    i += 1
                else:
                    order[i], order[j] = order[j], order[i]
                    j -= 1
            if b < i < e:
                mid = i
        kid = n_nodes
        n_nodes += 2
        child[node] = kid
        st_node[sp], st_b[sp], st_e[sp], st_l[sp] = kid + 1, mid, e, lev + 1
        st_node[sp + 1], st_b[sp + 1], st_e[sp + 1], st_l[sp + 1] = kid, b, mid, lev + 1
        sp += 2
    return (n_lo[:n_nodes].copy(), n_hi[:n_nodes].copy(), child[:n_nodes].copy(),
            start[:n_nodes].copy(), count[:n_nodes].copy(), order, depth)


class FlatBVH:
    """A built tree: the flat arrays of the module docstring, plus ``stack`` (traversal stack size).

    (Tried: both children's boxes in the parent's record as float32, one
    cache line per visit; measured 25 % slower than these float64 arrays.)
    """

    def __init__(self, lo, hi, child, start, count, order, depth):
        self.lo, self.hi, self.child, self.start, self.count = lo, hi, child, start, count
        self.order = order
        self.depth = int(depth)
        self.stack = self.depth + 2


def build_bvh(lo: np.ndarray, hi: np.ndarray, leaf_max: int = LEAF_MAX) -> FlatBVH:
    """Binned-SAH BVH over boxes lo, hi (F, 3) float64 (F >= 1).

    Node boxes are padded outward by 1e-12 of the root's diagonal plus 1e-15 of
    each coordinate's magnitude (a few ulps), so the slab test is conservative.
    """
    lo = np.ascontiguousarray(lo, dtype=np.float64)
    hi = np.ascontiguousarray(hi, dtype=np.float64)
    n_lo, n_hi, child, start, count, order, depth = _build(lo, hi, leaf_max, N_BINS)
    diag = float(np.linalg.norm(n_hi[0] - n_lo[0])) if np.all(np.isfinite(n_hi[0] - n_lo[0])) else 0.0
    pad_lo = 1e-12 * diag + 1e-15 * np.abs(n_lo) + 1e-300
    pad_hi = 1e-12 * diag + 1e-15 * np.abs(n_hi) + 1e-300
    return FlatBVH(n_lo - pad_lo, n_hi + pad_hi, child, start, count, order, depth)
