"""Photon emission guided by direct visibility (docs/photon-mapping.md, "Emission guided by direct
visibility"; setting ``photon_guiding``).

1. **Camera pilot** (:func:`camera_pilot`): ``PILOT_RAYS`` jittered primary rays, each at its own
   stratified shutter time, followed through delta and glossy lobes (a mirror, clear glass) to the
   first surface with a non-delta lobe, as the camera paths read the maps there: the points the
   camera sees, with the direction back toward the camera and the time.
2. **Marks** (:func:`build_guides`): the seen points and the points they see
   (:func:`bounce_points`: ``BOUNCE_RAYS`` rays in uniform directions from each seen point; a
   photon stored on a seen surface at its second hit bounced first at such a point).  From each,
   ``LIGHT_SAMPLES`` photons of each light that would reach it straight from the light
   (``kernels.guide.guide_marks``: the inverse of the light's emission warps), each with a
   shadow ray at the point's time; an unoccluded one is a mark at that photon's guided uniform
   columns (:data:`COLUMNS`), weight 1 (a seen point's) or ``BOUNCE_WEIGHT`` (a point a seen
   point sees).
3. **Importance per cell** (:func:`_guide_from_marks`): an adaptive box-kernel density estimate
   of the marks on the grids of :data:`GRID` (coarse to fine, each twice the one before): each
   mark's weight is spread evenly over its cell and the cells one each way in every column, on
   the finest grid on which those 3^D cells hold ``NEIGHBOURS`` marks or more (the coarsest
   where none does).  So a window's patch of the sun's disc, where the marks are dense, is drawn
   on fine cells (not blurred into neighbouring wall cells), and the ground outside, where they
   are sparse, on coarse ones without holes between the marks.  A cell's probability is its
   density (weight over measure) raised to ``TEMPER`` times its measure, normalised: a power
   below 1 keeps photons on what the pilot marks thinly (photons that reach the view after a
   bounce outside would otherwise be hundreds of times heavier than the rest, each a speck).
4. **Emission** (``kernels.emission.emit(..., guide=)``): the uniforms of a photon come from
   ``pdf(u) = (1 - g) + g sum_levels p_(cell of u) res^D`` (g = ``GUIDED_SHARE``) and its power
   is divided by pdf (``kernels.guide.guide_warp``): unbiased for any cells and probabilities.

A light with no marked cell (nothing the camera sees is lit by it directly), a MESH light, and a
textured or portal-lit world emit uniformly (guide None).  The pilot's random stream is
``rng_for(0, STREAM_GUIDE)`` and the guides are built once per render (:func:`guides_for`): every
progressive pass and every pass chunk on any machine or thread count reads the same guides.  :class:`VisibleCells` (voxels of the seen points) counts the photons stored on
camera-visible surfaces for ``--stats`` (the pilot runs with ``photon_guiding``, or for the stats
alone where the environment variable ``STPM_VISIBLE_STATS`` is set: about 0.1-0.3 s a render).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..camera import generate_rays
from ..kernels.guide import guide_marks
from ..kernels.light_params import kernel_light, light_poses
from ..kernels.environment import E_PORTAL_PHOTON, E_TEXTURED
from ..sampling import rng_for
from .record import oct_decode

__all__ = ["EmissionGuide", "VisibleCells", "CameraPilot", "camera_pilot", "build_guides", "guides_for",
           "visible_cells",
           "GUIDED_SHARE", "GRID", "COLUMNS", "PILOT_RAYS", "LIGHT_SAMPLES"]

VISIBLE_STATS_ENV = "STPM_VISIBLE_STATS"   # set (not 0): run the camera pilot for the stats without guiding too
GUIDED_SHARE = 0.8            # g: the guided share of a light's photons (issue 16: >= 20 % unguided)
PILOT_RAYS = 4096             # camera pilot rays
BOUNCE_RAYS = 4              # rays from each seen point to the points it sees
PILOT_DEPTH = 4               # delta / glossy bounces the pilot follows
STREAM_GUIDE = 0x6D1D         # the pilot's random stream
CELLS = 128                   # voxels along the diagonal of the seen points (VisibleCells, stats only)
#: guided uniform columns of (u1_0, u1_1, u2_0, u2_1) per light type and cells per column
COLUMNS = {"POINT": (0, 1), "SPOT": (0, 1), "SUN": (2, 3), "AREA": (0, 1, 2, 3), "WORLD": (0, 1, 2, 3)}
#: cells per column of the guide's grids, coarse to fine (each mark's kernel on one of them: NEIGHBOURS).
#: SUN stops at 2048 (cells of 1/2048 of the disc's width, 2.9 cm in the 4 m room): a sun's
#: photons reaching one point come from a patch of the disc blurred by the cone (the point's
#: distance from the disc x tan(angle / 2), 1.8 cm for a window 1.8 m from it at 0.02 rad), and the
#: kernel's one cell each way must cover that, or the window's edge sends the heaviest photons in.
GRID = {"POINT": tuple(2 ** k for k in range(4, 13)), "SPOT": tuple(2 ** k for k in range(4, 13)),
        "SUN": tuple(2 ** k for k in range(4, 12)), "AREA": (4, 8, 16, 32), "WORLD": (4, 8, 16, 32)}
BOUNCE_WEIGHT = 1.0           # a mark of a point a seen point sees, against a seen point's own (1)
TEMPER = 0.3                  # a cell's probability: (its marks' density)^TEMPER x its measure (1: the marks' density)
NEIGHBOURS = 16               # a mark's kernel: the finest grid whose 3^D cells about it hold this many marks
LIGHT_SAMPLES = {"POINT": 1, "SPOT": 1, "SUN": 2, "AREA": 8, "WORLD": 32}    # marking photons per seen point


@dataclass(frozen=True)
class EmissionGuide:
    """One light's guide over its guided columns ``cols`` of (u1_0, u1_1, u2_0, u2_1): cells of
    several grids, coarse to fine: level l has ``res[l]`` cells per column (each a multiple of the
    one before), its cells ``cells[start[l]:start[l + 1]]`` (sorted flat int64 indices); ``p``
    (M,) each cell's probability within the guided share ``g`` (sum 1).  The density on [0, 1)^D
    is ``pdf(u) = (1 - g) + g sum_l p_(cell of u at level l) res[l]^D``
    (``kernels.guide.guide_warp``); res (L,) int64, start (L + 1,) int64."""
    cols: tuple
    res: np.ndarray
    start: np.ndarray
    cells: np.ndarray
    p: np.ndarray
    g: float = GUIDED_SHARE

    @classmethod
    def uniform(cls, cols, res: int, cells: np.ndarray, g: float = GUIDED_SHARE) -> "EmissionGuide":
        """The binary guide: cells (M,) of one res^D grid, each with probability 1 / M."""
        cells = np.unique(np.asarray(cells, np.int64))
        return cls(tuple(cols), np.array([res], np.int64), np.array([0, cells.size], np.int64), cells,
                   np.full(cells.size, 1.0 / cells.size), g)

    @property
    def D(self) -> int:
        return len(self.cols)

    @property
    def cdf(self) -> np.ndarray:
        c = np.cumsum(self.p)
        return c / c[-1]

    def _levels(self):
        return [(int(self.start[l]), int(self.start[l + 1]), int(self.res[l])) for l in range(self.res.size)]

    @property
    def dens(self) -> np.ndarray:
        """(M,) g p_j res^D: what cell j adds to the density where it lies."""
        r = np.repeat(self.res.astype(np.float64), np.diff(self.start))
        return self.g * self.p * r ** self.D

    @property
    def marked_fraction(self) -> float:
        """Measure of [0, 1)^D covered by listed cells of any level."""
        D = self.D
        # union of the listed cells, level by level coarse to fine (cells inside coarser listed ones once)
        total, seen = 0.0, []
        for lo, hi, r in self._levels():
            if hi == lo:
                continue
            c = self.cells[lo:hi]
            keep = np.ones(c.size, bool)
            coords = np.stack(np.unravel_index(c, (r,) * D), -1)
            for rr, cc in seen:
                par = np.ravel_multi_index(tuple((coords // (r // rr)).T), (rr,) * D)
                keep &= ~np.isin(par, cc)
            total += np.count_nonzero(keep) / r ** D
            seen.append((r, c))
        return total

    def pdf(self, V: np.ndarray) -> np.ndarray:
        """(n,) the mixture density at guided columns V (n, D) (numpy; tests and stats)."""
        V = np.asarray(V, np.float64)
        out = np.full(V.shape[0], 1.0 - self.g)
        dens = self.dens
        for lo, hi, res in self._levels():
            c = np.zeros(V.shape[0], np.int64)
            for k in range(V.shape[1]):
                c = c * res + np.minimum((V[:, k] * res).astype(np.int64), res - 1)
            sub = self.cells[lo:hi]
            if sub.size:
                j = np.minimum(np.searchsorted(sub, c), sub.size - 1)
                hit = sub[j] == c
                out[hit] += dens[lo:hi][j[hit]]
        return out


@dataclass(frozen=True)
class CameraPilot:
    """What the camera sees: ``points`` (m, 3) world, ``wi`` (m, 3) unit toward the camera (along
    the path), ``times`` (m,) normalised shutter times."""
    points: np.ndarray
    wi: np.ndarray
    times: np.ndarray


@dataclass(frozen=True)
class VisibleCells:
    """Voxels near what the camera sees: ``keys`` (K,) sorted int64 (each seen point's voxel and
    its 26 neighbours), the grid's corner ``lo`` (3,) and voxel size ``h`` (scene units)."""
    keys: np.ndarray
    lo: np.ndarray
    h: float

    def contains(self, p: np.ndarray) -> np.ndarray:
        """(m,) bool: world points p (m, 3) in a visible voxel."""
        p = np.asarray(p, np.float64)
        if p.shape[0] == 0 or self.keys.size == 0:
            return np.zeros(p.shape[0], bool)
        v = np.floor((p - self.lo) / self.h)
        ok = np.all((v >= 0.0) & (v < (1 << 20)), axis=1)
        k = _key(np.where(ok[:, None], v, 0.0).astype(np.int64))
        i = np.minimum(np.searchsorted(self.keys, k), self.keys.size - 1)
        return ok & (self.keys[i] == k)


