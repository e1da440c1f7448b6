"""Look-ups shared by the camera samples of one pixel (issue 16, item 3).

A pixel's samples mostly land on the same surface, a small fraction of the estimate's radius
apart (docs/photon-mapping.md, "Sharing a pixel's look-ups"), and each k-nearest search costs
about the same.  So the queries of one tile are grouped by (pixel, instance), and inside a group
(queries in sample order, which is random in time: a pixel's time strata are permuted):

1. the group's first ``SHARE_PILOTS`` queries are its **pilots**: estimated alone, and the
   smallest of the regions they read (``PhotonMap.estimate(..., support=True)``: radius r_p, time
   half-width tau_p) sets the group's **reach**: ``SHARE_RADIUS_FRACTION`` x r_p in space,
   ``SHARE_WINDOW_FRACTION`` x tau_p in time;
2. the first query not yet answered is a **representative**: it is estimated, and every other
   unanswered query of the group within the reach of it (space and time), on the same side of the
   surface (shading normals within ``SHARE_NORMAL_COS``) and in the same time slice (the photons its
   estimate may read) takes its irradiance E;
3. repeat with the queries left, at most ``SHARE_ROUNDS`` rounds; the last round estimates every
   query left on its own, and it comes early once a round's representatives answered fewer than
   ``SHARE_MIN_GAIN`` other queries each (the rounds' small scattered batches cost more per query).

Why several pilots and the smallest region: where a caustic's focus covers a small part of the
pixel, one pilot outside it (a large radius: few caustic photons near) would let one
representative's value stand for the whole pixel, focus included, and the pixel's noise would rise
(measured on the demo's glass-sphere caustic: RMSE against unshared 2.6x the camera noise with one
pilot, 0.16x with eight).

Why the reach is the pilots' and not the representative's: a representative's own radius and
window are larger where it is dark (fewer photons), so a reach taken from it spreads dark values
farther than bright ones, a bias toward dark at every edge in space or in time (measured: -0.2 to
-1.4 % on the tests' mirror caustic with the radius at f = 0.25-0.5, -6 to -7 % over the demo's
moving caustic with the window too).
With the reach fixed per group before any representative is drawn, and representatives drawn in
an order unrelated to position and time, a shared value is that of a random query within the
reach: the pixel's expected value moves only by the irradiance's curvature over the reach
(second order), and its noise rises because fewer independent estimates are averaged.  A moving
receiver reuses across at most SHARE_WINDOW_FRACTION x the pilots' window (the TEMPORAL window of
an estimate at that pixel and surface), never across a time slice.  The tolerance measured and
tested is in docs/photon-mapping.md.

The albedo and throughput stay each query's own: only E is shared; and, for camera vertices whose
rough lobes read the caustic map (``wo`` given), their glossy radiance L_g where also the view
directions agree (``SHARE_WO_COS``: within 1.1 degrees, so f_c(wo, wi) of a lobe of roughness >=
0.5 barely differs; a pixel's first hits differ by a fraction of the pixel's angle).
"""
from __future__ import annotations

import numpy as np

__all__ = ["SHARE_RADIUS_FRACTION", "SHARE_WINDOW_FRACTION", "SHARE_NORMAL_COS", "SHARE_ROUNDS",
           "SHARE_PILOTS", "SHARE_MIN_GAIN", "shared_estimate"]

SHARE_RADIUS_FRACTION = 0.25  # f: reuse within f x the group pilots' radius (0: sharing off)
SHARE_WINDOW_FRACTION = 0.5   # ... and within this fraction of the pilots' time window (half-width)
SHARE_NORMAL_COS = 0.9        # ... with shading normals at most acos(0.9) = 26 degrees apart
SHARE_ROUNDS = 16             # representatives per group at most; the queries left are estimated alone
SHARE_PILOTS = 8              # queries per group estimated alone first: the smallest of their regions sets the reach
SHARE_MIN_GAIN = 1.0          # ... and once a round's representatives answer fewer others than this each
SHARE_WO_COS = 0.9998         # glossy reads (wo given): view directions at most acos(0.9998) = 1.1 degrees apart


