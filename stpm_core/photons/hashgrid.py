"""A uniform hash grid over one pass's photons: the progressive kernel's fixed-region look-ups.

A progressive pass knows each query's region before it looks (radius r, and for
TEMPORAL the cylinder's half-height in s t; :class:`.progressive.ProgressiveMaps`),
so the look-up is a fixed-radius range query, not a k-nearest search.  Here it
runs on a grid of cubes of side ``h`` instead of the kd-tree (``FlatTree.range_sum``):

    grid = HashGrid(position, time, packed, s=s, h=h)       # counting the photons into cells
    Phi, cnt = grid.range_sum(q, ns, rad, half, cone, cone_k, workers)   # same call as the tree's

Layout (records in cache order):

* cell (i, j, k) = floor((x - lo) / h) per axis, one int64 key ``(i << 42) | (j << 21) | k``;
* photons sorted by (cell key, time): one cell's photons are one contiguous block of the
  (N, 12) float32 rows the kd-tree uses, ``(x, y, z, t, wi, 0, Phi, 0)``, in increasing time;
* occupied cells only, in an open-addressing table of ``2^ceil(log2(2 C))`` slots for C occupied
  cells (at most 2 N: memory is bounded by the photons, never by the scene's extent over h):
  slot -> (key, first row, end row); a missing cell is an empty slot.

Query (:func:`_range_grid`): the cells overlapping the region's bounding box, each probed in the
table (or, when the box holds more cells than the table has occupied ones, the occupied cells
scanned instead); in a cell, the rows whose time cannot reach the region are skipped by binary
search (a conservative bound), and every other photon gets *exactly the kd-tree's test and sum*
(``kdtree._range``): the same float64 distances from the float32 records, the same ``<`` / ``<=``,
the same side test and cone weight.  So each query sees the same photon set as the tree's range
query, and the sums differ from the tree's only by the order of the float64 additions
(tests/test_hashgrid.py: counts equal, sums to 1e-12 relative, on random and adversarial inputs).

Cell size: ``h`` about the typical query radius (the median radius of the first look-up batch;
:func:`cell_size`): a ball of radius r <= h touches at most 2^3 cells.  Larger regions (the pilot
caps dark queries at a few typical radii) touch more; the scan of occupied cells bounds their cost.

Measured (2026-12-06, ``benchmarks/bench_lookups.py`` and the pass maps it records): *not faster
than the kd-tree* on the progressive presets' passes, so ``progressive.RANGE_LOOKUP`` stays
'kdtree'.  A pass region holds about k = 20 photons, and the radii span an order of magnitude
across an image (a bright caustic next to dark floor): with h the median, the tree and the grid
answer in about the same time (grid / tree 0.72-1.3 per map), the build (a sort of (cell, time))
costs 1-1.4x the tree's, and a uniform h is fragile: h = the 10th or 75th percentile of the radii
made one map's queries 1.5-2.8x slower and another's 0.7x.  The kd-tree adapts to both.

:class:`CellTable` is the same open-addressing table holding values per cell key: the pilot's
regions per grid cell (:meth:`.progressive.Pilot.initial_size`), bounded to a number of cells.
"""
from __future__ import annotations

import numpy as np

from . import kdtree as _kdtree

__all__ = ["AVAILABLE", "HashGrid", "CellTable", "cell_size", "AXIS_BITS"]

AXIS_BITS = 21                   # cells per axis: at most 2^21 (3 x 21 bits in one int64 key)
_AXIS_MAX = (1 << AXIS_BITS) - 1
CELL_FACTOR = 1.0                # h = CELL_FACTOR x the CELL_QUANTILE-th percentile of the query radii
CELL_QUANTILE = 50.0

AVAILABLE = _kdtree.AVAILABLE
if AVAILABLE:
    import numba as _nb


