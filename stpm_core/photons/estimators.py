"""Irradiance estimates from a time-stamped photon map: STANDARD, TEMPORAL, KD4D.

All three return irradiance ``E`` (n, 3) in W/m^2 at query points ``p`` (n, 3)
and shutter times ``t`` (n,), counting only photons that arrived on the side
of the shading normal ``ns`` (``dot(ns, wi) > 0``) and, given the queries'
geometric normals ``ng``, lying in their tangent slab (``PLANE_FRACTION``,
``PLANE_FRONT``: other surfaces inside the search ball add nothing).  The
derivations, with the units of every name used here, are in
docs/photon-mapping.md.

Photon power is a *per-shutter* quantity: ``Phi`` (W) is the photon's share of
the flux integrated over the normalised shutter, and photon times are drawn
from the shutter density g(t).  So the photons around (x, t) have density
``E(x, t) g(t)`` in (area x time) and a region of area A and shutter mass W
(``W = integral of g over its time span``) holds expected power E * A * W.

k-nearest correction: the k-th neighbour only fixes the radius; the k - 1
photons inside are, given that radius, independent samples of the density
restricted to the neighbourhood, and E[(k-1) / V_k] equals the density
exactly for a Poisson process.  So every estimate sums the k - 1 *inner*
photons over the volume reaching the k-th (the textbook k / V_k overestimates
by k / (k-1)).

Search engines: each estimate first gathers, per query, the summed power of
its selected photons and the radius / window that bound them -- with the
compiled kd-tree of :mod:`.kdtree` (numba) when available, else scipy's
cKDTree (``PhotonMap.backend``); both give the same neighbours, and the
normalisations below are one numpy code path (``PhotonMap._normalise``).
A ``bounded`` map's compiled searches stop at r_max (``SEARCH_CAP``, :meth:`PhotonMap.search_cap`):
a query with fewer than kq photons within r_max sums those over the r_max region (radius r_max;
TEMPORAL's window the whole slice), which keeps the expected value (docs/photon-mapping.md,
"Bounded searches").

Estimators (``k`` = ``settings.k_nearest``):

* STANDARD: k nearest in space; ``E = sum Phi / (pi r_k^2)`` -- the
  shutter-averaged irradiance (time ignored).
* TEMPORAL: m spatial candidates (the m-th fixes the disc radius r_m), the k
  nearest in time among the m - 1 inner ones (the k-th fixes the window
  half-width tau); ``E = sum Phi / (pi r_m^2 * W)`` with ``W`` the shutter
  mass of [t - tau, t + tau] clipped to the shutter.  ``temporal_alpha`` >= 1:
  m = ceil(alpha k) over the whole shutter (1.5 = the paper).  0 (default):
  the photons are cut into B time slices of equal shutter mass, B growing as
  (N / k)^(1/3), each with its own 3D kd-tree; a query searches the slice
  holding its time with m = ceil(1.5 k) and clips the window to that slice,
  so the window shrinks as photons grow while the search stays as cheap as
  the paper's.
* KD4D: k nearest in (x, y, z, s t); ``E = sum Phi / (V / s)`` with V the
  3-ball of radius R_k in (surface x scaled time), clipped to the shutter slab
  and weighted by g: ``V/s = integral over the clipped window of
  pi (R^2 - s^2 (tau - t)^2) g(tau) dtau``.
"""
from __future__ import annotations

import math
import threading
import time as _time
import warnings

import numpy as np
from scipy.spatial import cKDTree

from . import kdtree as _kdtree
from .record import decode_normal_codes, delta_only, normal_codes, oct_decode

__all__ = [
    "PhotonMap", "ESTIMATOR_NAMES", "CONE_K", "EDGE_CORRECTION", "PLANE_FRACTION", "PLANE_FRONT", "NORMAL_COS",
    "plane_weights", "auto_temporal_alpha", "temporal_candidates",
    "temporal_slices", "shutter_mass", "slab_ball_volume",
]

ESTIMATOR_NAMES = ("STANDARD", "TEMPORAL", "KD4D")
CONE_K = 1.1                 # cone kernel: w(d) = 1 - d / (CONE_K * r)
PLANE_FRACTION = 0.5         # tangent slab: a photon counts only if -PLANE_FRACTION r <= (x_p - x_q) . n_g
PLANE_FRONT = np.inf         # <= PLANE_FRONT r, n_g toward the query's viewer, r the search radius; open in
                             # front: a concave corner's other surface keeps filling the disc (0.5 darkened
                             # room corners: the textured room's FLIP 0.0413 -> 0.0430; docs "Tangent slab")
                             # (docs/photon-mapping.md, "Tangent slab"; inf: no bound on that side)
#: Photon normals (with the slab on): a photon behind the query's tangent plane counts only if
#: dot(n_p, n_g) >= NORMAL_COS (in front: any normal, a concave corner's other face), n_p its
#: surface's stored geometric normal (record.py ``ng_oct``, on the side of its wi), n_g the query's slab
#: normal: an open outer corner's face behind a wall (perpendicular to it) adds nothing.  Compiled into
#: the look-ups (``kdtree.NORMAL_COS``; edit it there); docs/photon-mapping.md, "Tangent slab".
NORMAL_COS = _kdtree.NORMAL_COS
#: Boundary correction (docs/photon-mapping.md, "Boundary correction at a convex edge"): a map built with ``edge=True``
#: (the global map of a render: ``maps.EDGE_MAPS``) divides a compiled STANDARD / TEMPORAL estimate with
#: the slab on by the fraction of its disc the query's surface covers where its photons end at a
#: straight edge (a wall beside a window opening: kdtree._edge_scale).  Not the caustic map: a caustic
#: ends where its photons end, which the photons cannot tell from a surface's edge.  False: as before.
EDGE_CORRECTION = True
TEMPORAL_SLICE_C = 0.25      # automatic time slices B = max(1, round(C * (N / k)^(1/3)))
TEMPORAL_SLICE_ALPHA = 1.5   # candidates per estimate inside a slice, as a multiple of k (the paper's 1.5; fewer
                             # is cheaper but darkens a receiver moving along its normal: docs/photon-mapping.md)