def shared_estimate(estimate, p: np.ndarray, ns: np.ndarray, t: np.ndarray, group: np.ndarray, *,
                    f: float = None, f_t: float = None, cos_n: float = None, rounds: int = None,
                    wo: np.ndarray | None = None, ng: np.ndarray | None = None):
    """Irradiance (n, 3) at the queries, estimated at representatives and shared inside groups.

    Parameters
    ----------
    estimate : callable (p, ns, t) -> (E (m, 3), r (m,), tau (m,), lo (m,), hi (m,)): the map's
        estimate with its support (``PhotonMaps.estimate(kind, ..., support=True)``).
    p : (n, 3) float64 positions; ns : (n, 3) shading normals on the query's side; t : (n,) times.
    group : (n,) int64 key: queries may share only inside one key (pixel x instance).
    f, f_t, cos_n, rounds : default to the module's constants.
    wo : (n, 3) view directions, or None; given, ``estimate`` is called with the queries' indices
        (m,) as a fourth argument and also returns the glossy radiance L_g (m, 3) as a sixth result (``PhotonMaps.estimate(..., glossy=...)``) and it is shared
        as E, where also wo . wo_rep >= ``SHARE_WO_COS``.
    ng : (n, 3) the queries' geometric normals, or None; given, ``estimate`` is called with
        ``ng=`` those of the queries it estimates (their tangent slabs, ``PhotonMap.estimate``).

    Returns (E (n, 3) float64, estimated: how many queries were estimated, the others shared); with
    wo (E, L_g (n, 3), estimated).
    """
    f = SHARE_RADIUS_FRACTION if f is None else float(f)
    f_t = SHARE_WINDOW_FRACTION if f_t is None else float(f_t)
    cos_n = SHARE_NORMAL_COS if cos_n is None else float(cos_n)
    rounds = SHARE_ROUNDS if rounds is None else int(rounds)
    n = p.shape[0]
    E = np.empty((n, 3))
    glossy = wo is not None
    Lg = np.empty((n, 3)) if glossy else None
    order = np.argsort(group, kind="stable")  # by group, then sample order
    # -- Pilots: the first query of each group, estimated alone; its region sets the group's reach --
    g = group[order]
    first = np.ones(n, np.bool_)
    first[1:] = g[1:] != g[:-1]
    start = np.flatnonzero(first)            # each group's first position in order
    gi = np.cumsum(first) - 1                # each sorted query's group
    rank = np.arange(n) - start[gi]          # its place in the group
    is_pilot = rank < SHARE_PILOTS
    pilots = order[is_pilot]
    got = estimate(p[pilots], ns[pilots], t[pilots], *((pilots,) if glossy else ()),
                   **({} if ng is None else {"ng": ng[pilots]}))
    Ep, rp, taup = got[:3]
    E[pilots] = Ep
    if glossy:
        Lg[pilots] = got[5]
    estimated = pilots.size
    # the group's reach: f x the smallest pilot radius, f_t x the smallest pilot window
    n_g = start.size
    r_min, tau_min = np.full(n_g, np.inf), np.full(n_g, np.inf)
    np.minimum.at(r_min, gi[is_pilot], rp)
    np.minimum.at(tau_min, gi[is_pilot], taup)
    todo = order[~is_pilot]                  # queries not answered yet, by group, then sample order
    g_todo = gi[~is_pilot]
    reach2 = (f * r_min) ** 2                # (groups,) m^2: share within f r of a representative
    reach_t = np.where(np.isfinite(tau_min), f_t * np.where(np.isfinite(tau_min), tau_min, 0.0), np.inf)
    last = rounds <= 1
    for rnd in range(max(rounds, 1)):
        if todo.size == 0:
            break
        # -- Representatives: the first query left of each group (all of them in the last round) ----
        g = g_todo
        first = np.ones(todo.size, np.bool_)
        if not (last or rnd == rounds - 1):
            first[1:] = g[1:] != g[:-1]
        reps = todo[first]
        got = estimate(p[reps], ns[reps], t[reps], *((reps,) if glossy else ()),
                       **({} if ng is None else {"ng": ng[reps]}))
        Er, r, _, lo, hi = got[:5]
        E[reps] = Er
        if glossy:
            Lg[reps] = got[5]
        estimated += reps.size
        if first.all():
            break
        # -- The others of each group: within the group's reach, normals agreeing, in the same slice --
        j = np.cumsum(first) - 1             # each query's representative (index into reps)
        rep = reps[j]
        dp = p[todo] - p[rep]
        near = np.einsum("ij,ij->i", dp, dp) <= reach2[g]
        same_side = np.einsum("ij,ij->i", ns[todo], ns[rep]) >= cos_n
        tq = t[todo]
        in_time = (np.abs(tq - t[rep]) <= reach_t[g]) & (tq >= lo[j]) & (tq <= hi[j])
        share = near & same_side & in_time & ~first & (r[j] > 0.0)
        if glossy:
            share &= np.einsum("ij,ij->i", wo[todo], wo[rep]) >= SHARE_WO_COS
            Lg[todo[share]] = got[5][j[share]]
        E[todo[share]] = Er[j[share]]
        keep = ~(share | first)
        todo, g_todo = todo[keep], g_todo[keep]
        last = np.count_nonzero(share) < SHARE_MIN_GAIN * reps.size   # sharing has run dry: the rest alone
    return (E, Lg, estimated) if glossy else (E, estimated)