def cell_size(radii: np.ndarray, extent: float) -> float:
    """h (m): CELL_FACTOR x the median finite positive radius, never finer than extent / 2^20
    (cell indices fit their 21 bits) nor 0."""
    r = np.asarray(radii, dtype=np.float64)
    r = r[np.isfinite(r) & (r > 0)]
    h = CELL_FACTOR * float(np.percentile(r, CELL_QUANTILE)) if r.size else 0.0
    floor = max(float(extent), 1e-6) / float(1 << 20)
    return max(h, floor) if np.isfinite(h) else floor


if AVAILABLE:
    _jit = _nb.njit(cache=True, nogil=True, fastmath=False, boundscheck=False)

    @_jit
    def _hash(key, mask):
        """Slot of a cell key in a table of mask + 1 slots (multiplicative hash, xor-folded)."""
        x = np.uint64(key) * np.uint64(0x9E3779B97F4A7C15)
        x ^= x >> np.uint64(29)
        return np.int64(x & np.uint64(mask))

    @_jit
    def _fill_table(ukeys, starts, ends, tkey, tlo, thi):
        """Insert occupied cells (ukeys (C,), rows [starts, ends)) into the empty table (tkey = -1)."""
        mask = tkey.shape[0] - 1
        for c in range(ukeys.shape[0]):
            slot = _hash(ukeys[c], mask)
            while tkey[slot] != -1:
                slot = (slot + 1) & mask
            tkey[slot] = ukeys[c]
            tlo[slot] = starts[c]
            thi[slot] = ends[c]

    @_jit
    def _find(key, tkey, mask):
        """Table slot of key, or -1 if the cell holds no photon."""
        slot = _hash(key, mask)
        while True:
            k = tkey[slot]
            if k == key:
                return slot
            if k == -1:
                return -1
            slot = (slot + 1) & mask

    @_jit
    def _axis_range(v, r, lo, h, top):
        """Cells [a, b] of one axis that a region [v - r, v + r] reaches (b < a: none), clamped to [0, top]."""
        fa = np.floor((v - r - lo) / h)
        fb = np.floor((v + r - lo) / h)
        if not (fb >= 0.0) or not (fa <= top):          # (also NaN)
            return 1, 0
        a = 0 if fa < 0.0 else np.int64(fa)
        b = top if fb > top else np.int64(fb)
        return a, b

    @_jit
    def _scan_cell(P, st, a, b, q0, q1, q2, q3, r2, h, t_lo, t_hi, D, cyl, s, cone, inv_r, n0, n1, n2, acc):
        """Rows [a, b) of one cell (sorted by time st = s t): the kd-tree's exact test and sums into acc
        (p0, p1, p2, count).  Rows with st < t_lo are skipped by binary search, rows with st > t_hi end
        the scan (t_lo, t_hi a conservative bound of the region's time span; -inf, inf for D = 3)."""
        if D == 4:
            lo_, hi_ = a, b
            while lo_ < hi_:
                mid = (lo_ + hi_) >> 1
                if st[mid] < t_lo:
                    lo_ = mid + 1
                else:
                    hi_ = mid
            a = lo_
        for j in range(a, b):
            e0 = np.float64(P[j, 0]) - q0
            e1 = np.float64(P[j, 1]) - q1
            e2 = np.float64(P[j, 2]) - q2
            d2 = e0 * e0 + e1 * e1 + e2 * e2
            if D == 4:
                if st[j] > t_hi:
                    break
                e3 = s * np.float64(P[j, 3]) - q3
                if cyl:
                    if abs(e3) > h:
                        continue
                else:
                    d2 += e3 * e3
            if d2 >= r2:
                continue
            acc[3] += 1.0
            if P[j, 4] * n0 + P[j, 5] * n1 + P[j, 6] * n2 > 0.0:
                w = 1.0
                if cone:
                    w = 1.0 - np.sqrt(d2) * inv_r
                acc[0] += w * P[j, 8]
                acc[1] += w * P[j, 9]
                acc[2] += w * P[j, 10]

    @_jit
    def _range_grid(P, st, lo, h, top, tkey, tlo, thi, ukeys, starts, ends, q, ns, rad, half, D, cyl, s, cone,
                    cone_k, acc, out_phi, out_cnt):
        """Fixed regions on the grid: the same regions, tests and outputs as ``kdtree._range``.

        P (N, 12) float32 rows in (cell, time) order, st (N,) float64 s t of each row; lo (3,) the
        grid's corner, h its cell side, top (3,) int64 the last occupied cell index per axis; the
        table (tkey, tlo, thi) and the occupied cells (ukeys, starts, ends) from :class:`HashGrid`.
        Queries q (n, 4), ns (n, 3) float32, rad (n,), half (n,) as for the tree; acc: float64 (4,)
        scratch.  Writes out_phi (n, 3) and out_cnt (n,).
        """
        mask = tkey.shape[0] - 1
        n_cells = ukeys.shape[0]
        for i in range(q.shape[0]):
            q0, q1, q2, q3 = q[i, 0], q[i, 1], q[i, 2], q[i, 3]
            r = rad[i]
            r2 = r * r
            hh = half[i]
            inv_r = 1.0 / (cone_k * max(r, 1e-300))
            n0, n1, n2 = ns[i, 0], ns[i, 1], ns[i, 2]
            acc[0] = 0.0
            acc[1] = 0.0
            acc[2] = 0.0
            acc[3] = 0.0
            # -- the region's time span in s t, widened so that rounding never drops a photon -------
            t_lo, t_hi = -np.inf, np.inf
            if D == 4:
                span = hh if cyl else r
                pad = 1e-9 * (abs(q3) + span) + 1e-300
                t_lo = q3 - span - pad
                t_hi = q3 + span + pad
            # -- cells of the region's bounding box ------------------------------------------------
            ax, bx = _axis_range(q0, r, lo[0], h, top[0])
            ay, by = _axis_range(q1, r, lo[1], h, top[1])
            az, bz = _axis_range(q2, r, lo[2], h, top[2])
            if bx >= ax and by >= ay and bz >= az:
                # (in float64: a huge region's box holds up to 2^63 cells)
                n_box = np.float64(bx - ax + 1) * np.float64(by - ay + 1) * np.float64(bz - az + 1)
                if n_box <= n_cells:
                    for cx in range(ax, bx + 1):
                        for cy in range(ay, by + 1):
                            base = (cx << 42) | (cy << 21)
                            for cz in range(az, bz + 1):
                                slot = _find(base | cz, tkey, mask)
                                if slot >= 0:
                                    _scan_cell(P, st, tlo[slot], thi[slot], q0, q1, q2, q3, r2, hh, t_lo, t_hi,
                                               D, cyl, s, cone, inv_r, n0, n1, n2, acc)
                else:
                    # a region wider than the occupied cells: scan those whose index lies in the box
                    for c in range(n_cells):
                        key = ukeys[c]
                        cx = key >> 42
                        cy = (key >> 21) & 2097151
                        cz = key & 2097151
                        if ax <= cx <= bx and ay <= cy <= by and az <= cz <= bz:
                            _scan_cell(P, st, starts[c], ends[c], q0, q1, q2, q3, r2, hh, t_lo, t_hi,
                                       D, cyl, s, cone, inv_r, n0, n1, n2, acc)
            out_phi[i, 0] = acc[0]
            out_phi[i, 1] = acc[1]
            out_phi[i, 2] = acc[2]
            out_cnt[i] = np.int64(acc[3])


