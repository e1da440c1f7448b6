"""Progressive photon mapping in space x time: fixed-size kernels that shrink pass by pass.

    pilot = build_pilot(scene, settings, caster, lights)        # once per render, its own photons
    for i in 1, 2, ...:
        maps = build_photon_maps(scene, settings_i, ...)         # pass i's own photons
        pm = ProgressiveMaps(maps, pilot, pass_index=i, ...)     # what the integrator reads
        image_i = trace_image(..., pm, ...)
    image = mean of image_i                                       # converges

Knaus & Zwicker's probabilistic progressive photon mapping (2011): each pass
is an ordinary density estimate whose kernel has a *sample-independent* size;
its measure (area, or area x shutter mass) shrinks by

    V_{i+1} = V_i (i + a) / (i + 1),     so   V_i = V_1 Gamma(i + a) / (Gamma(1 + a) Gamma(i + 1)) ~ i^(a - 1),

and the average of the passes converges: its variance falls as N^-a, its
bias as N^-(1-a) b/d for a d-dimensional kernel whose bias is of order
V^(b/d) (b = 2 where the light is smooth, 1 across an edge), so
a = 2b / (d + 2b) balances them.  d = 2 for the surface disc (STANDARD: time
ignored), 3 for the space-time kernels (TEMPORAL's cylinder and KD4D's ball:
2 surface dimensions + time); the default a = 2 / (d + 2) is the edge case.
docs/photon-mapping.md ("Progressive") derives it with units.

Kernel shapes (:meth:`Pilot.region_at` gives pass 1's, :meth:`ProgressiveMaps.estimate` shrinks
them and clips them to the pass's time stratum):

* STANDARD: the ball |x - x_q| < r, normalised by the disc pi r^2 (time ignored);
* TEMPORAL: the cylinder |x - x_q| < r, |t - t_q| <= tau with (r, tau) from the pilot's own
  TEMPORAL search (its aspect follows the light), normalised by pi r^2 W, W the shutter mass of
  the window;
* KD4D: the 4D ball of radius R in (x, y, z, s t) (s the scene's time scale), normalised by the
  clipped ball measure V(R) / s (``estimators.slab_ball_volume``).

The initial size at each query point comes from a pilot photon map traced
with its own random stream (never the pass's photons, or the passes would
not be independent estimates of a fixed kernel and the analysis would no
longer hold): the pilot's k_p-nearest region at the query, scaled so that one
pass's photons are expected to put about k = ``settings.k_nearest`` photons
inside it, read on a grid of cells (one pilot search per cell and render).  So
pass 1 looks like a fixed-k render of one pass's photons, and every later pass
is sharper.
"""
from __future__ import annotations

import math
import threading
import time as _time

import numpy as np

from ..sampling import rng_for
from . import hashgrid as _hashgrid
from . import estimators as _estimators
from .estimators import CONE_K, shutter_mass, slab_ball_volume
from .kdtree import MODE_TEMPORAL
from .maps import KINDS, build_photon_maps

__all__ = ["PILOT_K", "kernel_dims", "auto_shrink_alpha", "shrink_ratio", "Pilot", "build_pilot",
           "ProgressiveMaps", "pilot_photons"]

PILOT_K = 16                  # photons per pilot search (k_p); fewer than k: the pilot is traced smaller
CAP_FACTOR = 4.0              # pilot searches stop at CAP_FACTOR x the pilot photons' own 90th-percentile radius
CAP_SAMPLE = 4096             # pilot photons whose own radius sets the cap
TEMPORAL_PILOT = 1.5          # TEMPORAL's pilot: spatial candidates per search as a multiple of PILOT_K (the paper's)
GRID_FRACTION = 0.25          # pilot sizes are read on a grid of cells this x the pilot photons' median radius
TIME_CELLS = 32               # ... and this many cells across the shutter (space-time kernels)
GRID_CELLS_MAX = 1 << 17      # cells a region table keeps (6 MiB); regions of cells beyond are computed, not kept
_AXIS_BITS = 18               # grid cells per axis: 2^18 (keys: 3 x 18 bits + 7 bits of time)
STREAM_PILOT = 0x9170         # the pilot's random stream (independent of every pass's)