def _key(v: np.ndarray) -> np.ndarray:
    return (v[:, 0] << 40) | (v[:, 1] << 20) | v[:, 2]


def visible_cells(pilot: CameraPilot) -> VisibleCells:
    """The voxels (and their neighbours) of the pilot's seen points; voxel size: the diagonal of
    the points' 1st-99th percentile box over ``CELLS``."""
    p = pilot.points
    if p.shape[0] == 0:
        return VisibleCells(np.empty(0, np.int64), np.zeros(3), 1.0)
    a, b = np.percentile(p, 1.0, axis=0), np.percentile(p, 99.0, axis=0)
    h = max(float(np.linalg.norm(b - a)) / CELLS, 1e-6)
    lo = p.min(axis=0) - 2.0 * h
    h = max(h, float(np.max(p.max(axis=0) - lo)) / ((1 << 20) - 4))
    v = np.unique(_key(np.floor((p - lo) / h).astype(np.int64)))
    off = np.stack(np.meshgrid([-1, 0, 1], [-1, 0, 1], [-1, 0, 1]), -1).reshape(-1, 3)
    # the neighbours' keys: the packed offsets added (every voxel index lies in [2, 2^20 - 2) here)
    koff = off[:, 0] * (1 << 40) + off[:, 1] * (1 << 20) + off[:, 2]
    return VisibleCells(np.unique((v[:, None] + koff[None]).ravel()), lo, h)