class HashGrid:
    """One map's photons counted into a hash grid of cubes of side h (m), for fixed-region look-ups.

    Parameters
    ----------
    position : (N, 3) float32 positions (m, relative to the map origin); time : (N,) float32 shutter
    times; packed : (N, 8) float32 rows (wi, 0, Phi, 0); s : the time scale (m per shutter) of the
    4D regions; h : cell side (m), e.g. :func:`cell_size` of the queries' radii.

    Attributes: ``h``, ``cells`` (occupied), ``slots`` (table size), ``nbytes`` (memory held).
    """

    def __init__(self, position: np.ndarray, time: np.ndarray, packed: np.ndarray, *, s: float, h: float):
        N = int(position.shape[0])
        pos = np.asarray(position, dtype=np.float32).reshape(-1, 3)
        tt = np.asarray(time, dtype=np.float32).reshape(-1)
        self.s = float(s)
        self.lo = pos.astype(np.float64).min(axis=0) if N else np.zeros(3)
        extent = float((pos.astype(np.float64).max(axis=0) - self.lo).max()) if N else 0.0
        # h no finer than extent / 2^20: every photon's cell index fits its 21 bits
        self.h = max(float(h), max(extent, 1e-6) / float(1 << 20)) if np.isfinite(h) else max(extent, 1.0)
        # -- cell of every photon, photons sorted by (cell, time) ----------------------------------
        cell = np.clip(np.floor((pos.astype(np.float64) - self.lo) / self.h), 0, _AXIS_MAX).astype(np.int64)
        key = (cell[:, 0] << 42) | (cell[:, 1] << 21) | cell[:, 2]
        st = self.s * tt.astype(np.float64)                 # the tree's s t: the same float64 product
        order = np.lexsort((st, key))
        key = key[order]
        self.st = np.ascontiguousarray(st[order])
        self.top = cell.max(axis=0) if N else np.full(3, -1, np.int64)
        self.P = np.empty((N, 12), dtype=np.float32)
        self.P[:, :3] = pos[order]
        self.P[:, 3] = tt[order]
        self.P[:, 4:12] = np.asarray(packed, dtype=np.float32)[order]
        # -- occupied cells and their table -----------------------------------------------------------
        if N:
            first = np.flatnonzero(np.concatenate(([True], key[1:] != key[:-1])))
            self.ukeys = np.ascontiguousarray(key[first])
            self.starts = first.astype(np.int64)
            self.ends = np.append(first[1:], N).astype(np.int64)
        else:
            self.ukeys = self.starts = self.ends = np.zeros(0, np.int64)
        slots = 1
        while slots < 2 * max(self.ukeys.size, 1):
            slots *= 2
        self.tkey = np.full(slots, -1, np.int64)
        self.tlo = np.zeros(slots, np.int64)
        self.thi = np.zeros(slots, np.int64)
        _fill_table(self.ukeys, self.starts, self.ends, self.tkey, self.tlo, self.thi)

    @property
    def cells(self) -> int:
        return int(self.ukeys.size)

    @property
    def slots(self) -> int:
        return int(self.tkey.size)

    @property
    def nbytes(self) -> int:
        return int(self.P.nbytes + self.st.nbytes + 3 * self.tkey.nbytes + 3 * self.ukeys.nbytes)

    def range_sum(self, q: np.ndarray, ns: np.ndarray, rad: np.ndarray, half: np.ndarray | None, cone: bool,
                  cone_k: float, workers: int, *, dims: int = 4):
        """Sums Phi (n, 3) W and counts (n,) of the photons inside fixed regions: ``FlatTree.range_sum``'s
        call and answers (its ``dims`` here a keyword: 3 = balls in space, time ignored; 4 = balls in
        (x, y, z, s t), or cylinders when half (n,) is given).  Queries run in Morton order."""
        n = q.shape[0]
        q = np.ascontiguousarray(q, dtype=np.float64)
        ns = np.ascontiguousarray(ns, dtype=np.float32)
        rad = np.ascontiguousarray(rad, dtype=np.float64)
        D = int(dims)
        cyl = half is not None and D == 4
        half = np.zeros(n) if half is None else np.ascontiguousarray(half, dtype=np.float64)
        phi = np.zeros((n, 3))
        cnt = np.zeros(n, np.int64)
        if n == 0 or self.P.shape[0] == 0:
            return phi, cnt
        lo = q.min(axis=0)
        scale = 1024.0 / np.maximum(q.max(axis=0) - lo, 1e-30)
        order = np.argsort(_kdtree._morton(q, lo, scale, 3), kind="stable")
        qs, nss, rs, hs = q[order], ns[order], rad[order], half[order]

        def part(a, b):
            _range_grid(self.P, self.st, self.lo, self.h, self.top, self.tkey, self.tlo, self.thi, self.ukeys,
                        self.starts, self.ends, qs[a:b], nss[a:b], rs[a:b], hs[a:b], D, cyl, self.s, cone,
                        float(cone_k), np.zeros(4), phi[a:b], cnt[a:b])

        _kdtree.run_chunks(part, n, workers)
        out_phi, out_cnt = np.empty_like(phi), np.empty_like(cnt)
        out_phi[order], out_cnt[order] = phi, cnt
        return out_phi, out_cnt