def kernel_dims(estimator: str) -> int:
    """The kernel's dimension d: 2 for STANDARD (a surface disc), 3 for TEMPORAL / KD4D (surface x time)."""
    return 2 if str(estimator).upper() == "STANDARD" else 3


def auto_shrink_alpha(estimator: str) -> float:
    """a = 2 / (d + 2): the best balance of variance and bias where edges dominate the error (0.5 for d = 2,
    0.4 for d = 3).

    A symmetric kernel's bias is second order (V^(2/d)) where the light is smooth, which gives
    Knaus & Zwicker's a = 4 / (d + 4); across a shadow or caustic edge, or a moment light switches
    on, it is first order (V^(1/d)), which gives 2 / (d + 2).  Images are judged where they have
    edges, and the measured optimum on the moving caustic (docs/photon-mapping.md, "Progressive")
    sits there.
    """
    return 2.0 / (kernel_dims(estimator) + 2.0)


def shrink_ratio(i: int, alpha: float) -> float:
    """V_i / V_1 = prod_{j=1}^{i-1} (j + a) / (j + 1) = Gamma(i + a) / (Gamma(1 + a) Gamma(i + 1)); i >= 1."""
    if i < 1:
        raise ValueError(f"pass index must be >= 1, got {i}")
    return math.exp(math.lgamma(i + alpha) - math.lgamma(1.0 + alpha) - math.lgamma(i + 1.0))


def pilot_photons(n_pass: int, k: int) -> int:
    """Photons of a pilot map: (k_p - 1) / k of a pass's, so its k_p-nearest region holds about k of a pass's."""
    if n_pass <= 0:
        return 0
    return max(int(math.ceil(n_pass * (PILOT_K - 1) / max(k, PILOT_K))), 4 * PILOT_K)


