"""Compiled kd-tree look-ups (numba) for the three estimators, with scipy as the fallback.

The estimators in :mod:`.estimators` need, per query, a k-nearest search and
then a reduction over the neighbours (side test, optional cone weight, sum
of power; for TEMPORAL first the k nearest in time among m spatial
candidates).  With scipy, the search returns (n, k) index and distance
arrays that numpy then gathers and reduces: about 80 % of a look-up is
``cKDTree.query`` and the rest is array traffic.  Here one compiled function
does search and reduction per query, so no (n, k) array is ever built.

The results are *the same estimates* as the scipy path:

* distances are computed in float64 from the float32 record positions (the
  float64 copy scipy searches holds exactly those values), as the same sum
  of squared coordinate differences in the same order; KD4D's fourth
  coordinate is the same float64 product ``s * t``.  So every neighbour set
  is the one scipy returns, except for exact distance ties at the k-th
  neighbour, where either answer is a valid k-nearest set (both searches
  then pick arbitrarily);
* TEMPORAL's selection takes the k - 1 smallest time distances among the
  m - 1 inner candidates and the k-th as the window half-width, like
  ``np.argpartition`` (again arbitrary only among exact ties);
* power is summed in float64 (the numpy path sums float32), so estimates
  agree to float32 rounding (about 1e-6 relative; tested).

The normalisations (disc area, window mass, clipped ball volume) are not
here: :class:`PhotonMap` applies the same numpy code to the radii and window
widths this module returns.

Tree: a balanced kd-tree built here (numba), median split on the widest
axis of each node (measured on up to 512 strided rows), 2^L leaves of at most ``LEAF_SIZE``
photons; leaf l is the photons [l N / L, (l + 1) N / L) in tree order.  Two
arrays in tree order: the coordinates as rows ``xyzt`` (4, N) float32 (x, y, z,
t: a leaf's are four contiguous runs, 16 bytes per photon tested), and one
32-byte row per photon ``pts`` (N, 8) float32 ``(wi, delta_only, Phi, n_code)``, two to a
cache line, which only the sums of the kept photons read.
(Until 2026-12-07 one 48-byte row held both; the search then dragged power
and direction of every photon tested through the cache.)  Node boxes are
float32 rounded outward (exact for x, y, z; a hair larger for s t, which only
makes pruning more conservative), a node's two children in one 64-byte line.

Search (:func:`_knn`): depth first, the nearer child followed at once and
the farther pushed if its box reaches the current bound; only leaves within
the bound are scanned.  A leaf's squared distances are computed in one
branch-free loop, then every photon is written to the buffer and the count
advanced only for those nearer than the bound (no branch to mispredict: about
half of a scanned leaf is kept).  The buffer (2 kq + a leaf, with time
distances, TEMPORAL's) is cut back to the kq nearest when the next leaf might
not fit (O(1) per photon where a heap costs O(log kq); TEMPORAL with a large
fixed alpha keeps hundreds); the cut and TEMPORAL's time selection find their
nth smallest by a histogram (:func:`_kth_smallest_count`), not a quickselect.
Warm start: the previous query's kq nearest are kq photons within the farthest
of them from q, so that distance already bounds the search from its first node
(the bound then rarely tightens during a search, so the order in which leaves
are visited hardly matters: a best-first search with a heap, until 2026-12-07,
visited the same leaves at more cost per node).  The window's sum is branch-free
too (a photon outside the window, on the far side or off the query's tangent slab adds w = 0:
:func:`_in_slab`, docs/photon-mapping.md "Tangent slab").

Bounded searches (``_lookup``'s cap2, ``FlatTree.lookup(..., cap=r_max)``): the search starts from
min(warm start, r_max^2) and never looks beyond r_max; a query with fewer than kq photons strictly
within r_max sums all of them over the r_max region (TEMPORAL: no time selection, tau = inf) and
leaves no warm start for the next query.  Which maps are bounded and how r_max is chosen:
:mod:`.estimators` (``SEARCH_CAP``, found when the map is built), docs/photon-mapping.md ("Bounded searches").

Queries are processed in Morton order, so consecutive queries are neighbours
(warm start, tree nodes in cache).  The order is a list of row indices
(:func:`morton_order`: compiled codes, a radix sort for large batches); the
kernel gathers those rows of the caller's arrays into contiguous scratch, searches,
and scatters the results back, so a batch (or one time slice's part of it:
``FlatTree.lookup(rows=, out=)``) is never copied or permuted in numpy
(docs/photon-mapping.md, "Look-up overheads").  An exact candidate cache (photons within
r_c + 2 beta r_c of the last full search, reused by the queries within beta
r_c of it) was measured slower than a warm-started search in every render
tried (2026-11-25: STANDARD 0.49 -> 0.31 s, TEMPORAL 0.59 -> 0.46 s, KD4D
0.74 -> 0.51 s of render_s without it) and was removed.

Threads: the compiled functions release the GIL (``nogil``) and run one
query range each; :func:`run_chunks` splits a batch of queries over a small
thread pool.  No numba threading layer is used, so calling from several
render threads at once is safe.

Fallback: if numba cannot be imported (or compiling fails), ``AVAILABLE`` is
False and :class:`PhotonMap` uses scipy's cKDTree; set ``STPM_NO_NUMBA=1`` to
force that path.
"""
from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..numba_probe import probe

__all__ = ["AVAILABLE", "LEAF_SIZE", "MODE_STANDARD", "MODE_TEMPORAL", "MODE_KD4D", "NORMAL_COS", "FlatTree",
           "run_chunks", "disable"]

LEAF_SIZE = 32           # at most this many photons per leaf (2^L leaves of 16..32; docs/photon-mapping.md, section 5b)
MODE_STANDARD, MODE_TEMPORAL, MODE_KD4D = 0, 1, 2
_CHUNK_MIN = 2048        # fewer queries than this per thread are not split
# the slab's normal test (_facing): a photon behind the query's tangent plane counts only if dot(n_p, n_g)
# >= NORMAL_COS, n_p its stored geometric normal: cos 80 deg, so faces at right angles to the query's (an
# open outer corner's, 90 deg) drop out and bumps keep most of theirs (63 deg slopes: 0.88-0.91 of no
# slab, the slab alone 0.93-0.94, cos 60 deg 0.79-0.84; docs/photon-mapping.md "Tangent slab").  > 0 (compared
# squared); compiled in (estimators.NORMAL_COS re-exports it)
NORMAL_COS = float(np.cos(np.radians(80.0)))
_NORMAL_COS2 = NORMAL_COS * NORMAL_COS
assert NORMAL_COS > 0.0
# boundary correction at a surface's edge (_edge_scale; docs/photon-mapping.md "Boundary correction"): read only
# where the k photons' centroid in the tangent plane lies EDGE_Z standard errors of a uniform disc (r / (2 sqrt
# N)) off the query; the edge's normal searched over EDGE_DIRS directions within EDGE_SPAN rad of the centroid's;
# the support's gap before a chord counted EDGE_GAP x its single-direction expectation; applied only where the
# missing part would have held EDGE_MISS photons or more, and where the strip EDGE_STRIP r wide inside the edge
# holds EDGE_ACCEPT of the photons a uniform density puts there (a density step keeps few); at least EDGE_MIN
# photons, none more than EDGE_FRONT r in front of the plane (a concave corner's other face fills the disc)
EDGE_Z = 1.5
EDGE_DIRS = 11
EDGE_SPAN = 0.5
EDGE_GAP = 1.5
EDGE_MISS = 4.0
EDGE_STRIP = 0.3
EDGE_ACCEPT = 0.6
EDGE_MIN = 16
EDGE_FRONT = 0.05
_EDGE_COS = np.cos(EDGE_SPAN * np.linspace(-1.0, 1.0, EDGE_DIRS))
_EDGE_SIN = np.sin(EDGE_SPAN * np.linspace(-1.0, 1.0, EDGE_DIRS))
_EDGE_QUAD = 128         # midpoint nodes of the cut segment's (cone-)weighted area
_RADIX_MIN = 4096        # queries Morton-sorted by radix from this many (numpy's argsort below: as fast there)

# Morton codes: row D - 3 maps a 10-bit cell index v to v's bit b moved to bit D b (D = 3, 4)
_SPREAD = np.zeros((2, 1024), np.int64)
for _D in (3, 4):
    for _b in range(10):
        _SPREAD[_D - 3] |= ((np.arange(1024) >> _b) & 1) << (_D * _b)
del _D, _b

AVAILABLE, _IMPORT_ERROR = probe()
if AVAILABLE:
    import numba as _nb
    # the rough lobes a camera vertex weighs caustic photons by (FlatTree.lookup's glossy sums)
    from ..kernels.bsdf import _glossy_add as _bsdf_glossy_add, _hit as _bsdf_hit


def disable(reason: str) -> None:
    """Switch the compiled path off for this process (after a compile or run failure)."""
    global AVAILABLE, _IMPORT_ERROR
    AVAILABLE = False
    _IMPORT_ERROR = reason


# ---------------------------------------------------------------------------
# Thread pool shared by every map
# ---------------------------------------------------------------------------
_POOL: ThreadPoolExecutor | None = None
_POOL_LOCK = threading.Lock()