# ---------------------------------------------------------------------------
# A bounded table of values per cell key (the pilot's regions per grid cell)
# ---------------------------------------------------------------------------
if AVAILABLE:
    @_jit
    def _table_get(keys, tkey, tr, ttau, out_have, out_r, out_tau):
        """For each key (n,) >= 0: out_have True and its values if the table holds it."""
        mask = tkey.shape[0] - 1
        for i in range(keys.shape[0]):
            slot = _find(keys[i], tkey, mask)
            if slot >= 0:
                out_have[i] = True
                out_r[i] = tr[slot]
                out_tau[i] = ttau[slot]
            else:
                out_have[i] = False

    @_jit
    def _table_put(keys, r, tau, tkey, tr, ttau, count, limit):
        """Insert keys (n,) not yet held, while the table holds fewer than limit; returns the new count."""
        mask = tkey.shape[0] - 1
        for i in range(keys.shape[0]):
            if count >= limit:
                break
            slot = _hash(keys[i], mask)
            while tkey[slot] != -1 and tkey[slot] != keys[i]:
                slot = (slot + 1) & mask
            if tkey[slot] == -1:
                tkey[slot] = keys[i]
                tr[slot] = r[i]
                ttau[slot] = tau[i]
                count += 1
        return count


class CellTable:
    """Values (r, tau) per non-negative int64 cell key, at most ``limit`` keys (then further keys are
    not kept): open addressing in 2^ceil(log2 2 limit) slots, looked up and filled in compiled loops
    (a sorted array merged per batch costs a copy of the table per batch)."""

    def __init__(self, limit: int):
        self.limit = int(limit)
        slots = 1
        while slots < 2 * max(self.limit, 1):
            slots *= 2
        self.tkey = np.full(slots, -1, np.int64)
        self.r = np.zeros(slots)
        self.tau = np.zeros(slots)
        self.count = 0

    def get(self, keys: np.ndarray):
        """(have (n,) bool, r (n,), tau (n,)) for keys (n,) int64 (r, tau undefined where not had)."""
        keys = np.ascontiguousarray(keys, dtype=np.int64)
        have = np.zeros(keys.size, np.bool_)
        r, tau = np.empty(keys.size), np.empty(keys.size)
        _table_get(keys, self.tkey, self.r, self.tau, have, r, tau)
        return have, r, tau

    def put(self, keys: np.ndarray, r: np.ndarray, tau: np.ndarray) -> None:
        """Keep keys (n,) int64 with their values, up to the table's limit."""
        self.count = int(_table_put(np.ascontiguousarray(keys, dtype=np.int64), np.ascontiguousarray(r, np.float64),
                                    np.ascontiguousarray(tau, np.float64), self.tkey, self.r, self.tau,
                                    self.count, self.limit))

    def keys(self) -> np.ndarray:
        """The keys held, sorted."""
        return np.sort(self.tkey[self.tkey >= 0])
