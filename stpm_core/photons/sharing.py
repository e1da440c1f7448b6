"""Look-ups shared by the camera samples of one pixel (issue 16, item 3).

A pixel's samples mostly land on the same surface, a small fraction of the estimate's radius
apart (docs/photon-mapping.md, "Sharing a pixel's look-ups"), and each k-nearest search costs
about the same.  So the queries of one tile are grouped by (pixel, instance), and inside a group:

1. the first query not yet answered (in time order) is a **representative**: it is estimated,
   and the estimator returns the region it read (``PhotonMap.estimate(..., support=True)``:
   radius r, time window [a, b]);
2. every other unanswered query of the group that lies within ``SHARE_RADIUS_FRACTION`` x r of
   it in space, on the same side of the surface (shading normals within ``SHARE_NORMAL_COS``) and
   inside its time window (shrunk about the representative's time by ``SHARE_WINDOW_FRACTION``)
   takes its irradiance E;
3. repeat with the queries left, at most ``SHARE_ROUNDS`` rounds; the last round estimates every
   query left on its own, and it comes early once a round's representatives answered fewer than
   ``SHARE_MIN_GAIN`` other queries each (the rounds' small scattered batches cost more per query).

What a shared value changes: a query reads the estimate of a region whose centre is at most f r
away from it (its own region's centre, in space) and whose time window holds its time; a moving
receiver never reuses across times farther apart than the estimate's own window.  The expected
value moves by at most the irradiance's change over f r in space (and inside the window in
time); the noise of a pixel's mean rises because fewer independent estimates are averaged, but a
pixel's estimates were already made of nearly the same photons.  The tolerance measured and
tested is in docs/photon-mapping.md.

The albedo and throughput stay each query's own: only E is shared.
"""
from __future__ import annotations

import numpy as np

__all__ = ["SHARE_RADIUS_FRACTION", "SHARE_WINDOW_FRACTION", "SHARE_NORMAL_COS", "SHARE_ROUNDS",
           "shared_estimate"]

SHARE_RADIUS_FRACTION = 0.25  # f: reuse within f x the estimate's radius (0: sharing off)
SHARE_WINDOW_FRACTION = 0.5   # ... within this fraction of the pilot's window half-width, and inside the representative's window
SHARE_NORMAL_COS = 0.9        # ... with shading normals at most acos(0.9) = 26 degrees apart
SHARE_ROUNDS = 16             # representatives per group at most; the queries left are estimated alone
SHARE_MIN_GAIN = 1.0          # ... and once a round's representatives answer fewer others than this each


def shared_estimate(estimate, p: np.ndarray, ns: np.ndarray, t: np.ndarray, group: np.ndarray, *,
                    f: float = None, f_t: float = None, cos_n: float = None, rounds: int = None):
    """Irradiance (n, 3) at the queries, estimated at representatives and shared inside groups.

    Parameters
    ----------
    estimate : callable (p, ns, t) -> (E (m, 3), r (m,), a (m,), b (m,)): the map's estimate with
        its support (``PhotonMaps.estimate(kind, ..., support=True)``).
    p : (n, 3) float64 positions; ns : (n, 3) shading normals on the query's side; t : (n,) times.
    group : (n,) int64 key: queries may share only inside one key (pixel x instance).
    f, f_t, cos_n, rounds : default to the module's constants.

    Returns (E (n, 3) float64, estimated: how many queries were estimated, the others shared).
    """
    f = SHARE_RADIUS_FRACTION if f is None else float(f)
    f_t = SHARE_WINDOW_FRACTION if f_t is None else float(f_t)
    cos_n = SHARE_NORMAL_COS if cos_n is None else float(cos_n)
    rounds = SHARE_ROUNDS if rounds is None else int(rounds)
    n = p.shape[0]
    E = np.empty((n, 3))
    order = np.lexsort((t, group))           # by group, then time
    # -- Pilots: the first query of each group, estimated alone; its region sets the group's reach --
    g = group[order]
    first = np.ones(n, np.bool_)
    first[1:] = g[1:] != g[:-1]
    pilots = order[first]
    Ep, rp, ap, bp = estimate(p[pilots], ns[pilots], t[pilots])
    E[pilots] = Ep
    estimated = pilots.size
    todo = order[~first]                     # queries not answered yet, by group, then time
    gi = np.cumsum(first) - 1                # each sorted query's group (index into pilots)
    g_todo = gi[~first]
    reach2 = (f * rp) ** 2                   # (pilots,) m^2: share within f r of a representative
    with np.errstate(invalid="ignore"):      # an unbounded window (STANDARD): any time
        half = np.maximum(t[pilots] - ap, bp - t[pilots])
        reach_t = np.where(np.isfinite(half), f_t * half, np.inf)
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
        Er, r, a, b = estimate(p[reps], ns[reps], t[reps])
        E[reps] = Er
        estimated += reps.size
        if first.all():
            break
        # -- The others of each group: within the group's reach, normals agreeing, in the window ------
        j = np.cumsum(first) - 1             # each query's representative (index into reps)
        rep = reps[j]
        dp = p[todo] - p[rep]
        near = np.einsum("ij,ij->i", dp, dp) <= reach2[g]
        same_side = np.einsum("ij,ij->i", ns[todo], ns[rep]) >= cos_n
        tq = t[todo]
        in_time = (np.abs(tq - t[rep]) <= reach_t[g]) & (tq >= a[j]) & (tq <= b[j])
        share = near & same_side & in_time & ~first & (r[j] > 0.0)
        E[todo[share]] = Er[j[share]]
        keep = ~(share | first)
        todo, g_todo = todo[keep], g_todo[keep]
        last = np.count_nonzero(share) < SHARE_MIN_GAIN * reps.size   # sharing has run dry: the rest alone
    return E, estimated
