"""A bounded hash table of values per grid cell: the progressive pilot's regions per cell.

:class:`CellTable` holds (r, tau) per non-negative int64 cell key, at most ``limit`` keys, in an
open-addressing table of ``2^ceil(log2 2 limit)`` slots (multiplicative hash, linear probing),
looked up and filled in compiled loops (:meth:`.progressive.Pilot.initial_size`).  It replaced a
sorted array merged with ``np.insert`` per batch (a copy of up to 131,072 cells every call):
table upkeep 0.17 -> 0.09 s over 16 passes of the demo.

A uniform hash grid over a pass's photons for the progressive kernel's fixed-region look-ups
(issue 16, item 3) was built on this table, tested to give the kd-tree's photon sets and sums,
and measured *not faster* than the kd-tree (range queries 1.24-1.34x the tree's time, whole
look-ups 1.09-1.11x; a uniform cell size cannot serve regions whose radii span 10x in one image,
while the tree adapts).  Kept switched off it would have been a second implementation of the
range query, so it was removed; it is on the branch ``hashgrid`` (commit 51f75ff) and the
measurements are in docs/photon-mapping.md section 8.
"""
from __future__ import annotations

import numpy as np

from . import kdtree as _kdtree

__all__ = ["AVAILABLE", "CellTable"]

AVAILABLE = _kdtree.AVAILABLE
if AVAILABLE:
    import numba as _nb

    _jit = _nb.njit(cache=True, nogil=True, fastmath=False, boundscheck=False)

    @_jit
    def _hash(key, mask):
        """Slot of a cell key in a table of mask + 1 slots (multiplicative hash, xor-folded)."""
        x = np.uint64(key) * np.uint64(0x9E3779B97F4A7C15)
        x ^= x >> np.uint64(29)
        return np.int64(x & np.uint64(mask))

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