def _pool(workers: int) -> ThreadPoolExecutor:
    global _POOL
    with _POOL_LOCK:
        if _POOL is None or _POOL._max_workers < workers:
            _POOL = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="stpm-lookup")
        return _POOL


def run_chunks(fn, n: int, workers: int) -> None:
    """Call fn(lo, hi) over [0, n) split into about ``workers`` ranges, in parallel (fn releases the GIL)."""
    workers = max(1, (os.cpu_count() or 1) if workers is None or workers <= 0 else int(workers))
    parts = min(workers, max(1, n // _CHUNK_MIN))
    if parts <= 1:
        fn(0, n)
        return
    edges = np.linspace(0, n, parts + 1).astype(np.int64)
    futures = [_pool(workers).submit(fn, int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]
    for f in futures:
        f.result()


# ---------------------------------------------------------------------------
# Compiled kernels
# ---------------------------------------------------------------------------
if AVAILABLE:
    _jit = _nb.njit(cache=True, nogil=True, fastmath=False, boundscheck=False)

    @_jit
    def _coord(P, j, d, s):
        """Coordinate d of row j of P (N, 4) float32 (x, y, z, t): x, y, z or s * t, in float64."""
        if d == 3:
            return s * np.float64(P[j, 3])
        return np.float64(P[j, d])

    @_jit
    def _dist2(C, j, q0, q1, q2, q3, D, s):
        """Squared distance in float64 from photon j of C (4, N) float32 (x, y, z, t rows) to the query
        (q0, q1, q2, q3): over x, y, z, and for D = 4 also the scaled time s * t."""
        e0 = np.float64(C[0, j]) - q0
        e1 = np.float64(C[1, j]) - q1
        e2 = np.float64(C[2, j]) - q2
        d2 = e0 * e0 + e1 * e1 + e2 * e2
        if D == 4:
            e3 = s * np.float64(C[3, j]) - q3
            d2 += e3 * e3
        return d2
    @_jit
    def _split_rows(P, perm, lo, hi, nth, dim, s):
        """Quickselect rows lo..hi-1 of P (and perm) so row nth holds the nth smallest coordinate dim.

        Rows are swapped in place, so the tree is built on contiguous memory.
        """
        while hi - lo > 1:
            # median of three as pivot (deterministic)
            a = _coord(P, lo, dim, s)
            b = _coord(P, (lo + hi) // 2, dim, s)
            c = _coord(P, hi - 1, dim, s)
            if a > b:
                a, b = b, a
            if b > c:
                b = c
                if a > b:
                    b = a
            pivot = b
            i, j = lo, hi - 1
            while i <= j:
                while _coord(P, i, dim, s) < pivot:
                    i += 1
                while _coord(P, j, dim, s) > pivot:
                    j -= 1
                if i <= j:
                    for d in range(4):
                        tmp = P[i, d]
                        P[i, d] = P[j, d]
                        P[j, d] = tmp
                    ti = perm[i]
                    perm[i] = perm[j]
                    perm[j] = ti
                    i += 1
                    j -= 1
            if nth <= j:
                hi = j + 1
            elif nth >= i:
                lo = i
            else:
                return

    @_jit
    def _build(P, D, s, n_leaves):
        """Balanced kd-tree over the rows of P (N, 4) float32 (x, y, z, t), in D = 3 or 4 dims (4th = s t).

        P is reordered in place to tree order.  Returns perm (N,) int64 (tree row -> input row)
        and box (2 L, 8) float32: row i + 1 holds node i's tight bounding box (min in columns
        0..D-1, max in 4..4+D-1) rounded outward to float32.  Implicit layout: the children of
        node i are 2i+1 and 2i+2 (rows 2i+2, 2i+3: one 64-byte line); leaves are nodes
        L-1 .. 2L-2, and leaf l holds rows [l N // L, (l + 1) N // L).
        """
        N = P.shape[0]
        n_nodes = 2 * n_leaves - 1
        perm = np.arange(N)
        node_lo = np.zeros(n_nodes, np.int64)
        node_hi = np.zeros(n_nodes, np.int64)
        bmin = np.empty((n_nodes, D))
        bmax = np.empty((n_nodes, D))
        node_hi[0] = N
        # middle leaf of every inner node: node i at depth d, position p in its level covers
        # leaves [p, p + 1) * L / 2^d
        leaf_mid = np.zeros(n_leaves, np.int64)
        for i in range(n_leaves - 1):
            d = 0
            while (2 << d) <= i + 1:
                d += 1
            width = n_leaves >> d
            leaf_mid[i] = (i + 1 - (1 << d)) * width + width // 2
        for i in range(n_leaves - 1):
            lo, hi = node_lo[i], node_hi[i]
            # split axis: the widest of the node's extent, measured on <= 512 strided rows
            # (any split gives a valid tree; this only keeps the cells compact)
            step = max(1, (hi - lo) // 512)
            dim, width = 0, -1.0
            for d in range(D):
                vmin, vmax = np.inf, -np.inf
                for j in range(lo, hi, step):
                    v = _coord(P, j, d, s)
                    vmin = min(vmin, v)
                    vmax = max(vmax, v)
                if vmax - vmin > width:
                    dim, width = d, vmax - vmin
            # split rows so that leaf l ends up holding rows [l N // L, (l + 1) N // L)
            mid = (leaf_mid[i] * N) // n_leaves
            if hi - lo > 1 and lo < mid < hi:
                _split_rows(P, perm, lo, hi, mid, dim, s)
            node_lo[2 * i + 1], node_hi[2 * i + 1] = lo, mid
            node_lo[2 * i + 2], node_hi[2 * i + 2] = mid, hi
        # tight boxes: leaves from their rows, inner nodes as the union of their children
        for i in range(n_nodes - 1, -1, -1):
            for d in range(D):
                bmin[i, d] = np.inf
                bmax[i, d] = -np.inf
            if i >= n_leaves - 1:
                for j in range(node_lo[i], node_hi[i]):
                    for d in range(D):
                        v = _coord(P, j, d, s)
                        bmin[i, d] = min(bmin[i, d], v)
                        bmax[i, d] = max(bmax[i, d], v)
            else:
                for d in range(D):
                    bmin[i, d] = min(bmin[2 * i + 1, d], bmin[2 * i + 2, d])
                    bmax[i, d] = max(bmax[2 * i + 1, d], bmax[2 * i + 2, d])
        box = np.zeros((n_nodes + 1, 8), np.float32)
        for i in range(n_nodes):
            for d in range(D):
                lo32 = np.float32(bmin[i, d])
                if np.float64(lo32) > bmin[i, d]:
                    lo32 = np.nextafter(lo32, np.float32(-np.inf))
                hi32 = np.float32(bmax[i, d])
                if np.float64(hi32) < bmax[i, d]:
                    hi32 = np.nextafter(hi32, np.float32(np.inf))
                box[i + 1, d] = lo32
                box[i + 1, 4 + d] = hi32
        return perm, box

    @_jit
    def _box_dist2(box, row, q0, q1, q2, q3, D):
        """Squared distance (float64) from the query to the bounding box in row ``row`` of box."""
        # per axis the gap e = max(lo - v, v - hi, 0), branch-free (a NaN coordinate adds 0); the
        # squares are summed in axis order
        e = _gap(np.float64(box[row, 0]), np.float64(box[row, 4]), q0)
        acc = e * e
        e = _gap(np.float64(box[row, 1]), np.float64(box[row, 5]), q1)
        acc += e * e
        e = _gap(np.float64(box[row, 2]), np.float64(box[row, 6]), q2)
        acc += e * e
        if D == 4:
            e = _gap(np.float64(box[row, 3]), np.float64(box[row, 7]), q3)
            acc += e * e
        return acc

    @_jit
    def _gap(lo, hi, v):
        """Distance (float64, >= 0) from v to the interval [lo, hi]; 0 inside it or for a NaN v."""
        a = lo - v
        b = v - hi
        e = a if a > b else b
        return e if e > 0.0 else 0.0

    @_jit
    def _select(key, lo, hi, nth):
        """Quickselect key[lo:hi] in place: key[nth] is the nth smallest, no larger key left of it."""
        while hi - lo > 1:
            a, b, c = key[lo], key[(lo + hi) // 2], key[hi - 1]
            if a > b:
                a, b = b, a
            if b > c:
                b = c
                if a > b:
                    b = a
            pivot = b
            i, j = lo, hi - 1
            while i <= j:
                while key[i] < pivot:
                    i += 1
                while key[j] > pivot:
                    j -= 1
                if i <= j:
                    key[i], key[j] = key[j], key[i]
                    i += 1
                    j -= 1
            if nth <= j:
                hi = j + 1
            elif nth >= i:
                lo = i
            else:
                return

    @_jit
    def _kth_smallest(key, n, nth, hist, bucket, sub):
        """The nth smallest (0-based) of key[:n] (keys >= 0), found by a histogram; key is not reordered.

        Keys go to hist.shape[0] equal buckets over [0, max key] (bucket[:n] their bucket, hist the
        counts); the bucket where the running count passes nth holds the answer, found by
        quickselect among its few keys (copied to sub).  Exact: the bucket index is monotone in
        the key.  Replaces a quickselect over all n keys (carrying two more arrays), whose
        partition branches are unpredictable: that was about a quarter of a TEMPORAL look-up
        (docs/photon-mapping.md, section 7).
        hist (nb,) int64, bucket (>= n,) int64, sub (>= n,) float64 scratch.
        """
        return _kth_smallest_count(key, n, nth, hist, bucket, sub)[0]

    @_jit
    def _kth_smallest_count(key, n, nth, hist, bucket, sub):
        """(the nth smallest of key[:n], how many of key[:n] are strictly smaller): :func:`_kth_smallest`.

        The loops are branch-free where the branch would be unpredictable (the max, the copy of the
        answer's bucket).
        """
        kmax = 0.0
        for a in range(n):
            v = key[a]
            kmax = v if v > kmax else kmax
        if kmax == 0.0:
            return 0.0, 0
        nb = hist.shape[0]
        scale = nb / kmax
        for b in range(nb):
            hist[b] = 0
        for a in range(n):
            v = key[a] * scale
            b = int(v) if v < nb else nb - 1       # (the max, and a NaN, to the last bucket)
            bucket[a] = b
            hist[b] += 1
        cum = 0
        b = 0
        while cum + hist[b] <= nth:
            cum += hist[b]
            b += 1
        m = 0
        for a in range(n):
            sub[m] = key[a]                        # (m <= a: always inside sub)
            m += 1 if bucket[a] == b else 0
        _select(sub, 0, m, nth - cum)
        ans = sub[nth - cum]
        n_less = cum
        for a in range(nth - cum):                 # (the answer's bucket: those left of it are <= it)
            n_less += 1 if sub[a] < ans else 0
        return ans, n_less

    @_jit
    def _cut(bd, bi, bx, cnt, kq, hist, bucket, sub, ti):
        """Keep the kq nearest of the search buffer's cnt entries (bd, bi, bx) in its first kq slots.

        bd[kq - 1] is then the kq-th squared distance and the others no larger; the entries kept
        keep their buffer order (a stable compaction: no unpredictable swaps), those at exactly
        the kq-th distance after them.  hist, bucket, sub, ti: scratch (:func:`_kth_smallest`;
        sub and ti of >= cnt entries).
        """
        thr, n_less = _kth_smallest_count(bd, cnt, kq - 1, hist, bucket, sub)
        # one pass: those strictly nearer to the front, in buffer order (always copy, advance when
        # kept), and the first kq - n_less entries at exactly thr (at least one: the kq-th itself)
        # copied out on the way (the copy never overwrites an entry not yet read: w <= a)
        need = kq - n_less
        nt = 0
        w = 0
        for a in range(cnt):
            d = bd[a]
            i_a = bi[a]
            x_a = bx[a]
            if d == thr and nt < need:
                ti[nt] = i_a
                sub[nt] = x_a
                nt += 1
            bd[w] = d
            bi[w] = i_a
            bx[w] = x_a
            w += 1 if d < thr else 0
        b = 0
        while w < kq:
            bd[w] = thr
            bi[w] = ti[b]
            bx[w] = sub[b]
            w += 1
            b += 1

    @_jit
    def _knn(C, box, n_leaves, q, D, s, kq, bd, bi, bx, qnode, qdist, bound0, hist, bucket, sub, ti, leaf_d2):
        """Depth-first kq-nearest search.  On return bd[:kq] / bi[:kq] hold the squared distances and
        rows of the kq nearest, bd[kq - 1] the kq-th (the others no farther).  bx: scratch of the
        buffer's length that the cuts carry along (the caller computes time distances for the kept
        photons only).

        C (4, N) float32: the coordinate rows in tree order.  Nodes whose box lies within the
        current bound are entered, the nearer child first (stack qnode / qdist, scratch of at least
        the tree depth + 1 entries; the node count is plenty).  Photons nearer than the current
        bound are appended to the buffer bd / bi / bx (capacity at least 2 kq + LEAF_SIZE + 1); a
        buffer that might not take the next leaf is cut back to its kq nearest by :func:`_cut`, which
        also tightens the bound (O(1) per photon, where a kq-heap costs O(log kq)).  hist, bucket,
        sub, ti: _cut's scratch (sub, ti as long as the buffer); leaf_d2 (>= LEAF_SIZE,) scratch.

        bound0: a squared distance known to hold at least kq photons strictly inside (inf if
        none is known), or a cap the caller will not search beyond; the search then prunes from
        its first node.  Returns how many photons it found strictly below bound0, at most kq:
        kq when it found the kq nearest; fewer (c < kq) when bound0 holds fewer, which are then
        bd[:c] / bi[:c] (the buffer is only cut once it holds more than kq, so they are all
        there), and the caller searches again with a larger bound or uses those c.
        """
        cap = bd.shape[0]
        N = C.shape[1]
        cnt = 0
        bound = bound0
        first_leaf = n_leaves - 1
        q0, q1, q2, q3 = q[0], q[1], q[2], q[3]
        qnode[0] = 0
        qdist[0] = 0.0
        nq = 1
        while nq > 0:
            # pop the last node pushed (depth first; with a warm-start bound, which the search
            # rarely tightens, every order visits the same leaves: those within the bound)
            nq -= 1
            node, dist = qnode[nq], qdist[nq]
            # descend to a leaf through the nearer children, pushing the farther ones
            while node < first_leaf and dist < bound:
                cl = 2 * node + 1
                dl = _box_dist2(box, cl + 1, q0, q1, q2, q3, D)
                dr = _box_dist2(box, cl + 2, q0, q1, q2, q3, D)
                if dl <= dr:
                    node, dist, far, dfar = cl, dl, cl + 1, dr
                else:
                    node, dist, far, dfar = cl + 1, dr, cl, dl
                if dfar < bound:
                    qnode[nq] = far
                    qdist[nq] = dfar
                    nq += 1
            if node < first_leaf or dist >= bound:
                continue
            # scan the leaf's contiguous rows
            # (first every squared distance, a branch-free loop over the leaf's coordinate rows; then
            # the appends.  LLVM does not vectorise this loop; a form over slices of the rows that it
            # does vectorise measured slower at 16-32 photons a leaf)
            leaf = node - first_leaf
            j0 = (leaf * N) // n_leaves
            nl = ((leaf + 1) * N) // n_leaves - j0
            if D == 4:
                for a in range(nl):
                    e0 = np.float64(C[0, j0 + a]) - q0
                    e1 = np.float64(C[1, j0 + a]) - q1
                    e2 = np.float64(C[2, j0 + a]) - q2
                    e3 = s * np.float64(C[3, j0 + a]) - q3
                    leaf_d2[a] = (e0 * e0 + e1 * e1 + e2 * e2) + e3 * e3
            else:
                for a in range(nl):
                    e0 = np.float64(C[0, j0 + a]) - q0
                    e1 = np.float64(C[1, j0 + a]) - q1
                    e2 = np.float64(C[2, j0 + a]) - q2
                    leaf_d2[a] = e0 * e0 + e1 * e1 + e2 * e2
            if cnt + nl > cap:
                _cut(bd, bi, bx, cnt, kq, hist, bucket, sub, ti)
                cnt = kq
                bound = bd[kq - 1]
            for a in range(nl):
                # (every photon written, the count advanced only for those inside the bound: no
                # branch to mispredict where about half the leaf's photons are kept)
                d2 = leaf_d2[a]
                bd[cnt] = d2
                bi[cnt] = j0 + a
                cnt += 1 if d2 < bound else 0
            if bound == np.inf and cnt >= kq:
                _cut(bd, bi, bx, cnt, kq, hist, bucket, sub, ti)
                cnt = kq
                bound = bd[kq - 1]
        if cnt < kq:
            return cnt
        if cnt > kq:
            _cut(bd, bi, bx, cnt, kq, hist, bucket, sub, ti)
        else:
            # exactly kq kept below a warm-start bound and never cut: the kq-th (the largest) to
            # slot kq - 1
            am = 0
            for a in range(1, kq):
                if bd[a] > bd[am]:
                    am = a
            bd[am], bd[kq - 1] = bd[kq - 1], bd[am]
            bi[am], bi[kq - 1] = bi[kq - 1], bi[am]
            bx[am], bx[kq - 1] = bx[kq - 1], bx[am]
        return kq

    @_jit
    def _in_slab(C, j, q0, q1, q2, q3, m0, m1, m2, r2, ball4, s, plane_b, plane_f):
        """Does photon j of C (4, N) lie in the query's tangent slab, -plane_b rho <= h <= plane_f rho?

        h = (x_j - q) . m (m) its height over the plane through q (q0, q1, q2) of unit normal m
        (m0, m1, m2; zero: every photon is in); rho the radius of the region's section at the
        photon: sqrt(r2) for a 3D ball or cylinder, sqrt(r2 - (s t_j - q3)^2) for a 4D ball (its
        spatial section at the photon's time, so the slab is the same fraction of the disc the
        photon shares).  plane_b, plane_f: inf, no bound on that side.  Squares compared: no sqrt.
        """
        h = ((np.float64(C[0, j]) - q0) * m0 + (np.float64(C[1, j]) - q1) * m1
             + (np.float64(C[2, j]) - q2) * m2)
        rho2 = r2
        if ball4:
            e3 = s * np.float64(C[3, j]) - q3
            rho2 = max(r2 - e3 * e3, 0.0)
        if h >= 0.0:
            return plane_f == np.inf or h * h <= plane_f * plane_f * rho2
        return plane_b == np.inf or h * h <= plane_b * plane_b * rho2

    @_jit
    def _facing(P, C, j, q0, q1, q2, m0, m1, m2):
        """Behind the query's tangent plane, does photon j's surface face the query's way: dot(n_p, m)
        >= NORMAL_COS?  (True in front of the plane, h = (x_j - q) . m >= 0, and without a stored normal.)

        n_p decoded from P[j, 7] (``record.normal_codes``: 1 + iu 4096 + iv, iu, iv the 12-bit
        octahedral coordinates in [0, 4094]; 0 = none; ``record.decode_normal_codes`` is the numpy
        copy), m (m0, m1, m2) the query's unit slab normal (both on their wi / viewer side).  Unnormalised
        n_p: d = n_p . m >= 0 and d^2 >= NORMAL_COS^2 |n_p|^2, no sqrt.  Rejects the face of an open
        outer corner behind a wall (docs/photon-mapping.md, "Tangent slab", "Photon normals").  In
        front of the plane every normal counts: there lies a concave corner's other face (the floor at
        a wall's foot), which fills the part of the disc beyond the query's surface, as PLANE_FRONT = inf.
        """
        c = P[j, 7]
        if not c > 0.0:
            return True
        h = ((np.float64(C[0, j]) - q0) * m0 + (np.float64(C[1, j]) - q1) * m1
             + (np.float64(C[2, j]) - q2) * m2)
        if h >= 0.0:
            return True
        k = np.int64(c) - 1
        u = np.float64((k >> 12) - 2047) * (1.0 / 2047.0)
        v = np.float64((k & 4095) - 2047) * (1.0 / 2047.0)
        z = 1.0 - abs(u) - abs(v)
        x = u
        y = v
        if z < 0.0:
            x = (1.0 - abs(v)) * (1.0 if u >= 0.0 else -1.0)
            y = (1.0 - abs(u)) * (1.0 if v >= 0.0 else -1.0)
        d = x * m0 + y * m1 + z * m2
        return d >= 0.0 and d * d >= _NORMAL_COS2 * (x * x + y * y + z * z)

    @_jit
    def _cut_fraction(d, inv_k):
        """Weighted fraction of a unit disc left by cutting off the segment x > d (0 <= d <= 1): the
        weight 1 - rho inv_k (inv_k = 1 / CONE_K for the cone kernel, 0 for the box).  The segment's
        weight by the midpoint rule over its angle (_EDGE_QUAD nodes; the box's closed form
        1 - (acos d - d sqrt(1 - d^2)) / pi within 8e-4), the disc's pi (1 - 2 inv_k / 3)."""
        a = np.arccos(d)
        h = 2.0 * a / _EDGE_QUAD
        seg = 0.0
        for i in range(_EDGE_QUAD):
            th = -a + (i + 0.5) * h
            b = d / np.cos(th)           # where the ray at angle th leaves the covered part
            if b < 1.0:
                seg += (1.0 - b * b) * 0.5 - (1.0 - b * b * b) * inv_k / 3.0
        return 1.0 - seg * h / (np.pi * (1.0 - 2.0 * inv_k / 3.0))

    @_jit
    def _disc_seg(x):
        """Area of the unit disc's segment beyond the chord at x (-1 <= x <= 1): acos x - x sqrt(1 - x^2)."""
        x = min(max(x, -1.0), 1.0)
        return np.arccos(x) - x * np.sqrt(1.0 - x * x)

    @_jit
    def _edge_collect(P, C, bi, n_sel, q0, q1, q2, q3, m0, m1, m2, r2, s, plane_b, plane_f, ex, ey, ez):
        """(N, front): the in-plane offsets (x_p - q) - h m (h = (x_p - q) . m) of the n_sel inner candidates
        bi[:n_sel] that pass the slab and normal tests into ex, ey, ez[:N]; front: does any lie more than
        EDGE_FRONT r in front of the plane (r = sqrt(r2))?  What _lookup's sum loop collects on its way
        (this separate pass serves its branch for ties in time)."""
        lim = EDGE_FRONT * np.sqrt(r2)
        n = 0
        front = False
        for a in range(n_sel):
            j = bi[a]
            if not (_in_slab(C, j, q0, q1, q2, q3, m0, m1, m2, r2, False, s, plane_b, plane_f)
                    and _facing(P, C, j, q0, q1, q2, m0, m1, m2)):
                continue
            v0 = np.float64(C[0, j]) - q0
            v1 = np.float64(C[1, j]) - q1
            v2 = np.float64(C[2, j]) - q2
            h = v0 * m0 + v1 * m1 + v2 * m2
            front = front or h > lim
            ex[n] = v0 - h * m0
            ey[n] = v1 - h * m1
            ez[n] = v2 - h * m2
            n += 1
        return n, front

    @_jit
    def _edge_scale(ex, ey, ez, n, front, m0, m1, m2, r2, inv_k):
        """1 / (the fraction of the query's disc its surface covers), as its photons show it; 1 where
        they show no edge (docs/photon-mapping.md, "Boundary correction at a convex edge").

        ex, ey, ez[:n]: the in-plane offsets from the query of the search's inner candidates that pass
        the slab and normal tests (position only: no side or time test, so TEMPORAL reads all its
        candidates; :func:`_edge_collect`), m the plane's unit normal, r = sqrt(r2) the disc's radius;
        overwritten.  Uniform over the disc, their centroid c lies within a standard error r / (2
        sqrt n) of q; where a straight edge cuts the disc it moves away from the edge.  Where |c| >
        EDGE_Z r / (2 sqrt n): the support h = min over EDGE_DIRS directions u within EDGE_SPAN of -c /
        |c| of max_p (x_p - q) . u (the nearest line with no photon beyond; its u the edge's normal),
        d = h / r clamped to [0, 1] (the query lies on its surface: at most 2x) plus EDGE_GAP x the
        expected gap of n uniform points before a chord, f_box(d) / (n chord(d)), f_box(d) = 1 -
        (acos d - d sqrt(1 - d^2)) / pi.  Applied only if the missing part would have held EDGE_MISS
        photons or more, n (1 - f_box) >= EDGE_MISS f_box (a direction's scan stops as soon as a photon
        lies beyond the d where that fails), and if the strip EDGE_STRIP r wide inside the line holds at
        least EDGE_ACCEPT of what the density n / (pi r^2 f_box) puts there: a surface's edge is sharp,
        while beyond a density step (a dimmer region of the same surface) photons go on to the disc's
        rim, and where they thin out the strip is short of photons.  Returns 1 / _cut_fraction(d,
        inv_k) (the kernel's weight).  No correction with fewer than EDGE_MIN photons or with front
        (one lies more than EDGE_FRONT r in front of the plane: a concave corner's other face fills
        that part of the disc, PLANE_FRONT = inf)."""
        if front or n < EDGE_MIN:
            return 1.0
        c0 = 0.0
        c1 = 0.0
        c2 = 0.0
        for a in range(n):
            c0 += ex[a]
            c1 += ey[a]
            c2 += ez[a]
        cc = c0 * c0 + c1 * c1 + c2 * c2               # (n |c|)^2
        if not cc * 4.0 > EDGE_Z * EDGE_Z * r2 * n:    # |c| <= EDGE_Z r / (2 sqrt n)
            return 1.0
        r = np.sqrt(r2)
        cn = np.sqrt(cc)
        u0, u1, u2 = -c0 / cn, -c1 / cn, -c2 / cn       # toward the missing part, in the plane
        w0, w1, w2 = m1 * u2 - m2 * u1, m2 * u0 - m0 * u2, m0 * u1 - m1 * u0   # m x u
        u0, u1, u2 = u0 / r, u1 / r, u2 / r             # (in units of r)
        w0, w1, w2 = w0 / r, w1 / r, w2 / r
        for a in range(n):
            x = ex[a] * u0 + ey[a] * u1 + ez[a] * u2
            y = ex[a] * w0 + ey[a] * w1 + ez[a] * w2
            ex[a] = x
            ey[a] = y
        # beyond dmax the miss test fails: seg(d) < pi EDGE_MISS / (n + EDGE_MISS); seg(d) <= (4 sqrt 2 / 3)
        # (1 - d)^(3/2), so the d where that bound equals it lies at or beyond the exact one (the early stop
        # below never stops a direction that could pass; the exact test follows)
        need = np.pi * EDGE_MISS / (n + EDGE_MISS)
        dmax = 1.0 - (need * 3.0 / (4.0 * np.sqrt(2.0))) ** (2.0 / 3.0)
        hmin = np.inf
        cb = 1.0
        sb = 0.0
        for i in range(EDGE_DIRS):
            ct = _EDGE_COS[i]
            st = _EDGE_SIN[i]
            hm = -np.inf
            for a in range(n):
                hm = max(hm, ex[a] * ct + ey[a] * st)
                if hm > dmax:
                    break                              # this direction cannot pass the miss test
            if hm < hmin:
                hmin, cb, sb = hm, ct, st
        if not hmin <= dmax:
            return 1.0
        d = max(hmin, 0.0)
        fb = 1.0 - _disc_seg(d) / np.pi
        d = min(d + EDGE_GAP * np.pi * fb / (n * 2.0 * np.sqrt(1.0 - d * d)), 1.0)
        fb = 1.0 - _disc_seg(d) / np.pi
        if n * (1.0 - fb) < EDGE_MISS * fb:
            return 1.0
        cnt = 0
        for a in range(n):
            if ex[a] * cb + ey[a] * sb >= hmin - EDGE_STRIP:
                cnt += 1
        if cnt < EDGE_ACCEPT * n / (np.pi * fb) * (_disc_seg(hmin - EDGE_STRIP) - _disc_seg(hmin)):
            return 1.0
        return 1.0 / _cut_fraction(d, inv_k)

    @_jit
    def _glossy_sum(P, bi, wk, n_sel, gC, i, E, E_avg, gW, coat_w):
        """(g0, g1, g2) = sum over the kept photons a < n_sel (weights wk[a] > 0, rows bi[a]) whose
        path was delta-only (P[j, 3] > 0) of wk[a] f_c(wo, wi_j) Phi_j: f_c the rough non-delta
        lobes other than DIFFUSE (rough COAT times coat_w, METAL, GLASS) of closure row gC[i]
        (``kernels.bsdf._glossy_add``), gW[i] = (wo, ns, ng) of the query's hit."""
        wo = (gW[i, 0], gW[i, 1], gW[i, 2])
        hit = _bsdf_hit(gC, i, E, E_avg, wo, (gW[i, 3], gW[i, 4], gW[i, 5]), (gW[i, 6], gW[i, 7], gW[i, 8]))
        g0 = 0.0
        g1 = 0.0
        g2 = 0.0
        for a in range(n_sel):
            w = wk[a]
            j = bi[a]
            if not (w > 0.0 and P[j, 3] > 0.0):
                continue
            wi = (np.float64(P[j, 0]), np.float64(P[j, 1]), np.float64(P[j, 2]))
            f0, f1, f2, _ = _bsdf_glossy_add(gC, i, E, hit, wo, wi, 0.0, 0.0, 0.0, 0.0, coat_w)
            g0 += w * f0 * P[j, 4]
            g1 += w * f1 * P[j, 5]
            g2 += w * f2 * P[j, 6]
        return g0, g1, g2

    @_jit
    def _lookup(P, C, box, n_leaves, q, ns, ng, order, plane_b, plane_f, mode, kq, k, s, cone, cone_k, cap2, out_phi,
                out_r, out_tau, glossy, gC, gW, E, E_avg, coat_w, out_g, edge):
        """Fused search + reduction for the queries ``order`` (m,) int64 (rows of q, in the order searched) of
        q (n, 4) (x, y, z, s t or t), normals ns (n, 3) float32; query i's results go to row i of the outputs
        (rows not in order are left as they are).

        P (N, 8) float32 rows (wi, delta_only, Phi, n_code: _facing) and C (4, N) float32 coordinate rows, both in
        tree order.

        mode STANDARD / KD4D: kq = k nearest (3D / 4D); TEMPORAL: kq = m candidates, then the k
        nearest in time among the m - 1 inner ones.  Writes out_phi (n, 3) W (sum of w Phi over
        the k - 1 inner / selected photons on the ns side and in the query's tangent slab), out_r
        (n,) distance of the kq-th photon (m) and out_tau (n,) TEMPORAL's window half-width
        (shutter units).

        Tangent slab: ng (n, 3) float32 the query's unit geometric normal, on the side the query is
        seen from; a photon counts only if -plane_b rho <= (x_p - x_q) . ng <= plane_f rho (rho the
        kq-th distance r; for KD4D the radius of the 4D ball's spatial section at the photon's time:
        :func:`_in_slab`), so a surface within the search ball but off the query's plane (a wall
        behind a curtain) adds w = 0.  inf: no bound on that side (both inf:
        every photon of the ball).  The radius still comes from all photons; the estimate's measure
        stays the disc (docs/photon-mapping.md, "Tangent slab").

        cap2: the search's cap r_max^2 (m^2, in the tree's dimensions; inf = unbounded).  A query
        whose kq-th neighbour is not strictly within r_max sums all c < kq photons strictly within
        it instead (no time selection: every candidate of the slice), out_r = r_max and out_tau
        = inf (the whole time slice); the search never looks beyond r_max (docs/photon-mapping.md,
        "Bounded searches").  With cap2 = inf every value is the unbounded search's, bit for bit.

        edge: with the slab on and not KD4D, out_phi (and out_g) times :func:`_edge_scale` of the inner
        candidates that pass the slab and normal tests (their in-plane offsets collected by the sum
        loop): 1 / the covered fraction of the disc where the query's surface ends inside it.

        glossy: also out_g (n, 3) W/sr, the same photons' sum of w f_c(wo, wi) Phi over those whose
        path was delta-only, f_c query i's rough lobes (:func:`_glossy_sum`; gC (n, N_CLOSURE) its
        closure row, gW (n, 9) its wo, ns, ng; E, E_avg the GGX tables; coat_w 1, or 0 without the
        rough coat): what a rough lobe reads of the caustic map (docs/rendering.md, "Path
        partition"), normalised as out_phi.
        """
        D = 4 if mode == MODE_KD4D else 3
        nbuf = 2 * kq + LEAF_SIZE + 1
        bd = np.empty(nbuf)
        bi = np.empty(nbuf, np.int64)
        bx = np.empty(nbuf)
        sub = np.empty(nbuf)
        ti = np.empty(nbuf, np.int64)
        bucket = np.empty(nbuf, np.int64)
        hist = np.empty(kq, np.int64)
        leaf_d2 = np.empty(LEAF_SIZE + 1)
        wk = np.empty(nbuf)                    # the weight of each kept photon (glossy)
        ex = np.empty(nbuf)                    # in-plane offsets of the slab's photons (_edge_scale)
        ey = np.empty(nbuf)
        ez = np.empty(nbuf)
        qq = np.empty(4)
        qnode = np.empty(box.shape[0], np.int64)
        qdist = np.empty(box.shape[0])
        # the queries' rows gathered in search order first, the results scattered back last: one
        # streaming pass each, where reading and writing rows scattered over the caller's arrays
        # inside the search loop stalls it (a time slice's queries are a subset of a large batch)
        m = order.shape[0]
        qs = np.empty((m, 4))
        nn = np.empty((m, 6), np.float32)      # ns, ng
        res = np.empty((m, 5))                 # phi, r, tau
        for ii in range(m):
            i = order[ii]
            for a in range(4):
                qs[ii, a] = q[i, a]
            for a in range(3):
                nn[ii, a] = ns[i, a]
                nn[ii, 3 + a] = ng[i, a]
        full = False                           # bi[:kq] holds the previous query's kq nearest
        for ii in range(m):
            i = order[ii]
            q0, q1, q2, q3 = qs[ii, 0], qs[ii, 1], qs[ii, 2], qs[ii, 3]
            # -- the kq nearest by a tree search, warm-started: the previous query's kq nearest
            # (still in bi[:kq]) are kq photons within the farthest of them from q; never beyond the cap
            qq[0], qq[1], qq[2], qq[3] = q0, q1, q2, q3
            bound0 = cap2
            if full:
                far2 = 0.0
                for a in range(kq):
                    j = bi[a]
                    d2 = _dist2(C, j, q0, q1, q2, q3, D, s)
                    far2 = max(far2, d2)
                bound0 = min(far2 * (1.0 + 1e-9), cap2)  # (slack: the farthest itself strictly inside)
            c = _knn(C, box, n_leaves, qq, D, s, kq, bd, bi, bx, qnode, qdist, bound0, hist, bucket, sub, ti, leaf_d2)
            if c < kq and bound0 < cap2:
                c = _knn(C, box, n_leaves, qq, D, s, kq, bd, bi, bx, qnode, qdist, cap2, hist, bucket, sub, ti, leaf_d2)
            full = c == kq
            # slot kq - 1 = the kq-th neighbour (fixes the radius); slots 0 .. kq - 2 are inner.
            # Capped (c < kq within r_max): the c photons bd[:c] inside the r_max ball, r = r_max
            r = np.sqrt(bd[kq - 1]) if full else np.sqrt(cap2)
            res[ii, 3] = r
            n_sel = kq - 1 if full else c
            tau = np.inf
            ties = 0
            if mode != MODE_TEMPORAL:
                res[ii, 4] = 0.0
            elif not full:
                # capped: no time selection, every candidate (finite time distances < tau = inf)
                for a in range(c):
                    bx[a] = abs(np.float64(C[3, bi[a]]) - q3)
                res[ii, 4] = tau
            else:
                # the k nearest in time among the kq - 1 inner candidates: the k-th fixes tau.
                # (their time distances, computed for the kept photons only)
                for a in range(kq - 1):
                    bx[a] = abs(np.float64(C[3, bi[a]]) - q3)
                # bx holds their time distances (from the search; bx, bd, bi keep their order);
                # the sum below then takes every candidate nearer in time than tau, plus as many
                # at exactly tau as make k - 1.
                tau, n_less = _kth_smallest_count(bx, kq - 1, k - 1, hist, bucket, sub)
                ties = k - 1 - n_less
                res[ii, 4] = tau
            inv_r = 1.0 / (cone_k * max(r, 1e-300))
            n0, n1, n2 = nn[ii, 0], nn[ii, 1], nn[ii, 2]
            m0, m1, m2 = np.float64(nn[ii, 3]), np.float64(nn[ii, 4]), np.float64(nn[ii, 5])
            # (no slab for a zero normal or two open sides: the test skipped, not only passed)
            slab = (m0 != 0.0 or m1 != 0.0 or m2 != 0.0) and (plane_b < np.inf or plane_f < np.inf)
            r2 = bd[kq - 1] if full else cap2     # the tangent slab's reach (_in_slab): r^2, KD4D's R^2
            ball4 = mode == MODE_KD4D
            p0 = 0.0
            p1 = 0.0
            p2 = 0.0
            # the boundary correction's photons (_edge_scale): collected by the sum loop below
            eslab = edge and slab and not ball4
            elim = EDGE_FRONT * np.sqrt(r2)
            n_e = 0
            front = False
            if ties > 0:
                # some of the k - 1 at exactly tau: the first ``ties`` of them in buffer order
                for a in range(n_sel):
                    wk[a] = 0.0
                    if bx[a] > tau:
                        continue
                    if bx[a] == tau:
                        if ties <= 0:
                            continue
                        ties -= 1
                    j = bi[a]
                    if P[j, 0] * n0 + P[j, 1] * n1 + P[j, 2] * n2 > 0.0 and (not slab or (_in_slab(
                            C, j, q0, q1, q2, q3, m0, m1, m2, r2, ball4, s, plane_b, plane_f)
                            and _facing(P, C, j, q0, q1, q2, m0, m1, m2))):
                        w = 1.0
                        if cone:
                            w = 1.0 - np.sqrt(bd[a]) * inv_r
                        wk[a] = w
                        p0 += w * P[j, 4]
                        p1 += w * P[j, 5]
                        p2 += w * P[j, 6]
            else:
                # branch-free: a photon out of the window, on the far side or off the tangent slab
                # adds w = 0 (exactly nothing; kept photons add what they did with branches)
                for a in range(n_sel):
                    j = bi[a]
                    w = 1.0
                    if mode == MODE_TEMPORAL:
                        w = 1.0 if bx[a] < tau else 0.0
                    if not (P[j, 0] * n0 + P[j, 1] * n1 + P[j, 2] * n2 > 0.0):
                        w = 0.0
                    if slab:
                        if not (_in_slab(C, j, q0, q1, q2, q3, m0, m1, m2, r2, ball4, s, plane_b, plane_f)
                                and _facing(P, C, j, q0, q1, q2, m0, m1, m2)):
                            w = 0.0
                        elif eslab:
                            v0 = np.float64(C[0, j]) - q0
                            v1 = np.float64(C[1, j]) - q1
                            v2 = np.float64(C[2, j]) - q2
                            h = v0 * m0 + v1 * m1 + v2 * m2
                            front = front or h > elim
                            ex[n_e] = v0 - h * m0
                            ey[n_e] = v1 - h * m1
                            ez[n_e] = v2 - h * m2
                            n_e += 1
                    if cone:
                        w *= 1.0 - np.sqrt(bd[a]) * inv_r
                    wk[a] = w
                    p0 += w * P[j, 4]
                    p1 += w * P[j, 5]
                    p2 += w * P[j, 6]
            f = 1.0
            if eslab:
                if ties > 0:
                    n_e, front = _edge_collect(P, C, bi, n_sel, q0, q1, q2, q3, m0, m1, m2, r2, s, plane_b,
                                               plane_f, ex, ey, ez)
                f = _edge_scale(ex, ey, ez, n_e, front, m0, m1, m2, r2, 1.0 / cone_k if cone else 0.0)
            res[ii, 0] = p0 * f
            res[ii, 1] = p1 * f
            res[ii, 2] = p2 * f
            if glossy:
                g0, g1, g2 = _glossy_sum(P, bi, wk, n_sel, gC, i, E, E_avg, gW, coat_w)
                out_g[i, 0], out_g[i, 1], out_g[i, 2] = g0 * f, g1 * f, g2 * f
        for ii in range(m):
            i = order[ii]
            out_phi[i, 0] = res[ii, 0]
            out_phi[i, 1] = res[ii, 1]
            out_phi[i, 2] = res[ii, 2]
            out_r[i] = res[ii, 3]
            out_tau[i] = res[ii, 4]

    @_jit
    def _knn_radius(C, box, n_leaves, q, D, s, kq, cap2, out_r):
        """Distance (n,) to the kq-th nearest photon of each query q (n, 4), at most sqrt(cap2).

        The search is bounded by cap2 (squared, m^2): where fewer than kq photons lie nearer, the
        answer is the cap, found without visiting anything beyond it.  Warm-started from the
        previous radius: the previous query's kq nearest lie within r_prev + |q - q_prev|.
        """
        nbuf = 2 * kq + LEAF_SIZE + 1
        bd = np.empty(nbuf)
        bi = np.empty(nbuf, np.int64)
        bx = np.empty(nbuf)
        sub = np.empty(nbuf)
        ti = np.empty(nbuf, np.int64)
        bucket = np.empty(nbuf, np.int64)
        hist = np.empty(kq, np.int64)
        leaf_d2 = np.empty(LEAF_SIZE + 1)
        qq = np.empty(4)
        qnode = np.empty(box.shape[0], np.int64)
        qdist = np.empty(box.shape[0])
        r_prev = np.inf
        for i in range(q.shape[0]):
            qq[0], qq[1], qq[2], qq[3] = q[i, 0], q[i, 1], q[i, 2], q[i, 3]
            bound0 = cap2
            if i > 0 and r_prev < np.inf:
                e0, e1, e2, e3 = qq[0] - q[i - 1, 0], qq[1] - q[i - 1, 1], qq[2] - q[i - 1, 2], qq[3] - q[i - 1, 3]
                dp = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2 + (e3 * e3 if D == 4 else 0.0))
                bound0 = min(cap2, ((r_prev + dp) * (1.0 + 1e-9)) ** 2)
            found = _knn(C, box, n_leaves, qq, D, s, kq, bd, bi, bx, qnode, qdist, bound0, hist, bucket, sub, ti,
                         leaf_d2) == kq
            if not found and bound0 < cap2:
                found = _knn(C, box, n_leaves, qq, D, s, kq, bd, bi, bx, qnode, qdist, cap2, hist, bucket, sub, ti,
                             leaf_d2) == kq
            if found:
                r = np.sqrt(bd[kq - 1])
                out_r[i] = r
                r_prev = r
            else:
                out_r[i] = np.sqrt(cap2)
                r_prev = np.inf

    @_jit
    def _range(P, C, box, n_leaves, q, ns, ng, plane_b, plane_f, rad, half, D, cyl, s, cone, cone_k, stack, out_phi,
               out_cnt, glossy, gC, gW, E, E_avg, coat_w, out_g):
        """Fixed-size kernels: photons inside each query's own region, summed (the progressive estimate).

        P (N, 8) float32 rows (wi, delta_only, Phi, n_code: _facing) and C (4, N) float32 coordinate rows, both in tree order.

        q (n, 4): x, y, z and s t (D = 4; ignored for D = 3); ns (n, 3) float32 normals; rad (n,)
        radius (m); half (n,) the cylinder's half-height in s t units (cyl only).  The region of
        query i is, in (x, y, z, s t):

        * D = 3: the ball |x - x_i| < rad_i (time ignored);
        * D = 4, cyl False: the 4D ball |x - x_i|^2 + (s t - s t_i)^2 < rad_i^2;
        * D = 4, cyl True: the cylinder |x - x_i| < rad_i and |s t - s t_i| <= half_i.

        Writes out_phi (n, 3) W: sum of w Phi over the photons inside on the ns side and in the
        tangent slab -plane_b rho <= (x_p - x_i) . ng_i <= plane_f rho (rho = rad_i, or the 4D ball's
        section at the photon's time; ng (n, 3) float32 unit geometric normals on the query's side;
        inf: no bound; :func:`_in_slab`, as :func:`_lookup`'s) (w = 1, or the cone 1 - d / (cone_k rad) of the
        spatial distance d for D = 3 / cyl and of the 4D one for the ball), out_cnt (n,) how many
        photons were inside (either side, in the slab or not).  stack: int64 scratch of at
        least the tree depth + 2.  Depth-first: a node is entered only if its box reaches the region.
        glossy: also out_g (n, 3) W/sr, the sum of w f_c(wo, wi) Phi over the same photons whose path
        was delta-only (P[j, 3] > 0), f_c query i's rough lobes but DIFFUSE (gC (n, N_CLOSURE) its
        closure row, gW (n, 9) its (wo, ns, ng), E, E_avg the GGX tables, coat_w the coat's weight:
        ``kernels.bsdf._glossy_add``, as :func:`_glossy_sum` of the k-nearest search).
        """
        N = P.shape[0]
        first_leaf = n_leaves - 1
        for i in range(q.shape[0]):
            q0, q1, q2, q3 = q[i, 0], q[i, 1], q[i, 2], q[i, 3]
            r2 = rad[i] * rad[i]
            h = half[i]
            inv_r = 1.0 / (cone_k * max(rad[i], 1e-300))
            n0, n1, n2 = ns[i, 0], ns[i, 1], ns[i, 2]
            m0, m1, m2 = np.float64(ng[i, 0]), np.float64(ng[i, 1]), np.float64(ng[i, 2])
            # (no slab for a zero normal or two open sides: the test skipped, not only passed)
            slab = (m0 != 0.0 or m1 != 0.0 or m2 != 0.0) and (plane_b < np.inf or plane_f < np.inf)
            ball4 = D == 4 and not cyl            # the tangent slab's reach (_in_slab): the 4D ball's section
            p0 = 0.0
            p1 = 0.0
            p2 = 0.0
            g0 = 0.0
            g1 = 0.0
            g2 = 0.0
            if glossy:
                # the query's rough lobes, set up once (kernels.bsdf._hit)
                wo = (gW[i, 0], gW[i, 1], gW[i, 2])
                hit = _bsdf_hit(gC, i, E, E_avg, wo, (gW[i, 3], gW[i, 4], gW[i, 5]), (gW[i, 6], gW[i, 7], gW[i, 8]))
            cnt = 0
            top = 0
            stack[0] = 0
            top = 1
            while top > 0:
                top -= 1
                node = stack[top]
                # -- does the node's box reach the region? ---------------------------------------
                row = node + 1
                if D == 4 and cyl:
                    if _box_dist2(box, row, q0, q1, q2, q3, 3) >= r2:
                        continue
                    lo3 = np.float64(box[row, 3])
                    hi3 = np.float64(box[row, 7])
                    if q3 < lo3 - h or q3 > hi3 + h:
                        continue
                elif _box_dist2(box, row, q0, q1, q2, q3, D) >= r2:
                    continue
                if node < first_leaf:
                    stack[top] = 2 * node + 1
                    stack[top + 1] = 2 * node + 2
                    top += 2
                    continue
                # -- scan the leaf's contiguous rows ------------------------------------------------
                leaf = node - first_leaf
                for j in range((leaf * N) // n_leaves, ((leaf + 1) * N) // n_leaves):
                    e0 = np.float64(C[0, j]) - q0
                    e1 = np.float64(C[1, j]) - q1
                    e2 = np.float64(C[2, j]) - q2
                    d2 = e0 * e0 + e1 * e1 + e2 * e2
                    if D == 4:
                        e3 = s * np.float64(C[3, j]) - q3
                        if cyl:
                            if abs(e3) > h:
                                continue
                        else:
                            d2 += e3 * e3
                    if d2 >= r2:
                        continue
                    cnt += 1
                    if P[j, 0] * n0 + P[j, 1] * n1 + P[j, 2] * n2 > 0.0 and (not slab or (_in_slab(
                            C, j, q0, q1, q2, q3, m0, m1, m2, r2, ball4, s, plane_b, plane_f)
                            and _facing(P, C, j, q0, q1, q2, m0, m1, m2))):
                        w = 1.0
                        if cone:
                            w = 1.0 - np.sqrt(d2) * inv_r
                        p0 += w * P[j, 4]
                        p1 += w * P[j, 5]
                        p2 += w * P[j, 6]
                        if glossy and P[j, 3] > 0.0:
                            wi = (np.float64(P[j, 0]), np.float64(P[j, 1]), np.float64(P[j, 2]))
                            f0, f1, f2, _ = _bsdf_glossy_add(gC, i, E, hit, wo, wi, 0.0, 0.0, 0.0, 0.0, coat_w)
                            g0 += w * f0 * P[j, 4]
                            g1 += w * f1 * P[j, 5]
                            g2 += w * f2 * P[j, 6]
            out_phi[i, 0] = p0
            out_phi[i, 1] = p1
            out_phi[i, 2] = p2
            out_cnt[i] = cnt
            if glossy:
                out_g[i, 0] = g0
                out_g[i, 1] = g1
                out_g[i, 2] = g2

    @_jit
    def _radix_order(code, bits):
        """The stable sort order (m,) int64 of code (m,) int64 (values below 2^bits): a least-significant-digit
        radix sort, 10 bits a pass (numpy's stable argsort is a merge sort: 4x slower at 20k codes)."""
        m = code.shape[0]
        idx = np.arange(m)
        tmp = np.empty(m, np.int64)
        cnt = np.empty(1025, np.int64)
        for shift in range(0, bits, 10):
            cnt[:] = 0
            for ii in range(m):
                cnt[((code[idx[ii]] >> shift) & 1023) + 1] += 1
            for b in range(1024):
                cnt[b + 1] += cnt[b]
            for ii in range(m):
                i = idx[ii]
                d = (code[i] >> shift) & 1023
                tmp[cnt[d]] = i
                cnt[d] += 1
            idx, tmp = tmp, idx
        return idx

    @_jit
    def _morton_codes(q, rows, D):
        """Morton codes (m,) int64 of the rows ``rows`` (m,) int64 of q (n, 4) float64: their first D columns
        each quantised to 2^10 cells over the rows' bounding box.  One compiled pass: numpy's reductions
        over an (m, 4) array cost more than the codes at a look-up batch's few hundred rows."""
        m = rows.shape[0]
        lo = np.full(4, np.inf)
        hi = np.full(4, -np.inf)
        for ii in range(m):
            i = rows[ii]
            for a in range(D):
                lo[a] = min(lo[a], q[i, a])
                hi[a] = max(hi[a], q[i, a])
        scale = np.empty(4)
        for a in range(D):
            scale[a] = 1024.0 / max(hi[a] - lo[a], 1e-30)
        code = np.zeros(m, np.int64)
        for ii in range(m):
            i = rows[ii]
            c = 0
            for a in range(D):
                v = int((q[i, a] - lo[a]) * scale[a])
                v = min(max(v, 0), 1023)
                c |= _SPREAD[D - 3, v] << a        # bit b of axis a to bit D b + a
            code[ii] = c
        return code


_NO_C = np.zeros((0, 1))          # no glossy sums: empty closure rows / hit rows, GGX tables
_NO_E = np.zeros((1, 1, 1))
_NO_EA = np.zeros(1)
_NO_E.setflags(write=False)          # read-only as the GGX tables (kernels.bsdf): one compiled signature
_NO_EA.setflags(write=False)


def morton_order(q: np.ndarray, D: int, rows: np.ndarray | None = None) -> np.ndarray:
    """Rows (m,) int64 of q (n, 4) float64 -- all of them, or those in ``rows`` -- sorted by the Morton
    code of their first D columns (2^10 cells per axis over their bounding box; stable among equal
    codes; :func:`_morton_codes`, then numpy's stable sort, or above ``_RADIX_MIN`` rows :func:`_radix_order`)."""
    rows = np.arange(q.shape[0], dtype=np.int64) if rows is None else np.ascontiguousarray(rows, dtype=np.int64)
    code = _morton_codes(q, rows, D)
    return rows[_radix_order(code, 10 * D) if code.shape[0] >= _RADIX_MIN else np.argsort(code, kind="stable")]


def _plane_c(plane) -> float:
    """The tangent slab's half-thickness as a fraction of the search radius (float64, > 0; inf: no slab)."""
    c = float(plane)
    if not c > 0.0:
        raise ValueError(f"tangent slab fraction must be > 0 (inf: no slab), got {plane!r}")
    return c


class FlatTree:
    """A compiled kd-tree over one map's photons, in 3D (x, y, z) or 4D (x, y, z, s t).

    Parameters
    ----------
    position : (N, 3) float32 positions (m); time : (N,) float32 shutter times;
    packed : (N, 8) float32 rows (wi, delta_only, Phi, n_code); dims : 3 or 4; s : KD4D's time scale (m per shutter).

    Attributes (tree order): xyzt (4, N) float32 coordinate rows; pts (N, 8) float32 rows (wi, delta_only, Phi, n_code),
    64-byte aligned; perm (N,) int64 tree row -> input row; box (2 L, 8) float32 node boxes.
    """

    def __init__(self, position: np.ndarray, time: np.ndarray, packed: np.ndarray, *, dims: int, s: float):
        N = int(position.shape[0])
        # coordinates (x, y, z, t), reordered by the build to tree order
        xyzt = np.empty((N, 4), dtype=np.float32)
        xyzt[:, :3] = position
        xyzt[:, 3] = time
        n_leaves = 1
        while n_leaves * LEAF_SIZE < N:
            n_leaves *= 2
        self.dims, self.s, self.n_leaves = int(dims), float(s), n_leaves
        # xyzt is reordered in place to tree order: every leaf is one contiguous block
        perm, box = _build(xyzt, self.dims, self.s, n_leaves)
        # 64-byte aligned copy, so a node's two children share one cache line
        raw = np.empty(box.size * 4 + 64, np.uint8)
        off = (-raw.ctypes.data) % 64
        self.box = raw[off:off + box.size * 4].view(np.float32).reshape(box.shape)
        self.box[:] = box
        self.perm = perm
        # per photon one 32-byte row (wi, delta_only, Phi, n_code) in tree order, 64-byte aligned (two rows a line):
        # what the sums read of the photons the search keeps
        raw = np.empty(N * 32 + 64, np.uint8)
        off = (-raw.ctypes.data) % 64
        self.pts = raw[off:off + N * 32].view(np.float32).reshape(N, 8)
        self.pts[:] = packed[perm]
        # the coordinates again as rows (4, N) float32 (x, y, z, t): a leaf's are 4 contiguous runs,
        # all the search's distance loop reads
        self.xyzt = np.ascontiguousarray(xyzt.T)

    def lookup(self, mode: int, q: np.ndarray, ns: np.ndarray, kq: int, k: int, cone: bool, cone_k: float,
               workers: int, glossy=None, cap: float = np.inf, *, ng: np.ndarray | None = None,
               plane: float = np.inf, plane_front: float | None = None, rows: np.ndarray | None = None,
               out: tuple | None = None, edge: bool = False):
        """Sums Phi (n, 3) W, radius r (n,) m of the kq-th neighbour and TEMPORAL's tau (n,) for queries q (n, 4).

        cap: the search's largest radius r_max (m, in the tree's dimensions; inf: unbounded).  A query
        with fewer than kq photons strictly within r_max gets the sum over all of them, r = r_max
        (exactly: the caller tells capped queries by ``r >= cap``) and tau = inf (:func:`_lookup`).

        ng (n, 3) unit geometric normals on the side the query is seen from (None: ns), plane and
        plane_front (None: plane): the tangent slab, a photon counts only if -plane r <= (x_p - x_q) . ng
        <= plane_front r (:func:`_lookup`; inf, the default: no bound).

        glossy: None, or (gC (n, N_CLOSURE) float64 closure rows, gW (n, 9) float64 (wo, ns, ng) of
        each query's hit, E, E_avg the GGX tables, coat_w): then a fourth result, the sums (n, 3) of
        w f_c(wo, wi) Phi over the same photons with a delta-only path (:func:`_lookup`).

        edge: divide each estimate with the slab on (not KD4D) by the fraction of its disc its surface
        covers where its photons show a straight edge (:func:`_edge_scale`; docs/photon-mapping.md,
        "Boundary correction at a convex edge"); False: every estimate as without it, bit for bit.

        rows (m,) int64: answer only these rows of q (and of ns, ng, glossy's), e.g. one time slice's
        queries, without gathering them into new arrays; out: (phi, r, tau[, g]) float64 arrays of n
        rows to write the answers into (their other rows are left as they are), returned as the
        results.  Default: every row, into new arrays.

        Queries are processed in Morton order (of x, y, z, plus s t for KD4D: :func:`morton_order`),
        so consecutive queries are neighbours: the tree nodes they read stay in cache and each
        search starts from the previous one's radius.  The kernel reads and writes the rows in
        place through that order (no sorted copies of the queries, no permuted copies of the results).
        Requires 1 <= kq <= N (and for TEMPORAL 2 <= k < kq): the search reads kq photons.
        """
        N = self.pts.shape[0]
        if not 1 <= kq <= N or (mode == MODE_TEMPORAL and not 2 <= k < kq):
            raise ValueError(f"k-nearest look-up of kq = {kq}, k = {k} in a tree of {N} photons")
        if not cap > 0.0:
            raise ValueError(f"k-nearest look-up capped at r_max = {cap} (must be > 0, or inf)")
        cap2 = float(cap) * float(cap) if np.isfinite(cap) else np.inf
        n = q.shape[0]
        q = np.ascontiguousarray(q, dtype=np.float64)
        ns = np.ascontiguousarray(ns, dtype=np.float32)
        ng = ns if ng is None else np.ascontiguousarray(np.asarray(ng, np.float32).reshape(-1, 3))
        D = 4 if mode == MODE_KD4D else 3
        order = morton_order(q, D, rows)
        plane_b, plane_f = _plane_c(plane), _plane_c(plane if plane_front is None else plane_front)
        if out is None:
            phi, r, tau = np.zeros((n, 3)), np.zeros(n), np.zeros(n)
            g = np.zeros((n if glossy is not None else 0, 3))
        else:
            phi, r, tau = out[:3]
            g = out[3] if glossy is not None else np.zeros((0, 3))
        if glossy is not None:
            gC = np.ascontiguousarray(glossy[0], np.float64)
            gW = np.ascontiguousarray(glossy[1], np.float64)
            E_t, E_avg, coat_w = glossy[2], glossy[3], float(glossy[4])
        else:
            gC, gW, E_t, E_avg, coat_w = _NO_C, _NO_C, _NO_E, _NO_EA, 0.0

        def part(a, b):
            _lookup(self.pts, self.xyzt, self.box, self.n_leaves, q, ns, ng, order[a:b], plane_b, plane_f, mode,
                    kq, k, self.s, cone, cone_k, cap2, phi, r, tau, glossy is not None, gC, gW, E_t, E_avg, coat_w,
                    g, bool(edge))

        run_chunks(part, order.shape[0], workers)
        return (phi, r, tau) if glossy is None else (phi, r, tau, g)

    def knn_radius(self, q: np.ndarray, kq: int, cap: float, workers: int) -> np.ndarray:
        """Distance (n,) m to the kq-th nearest photon of each query q (n, 4) (x, y, z, s t), capped at ``cap``.

        In the tree's own dimensions (3D: x, y, z; 4D: with s t).  Where fewer than kq photons lie
        within ``cap``, the cap is returned; the search never looks beyond it.  Requires 1 <= kq <= N.
        """
        if not 1 <= kq <= self.pts.shape[0]:
            raise ValueError(f"k-NN radius of kq = {kq} in a tree of {self.pts.shape[0]} photons")
        n = q.shape[0]
        q = np.ascontiguousarray(q, dtype=np.float64)
        D = self.dims
        out = np.empty(n)
        if n == 0:
            return out
        order = morton_order(q, D)
        qs = q[order]
        r = np.empty(n)
        cap2 = float(cap) ** 2 if np.isfinite(cap) else np.inf

        def part(a, b):
            _knn_radius(self.xyzt, self.box, self.n_leaves, qs[a:b], D, self.s, int(kq), cap2, r[a:b])

        run_chunks(part, n, workers)
        out[order] = r
        return out

    def range_sum(self, q: np.ndarray, ns: np.ndarray, rad: np.ndarray, half: np.ndarray | None, cone: bool,
                  cone_k: float, workers: int, glossy=None, *, ng: np.ndarray | None = None, plane: float = np.inf,
                  plane_front: float | None = None):
        """Sums Phi (n, 3) W and counts (n,) of the photons inside fixed regions (:func:`_range`).

        ng (n, 3) unit geometric normals (None: ns), plane and plane_front: the tangent slab
        -plane rad <= (x_p - x_q) . ng <= plane_front rad (inf, the default: no bound), as :meth:`lookup`'s.

        glossy: None, or (gC, gW, E, E_avg, coat_w) as :meth:`lookup`'s: then a third result, the sums
        (n, 3) of w f_c(wo, wi) Phi over the same photons with a delta-only path.

        q (n, 4): x, y, z and s t (the tree's own s; column 3 ignored by a 3D tree); rad (n,) m;
        half (n,) the cylinder's half-height in s t units, or None for balls (3D: time ignored,
        4D: balls in (x, y, z, s t)).  Queries run in the order given (each region's sum is its own).
        """
        n = q.shape[0]
        q = np.ascontiguousarray(q, dtype=np.float64)
        ns = np.ascontiguousarray(ns, dtype=np.float32)
        ng = ns if ng is None else np.ascontiguousarray(np.asarray(ng, np.float32).reshape(-1, 3))
        plane_b, plane_f = _plane_c(plane), _plane_c(plane if plane_front is None else plane_front)
        rad = np.ascontiguousarray(rad, dtype=np.float64)
        cyl = half is not None and self.dims == 4
        half = np.zeros(n) if half is None else np.ascontiguousarray(half, dtype=np.float64)
        D = self.dims
        # (no Morton sort: a fixed region's sum does not depend on the query before it, and the
        # sort and its permutations cost more than the locality gained: 0.8 ms of 4 ms a call of
        # a progressive pass's 4k queries, which come in tile order)
        phi = np.zeros((n, 3))
        cnt = np.zeros(n, np.int64)
        depth = int(np.log2(max(self.n_leaves, 1))) + 4
        g = np.zeros((n if glossy is not None else 0, 3))
        if glossy is not None:
            gC = np.ascontiguousarray(glossy[0], np.float64)
            gW = np.ascontiguousarray(glossy[1], np.float64)
            E_t, E_avg, coat_w = glossy[2], glossy[3], float(glossy[4])
        else:
            gC, gW, E_t, E_avg, coat_w = _NO_C, _NO_C, _NO_E, _NO_EA, 0.0

        def part(a, b):
            ga, gb = (a, b) if glossy is not None else (0, 0)
            _range(self.pts, self.xyzt, self.box, self.n_leaves, q[a:b], ns[a:b], ng[a:b], plane_b, plane_f, rad[a:b],
                   half[a:b], D, cyl, self.s,
                   cone, cone_k, np.empty(2 * depth, np.int64), phi[a:b], cnt[a:b], glossy is not None, gC[ga:gb],
                   gW[ga:gb], E_t, E_avg, coat_w, g[ga:gb])

        run_chunks(part, n, workers)
        return (phi, cnt) if glossy is None else (phi, cnt, g)