def camera_pilot(scene, caster, table, *, shading, inst_offset, origin, rng, rays: int = PILOT_RAYS,
                 time_override=None) -> CameraPilot:
    """The points the camera sees (module docstring, step 1).  Primary rays on a jittered grid,
    stratified times (or the still's ``time_override``); the first hits with a non-delta lobe,
    and, through delta / glossy lobes (``trace_photon_paths``'s caustic rules), the first such
    surface behind a mirror or clear glass."""
    from .trace import _times, trace_photon_paths
    W, H = (int(v) for v in scene.resolution)
    nx = max(int(round(np.sqrt(rays * W / max(H, 1)))), 1)
    ny = max(rays // nx, 1)
    ix, iy = np.meshgrid(np.arange(nx), np.arange(ny))
    px = (ix.ravel() + rng.random(ix.size)) * (W / nx)
    py = (iy.ravel() + rng.random(ix.size)) * (H / ny)
    t = _times(scene, ix.size, rng, time_override)[rng.permutation(ix.size)]
    o, d = generate_rays(scene.camera, (W, H), px, py, t)
    one = np.ones((ix.size, 3))
    kw = dict(origin=origin, inst_offset=inst_offset, shading=shading, diffuse_bounces=None)
    first = trace_photon_paths(caster, table, o, d, one, t, rng, mode="global", min_nondelta=0, max_depth=0, **kw)
    behind = trace_photon_paths(caster, table, o, d, one, t, rng, mode="caustic", max_depth=PILOT_DEPTH, **kw)
    rec = np.concatenate([first, behind])
    return CameraPilot(rec["position"].astype(np.float64) + origin, oct_decode(rec["wi_oct"]).astype(np.float64),
                       rec["time"].astype(np.float64))


def bounce_points(pilot: CameraPilot, caster, rng, *, scale: float) -> CameraPilot:
    """The points the seen points see (module docstring, step 2): from each seen point (moved
    1e-4 x scale toward the camera) one ray in a uniform direction of the sphere at the point's
    time; its first hit, with the direction back along the ray.  (Directions into the surface
    hit it next to the seen point itself.)  Photons stored on seen surfaces at their second hit
    bounced first at such points."""
    if pilot.points.shape[0] == 0:
        return pilot
    pilot = CameraPilot(*(np.repeat(a, BOUNCE_RAYS, axis=0) for a in (pilot.points, pilot.wi, pilot.times)))
    m = pilot.points.shape[0]
    u = rng.random((m, 2))
    z = 1.0 - 2.0 * u[:, 0]
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    d = np.column_stack([r * np.cos(2.0 * np.pi * u[:, 1]), r * np.sin(2.0 * np.pi * u[:, 1]), z])
    o = pilot.points + (1e-4 * scale) * pilot.wi
    hits = caster.intersect(o, d, pilot.times)
    h = hits.hit
    return CameraPilot(np.asarray(hits.position[h], np.float64), -d[h], pilot.times[h])


def _guidable(lights, li: int) -> bool:
    light = lights.lights[li]
    if light.type not in COLUMNS:
        return False
    if light.type == "WORLD":
        par, portals = kernel_light(lights, li)[7][4], kernel_light(lights, li)[7][5]
        if par[E_TEXTURED] != 0.0 or (portals.shape[0] > 0 and par[E_PORTAL_PHOTON] > 0.0):
            return False                     # an image's own distribution / the portals guide it
    return True


def _cells(V: np.ndarray, res: int) -> np.ndarray:
    """(K,) int64 flat cells of points V (K, D) in [0, 1)^D on a res^D grid."""
    c = np.minimum((V * res).astype(np.int64), res - 1)
    return np.ravel_multi_index(tuple(c.T), (res,) * V.shape[1])


def _offsets(D: int) -> np.ndarray:
    """(3^D, D) the offsets to a cell and its neighbours one cell each way in every column."""
    return np.stack(np.meshgrid(*([[-1, 0, 1]] * D), indexing="ij"), -1).reshape(-1, D)


DENSE_CELLS = 1 << 22          # grids of at most this many cells are filtered as dense arrays


def _box3(A: np.ndarray) -> np.ndarray:
    """A (res,)*D summed over each cell and its neighbours one cell each way in every column
    (zero outside the grid): D separable passes of three shifted copies."""
    for ax in range(A.ndim):
        B = A.copy()
        lo = [slice(None)] * A.ndim
        hi = [slice(None)] * A.ndim
        lo[ax], hi[ax] = slice(1, None), slice(None, -1)
        B[tuple(lo)] += A[tuple(hi)]
        B[tuple(hi)] += A[tuple(lo)]
        A = B
    return A


def _inside(res: int, D: int) -> np.ndarray:
    """(res,)*D the number of a cell's 3^D neighbourhood inside the grid (separable: 2 or 3 a column)."""
    n1 = np.full(res, 3.0)
    n1[0] = n1[-1] = 2.0
    if res == 1:
        n1[0] = 1.0
    A = np.ones((1,) * D)
    for ax in range(D):
        shape = [1] * D
        shape[ax] = res
        A = A * n1.reshape(shape)
    return A


def _spread(flat: np.ndarray, wts: np.ndarray, res: int, D: int) -> tuple[np.ndarray, np.ndarray]:
    """Each mark's weight spread evenly over its cell and the neighbours one cell each way in every
    column (those inside the grid): flat (K,) int64 cells of a res^D grid, wts (K,).  Marks are
    gathered per cell first; a grid of at most ``DENSE_CELLS`` cells is filtered as a dense array
    (separable), a larger one per occupied cell.  Returns the sorted flat cells (M,) and their
    summed weights (M,)."""
    if res ** D <= DENSE_CELLS:
        A = np.bincount(flat, wts, minlength=res ** D).reshape((res,) * D)
        A = _box3(A / _inside(res, D)).ravel()
        cells = np.flatnonzero(A > 0.0)
        return cells.astype(np.int64), A[cells]
    keys, inv = np.unique(flat, return_inverse=True)
    wk = np.bincount(inv.ravel(), wts, minlength=keys.size)
    coords = np.stack(np.unravel_index(keys, (res,) * D), -1)
    allc = coords[:, None, :] + _offsets(D)[None]
    ok = np.all((allc >= 0) & (allc < res), axis=2)
    ww = (wk / ok.sum(1))[:, None] * ok
    f = np.ravel_multi_index(tuple(np.clip(allc, 0, res - 1).reshape(-1, D).T), (res,) * D).reshape(ok.shape)
    cells, inv2 = np.unique(f[ok], return_inverse=True)
    return cells, np.bincount(inv2.ravel(), ww[ok], minlength=cells.size)


def _neighbourhood_counts(flat: np.ndarray, res: int, D: int) -> np.ndarray:
    """(K,) the number of marks (flat (K,) int64 cells of a res^D grid) in each mark's cell and
    the cells one each way in every column (dense or per occupied cell, as :func:`_spread`)."""
    if res ** D <= DENSE_CELLS:
        A = np.bincount(flat, minlength=res ** D).reshape((res,) * D).astype(np.int64)
        return _box3(A).ravel()[flat]
    keys, inv, cnt = np.unique(flat, return_inverse=True, return_counts=True)
    coords = np.stack(np.unravel_index(keys, (res,) * D), -1)
    total = np.zeros(keys.size, np.int64)
    for o in _offsets(D):
        c = coords + o
        ok = np.all((c >= 0) & (c < res), axis=1)
        f = np.ravel_multi_index(tuple(np.clip(c, 0, res - 1).T), (res,) * D)
        j = np.minimum(np.searchsorted(keys, f), keys.size - 1)
        total += np.where(ok & (keys[j] == f), cnt[j], 0)
    return total[inv.ravel()]


def _guide_from_marks(cols, V: np.ndarray, wts: np.ndarray, grids) -> EmissionGuide | None:
    """The guide of marks V (K, D) in [0, 1)^D with weights wts (K,): an adaptive box-kernel
    density estimate.  Each mark's weight is spread evenly over its cell and the cells one each
    way in every column (:func:`_spread`) on the finest grid of ``grids`` on which those 3^D
    cells hold ``NEIGHBOURS`` marks or more (the coarsest grid where none does): sharp where the
    marks are dense (a window's patch of the sun's disc), wide where they are sparse (the ground
    outside it), without holes between marks (a hole's photons are the heavy ones).
    p: the cells' weights, tempered (``TEMPER``), over their sum."""
    D = V.shape[1]
    level = np.zeros(V.shape[0], np.int64)
    for l, res in enumerate(grids):
        level[_neighbourhood_counts(_cells(V, res), res, D) >= NEIGHBOURS] = l
    res_l, start, cells, w = [], [0], [], []
    for l, res in enumerate(grids):
        sel = level == l
        if not sel.any():
            continue
        c, ww = _spread(_cells(V[sel], res), wts[sel], res, D)
        res_l.append(res)
        start.append(start[-1] + c.size)
        cells.append(c)
        w.append(ww)
    if len(res_l) == 1 and cells[0].size == res_l[0] ** D:
        return None                          # every cell of one grid: nearly uniform anyway
    # Tempered: a cell's density (weight over its measure res^-D) raised to TEMPER, so a region the
    # pilot marks thinly (light that reaches the view after a bounce outside) keeps more photons
    area = np.repeat(np.array(res_l, np.float64) ** -D, np.diff(start))
    w = (np.concatenate(w) / area) ** TEMPER * area
    # rounded to 2^-24 of the largest (at least that): np.power may differ in its last bit between
    # machines (SIMD or libm), and every pass chunk, anywhere, must draw from the same cdf
    w = np.maximum(np.round(w / w.max() * 2.0 ** 24), 1.0)
    return EmissionGuide(tuple(cols), np.array(res_l, np.int64), np.array(start, np.int64),
                         np.concatenate(cells).astype(np.int64), w / w.sum())


def build_guides(pilot: CameraPilot, caster, lights, rng, *, scale: float) -> tuple[list, list]:
    """(guides, marks): per light of ``lights`` an :class:`EmissionGuide` or None (module
    docstring, step 2), and the number of unoccluded marking photons of each.  scale: the scene's
    diagonal (the seen points move 1e-4 x scale toward the camera before their shadow rays)."""
    guides, marks = [], []
    seen = bounce_points(pilot, caster, rng, scale=scale)      # (rows after the first m0 points)
    pilot = CameraPilot(np.concatenate([pilot.points, seen.points]), np.concatenate([pilot.wi, seen.wi]),
                        np.concatenate([pilot.times, seen.times]))
    m, m0 = pilot.points.shape[0], pilot.points.shape[0] - seen.points.shape[0]
    for li, light in enumerate(lights.lights):
        if m == 0 or float(lights.power[li]) <= 0.0 or not _guidable(lights, li):
            guides.append(None)
            marks.append(0)
            continue
        S = LIGHT_SAMPLES[light.type]
        P = np.ascontiguousarray(np.repeat(pilot.points, S, axis=0))
        R = np.ascontiguousarray(P + (1e-4 * scale) * np.repeat(pilot.wi, S, axis=0))
        T = np.repeat(pilot.times, S)
        U = rng.random((P.shape[0], 4))
        row = kernel_light(lights, li)[0]
        poses = light_poses(lights, li, T)
        uu, o_sh, d_sh = np.empty((P.shape[0], 4)), np.zeros((P.shape[0], 3)), np.zeros((P.shape[0], 3))
        tmax, ok = np.zeros(P.shape[0]), np.zeros(P.shape[0], np.uint8)
        guide_marks(row, poses, P, R, U, uu, o_sh, d_sh, tmax, ok)
        sel = np.flatnonzero(ok)
        lit = np.zeros(P.shape[0], bool)
        if sel.size:
            lit[sel] = ~caster.occluded(o_sh[sel], d_sh[sel], T[sel], tmax[sel] * (1.0 - 1e-6))
        if not lit.any():
            guides.append(None)
            marks.append(0)
            continue
        # Each mark weighs 1 (a seen point's) or BOUNCE_WEIGHT (a point a seen point sees)
        cols = COLUMNS[light.type]
        first = (np.arange(P.shape[0]) < S * m0)[lit]
        wts = np.where(first, 1.0, BOUNCE_WEIGHT)
        marks.append(int(lit.sum()))
        guides.append(_guide_from_marks(cols, uu[lit][:, cols], wts, GRID[light.type]))
    return guides, marks


def guides_for(scene, caster, lights, table, *, shading, inst_offset, origin, time_override, guiding: bool):
    """(cells, guides, marks, seconds) of a render: the :class:`VisibleCells` of the camera pilot,
    with ``guiding`` the guides and marks of :func:`build_guides` (else None per light and 0), and
    the seconds it took (0 when cached).

    Built once per LightSet (one render) and kept on it: every progressive pass, whatever its
    seed or time stratum, reads the same guides (the pilot spans the whole shutter); an
    accumulation still (a number ``time_override``) gets its own at its instant.  The pilot's
    stream is ``rng_for(0, STREAM_GUIDE)``, so every pass chunk, on any machine, builds the same."""
    instant = time_override if (time_override is not None and not isinstance(time_override, tuple)) else None
    key = (None if instant is None else float(instant), bool(guiding))
    cache = lights.__dict__.setdefault("_photon_guides", {})
    if key in cache:
        return cache[key] + (0.0,)
    t0 = time.perf_counter()
    rng = rng_for(0, STREAM_GUIDE)
    pilot = camera_pilot(scene, caster, table, shading=shading, inst_offset=inst_offset, origin=origin, rng=rng,
                         time_override=instant)
    cells = visible_cells(pilot)
    n = len(lights.lights)
    guides, marks = [None] * n, [0] * n
    if guiding:
        guides, marks = build_guides(pilot, caster, lights, rng, scale=2.0 * float(scene.bounding_sphere()[1]))
    cache[key] = (cells, guides, marks)
    return cells, guides, marks, time.perf_counter() - t0
