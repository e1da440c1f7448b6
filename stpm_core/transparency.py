"""Transparent surfaces: rays that pass through (Transparent BSDF, Principled Alpha, cut-outs).

A hit whose closure is transparent (``closure.C_PASS`` = 1: the node program chose a Transparent
BSDF, or a Principled BSDF's Alpha said so, ``kernels.svm``) scatters nothing: the ray goes on
in the same direction from just behind the surface, its weight multiplied by the closure's tint
``C_TRANSPARENT``, as Cycles' transparent bounces do.  These passes do not count as bounces;
a ray segment (camera, shadow or photon) passes at most ``RenderSettings.transparent_max_bounces``
surfaces in a row (Cycles' ``transparent_max_bounces``, default ``TRANSPARENT_MAX_BOUNCES`` = 8):
the next transparent one absorbs it (black, shadowed; ``limit`` below).

* :func:`pass_through` -- camera rays and photons: the hits (and their closures) of transparent
  rows are replaced, in place, by what lies behind them.
* :func:`shadow_transmittance` -- shadow rays: the tint (m, 3) of what they pass through before
  the light (0: blocked by an opaque surface), instead of a yes/no occlusion test.

Both run only for scenes with a material that may be transparent (``ShadingData.transparent``);
opaque hits on a shadow ray end it without running any node program.  Mix Shader choices at
each pass use a fresh seed (layers of leaves are independent).
"""
from __future__ import annotations

import numpy as np

from .kernels.closure import C_PASS, C_TRANSPARENT, N_CLOSURE
from .kernels.svm import shade
from .raycast.geometry import GUARD_FRACTION, offset_lengths
from .shading import hit_geometry

__all__ = ["TRANSPARENT_MAX_BOUNCES", "pass_through", "shadow_transmittance"]

TRANSPARENT_MAX_BOUNCES = 8          # RenderSettings.transparent_max_bounces' default (Cycles' too)


def _behind(position: np.ndarray, ng: np.ndarray, instance: np.ndarray, d: np.ndarray, inst_offset) -> tuple:
    """Origins (n, 3) just behind hits at position (n, 3) (geometric normals ng) for rays going
    on along d (n, 3), and the offsets (n,) used (``raycast.geometry.offset_lengths``)."""
    eps = offset_lengths(inst_offset, instance, position)
    side = np.where(np.einsum("ij,ij->i", d, ng) >= 0.0, eps, -eps)
    return position + side[:, None] * ng, eps


def _shade(sd, hits, d, times, seed: int) -> np.ndarray:
    """Closures (n, N_CLOSURE) of all of ``hits`` (rays d, times); Normal inputs set hits.ns."""
    C = np.empty((hits.t.shape[0], N_CLOSURE))
    G = hit_geometry(hits, d, sd=sd, times=times) if sd.uses_programs else None
    shade(sd, np.ascontiguousarray(hits.material), G, seed, C)
    return C


_FIELDS = ("instance", "prim", "u", "v", "position", "ng", "ns", "material")


def pass_through(caster, sd, inst_offset, hits, d: np.ndarray, times: np.ndarray, C: np.ndarray,
                 weight: np.ndarray | None, rng, at: np.ndarray | None = None, tmax=None,
                 limit: int = TRANSPARENT_MAX_BOUNCES) -> np.ndarray | None:
    """Replace the transparent hits among C's rows by what lies behind them; returns the weights.

    C (k, N_CLOSURE): closures of the hits ``at`` (k,) of ``hits`` (None: all, in order), rays d
    (k, 3) unit, times (k,); weight (k, 3) path throughput or photon power, multiplied in place
    by each pass's tint (None: 1; a new array is made if anything passes).  The hits' fields
    (t: the distance from the original origin) and C's rows are overwritten with the surface
    behind (or a miss); tmax: the rays' original far limit (None, a scalar or (k,)).
    Rows still transparent after ``limit`` passes get the inert closure (absorbed).
    """
    if not sd.transparent:
        return weight
    k = C.shape[0]
    at = np.arange(k) if at is None else at
    for step in range(limit + 1):
        rows = np.flatnonzero(C[:, C_PASS] > 0.0)
        if rows.size == 0:
            break
        if weight is None:
            weight = np.ones((k, 3))
        weight[rows] *= C[rows, C_TRANSPARENT:C_TRANSPARENT + 3]
        if step == limit:
            C[rows] = sd.closures[-1]                      # absorbed
            break
        h_rows = at[rows]
        dr = np.ascontiguousarray(d[rows])
        o, eps = _behind(hits.position[h_rows], hits.ng[h_rows], hits.instance[h_rows], dr, inst_offset)
        t0 = hits.t[h_rows]
        tm = None
        if tmax is not None:
            tm = np.maximum((tmax if np.ndim(tmax) == 0 else np.asarray(tmax)[rows]) - t0, 0.0)
        tr = np.ascontiguousarray(times[rows])
        h = caster.intersect(o, dr, tr, tm, guard=GUARD_FRACTION * eps)
        C[rows] = _shade(sd, h, dr, tr, int(rng.integers(1 << 62)))
        for f in _FIELDS:
            getattr(hits, f)[h_rows] = getattr(h, f)
        hits.t[h_rows] = t0 + h.t
    return weight


def shadow_transmittance(caster, sd, inst_offset, o: np.ndarray, d: np.ndarray, times: np.ndarray,
                         tmax: np.ndarray, guard: np.ndarray | None, rng,
                         limit: int = TRANSPARENT_MAX_BOUNCES) -> np.ndarray:
    """Tint (m, 3) of m shadow rays o + s d (unit d), 0 < s < tmax, at their times: the product of
    the tints of the transparent surfaces they cross, 0 where an opaque surface (or more than
    ``limit`` transparent ones) blocks them; 1 for a free ray.  guard: as ``caster.intersect``."""
    m = o.shape[0]
    T = np.ones((m, 3))
    alive = np.arange(m)
    mask = sd.transparent_mask
    o, d, times, tmax = (np.ascontiguousarray(a) for a in (o, d, times, tmax))
    for step in range(limit + 1):
        if alive.size == 0:
            break
        h = caster.intersect(o, d, times, tmax, guard=guard)
        hit = np.flatnonzero(np.isfinite(h.t))
        if hit.size == 0:
            break
        may = mask[h.material[hit]]
        T[alive[hit[~may]]] = 0.0                          # opaque: no program to run
        cand = hit[may]
        if cand.size == 0:
            break
        sub = _subset(h, cand)
        dc = np.ascontiguousarray(d[cand])
        Cc = _shade(sd, sub, dc, times[cand], int(rng.integers(1 << 62)))
        passes = Cc[:, C_PASS] > 0.0
        T[alive[cand[~passes]]] = 0.0
        go = cand[passes]
        T[alive[go]] *= Cc[passes, C_TRANSPARENT:C_TRANSPARENT + 3]
        if step == limit:
            T[alive[go]] = 0.0
            break
        o_n, eps = _behind(h.position[go], h.ng[go], h.instance[go], d[go], inst_offset)
        o, d, times = o_n, np.ascontiguousarray(d[go]), np.ascontiguousarray(times[go])
        tmax = np.maximum(tmax[go] - h.t[go], 0.0)
        guard = GUARD_FRACTION * eps
        alive = alive[go]
    return T


def _subset(hits, rows: np.ndarray):
    """A ``raycast.Hits`` of the rows of hits (copies)."""
    return type(hits)(t=hits.t[rows], **{f: np.ascontiguousarray(getattr(hits, f)[rows]) for f in _FIELDS})