_QUERY_BATCH_ELEMS = 1 << 21 # neighbours gathered per batch (bounds memory)
#: Bounded k-nearest searches (docs/photon-mapping.md, "Bounded searches"): a map built with
#: ``bounded=True`` (the caustic map of a render: ``maps.BOUNDED_MAPS``) never searches beyond
#: r_max = SEARCH_CAP_FACTOR x the SEARCH_CAP_PERCENTILE-th percentile of the distances from its own
#: photons to their kq-th neighbour (the same search: tree, dimensions and kq); a query with fewer
#: than kq photons within r_max sums those over the r_max region.  False: every search unbounded,
#: bit for bit as before.
SEARCH_CAP = True
SEARCH_CAP_PERCENTILE = 90.0 # of the photons' own kq-th radii: 90 % of the map's photons (of its power) lie denser
SEARCH_CAP_FACTOR = 1.5      # r_max / that radius: a capped query's density is < 1/2.25 of the percentile's
SEARCH_CAP_SAMPLE = 2048     # photons (strided in tree order) whose kq-th radius sets r_max


def _slab_normals(ng, ns: np.ndarray) -> np.ndarray:
    """(n, 3) float32: the geometric normals ng turned to the side of ns (the side the query is seen
    from: the slab's front); zeros where ng is None (no slab)."""
    if ng is None:
        return np.zeros_like(ns, dtype=np.float32)
    ng = np.asarray(ng, dtype=np.float32).reshape(-1, 3)
    if ng.shape != ns.shape:
        raise ValueError(f"geometric normals {ng.shape} do not match the queries' normals {ns.shape}")
    flip = np.einsum("ij,ij->i", ng, ns) < 0.0
    return np.where(flip[:, None], -ng, ng)


def plane_weights(scene) -> np.ndarray:
    """(n_instances,) float32: 1 where an instance neither moves nor deforms within the shutter, else 0.

    A query's geometric normal times its instance's weight is the normal :meth:`PhotonMap.estimate`
    filters by: on a static surface every photon it received lies in its tangent plane, so the
    slab drops only other surfaces' photons; on a moving or deforming one, photons of other times
    lie off the query time's plane (a receiver moving along its normal: docs/photon-mapping.md,
    "Tangent slab"), so the slab is off there (a zero normal).
    """
    return np.array([1.0 if inst.transform.is_static and not scene.meshes[inst.mesh].is_deforming else 0.0
                     for inst in scene.instances], dtype=np.float32)


# ---------------------------------------------------------------------------
# Memory order
# ---------------------------------------------------------------------------

def morton_codes(position: np.ndarray, bits: int = 10) -> np.ndarray:
    """3D Morton (Z-order) codes (N,) uint64 of positions (N, 3) quantised to 2^bits per axis."""
    pos = np.asarray(position, dtype=np.float64)
    lo, hi = pos.min(0), pos.max(0)
    q = ((pos - lo) / np.maximum(hi - lo, 1e-30) * ((1 << bits) - 1)).astype(np.uint64)
    code = np.zeros(pos.shape[0], dtype=np.uint64)
    for b in range(bits):
        for a in range(3):
            code |= ((q[:, a] >> np.uint64(b)) & np.uint64(1)) << np.uint64(3 * b + a)
    return code


# ---------------------------------------------------------------------------
# Shutter mass helpers
# ---------------------------------------------------------------------------

def _shutter_cdf(shutter, u: np.ndarray) -> np.ndarray:
    """Exact CDF of the shutter density at u (n,) clipped to [0, 1] (piecewise quadratic for a curve).

    :meth:`Shutter.cdf`, the inverse of ``Shutter.sample`` (one set of tables), so window masses
    and photon times agree.
    """
    return shutter.cdf(u)