class Pilot:
    """The pilot maps of one progressive render and the initial kernel size they give.

    Attributes
    ----------
    maps : PhotonMaps of the pilot photons (``photons_*`` = :func:`pilot_photons` of the pass's).
    scale : {kind: c} with c the measure factor V_0 = c V_pilot: one pass's photons expected in V_0
        = k (``(k / (k_p - 1)) (N_pilot / N_pass)``; 1 when the pilot count was rounded exactly).
    estimator : the kernel's shape; time_scale : s (m per shutter).
    """

    def __init__(self, maps, scale: dict, estimator: str, time_scale: float, seconds: float):
        self.maps = maps
        self.scale = dict(scale)
        self.estimator = estimator
        self.time_scale = float(time_scale)
        self.seconds = float(seconds)
        self.cap = {}
        self._median = {}
        self._grids = {}
        self._lock = threading.Lock()

    def _tree(self, kind: str, static: bool = False):
        """(the pilot map's kd-tree for this kernel, its dimension d); static: the surface disc's
        (a static view's kernel, :meth:`ProgressiveMaps.estimate`)."""
        m = self.maps.maps[kind]
        if static or self.estimator == "STANDARD" or m.timeless:
            return m.flat_tree(3), 2
        return m.flat_tree(4), 3

    def search_cap(self, kind: str, static: bool = False) -> float:
        """The farthest a pilot search looks (m): CAP_FACTOR x the 90th percentile of the PILOT_K-nearest
        radius of the pilot photons themselves (at most CAP_SAMPLE of them, evenly strided).

        A query with fewer than PILOT_K pilot photons that near lies far from any light the map
        carries (a dark region): its region stops at the cap, so its searches stay cheap, and the
        pass's photons there (if any) are read with that radius.  A pure function of the pilot.
        """
        key = (kind, True) if static else kind
        if key not in self.cap:
            m = self.maps.maps[kind]
            tree, d = self._tree(kind, static)
            idx = np.arange(0, m.n, max(1, m.n // CAP_SAMPLE))
            q = np.empty((idx.size, 4))
            q[:, :3] = m.position[idx]
            q[:, 3] = self.time_scale * m.time[idx]
            r = tree.knn_radius(q, PILOT_K + 1, np.inf, m.workers)     # + 1: the photon itself
            # _median first: tile threads that see cap[kind] go on to read _median[kind]
            self._median[key] = float(np.median(r))
            self.cap[key] = CAP_FACTOR * float(np.percentile(r, 90.0))
        return self.cap[key]

    def initial_size(self, kind: str, q: np.ndarray, ns: np.ndarray, static: bool = False):
        """Pass 1's region at queries q (n, 4) (x, y, z relative to the map origin, s t): (r (n,) m,
        tau (n,) shutter units or None) -- :meth:`region_at` read on a grid.

        The region of a query is the one at the centre of its grid cell (cells of GRID_FRACTION x the
        pilot photons' median radius, TIME_CELLS across the shutter), evaluated once per cell and
        kept: a pilot search per camera sample and pass costs as much as the pass's own look-up;
        per cell it is paid once per render.  Still a pure function of the pilot and the point (the
        passes' analysis holds); the k-NN radius moves by at most the distance it is read from, a
        quarter of the radius, so the regions hardly differ from the exact ones.  static: the surface
        disc of a static view (tau None), on a grid of its own.
        """
        m = self.maps.maps[kind]
        n = q.shape[0]
        if m.n <= PILOT_K:
            return np.full(n, np.inf), None
        grid = self._grid(kind, static)
        h, lo, nt = grid["h"], grid["lo"], grid["nt"]
        cells = np.clip(np.floor((q[:, :3] - lo) / h), 0, (1 << _AXIS_BITS) - 1).astype(np.int64)
        it = np.clip(np.floor(q[:, 3] / self.time_scale * nt), 0, nt - 1).astype(np.int64) if nt > 1 \
            else np.zeros(n, np.int64)
        keys = (((cells[:, 0] << _AXIS_BITS) | cells[:, 1]) << _AXIS_BITS | cells[:, 2]) << 7 | it
        with self._lock:
            table = grid["table"]
            have, r, tau = table.get(keys)
            if not have.all():
                # the regions at the new cells' centres, each once; kept while the table has room
                # (a full table: these cells' regions are used, not kept -- the same values either way)
                miss = ~have
                new, inv = np.unique(keys[miss], return_inverse=True)
                qc = np.empty((new.size, 4))
                ci = np.stack([(new >> (7 + 2 * _AXIS_BITS)) & ((1 << _AXIS_BITS) - 1),
                               (new >> (7 + _AXIS_BITS)) & ((1 << _AXIS_BITS) - 1),
                               (new >> 7) & ((1 << _AXIS_BITS) - 1)], axis=1)
                qc[:, :3] = lo + (ci + 0.5) * h
                qc[:, 3] = self.time_scale * ((new & 127) + 0.5) / nt if nt > 1 else self.time_scale * 0.5
                r_new, tau_new = self.region_at(kind, qc, static)
                tau_new = tau_new if tau_new is not None else np.zeros(new.size)
                r[miss], tau[miss] = r_new[inv], tau_new[inv]
                table.put(new, r_new, tau_new)
        return r, (tau if grid["timed"] else None)

    def _grid(self, kind: str, static: bool = False) -> dict:
        """The cache of regions on kind's grid (built empty on first use); static: the discs' grid."""
        key = (kind, True) if static else kind
        with self._lock:
            g = self._grids.get(key)
        if g is not None:
            return g
        m = self.maps.maps[kind]
        median = self._median_radius(kind, static)
        lo = m.position.min(axis=0) - 4 * self.search_cap(kind, static)
        timed = self.estimator == "TEMPORAL" and not m.timeless and not static
        nt = TIME_CELLS if self.estimator != "STANDARD" and not m.timeless and not static else 1
        g = {"h": max(GRID_FRACTION * median, 1e-9), "lo": lo, "nt": nt, "timed": timed,
             "table": _hashgrid.CellTable(GRID_CELLS_MAX)}
        with self._lock:
            return self._grids.setdefault(key, g)

    def _median_radius(self, kind: str, static: bool = False) -> float:
        self.search_cap(kind, static)
        return self._median[(kind, True) if static else kind]

    def region_at(self, kind: str, q: np.ndarray, static: bool = False):
        """Pass 1's region exactly at points q (n, 4) (x, y, z relative to the map origin, s t).

        STANDARD / KD4D: the pilot's PILOT_K-th nearest photon (3D / 4D) fixes a ball holding
        PILOT_K - 1 pilot photons; r is its radius scaled so the ball's measure holds about k of a
        pass's photons (tau None).  TEMPORAL: the pilot's own TEMPORAL search (TEMPORAL_PILOT x PILOT_K
        spatial candidates, the PILOT_K nearest in time among them) fixes a cylinder (r, tau) holding
        PILOT_K - 1 pilot photons, so its aspect follows the light: long in time where the light holds
        still, short where it changes; both sides scaled by the cube root of the measure factor.
        r is inf where the pilot map holds no more than PILOT_K photons (the pass then reads 0).
        static: STANDARD's disc whatever the estimator (a static view's kernel).
        """
        m = self.maps.maps[kind]
        n = q.shape[0]
        if m.n <= PILOT_K:
            return np.full(n, np.inf), None
        tree, d = self._tree(kind, static)
        c = self.scale[kind] ** (1.0 / d)
        if self.estimator == "TEMPORAL" and d == 3:
            m_c = min(int(math.ceil(TEMPORAL_PILOT * PILOT_K)), m.n)
            qt = np.ascontiguousarray(q, dtype=np.float64).copy()
            qt[:, 3] = q[:, 3] / self.time_scale                   # the 3D tree's queries carry t itself
            up = np.zeros((n, 3), np.float32)
            up[:, 2] = 1.0                                        # (the side test does not change r, tau)
            _, r, tau = m.flat_tree(3).lookup(MODE_TEMPORAL, qt, up, m_c, PILOT_K, False, CONE_K, m.workers)
            return r * c, tau * c
        r = tree.knn_radius(q, PILOT_K, self.search_cap(kind, static), m.workers)
        return r * c, None


def build_pilot(scene, settings, caster, lights, *, time_scale: float, progress=None, cancel=None) -> Pilot:
    """Trace the pilot maps: :func:`pilot_photons` of each map's pass count, from the pilot's own stream."""
    t0 = _time.perf_counter()
    k = int(settings.k_nearest)
    n_c, n_g = pilot_photons(settings.photons_caustic, k), pilot_photons(settings.photons_global, k)
    seed = int(rng_for(settings.seed, STREAM_PILOT).integers(0, 2**62))
    ps = settings.replace(seed=seed, photons_caustic=n_c, photons_global=n_g, time_scale=time_scale)
    maps = build_photon_maps(scene, ps, caster, lights, progress=progress, cancel=cancel)
    scale = {}
    for kind, n_pass, n_pilot in (("caustic", settings.photons_caustic, n_c), ("global", settings.photons_global, n_g)):
        scale[kind] = (k / (PILOT_K - 1)) * (n_pilot / n_pass) if n_pass > 0 else 1.0
    return Pilot(maps, scale, settings.estimator, time_scale, _time.perf_counter() - t0)


class ProgressiveMaps:
    """One pass's photon maps read with the pass's fixed-size kernels (what the integrator calls ``maps``).

    Parameters
    ----------
    maps : the pass's PhotonMaps (its own photons); pilot : :class:`Pilot` of the render;
    pass_index : i >= 1 (1-based over the whole render, whatever the machine rendering it);
    alpha : the shrink parameter a; kernel : 'BOX' or 'CONE'.

    ``estimate(kind, p, ns, t)`` returns irradiance E (n, 3) W/m^2 like :meth:`PhotonMaps.estimate`:
    E = sum of the photons' power in the region / its measure, with the region's radius
    r_i = r_1(x, t) (V_i / V_1)^(1/d) (no k/(k-1) term: a fixed region is unbiased for the
    kernel-smoothed density).
    """

    #: ``estimate(..., estimator='STANDARD')`` reads a static view with the surface disc
    #: (integrator.static_view_setup)
    reads_standard = True

    def __init__(self, maps, pilot: Pilot, *, pass_index: int, alpha: float, kernel: str = "BOX",
                 stratum: tuple | None = None, static_alpha: float | None = None):
        self.maps = maps
        # the pass's time stratum: (lo, hi) shutter times and its shutter mass w (its photons' and camera
        # samples' times lie in it); None = the whole shutter
        self.stratum = (0.0, 1.0, 1.0) if stratum is None else tuple(float(x) for x in stratum)
        self.pilot = pilot
        self.pass_index = int(pass_index)
        self.alpha = float(alpha)
        self.kernel = str(kernel).upper()
        self.estimator = pilot.estimator
        self.d = kernel_dims(self.estimator)
        self.radius_scale = shrink_ratio(self.pass_index, self.alpha) ** (1.0 / self.d)
        # a static view's disc (d = 2) shrinks by its own schedule: a = static_alpha, else 2 / (2 + 2)
        self.static_alpha = auto_shrink_alpha("STANDARD") if static_alpha is None else float(static_alpha)
        self.static_radius_scale = shrink_ratio(self.pass_index, self.static_alpha) ** 0.5
        self._photons_in = {kind: [0, 0] for kind in KINDS}     # photons inside regions, queries
        self._radius = {kind: [] for kind in KINDS}             # a sample of the radii used (for stats)
        self._lookup_s = 0.0

    def _range_sum(self, kind, dims, q, ns, r, half, cone, glossy=None, ng=None):
        """(Phi (n, 3), count (n,)) of the pass's photons inside each region and its tangent slab (the
        kd-tree's range query); with glossy (:meth:`estimate`) also the regions' glossy sums (n, 3)."""
        m = self.maps.maps[kind]
        return m.flat_tree(dims).range_sum(q, ns, r, half, cone, CONE_K, m.workers, glossy, ng=ng,
                                           plane=_estimators.PLANE_FRACTION, plane_front=_estimators.PLANE_FRONT)

    @property
    def glossy_lookups(self) -> bool:
        """Can :meth:`estimate` weigh caustic photons by a rough lobe (``glossy``)?  The range query
        is the compiled one's (``kdtree._range``): wherever the pass has caustic photons."""
        return self.has("caustic")

    def prepare(self, static: bool = False) -> None:
        """Build now the kd-trees :meth:`estimate` reads (else built on its first call; the same trees);
        static: also the 3D trees of static views' discs."""
        for kind in KINDS:
            if self.has(kind):
                m = self.maps.maps[kind]
                timeless = self.estimator == "STANDARD" or m.timeless or self.pilot.maps.maps[kind].timeless
                m.flat_tree(3 if timeless else 4)
                if not timeless and static:
                    m.flat_tree(3)                                # static views' discs

    def has(self, kind: str) -> bool:
        return self.maps.has(kind) and self.pilot.maps.maps[kind].n > PILOT_K

    def estimate(self, kind: str, p: np.ndarray, ns: np.ndarray, t: np.ndarray, *,
                 estimator: str | None = None, glossy=None, ng: np.ndarray | None = None):
        """Irradiance E (n, 3) W/m^2 at p (n, 3) on the ns (n, 3) side at shutter times t (n,).

        ng (n, 3): the queries' unit geometric normals (None: no slab); only photons in the tangent slab
        -PLANE_FRACTION r <= (x_p - x_q) . ng <= PLANE_FRONT r of the region's radius r count
        (``estimators``; ``PhotonMap.estimate``; docs/photon-mapping.md, "Tangent slab").

        estimator 'STANDARD' with a space-time kernel: the queries are static views
        (``integrator.static_view_rows``), read with the surface disc over the pass's stratum (its
        own pilot region and schedule: d = 2), whose shutter average is their pixels' value.
        glossy: None, or (closure rows (n, N_CLOSURE), (wo, ns, ng) (n, 9), E, E_avg, coat_w) as
        ``PhotonMaps.estimate``'s: then (E, L_g), L_g (n, 3) W/(m^2 sr) = the region's sum of
        f_c(wo, wi_p) Phi_p over its delta-only photons divided by the same measure as E
        (docs/rendering.md, "Path partition").
        """
        if kind not in KINDS:
            raise ValueError(f"unknown photon map {kind!r} (expected one of {KINDS})")
        t0 = _time.perf_counter()
        m = self.maps.maps[kind]
        p = np.asarray(p, dtype=np.float64).reshape(-1, 3)
        n = p.shape[0]
        E = np.zeros((n, 3))
        Lg = np.zeros((n, 3)) if glossy is not None else None
        if n == 0 or not self.has(kind):
            return E if glossy is None else (E, Lg)
        ns = np.ascontiguousarray(np.asarray(ns, dtype=np.float32).reshape(-1, 3))
        t = np.broadcast_to(np.asarray(t, dtype=np.float64), (n,))
        s = self.pilot.time_scale
        q = np.empty((n, 4))
        q[:, 3] = s * t
        # -- this pass's radius at each query: the pilot's, shrunk by the schedule -----------------
        pm = self.pilot.maps.maps[kind]
        q[:, :3] = p - pm.origin
        timeless = self.estimator == "STANDARD" or m.timeless or pm.timeless
        static = not timeless and str(estimator or "").upper() == "STANDARD"
        r, tau = self.pilot.initial_size(kind, q, ns, static)
        ok = np.isfinite(r)
        r = np.where(ok, r, 0.0)
        c = self.static_radius_scale if static else self.radius_scale
        timeless = timeless or static
        lo, hi, w = self.stratum
        cone = self.kernel == "CONE"
        disc = 1.0 - 2.0 / (3.0 * CONE_K) if cone else 1.0     # mean cone weight over a disc
        ball = 1.0 - 3.0 / (4.0 * CONE_K) if cone else 1.0     # ... over a ball
        half = None
        # -- this pass's region at each query: the pilot's, shrunk by the schedule ------------------
        # (pass photons lie in the stratum, at w-fold time density: a region holds k V_i / V_1 of them
        # when its measure, clipped to the stratum and divided by w, is the pilot's times V_i / V_1)
        if timeless:
            r = r * c                                            # a disc over the whole stratum
        elif tau is not None:
            W0 = shutter_mass(m.shutter, t - tau, t + tau)       # the pilot's window, as a pass-1 region
            tau = tau * c
            Wc = shutter_mass(m.shutter, np.maximum(t - tau, lo), np.minimum(t + tau, hi))
            r = r * np.sqrt(np.where(Wc > 0, W0 * c ** 3 * w / np.maximum(Wc, 1e-300), 0.0))
            half = s * tau                                       # the cylinder's half-height in s t
        else:
            r = r * c * w ** (1.0 / 3.0)                         # the 4D ball, unclipped
        # -- photons of this pass inside each region -----------------------------------------------
        q[:, :3] = p - m.origin
        ng = np.ascontiguousarray(_estimators._slab_normals(ng, ns))
        sums = self._range_sum(kind, 3 if timeless else 4, q, ns, r, half, cone, glossy, ng)
        Phi, cnt = sums[0], sums[1]
        # -- normalise by the region's measure in the stratum (area x its share of the stratum's mass) --
        rr = np.maximum(r, 1e-12)
        if timeless:
            measure = disc * np.pi * rr * rr
        elif half is not None:
            measure = disc * np.pi * rr * rr * Wc / w
        else:
            measure = ball * slab_ball_volume(m.shutter, rr, t, s, lo, hi) / w
        ok &= r > 0
        good = ok & (measure > 0)
        E[good] = Phi[good] / measure[good, None]
        if glossy is not None:
            Lg[good] = sums[2][good] / measure[good, None]
        st = self._photons_in[kind]
        st[0] += int(cnt.sum())
        st[1] += n
        if len(self._radius[kind]) < 64:
            self._radius[kind].append(r[ok][:: max(1, int(ok.sum()) // 256)])
        self._lookup_s += _time.perf_counter() - t0
        return E if glossy is None else (E, Lg)

    @property
    def stats(self) -> dict:
        """The pass maps' stats plus the kernel: radius scale, median radius and photons per estimate."""
        st = dict(self.maps.stats)
        st["lookup_s"] = self._lookup_s
        st["pass_index"] = self.pass_index
        st["shrink_alpha"] = self.alpha
        st["kernel_radius_scale"] = self.radius_scale
        for kind in KINDS:
            inside, queries = self._photons_in[kind]
            st[f"{kind}_photons_per_estimate"] = inside / queries if queries else 0.0
            rs = np.concatenate(self._radius[kind]) if self._radius[kind] else np.zeros(0)
            st[f"{kind}_median_radius"] = float(np.median(rs)) if rs.size else 0.0
        return st
