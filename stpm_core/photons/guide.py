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
   shadow ray at the point's time; an unoccluded one marks the cell of the light's emission
   domain that photon comes from (cells of a grid over the guided uniform columns,
   :data:`COLUMNS`).  Each of the two sets of marks picks its own grid from :data:`GRID`, the
   finest on which its marked cells hold ``MIN_MARKS`` marks each on average (a finer grid would
   leave holes between the marks, and a hole's photons are the heavy ones), marks the
   neighbours of every marked cell (one cell each way in every column), and the two are joined
   on the finer grid.
3. **Emission** (``kernels.emission.emit(..., guide=)``): the uniforms of a photon come from
   ``pdf(u) = g N_c / M [cell(u) marked] + (1 - g)`` (g = ``GUIDED_SHARE``, M marked cells of
   N_c) and its power is divided by pdf (``kernels.guide.guide_warp``): unbiased for any marks,
   and every photon drawn in a marked cell carries the same power, so the photons that light a
   seen surface directly (and what they store after bouncing there) keep equal powers.

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
#: cells per column tried, coarse to fine: the finest whose marked cells hold MIN_MARKS marks each on average
GRID = {"POINT": (16, 32, 64, 128, 256), "SPOT": (16, 32, 64, 128, 256), "SUN": (16, 32, 64, 128, 256),
        "AREA": (4, 8, 16), "WORLD": (4, 8, 16)}
MIN_MARKS = 16
BOUNCE_MARKS = 4              # the seen points' points: MIN_MARKS x this (they spread wider, thinner)
LIGHT_SAMPLES = {"POINT": 1, "SPOT": 1, "SUN": 2, "AREA": 8, "WORLD": 32}    # marking photons per seen point


@dataclass(frozen=True)
class EmissionGuide:
    """One light's guide: the guided columns ``cols`` of (u1_0, u1_1, u2_0, u2_1), ``res`` cells
    per column, ``mask`` (res^D,) uint8 (1 = marked), ``marked`` (M,) int64 sorted marked cells,
    ``g`` the guided share."""
    cols: tuple
    res: int
    mask: np.ndarray
    marked: np.ndarray
    g: float = GUIDED_SHARE

    @property
    def marked_fraction(self) -> float:
        return self.marked.size / self.mask.size

    def pdf(self, V: np.ndarray) -> np.ndarray:
        """(n,) the mixture density at guided columns V (n, D) (numpy; tests and stats)."""
        V = np.asarray(V, np.float64)
        c = np.zeros(V.shape[0], np.int64)
        for k in range(V.shape[1]):
            c = c * self.res + np.minimum((V[:, k] * self.res).astype(np.int64), self.res - 1)
        return (1.0 - self.g) + self.g * self.mask.size / self.marked.size * self.mask[c]


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
    v = np.floor((p - lo) / h).astype(np.int64)
    off = np.stack(np.meshgrid([-1, 0, 1], [-1, 0, 1], [-1, 0, 1]), -1).reshape(-1, 3)
    allv = np.unique((v[:, None, :] + off[None]).reshape(-1, 3), axis=0)
    return VisibleCells(np.unique(_key(allv)), lo, h)


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


def _dilate(cells: np.ndarray, res: int, D: int) -> np.ndarray:
    """Sorted flat cells (M,) and their neighbours one cell each way in every column."""
    coords = np.stack(np.unravel_index(cells, (res,) * D), -1)
    off = np.stack(np.meshgrid(*([[-1, 0, 1]] * D), indexing="ij"), -1).reshape(-1, D)
    allc = (coords[:, None, :] + off[None]).reshape(-1, D)
    allc = allc[np.all((allc >= 0) & (allc < res), axis=1)]
    return np.unique(np.ravel_multi_index(tuple(allc.T), (res,) * D))


def _refine(cells: np.ndarray, res: int, fine: int, D: int) -> np.ndarray:
    """Flat cells (M,) of a res^D grid as the cells of the fine^D grid they hold (fine = res 2^j)."""
    k = fine // res
    coords = np.stack(np.unravel_index(cells, (res,) * D), -1) * k
    sub = np.stack(np.meshgrid(*([np.arange(k)] * D), indexing="ij"), -1).reshape(-1, D)
    allc = (coords[:, None, :] + sub[None]).reshape(-1, D)
    return np.ravel_multi_index(tuple(allc.T), (fine,) * D)


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
        cols = COLUMNS[light.type]
        D = len(cols)
        if not lit.any():
            guides.append(None)
            marks.append(0)
            continue
        # Each set of marks (the seen points' own, those of the points they see) on the finest grid
        # whose marked cells hold MIN_MARKS marks each on average (fewer: holes between the marks),
        # dilated there and refined to the finer of the two grids (every grid a power of two)
        grids = GRID[light.type]
        parts = []
        for part, need in ((lit & (np.arange(P.shape[0]) < S * m0), MIN_MARKS),
                           (lit & (np.arange(P.shape[0]) >= S * m0), MIN_MARKS * BOUNCE_MARKS)):
            if not part.any():
                continue
            for res in grids:
                c = np.minimum((uu[part][:, cols] * res).astype(np.int64), res - 1)
                found = np.unique(np.ravel_multi_index(tuple(c.T), (res,) * D))
                if res == grids[0] or part.sum() >= need * found.size:
                    best = res, found
                else:
                    break
            parts.append((best[0], _dilate(best[1], best[0], D)))
        res = max(r for r, _ in parts)
        cells = np.unique(np.concatenate([_refine(c, r, res, D) for r, c in parts]))
        mask = np.zeros(res ** D, np.uint8)
        mask[cells] = 1
        marks.append(int(lit.sum()))
        guides.append(None if cells.size == mask.size else EmissionGuide(cols, res, mask, cells))
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