def shutter_mass(shutter, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Probability mass (n,) of shutter times in [a, b] clipped to [0, 1] (dimensionless, >= 0)."""
    return np.maximum(_shutter_cdf(shutter, b) - _shutter_cdf(shutter, a), 0.0)


def slab_ball_volume(shutter, R: np.ndarray, t: np.ndarray, s: float, lo=0.0, hi=1.0) -> np.ndarray:
    """Area x shutter-mass measure (n,) m^2 of 3-balls in (u, v, s*t) clipped to t in [0, 1].

    ``V/s = integral_{[a, b]} pi (R^2 - s^2 (tau - t)^2) g(tau) dtau = pi s^2 I(t, R/s)`` over the
    ball's time span ``[a, b] = [t - R/s, t + R/s]`` cut to [0, 1]: the disc the ball cuts at
    time tau, weighted by the shutter density g.  R (n,) m, t (n,) normalised shutter time,
    s in m per shutter; lo, hi: clip to [lo, hi] instead of the shutter (a progressive pass's time
    stratum).  ``I = Shutter.parabola_integral`` is exact for the piecewise-linear g:
    closed form for a box shutter ((4/3) pi R^3 / s unclipped), per curve segment otherwise; it is
    > 0 wherever [a, b] overlaps the density's support and exactly 0 where it does not (no photon
    can be there: the caller's Phi is 0 too).
    """
    R = np.asarray(R, dtype=np.float64)
    return np.pi * s * s * shutter.parabola_integral(np.asarray(t, dtype=np.float64), R / s, lo, hi)


# ---------------------------------------------------------------------------
# TEMPORAL candidate count and time slices
# ---------------------------------------------------------------------------

def _by_slice(edges: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Group times t (n,) by slice [edges[j], edges[j + 1]) of edges (B + 1,).

    Returns which (n,) slice of each time, order (n,) indices sorted by slice (stable) and
    starts (B + 1,): slice j's indices are ``order[starts[j]:starts[j + 1]]``.
    """
    B = len(edges) - 1
    which = np.clip(np.searchsorted(edges[1:B], t, side="right"), 0, B - 1)
    order = np.argsort(which, kind="stable")
    return which, order, np.searchsorted(which[order], np.arange(B + 1))


def temporal_slices(n_photons: int, k: int, temporal_alpha: float = 0.0) -> int:
    """Time slices B of the consistent TEMPORAL (1 for a fixed ``temporal_alpha`` >= 1).

    B = max(1, round(C (N/k)^(1/3))), and never so many that a slice holds
    fewer than 4 m photons.  Each slice covers 1/B of the shutter mass; its
    window is at most that long, so it shrinks like B^-1, and the candidate
    disc holds m = alpha k (``TEMPORAL_SLICE_ALPHA`` = 1.5) of the slice's N / B
    photons, so its radius shrinks like (alpha B k / N)^(1/2); B ~ (N / k)^(1/3)
    sends both to zero and balances a moving edge's spatial bias (~ r) against
    the temporal one (~ window, whose mass is about 1 / (alpha B)) -- see
    docs/photon-mapping.md.
    """
    if temporal_alpha >= 1.0:
        return 1
    N, k = max(int(n_photons), 1), max(int(k), 1)
    B = int(round(TEMPORAL_SLICE_C * (N / k) ** (1.0 / 3.0)))
    m = int(math.ceil(TEMPORAL_SLICE_ALPHA * k - 1e-9))   # (1.1 * 50 is 55.000000000000007 in float64)
    return max(1, min(B, N // (4 * m)))


def auto_temporal_alpha(n_photons: int, k: int) -> float:
    """The effective candidate multiple of the consistent TEMPORAL, over the whole shutter.

    Within one of B slices the search takes alpha k candidates (``TEMPORAL_SLICE_ALPHA``),
    i.e. alpha B k photons' worth of the whole shutter's density: alpha B (for reports; B from
    :func:`temporal_slices`).
    """
    return TEMPORAL_SLICE_ALPHA * temporal_slices(n_photons, k, 0.0)


def temporal_candidates(n_photons: int, k: int, temporal_alpha: float) -> int:
    """Spatial candidates m per TEMPORAL search (m - 1 >= k inner candidates when possible).

    ``temporal_alpha`` >= 1: m = ceil(alpha k) over the shutter; 0: m = ceil(TEMPORAL_SLICE_ALPHA k)
    (1.5 k) within a slice.
    """
    alpha = temporal_alpha if temporal_alpha >= 1.0 else TEMPORAL_SLICE_ALPHA
    return max(int(math.ceil(alpha * k - 1e-9)), k + 1)   # (1.1 * 50 is 55.000000000000007 in float64)


# ---------------------------------------------------------------------------
# The photon map
# ---------------------------------------------------------------------------

class PhotonMap:
    """One photon map: records, decoded working arrays and lazily built kd-trees.

    Parameters
    ----------
    records : (N,) PHOTON_DTYPE array.
    shutter : stpm_core.shutter.Shutter (its density weights time windows).
    time_scale : KD4D's s (scene units per shutter), > 0.
    workers : look-up threads (-1 or 0 = all cores); a batch of queries is split over them.
    backend : 'auto' (compiled numba kd-tree when numba imports, else scipy), 'numba' or
        'scipy'.  Both give the same estimates (:mod:`.kdtree`).
    origin : (3,) float64 world point the record positions are relative to
        (:func:`.record.photon_origin`; None = the world origin).
    bounded : cap every compiled k-nearest search at :meth:`search_cap` (if ``SEARCH_CAP``).

    Attributes
    ----------
    records : (N,) PHOTON_DTYPE in Morton order (the order of every array below).
    position : (N, 3) float64 relative to ``origin``, time : (N,) float64; power : (N, 3) float32 and
    wi : (N, 3) float32 unit incoming directions, both views of one packed
    (N, 8) float32 array (one 32-byte row gathered per neighbour).
    timeless : True when all photons share one time (instant shutter or an
        accumulation-buffer still): TEMPORAL and KD4D then equal STANDARD.
    backend : 'numba' or 'scipy', the search actually used.
    stats : dict of tree build seconds, look-up seconds and counts.
    """

    def __init__(self, records: np.ndarray, shutter, *, time_scale: float, workers: int = -1,
                 backend: str = "auto", origin: np.ndarray | None = None, bounded: bool = False,
                 edge: bool = False):
        self.shutter = shutter
        # compiled STANDARD / TEMPORAL look-ups with the slab divide by the part of the disc their
        # surface covers, where the photons show an edge (kdtree._edge_scale; EDGE_CORRECTION switches
        # it off everywhere)
        self.edge = bool(edge)
        # compiled searches capped at r_max (search_cap; SEARCH_CAP switches it off everywhere)
        self.bounded = bool(bounded)
        self._caps = {}                      # (id(tree), kq) -> r_max of that search (m)
        # World position of the records' (0, 0, 0) (record.py); queries are shifted by it
        self.origin = np.zeros(3) if origin is None else np.asarray(origin, dtype=np.float64).reshape(3)
        self.time_scale = float(time_scale)
        self.workers = workers
        self.n = int(records.shape[0])
        if backend not in ("auto", "numba", "scipy"):
            raise ValueError(f"unknown look-up backend {backend!r}")
        if backend == "numba" and not _kdtree.AVAILABLE:
            raise RuntimeError(f"numba look-ups unavailable ({_kdtree._IMPORT_ERROR})")
        self.backend = "numba" if backend != "scipy" and _kdtree.AVAILABLE else "scipy"
        t0 = _time.perf_counter()
        # Store photons in Morton (Z-curve) order: spatial neighbours sit close in memory,
        # so the neighbour gathers of every look-up hit the cache
        if self.n:
            records = records[np.argsort(morton_codes(records["position"]), kind="stable")]
        self.records = records
        self.position = np.ascontiguousarray(records["position"], dtype=np.float64)
        self.time = np.ascontiguousarray(records["time"], dtype=np.float64)
        # One 32-byte row per photon for the look-ups: (wi_x, wi_y, wi_z, delta_only, Phi_r, Phi_g, Phi_b,
        # n_code) (delta_only 1: the photon came through delta lobes alone, record.delta_only; read by the
        # glossy sums of caustic-map look-ups only; n_code its surface's geometric normal,
        # record.normal_codes, 0 = none: read by the slab's normal test, kdtree._facing)
        self._packed = np.zeros((self.n, 8), dtype=np.float32)
        if self.n:
            self._packed[:, :3] = oct_decode(records["wi_oct"])
            self._packed[:, 3] = delta_only(records)
            self._packed[:, 4:7] = records["power"]
            self._packed[:, 7] = normal_codes(records)
        self.wi = self._packed[:, :3]
        self.power = self._packed[:, 4:7]
        self.timeless = bool(shutter.is_instant or self.n == 0 or np.ptp(self.time) == 0.0)
        self._tree3 = None
        self._tree4 = None
        self._flat = {}                      # dims -> kdtree.FlatTree (numba backend)
        self._slices = {}                    # B -> TEMPORAL's time slices (see :meth:`time_slices`)
        self._lock = threading.Lock()
        # Sorting and packing count as map building
        self.stats = {"tree_build_s": _time.perf_counter() - t0, "lookup_s": 0.0, "lookup_count": 0,
                      "temporal_candidates": 0, "capped_count": 0}

    # -- kd-trees -----------------------------------------------------------
    def tree3(self) -> cKDTree:
        """3D scipy kd-tree over photon positions (built on first use)."""
        with self._lock:
            if self._tree3 is None:
                t0 = _time.perf_counter()
                self._tree3 = cKDTree(self.position, leafsize=16, balanced_tree=False, compact_nodes=False)
                self.stats["tree_build_s"] += _time.perf_counter() - t0
        return self._tree3

    def tree4(self) -> cKDTree:
        """4D scipy kd-tree over (x, y, z, s t) (built on first use)."""
        with self._lock:
            if self._tree4 is None:
                t0 = _time.perf_counter()
                xyzt = np.empty((self.n, 4))
                xyzt[:, :3] = self.position
                xyzt[:, 3] = self.time_scale * self.time
                self._tree4 = cKDTree(xyzt, leafsize=16, balanced_tree=False, compact_nodes=False)
                self.stats["tree_build_s"] += _time.perf_counter() - t0
        return self._tree4

    def flat_tree(self, dims: int):
        """Compiled kd-tree (numba backend) in 3D or 4D (x, y, z, s t), built on first use."""
        with self._lock:
            tree = self._flat.get(dims)
            if tree is None:
                t0 = _time.perf_counter()
                tree = _kdtree.FlatTree(self.records["position"], self.records["time"], self._packed,
                                        dims=dims, s=self.time_scale)
                self._flat[dims] = tree
                self.stats["tree_build_s"] += _time.perf_counter() - t0
        return tree

    def time_slices(self, B: int) -> dict:
        """TEMPORAL's B time slices of equal shutter mass, each with its own 3D kd-tree (built on first use).

        Returns a dict: ``edges`` (B + 1,) shutter times (slice j is [edges[j], edges[j + 1]),
        ``edges[0] = 0``, ``edges[B] = 1``, inner edges at the shutter's mass quantiles j / B);
        ``rows`` list of B (n_j,) int64 photon rows (Morton order kept inside a slice);
        ``trees`` list of B kd-trees over those rows (kdtree.FlatTree or scipy cKDTree).
        """
        with self._lock:
            sl = self._slices.get(B)
            if sl is not None and sl["backend"] == self.backend:
                return sl
            t0 = _time.perf_counter()
            edges = np.empty(B + 1)
            edges[0], edges[B] = 0.0, 1.0
            edges[1:B] = self.shutter.sample(np.arange(1, B) / B)
            _, order, starts = _by_slice(edges, self.time)
            rows = [order[starts[j]:starts[j + 1]] for j in range(B)]
            trees = []
            for r in rows:
                if len(r) == 0:
                    trees.append(None)
                elif self.backend == "numba":
                    trees.append(_kdtree.FlatTree(self.records["position"][r], self.records["time"][r],
                                                  self._packed[r], dims=3, s=self.time_scale))
                else:
                    trees.append(cKDTree(self.position[r], leafsize=16, balanced_tree=False, compact_nodes=False))
            sl = {"edges": edges, "rows": rows, "trees": trees, "backend": self.backend}
            self._slices[B] = sl
            self.stats["tree_build_s"] += _time.perf_counter() - t0
        return sl

    def search_cap(self, tree, kq: int) -> float:
        """r_max (m, in the tree's dimensions) of kq-nearest searches in ``tree`` (a kdtree.FlatTree of
        this map or of one of its time slices), or inf when this map's searches are unbounded.

        r_max = SEARCH_CAP_FACTOR x the SEARCH_CAP_PERCENTILE-th percentile over up to SEARCH_CAP_SAMPLE
        of the tree's photons (strided in tree order: spread over the map as its photons are) of the
        distance to their own kq-th neighbour, the photon itself not counted.  Computed once per
        (tree, kq): by :meth:`build` for the searches its estimator makes (map building), else at the
        first look-up that needs it.
        """
        if not (SEARCH_CAP and self.bounded):
            return np.inf
        key = (id(tree), int(kq))
        cap = self._caps.get(key)
        if cap is None:
            N = tree.pts.shape[0]
            if kq + 1 > N:
                cap = np.inf
            else:
                rows = np.unique(np.linspace(0, N - 1, min(N, SEARCH_CAP_SAMPLE)).astype(np.int64))
                q = tree.xyzt[:, rows].T.astype(np.float64)
                if tree.dims == 4:
                    q[:, 3] *= tree.s
                r = tree.knn_radius(q, kq + 1, np.inf, self.workers)
                cap = float(SEARCH_CAP_FACTOR * np.percentile(r, SEARCH_CAP_PERCENTILE))
                cap = cap if cap > 0.0 else np.inf      # (all photons at one point: nothing to bound)
            self._caps[key] = cap
        return cap

    def _capped_lookup(self, tree, mode, q, ns, kq, k, kernel, ng, glossy=None, rows=None, out=None, back=None):
        """tree.lookup(...) in the tangent slab of the normals ng (:func:`_slab_normals`), capped at
        :meth:`search_cap` (counted in ``stats['capped_count']``); rows, out: ``FlatTree.lookup``'s
        (answer only those rows of the queries, into those arrays); back: the slab's back fraction
        (None: ``PLANE_FRACTION``; :meth:`estimate`).  The boundary correction (``edge``) is made at
        the default slab only: a given back fraction is final gathering's cache
        (``gather.IrradianceCache.build``), which stays uncorrected (its oracle in tests/test_final_gather.py)."""
        cap = self.search_cap(tree, kq)
        res = tree.lookup(mode, q, ns, kq, k, kernel == "CONE", CONE_K, self.workers, glossy, cap=cap, ng=ng,
                          plane=PLANE_FRACTION if back is None else back, plane_front=PLANE_FRONT, rows=rows, out=out,
                          edge=self.edge and EDGE_CORRECTION and back is None)
        if np.isfinite(cap):
            r = res[1] if rows is None else res[1][rows]
            self.stats["capped_count"] += int(np.count_nonzero(r >= cap))
        return res

    def build(self, estimator: str, *, k: int = 50, temporal_alpha: float = 0.0) -> None:
        """Build now the tree(s) ``estimator``'s look-ups read and their search caps (:meth:`search_cap`), so
        that neither is charged to look-ups: both are map building (``stats['tree_build_s']``).

        (Until 2026-12-07 the caps were found inside the first look-up of each tree: 2048 k-nearest
        searches per tree, B of them for TEMPORAL's B time slices against one for STANDARD's tree;
        docs/photon-mapping.md, "Bounded searches".)
        """
        if self.n == 0:
            return
        estimator, k, m, B = self._plan(estimator.upper(), k, temporal_alpha)
        self._numba_or_scipy(lambda: self._build_searches(estimator, k, m, B))

    def _build_searches(self, estimator: str, k: int, m: int, B: int) -> None:
        """:meth:`build` with the map's current engine, for :meth:`_plan`'s (estimator, k, m, B)."""
        if B > 1:
            sl = self.time_slices(B)
            # each slice's search as _search_sliced makes it: kq = m_j = min(m, its photons), if k_j >= 2
            searches = [(tree, min(m, len(rows))) for rows, tree in zip(sl["rows"], sl["trees"])
                        if tree is not None and min(k, min(m, len(rows)) - 1) >= 2]
        elif self.backend == "numba":
            searches = [(self.flat_tree(4 if estimator == "KD4D" else 3), m if estimator == "TEMPORAL" else k)]
        else:
            self.tree4() if estimator == "KD4D" else self.tree3()
            return
        if self.backend != "numba":
            return
        t0 = _time.perf_counter()
        for tree, kq in searches:
            self.search_cap(tree, kq)
        self.stats["tree_build_s"] += _time.perf_counter() - t0

    def _plan(self, estimator: str, k: int, temporal_alpha: float) -> tuple[str, int, int, int]:
        """(estimator, k, m, B) of :meth:`estimate`'s searches on this map (n >= 2 photons) for an upper-case
        estimator name: the estimator actually run (STANDARD on a timeless map, or for TEMPORAL with
        fewer than 2 photons to select), k >= 2 clipped to the map, TEMPORAL's candidates m (else m = k)
        and its time slices B (else 1)."""
        if self.timeless:
            estimator = "STANDARD"  # time adds nothing: every photon has the same time
        # k >= 2 so there is at least one inner photon; never more than the map holds
        k = int(min(max(k, 2), self.n))
        m = k
        B = 1
        if estimator == "TEMPORAL":
            B = temporal_slices(self.n, k, temporal_alpha)
            m = min(temporal_candidates(self.n, k, temporal_alpha), self.n)
            k = min(k, m - 1)
            if k < 2:
                estimator = "STANDARD"
                k = m = int(min(self.n, 2))
                B = 1
        return estimator, k, m, B

    def _numba_or_scipy(self, fn):
        """fn() with the current engine; if the compiled one fails, switch this map to scipy and call fn() again."""
        try:
            return fn()
        except Exception as exc:  # noqa: BLE001 -- a compile or run failure falls back to scipy
            if self.backend != "numba":
                raise
            self._fall_back(exc)
            return fn()

    def _fall_back(self, exc: Exception) -> None:
        """The compiled path failed (e.g. no compiler cache, broken llvmlite): use scipy from now on."""
        _kdtree.disable(f"{type(exc).__name__}: {exc}")
        warnings.warn(f"STPM: compiled photon look-ups failed ({exc}); using scipy", RuntimeWarning)
        self.backend = "scipy"

    # -- the estimate ---------------------------------------------------------
    def estimate(self, p: np.ndarray, ns: np.ndarray, t: np.ndarray, *, estimator: str = "TEMPORAL",
                 k: int = 50, kernel: str = "BOX", temporal_alpha: float = 0.0, support: bool = False,
                 glossy=None, ng: np.ndarray | None = None, back: float | None = None):
        """Irradiance E (n, 3) W/m^2 at points p (n, 3), normals ns (n, 3), times t (n,).

        ng: (n, 3) unit geometric normals of the queries' surfaces, or None (no slab).  Only
        photons in the tangent slab |(x_p - x_q) . ng| <= ``PLANE_FRACTION`` r count (r the
        estimate's radius), so a surface near the query but off its plane (the wall behind a
        curtain) adds nothing; the measure stays the disc (docs/photon-mapping.md, "Tangent slab").
        With the slab, a photon behind the plane also needs its stored surface normal within
        acos(``NORMAL_COS``) of ng (an open outer corner's face, at right angles, adds nothing).
        A zero row switches the slab off for that query (h = 0 for every photon): for surfaces that
        move or deform, whose photons of other times lie off today's plane (:func:`plane_weights`).
        The geometric normal, not a bent shading one (smooth shading, normal maps).
        back: the slab's back fraction for these queries (None: ``PLANE_FRACTION``); any value >= 1
        bounds no photon of the search region (each lies within the region's radius of the query,
        so |h| <= rho) and leaves the photon-normal test alone (final gathering's cache:
        ``photons.gather.GATHER_PLANE_BACK``).

        glossy: None, or (closure rows (n, N_CLOSURE), (wo, ns, ng) (n, 9) of each query's hit, E,
        E_avg, coat_w) (``kdtree.FlatTree.lookup``): then returns (E, L_g), L_g (n, 3) W/(m^2 sr)
        the radiance the hit's rough lobes reflect of the same photons, those with a delta-only
        path: sum w f_c(wo, wi_p) Phi_p over the estimate's measure (docs/rendering.md, "Path
        partition").  The compiled search only (a ``RuntimeError`` on the scipy backend); with
        support, ``(E, r, tau, lo, hi, L_g)``.

        support: also return the region each estimate read, ``(E, r, tau, lo, hi)``, all (n,):
        r (m) its spatial radius (STANDARD r_k, TEMPORAL r_m, KD4D R_k), tau its time half-width
        (TEMPORAL tau, KD4D R / s; STANDARD and timeless maps inf: the estimate does not depend on
        t), [lo, hi] the shutter times its photons come from (TEMPORAL's time slice, else [0, 1];
        STANDARD (-inf, inf)).  r = 0 where nothing was estimated (an empty map or slice).  What
        ``photons.sharing`` needs to decide which other queries may reuse an estimate.
        """
        if back is not None and not float(back) > 0.0:
            raise ValueError(f"tangent slab back fraction must be > 0 (>= 1: no bound), got {back!r}")
        p = np.asarray(p, dtype=np.float64).reshape(-1, 3) - self.origin  # into the records' frame
        n = p.shape[0]
        E = np.zeros((n, 3), dtype=np.float64)
        if glossy is not None and self.backend != "numba":
            raise RuntimeError("glossy look-ups need the compiled search")
        if self.n < 2 or n == 0:
            if glossy is not None and not support:
                return E, np.zeros((n, 3))
            if glossy is not None:
                return E, np.zeros(n), np.full(n, np.inf), np.full(n, -np.inf), np.full(n, np.inf), np.zeros((n, 3))
            return (E, np.zeros(n), np.full(n, np.inf), np.full(n, -np.inf), np.full(n, np.inf)) if support else E
        ns = np.asarray(ns, dtype=np.float32).reshape(-1, 3)
        ng = _slab_normals(ng, ns)
        t = np.broadcast_to(np.asarray(t, dtype=np.float64), (n,))
        estimator = estimator.upper()
        if estimator not in ESTIMATOR_NAMES:
            raise ValueError(f"unknown estimator {estimator!r}")
        asked = estimator
        estimator, k, m, B = self._plan(estimator, k, temporal_alpha)
        if asked == "TEMPORAL" and not self.timeless:
            self.stats["temporal_candidates"] = m
            self.stats["temporal_slices"] = B
        t0 = _time.perf_counter()
        if B > 1:
            if glossy is not None:
                E[:], r, tau, lo, hi, Lg = self._search_sliced(B, p, ns, t, k, m, kernel, glossy, ng=ng, back=back)
                self.stats["lookup_s"] += _time.perf_counter() - t0
                self.stats["lookup_count"] += n
                return (E, r, tau, lo, hi, Lg) if support else (E, Lg)
            E[:], r, tau, lo, hi = self._estimate_sliced(B, p, ns, t, k, m, kernel, ng, back)
            self.stats["lookup_s"] += _time.perf_counter() - t0
            self.stats["lookup_count"] += n
            return (E, r, tau, lo, hi) if support else E
        # -- search: Phi summed over the inner / selected photons, radius, time window ----------
        if glossy is not None:
            Phi, r, tau, G = self._search_numba(estimator, p, ns, t, k, m, kernel, glossy, ng=ng, back=back)
            E[:] = self._normalise(estimator, Phi, r, tau, t, kernel)
            Lg = self._normalise(estimator, G, r, tau, t, kernel)
            self.stats["lookup_s"] += _time.perf_counter() - t0
            self.stats["lookup_count"] += n
            if not support:
                return E, Lg
            return self._support(estimator, E, r, tau) + (Lg,)
        if self.backend == "numba":
            try:
                Phi, r, tau = self._search_numba(estimator, p, ns, t, k, m, kernel, ng=ng, back=back)
            except Exception as exc:  # noqa: BLE001 -- fall back to scipy, same answer
                self._fall_back(exc)
        if self.backend == "scipy":
            Phi, r, tau = self._search_scipy(estimator, p, ns, t, k, m, kernel, ng, back)
        # -- normalise: the same numpy code for both searches ------------------------------------
        E[:] = self._normalise(estimator, Phi, r, tau, t, kernel)
        self.stats["lookup_s"] += _time.perf_counter() - t0
        self.stats["lookup_count"] += n
        if not support:
            return E
        return self._support(estimator, E, r, tau)

    def _support(self, estimator, E, r, tau):
        """(E, r, half, lo, hi): :meth:`estimate`'s result with its support (unsliced searches)."""
        n = r.shape[0]
        if estimator == "STANDARD":
            return E, r, np.full(n, np.inf), np.full(n, -np.inf), np.full(n, np.inf)
        half = tau if estimator == "TEMPORAL" else r / self.time_scale
        return E, r, half, np.zeros(n), np.ones(n)

    # -- TEMPORAL on time slices ---------------------------------------------------------------------
    def _estimate_sliced(self, B, p, ns, t, k, m, kernel, ng, back=None):
        """Consistent TEMPORAL: each query searches the slice holding its time: (E (n, 3) W/m^2,
        r_m (n,), tau (n,), and the slice [lo, hi] (n,) of each query).

        Within slice j = [a, b) the m candidates and the k nearest in time come from that slice's
        photons only, so the window is clipped to the slice: W = mass of [t - tau, t + tau] cut to
        [a, b] (docs/photon-mapping.md shows (k - 1) / (pi r_m^2 W) stays unbiased).
        A failure of the compiled search (build or look-up) redoes the estimate with scipy trees.
        """
        return self._numba_or_scipy(lambda: self._search_sliced(B, p, ns, t, k, m, kernel, ng=ng, back=back))

    def _search_sliced(self, B, p, ns, t, k, m, kernel, glossy=None, *, ng, back=None):
        """:meth:`_estimate_sliced` with the map's current engine (glossy: :meth:`estimate`'s; then
        the glossy radiance (n, 3) is a sixth result)."""
        sl = self.time_slices(B)
        edges = sl["edges"]
        which, order, starts = _by_slice(edges, t)
        n = p.shape[0]
        Phi, r, tau = np.zeros((n, 3)), np.zeros(n), np.zeros(n)
        G = np.zeros((n, 3)) if glossy is not None else None
        lo, hi = edges[which], edges[which + 1]
        if sl["backend"] == "numba":
            # every slice's queries read and answered in place (FlatTree.lookup's rows and out)
            qq = np.empty((n, 4))
            qq[:, :3] = p
            qq[:, 3] = t
            res = (Phi, r, tau) if glossy is None else (Phi, r, tau, G)
        for j in range(B):
            q = order[starts[j]:starts[j + 1]]
            rows, tree = sl["rows"][j], sl["trees"][j]
            if len(q) == 0 or tree is None:
                continue
            mj = min(m, len(rows))
            kj = min(k, mj - 1)
            if kj < 2:                                  # a nearly empty slice: nothing to estimate with
                continue
            if sl["backend"] == "numba":
                self._capped_lookup(tree, _kdtree.MODE_TEMPORAL, qq, ns, mj, kj, kernel, ng, glossy, rows=q, out=res,
                                    back=back)
            else:
                batch = max(256, _QUERY_BATCH_ELEMS // mj)
                for a in range(0, len(q), batch):
                    qb = q[a:a + batch]
                    Phi[qb], r[qb], tau[qb] = self._temporal(p[qb], ns[qb], t[qb], kj, mj, kernel, ng[qb],
                                                             tree=tree, rows=rows, back=back)
        E = self._normalise("TEMPORAL", Phi, r, tau, t, kernel, lo=lo, hi=hi)
        if glossy is not None:
            return E, r, tau, lo, hi, self._normalise("TEMPORAL", G, r, tau, t, kernel, lo=lo, hi=hi)
        return E, r, tau, lo, hi

    # -- normalisations (docs/photon-mapping.md, section 5) -------------------------------------------
    def _normalise(self, estimator, Phi, r, tau, t, kernel, lo=0.0, hi=1.0):
        """E (n, 3) W/m^2 from summed power Phi (n, 3) W, the k-th / m-th radius r (n,) and tau (n,).

        STANDARD: pi r_k^2; TEMPORAL: pi r_m^2 W, W the shutter mass of [t - tau, t + tau] cut to
        [lo, hi] (the shutter, or a time slice: scalars or (n,)); KD4D: the clipped ball V(R)/s;
        each times the kernel's mean weight over its neighbourhood.
        """
        cone = kernel == "CONE"
        if estimator == "KD4D":
            norm = 1.0 - 3.0 / (4.0 * CONE_K) if cone else 1.0   # mean cone weight over a 3-ball
            measure = norm * slab_ball_volume(self.shutter, np.maximum(r, 1e-12), t, self.time_scale)
            # measure 0: the ball's time span misses the shutter curve's support; a photon there can
            # only be a float32 time rounded just past its end, so read 0, never Phi / 0
            return np.where((measure > 0)[:, None], Phi / np.maximum(measure, 1e-300)[:, None], 0.0)
        norm = 1.0 - 2.0 / (3.0 * CONE_K) if cone else 1.0       # mean cone weight over a disc
        area = norm * np.pi * np.maximum(r, 1e-12) ** 2          # m^2
        if estimator == "TEMPORAL":
            W = shutter_mass(self.shutter, np.maximum(t - tau, lo), np.minimum(t + tau, hi))  # clipped window
            area = area * np.maximum(W, 1e-12)                    # m^2 (x mass)
        return Phi / area[:, None]

    # -- compiled search ------------------------------------------------------------------------
    def _search_numba(self, estimator, p, ns, t, k, m, kernel, glossy=None, *, ng, back=None):
        """(Phi (n, 3) W, r (n,) m, tau (n,)) from the fused numba kernel (see kdtree.py); with glossy
        (:meth:`estimate`) the glossy sums (n, 3) as a fourth."""
        q = np.empty((p.shape[0], 4))
        q[:, :3] = p
        if estimator == "KD4D":
            q[:, 3] = self.time_scale * t
            tree, mode = self.flat_tree(4), _kdtree.MODE_KD4D
        else:
            q[:, 3] = t
            tree = self.flat_tree(3)
            mode = _kdtree.MODE_TEMPORAL if estimator == "TEMPORAL" else _kdtree.MODE_STANDARD
        kq = m if estimator == "TEMPORAL" else k
        return self._capped_lookup(tree, mode, q, ns, kq, k, kernel, ng, glossy, back=back)

    # -- scipy search -----------------------------------------------------------------------------
    def _search_scipy(self, estimator, p, ns, t, k, m, kernel, ng, back=None):
        """(Phi (n, 3) W, r (n,) m, tau (n,)) with scipy's cKDTree, in memory-bounded batches."""
        n = p.shape[0]
        Phi, r, tau = np.zeros((n, 3)), np.zeros(n), np.zeros(n)
        per_query = m if estimator == "TEMPORAL" else k
        batch = max(256, _QUERY_BATCH_ELEMS // per_query)
        for lo in range(0, n, batch):
            sl = slice(lo, min(n, lo + batch))
            if estimator == "STANDARD":
                Phi[sl], r[sl] = self._standard(p[sl], ns[sl], k, kernel, ng[sl], back)
            elif estimator == "TEMPORAL":
                Phi[sl], r[sl], tau[sl] = self._temporal(p[sl], ns[sl], t[sl], k, m, kernel, ng[sl], back=back)
            else:
                Phi[sl], r[sl] = self._kd4d(p[sl], ns[sl], t[sl], k, kernel, ng[sl], back)
        return Phi, r, tau

    def _weighted_sum(self, idx: np.ndarray, ns: np.ndarray, w: np.ndarray | None, p: np.ndarray,
                      ng: np.ndarray, rho2: np.ndarray, back: float | None = None) -> np.ndarray:
        """sum_j [dot(ns, wi_j) > 0] [x_j in the tangent slab] w_j Phi_j over idx (n, j) -> (n, 3) W.

        The slab (``kdtree._in_slab``): -PLANE_FRACTION rho <= (x_j - p) . ng <= PLANE_FRONT rho, p (n, 3)
        the queries, ng (n, 3) their geometric normals, rho2 (n, 1) or (n, j) the squared radius of
        the region's section at each photon (r^2; KD4D's R^2 - (s dt)^2); and, where the slab is on
        (ng not zero), the normal test dot(n_j, ng) >= NORMAL_COS of photons with a stored normal
        behind the plane (h < 0; ``kdtree._facing``).  back: PLANE_FRACTION's stand-in (None: it)."""
        G = np.take(self._packed, idx, axis=0)                     # (n, j, 8): one gather per photon
        side = (G[..., 0] * ns[:, None, 0] + G[..., 1] * ns[:, None, 1] + G[..., 2] * ns[:, None, 2]) > 0.0
        h = np.einsum("njc,nc->nj", self.position[idx] - p[:, None, :], ng.astype(np.float64))
        c = np.where(h >= 0.0, PLANE_FRONT, PLANE_FRACTION if back is None else back)
        with np.errstate(invalid="ignore"):        # (inf x 0 where rho = 0 and a bound is off: no bound)
            side &= np.isinf(c) | (h * h <= c * c * rho2)
        code = G[..., 7]
        if np.any(code > 0.0):
            n_p = decode_normal_codes(code.ravel()).reshape(code.shape + (3,))
            on = np.any(ng != 0.0, axis=1)[:, None]
            side &= (~on | (code <= 0.0) | (h >= 0.0)
                     | (np.einsum("njc,nc->nj", n_p, ng.astype(np.float64)) >= NORMAL_COS))
        weight = side.astype(np.float32) if w is None else side * w.astype(np.float32)
        return np.einsum("nk,nkc->nc", weight, G[..., 4:7]).astype(np.float64)

    @staticmethod
    def _cone(d: np.ndarray, r: np.ndarray) -> np.ndarray:
        """Cone kernel weights 1 - d / (CONE_K r) (n, j)."""
        return 1.0 - d / (CONE_K * np.maximum(r, 1e-300)[:, None])

    def _standard(self, p, ns, k, kernel, ng, back=None):
        """STANDARD: Phi over the k - 1 inner photons (in the tangent slab), r_k."""
        d, idx = self.tree3().query(p, k, workers=self.workers)
        r = d[:, -1]                                   # radius reaching the k-th photon (m)
        w = self._cone(d[:, :-1], r) if kernel == "CONE" else None
        return self._weighted_sum(idx[:, :-1], ns, w, p, ng, (r * r)[:, None], back), r

    def _temporal(self, p, ns, t, k, m, kernel, ng, tree=None, rows=None, back=None):
        """TEMPORAL: Phi over the k - 1 nearest in time among m - 1 inner candidates, r_m, tau_k.

        ``tree`` / ``rows``: search a time slice's cKDTree whose point i is photon ``rows[i]``
        (default: the whole map's 3D tree).
        """
        d, idx = (tree or self.tree3()).query(p, m, workers=self.workers)
        if rows is not None:
            idx = rows[idx]
        r = d[:, -1]                                   # candidate disc radius: the m-th photon (m)
        cand, d_c = idx[:, :-1], d[:, :-1]             # m - 1 inner candidates
        dt = np.abs(self.time[cand] - t[:, None])      # time distances (shutter units)
        # Quickselect the k nearest in time; position k-1 holds the k-th (fixes the window)
        part = np.argpartition(dt, k - 1, axis=1)
        rows = np.arange(cand.shape[0])[:, None]
        tau = dt[rows[:, 0], part[:, k - 1]]           # window half-width (shutter units)
        sel = part[:, : k - 1]                         # k - 1 photons strictly inside the window
        w = self._cone(d_c[rows, sel], r) if kernel == "CONE" else None
        return self._weighted_sum(cand[rows, sel], ns, w, p, ng, (r * r)[:, None], back), r, tau

    def _kd4d(self, p, ns, t, k, kernel, ng, back=None):
        """KD4D: Phi over the k - 1 inner photons in (x, y, z, s t), R_k."""
        q = np.empty((p.shape[0], 4))
        q[:, :3] = p
        q[:, 3] = self.time_scale * t
        d, idx = self.tree4().query(q, k, workers=self.workers)
        R = d[:, -1]                                   # 4D radius reaching the k-th photon (m)
        w = self._cone(d[:, :-1], R) if kernel == "CONE" else None
        dt = self.time_scale * self.time[idx[:, :-1]] - q[:, 3:4]     # s t_j - s t (m)
        return self._weighted_sum(idx[:, :-1], ns, w, p, ng, np.maximum((R * R)[:, None] - dt * dt, 0.0), back), R
