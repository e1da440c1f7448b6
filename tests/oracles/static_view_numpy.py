"""The numpy static-view test the compiled ``kernels.static_views.static_segments`` is tested against
(it was ``integrator.static_view_rows`` before the kernel): vectorised over rows, the boxes and
capsules one at a time."""
from __future__ import annotations

import numpy as np

__all__ = ["segments_distance", "static_view_rows"]


def segments_distance(p0: np.ndarray, d1: np.ndarray, q0: np.ndarray, d2: np.ndarray) -> np.ndarray:
    """Distances (m,) between the segments p0 + s d1 (m, 3 each) and q0 + u d2 (3,), s, u in [0, 1]:
    the closest points' parameters clamped to the segments (Ericson, Real-Time Collision
    Detection, 5.1.9)."""
    r = p0 - q0
    a = np.einsum("ki,ki->k", d1, d1)
    e = float(d2 @ d2)
    f = r @ d2
    c = np.einsum("ki,ki->k", d1, r)
    b = d1 @ d2
    den = a * e - b * b
    s = np.where(den > 1e-30 * np.maximum(a * e, 1e-300), np.clip((b * f - c * e) / np.where(den > 0, den, 1.0), 0, 1), 0.0)
    if e > 0.0:
        u = (b * s + f) / e
        s = np.where(u < 0.0, np.clip(-c / np.maximum(a, 1e-300), 0, 1), np.where(u > 1.0, np.clip((b - c) / np.maximum(a, 1e-300), 0, 1), s))
        u = np.clip((b * s + f) / e, 0.0, 1.0)
    else:
        u = np.zeros_like(s)
        s = np.clip(-c / np.maximum(a, 1e-300), 0, 1)
    diff = p0 + s[:, None] * d1 - (q0 + u[:, None] * d2)
    return np.sqrt(np.einsum("ki,ki->k", diff, diff))


def static_view_rows(setup: tuple, o: np.ndarray, position: np.ndarray, instance: np.ndarray,
                     chain: np.ndarray | None = None) -> np.ndarray:
    """(m,) bool: segments o (m, 3) or (1, 3) -> position (m, 3) on instance (m,) (-1: a miss) that
    are static views (``integrator.static_view_rows``); chain (m,) bool or None: the path before."""
    static, lo, hi, ca, cb, cr = setup
    ok = np.zeros(instance.shape[0], dtype=bool)
    hit = instance >= 0
    ok[hit] = static[instance[hit]]
    if chain is not None:
        ok &= np.asarray(chain, bool)
    if lo.shape[0] == 0 or not ok.any():
        return ok
    rows = np.flatnonzero(ok)
    o = np.broadcast_to(np.asarray(o, np.float64), position.shape)[rows]
    seg = position[rows] - o
    inv = 1.0 / np.where(seg == 0.0, 1e-300, seg)
    near = np.zeros(rows.size, dtype=bool)
    for j in range(lo.shape[0]):
        a, b = (lo[j] - o) * inv, (hi[j] - o) * inv
        t0 = np.max(np.minimum(a, b), axis=1)
        t1 = np.min(np.maximum(a, b), axis=1)
        near |= (t1 >= np.maximum(t0, 0.0)) & (t0 <= 1.0)
    if near.any():
        k = np.flatnonzero(near)
        crosses = np.zeros(k.size, dtype=bool)
        for j in range(ca.shape[0]):
            crosses |= segments_distance(o[k], seg[k], ca[j], cb[j] - ca[j]) <= cr[j]
        near[k] = crosses
    ok[rows[near]] = False
    return ok
