"""The world as a light: a constant radiance ``L = color * strength``, or an environment image.

Blender's world lights the scene in Cycles; here it does too, for a constant colour or an
equirectangular Environment Texture (see docs/blender.md for what the exporter reads).  One
:class:`WorldLight` entry joins the :class:`~stpm_core.lights.LightSet` (after
the scene's lights and the mesh lights) when L > 0, with the same interface as
the other entries.  Units and equations (docs/lights-and-materials.md, "World"):

* Radiance ``L`` (3,) W/(m^2 sr) from every direction.  Irradiance on an
  unoccluded surface: ``E = pi L``.
* Next-event estimation at a point with (face-forwarded) normal n: direction
  wi cosine-distributed about n, ``pdf = cos / pi``, so ``weight = L pi / cos``
  and the integrator's ``f |cos| weight`` is ``f pi L`` times visibility (a
  shadow ray to infinity).  Without a normal: uniform on the sphere,
  ``weight = 4 pi L``.  Computed by ``kernels.lights.sample_light_rows`` (through
  ``LightSet.sample_direct``), like every other light entry.
* Photons: the flux crossing a disc of radius R (the scene's bounding sphere)
  from every direction is ``Phi = 4 pi * pi R^2 * L``.  A photon picks a
  uniform direction d (where it travels), a uniform point on the disc of
  radius R perpendicular to d through the scene centre, starts 2R upstream,
  and carries ``Phi / n``: any point inside the sphere then receives, from a
  solid angle dw around d, the power per area ``L dw``, i.e. radiance L.
  Aimed at a specular object (bounding sphere c, r): the same with the disc
  of radius r about c, power ``4 pi * pi r^2 * L / n``.  Computed by
  ``kernels.emission`` (through ``LightSet.emit`` / ``emit_toward``); the numpy
  code it replaced is ``world_emit`` of tests/oracles/emission_numpy.py.

An environment image (``World.image``) is a light entry of the same type: ``color`` is its
mean radiance over the sphere (for the choice among lights and the flux), its ``transform`` the
world's mapping (map-to-world rotation over the shutter), and :attr:`WorldLight.env` the arrays
the kernels read (:mod:`stpm_core.kernels.environment`):

* Next-event estimation draws wi from the mixture ``p(wi) = c p_cos(wi) + (1 - c) p_img(wi)``
  (p_cos the cosine density about the normal, or uniform on the sphere without one; p_img the
  image distribution) and weighs it by ``L(wi) / p(wi)``: the one-sample balance heuristic of
  the two techniques, so a sun spot is found by the image distribution and a sky of little
  contrast by the cosine, neither with fireflies.  c depends on the normal n (turned toward the
  viewer; ``kernels.environment.nee_cos``): c = lo + (hi - lo) (1 - f(n)), (lo, hi) =
  ``NEE_COS_RANGE``, f(n) the image distribution's probability above the tangent plane of n,
  tabulated over an ``NC_ROWS`` x ``NC_COLS`` grid of normals in the image frame
  (:func:`nee_cos_table`): where most of the image's power lies above the surface (a floor
  under a sun) the image draws more samples, where it lies below (a wall facing away) the
  cosine does (docs/blender.md, "the world's cosine fraction"); ``NEE_COS_FRACTION`` without a
  normal.
* Photons: the direction omega (where the light comes from) is drawn from
  ``q(omega) = a / (4 pi) + (1 - a) p_img(omega)`` (a = ``PHOTON_UNIFORM_FRACTION``, defensive:
  every direction keeps some density), the photon travels along -omega from the disc of radius
  R perpendicular to it and carries ``L(omega) pi R^2 / (q(omega) n)``; for a constant L this is
  the uniform case above.
* The distribution grid follows what the look-up returns, so that L / p stays near constant
  (a small sun then gives no fireflies), weighted by the mean of the channels times sin(theta)
  at the cell centre:

  - Closest, W <= ``MAP_RESOLUTION``: one cell per texel, the texel itself (exact);
  - Linear, W < ``MAP_RESOLUTION``: s x s cells per texel (s even, s W about
    ``MAP_RESOLUTION``, Cycles' default Map Resolution 1024), each the largest value the
    bilinear interpolation takes in it (a corner: with s even no cell straddles a texel centre);
  - larger images: the texels averaged over at most ``MAP_RESOLUTION`` x
    ``MAP_RESOLUTION / 2`` cells, for Linear after each texel takes the largest value of its
    3 x 3 neighbourhood (a bilinear look-up mixes a texel with its neighbours).

  Measured on a 128 x 64 sky with a 2 x 2 texel sun 2000x the sky (tests/test_environment.py):
  one texel per cell with Linear look-ups gave samples of weight up to 900x their mean.

This class holds the world's constants only: radiance, the scene's bounding sphere, the flux
through it, and the packed environment.
"""
from __future__ import annotations

from functools import cached_property

import numpy as np

from .motion import MotionTransform

__all__ = ["WorldLight", "environment_arrays", "constant_environment", "camera_environment", "portal_rows",
           "MAP_RESOLUTION", "NEE_COS_FRACTION", "NEE_COS_RANGE", "nee_cos_table", "PHOTON_UNIFORM_FRACTION", "PORTAL_NEE_FRACTION", "PORTAL_PHOTON_FRACTION"]

MAP_RESOLUTION = 1024            # columns of the distribution grid at most (rows: half), as Cycles' default
NEE_COS_FRACTION = 0.3           # next-event samples drawn uniformly where a point has no normal (the rest from the image)
NEE_COS_RANGE = (0.1, 0.5)       # ... about the normal: lo where all the image's power is above the surface, hi where none
PHOTON_UNIFORM_FRACTION = 0.1    # world photons drawn uniformly over the sphere (the rest from the image)
PORTAL_NEE_FRACTION = 0.5        # next-event samples drawn through the portals facing the point (if any)
PORTAL_PHOTON_FRACTION = 0.8     # world photons aimed through the portals (the rest over the whole disc)


NO_PORTALS = np.zeros((0, 12))


def portal_rows(portals) -> np.ndarray:
    """The kernels' portal rows (K, 12) float64 (``kernels.environment``: corner, full edges e1, e2,
    unit normal into the room) of light portals, :class:`~stpm_core.scene.Light` AREA entries
    posed at mid-shutter (a portal only steers sampling: its pose need not follow its motion).
    A disc / ellipse portal becomes its bounding rectangle (sampling through a larger opening
    stays unbiased); a sheared pose keeps ex and the part of ey orthogonal to it; a portal with
    no area or no facing side is left out."""
    from .lights import area_light_normal
    rows = []
    for l in portals or ():
        M = l.transform.at(np.array([0.5]))[0]
        sx = float(l.size)
        sy = float(l.size_y) if l.shape in ("RECTANGLE", "ELLIPSE") else sx
        ex, ey = 0.5 * sx * M[:3, 0], 0.5 * sy * M[:3, 1]
        ey = ey - ex * (ex @ ey) / max(float(ex @ ex), 1e-300)
        n, A4 = area_light_normal(ex[None], ey[None], M[None, :3, 2])
        if not (A4[0] > 0.0 and float(n[0] @ n[0]) > 0.5):
            continue
        c = M[:3, 3]
        rows.append(np.concatenate([c - ex - ey, 2.0 * ex, 2.0 * ey, n[0]]))
    return np.ascontiguousarray(np.array(rows, np.float64).reshape(-1, 12))


def constant_environment(radiance, portals=None) -> tuple:
    """The kernels' ``env`` tuple of a constant world of radiance (3,) W m^-2 sr^-1; portals: the
    portal rows (K, 12) (:func:`portal_rows`; None: none)."""
    from .kernels.environment import E_L, E_PORTAL_NEE, E_PORTAL_PHOTON, N_ENV
    par = np.zeros(N_ENV)
    par[E_L:E_L + 3] = np.asarray(radiance, np.float64).reshape(3)
    portals = NO_PORTALS if portals is None else np.ascontiguousarray(portals, np.float64).reshape(-1, 12)
    if portals.shape[0]:
        par[E_PORTAL_NEE], par[E_PORTAL_PHOTON] = PORTAL_NEE_FRACTION, PORTAL_PHOTON_FRACTION
    img = np.asarray(radiance, np.float32).reshape(1, 1, 3).copy()
    return img, np.ones((1, 1)), np.array([0.0, 1.0]), np.array([[0.0, 1.0]]), par, portals


def _cell_edges(n: int, m: int) -> np.ndarray:
    """Start indices (m,) of m nearly equal runs of n texels (m <= n)."""
    return (np.arange(m) * n) // m


def nee_cos_table(func: np.ndarray) -> np.ndarray:
    """(NC_ROWS * NC_COLS,) the cosine fraction of next-event estimation per normal direction
    (``kernels.environment.nee_cos``): the normal of cell (i, j) points to the image-frame (u, v)
    = ((j + 1/2) / NC_COLS, (i + 1/2) / NC_ROWS); c = lo + (hi - lo) (1 - f), f the share of the
    cell weights func (Hd, Wd) (the image distribution) whose cell centres lie above its tangent
    plane (func summed over at most 64 x 128 blocks first, each at its centre)."""
    from .kernels.environment import NC_COLS, NC_ROWS
    Hd, Wd = func.shape
    hb, wb = min(Hd, 64), min(Wd, 128)
    re, ce = _cell_edges(Hd, hb), _cell_edges(Wd, wb)
    blocks = np.add.reduceat(np.add.reduceat(func, re, axis=0), ce, axis=1)
    vc = (re + np.diff(np.append(re, Hd)) / 2.0) / Hd
    uc = (ce + np.diff(np.append(ce, Wd)) / 2.0) / Wd

    def directions(u, v):
        theta, phi = np.pi * (1.0 - v), np.pi - 2.0 * np.pi * u
        return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=-1)

    d = directions(*np.meshgrid(uc, vc)).reshape(-1, 3)
    w = blocks.reshape(-1) / max(float(blocks.sum()), 1e-300)
    n = directions(*np.meshgrid((np.arange(NC_COLS) + 0.5) / NC_COLS, (np.arange(NC_ROWS) + 0.5) / NC_ROWS)).reshape(-1, 3)
    f = ((n @ d.T) > 0.0) @ w
    lo, hi = NEE_COS_RANGE
    return lo + (hi - lo) * (1.0 - np.clip(f, 0.0, 1.0))


def _max_3x3(a: np.ndarray) -> np.ndarray:
    """Each texel's maximum over itself and its 8 neighbours (columns wrap, rows clamp), (H, W)."""
    up = np.vstack([a[1:], a[-1:]])
    down = np.vstack([a[:1], a[:-1]])
    m = np.maximum(a, np.maximum(up, down))
    return np.maximum(m, np.maximum(np.roll(m, 1, axis=1), np.roll(m, -1, axis=1)))


def _bilinear_cell_max(lum: np.ndarray, s: int) -> np.ndarray:
    """(s H, s W) cells, s even: the maximum of the bilinear interpolation of lum (H, W) (columns wrap,
    rows clamp, as ``kernels.environment``) over each cell, the largest of its four corners (with s
    even every cell lies within one bilinear patch, where a bilinear function peaks at a corner)."""
    H, W = lum.shape
    x = np.arange(s * W + 1) / s - 0.5                      # texel coordinates of the cell corners
    y = np.arange(s * H + 1) / s - 0.5
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    fx, fy = x - x0, y - y0
    c0, c1 = x0 % W, (x0 + 1) % W
    r0, r1 = np.clip(y0, 0, H - 1), np.clip(y0 + 1, 0, H - 1)
    top = lum[r0][:, c0] * (1 - fx) + lum[r0][:, c1] * fx          # (s H + 1, s W + 1) along x, row r0
    bot = lum[r1][:, c0] * (1 - fx) + lum[r1][:, c1] * fx
    corner = top * (1 - fy)[:, None] + bot * fy[:, None]
    return np.maximum(np.maximum(corner[:-1, :-1], corner[:-1, 1:]), np.maximum(corner[1:, :-1], corner[1:, 1:]))


def environment_arrays(world, portals=None) -> tuple:
    """The kernels' ``env`` tuple (img, func, marg, cond, par, portals) of a :class:`~stpm_core.scene.World`
    (portals: the rows of :func:`portal_rows`, None: none).

    img (H, W, 3) float32 = image * color * strength; func (Hd, Wd) float64 the cell weights
    (the distribution grid of the module docstring, times sin(theta) at the cell centres);
    marg (Hd + 1,), cond (Hd, Wd + 1) their normalised running sums (a row of zero weight gets
    an even cond).
    """
    from .kernels.environment import E_INTERP, E_L, E_MEAN, E_NEE_COS, E_PHOTON_UNIFORM, E_TEXTURED
    if world.image is None:
        return constant_environment(world.radiance, portals)
    tint = np.asarray(world.color, np.float64) * float(world.strength)
    img = np.ascontiguousarray(world.image, np.float32) * tint.astype(np.float32)
    img = np.ascontiguousarray(img, np.float32)
    H, W = img.shape[:2]
    lum = img.astype(np.float64).mean(axis=2)                               # (H, W)
    linear = world.interpolation != "CLOSEST"
    if linear and W < MAP_RESOLUTION:
        cells = _bilinear_cell_max(lum, max(2, (MAP_RESOLUTION // W) // 2 * 2))
    elif not linear and W <= MAP_RESOLUTION:
        cells = lum                                                         # exact: one cell per texel
    else:
        if linear:
            lum = _max_3x3(lum)          # bilinear look-ups reach a texel's neighbours: bound them
        Hd, Wd = min(H, MAP_RESOLUTION // 2), min(W, MAP_RESOLUTION)
        rows = np.add.reduceat(lum, _cell_edges(H, Hd), axis=0) / np.diff(np.append(_cell_edges(H, Hd), H))[:, None]
        cells = np.add.reduceat(rows, _cell_edges(W, Wd), axis=1) / np.diff(np.append(_cell_edges(W, Wd), W))[None, :]
    Hd, Wd = cells.shape
    sin_t = np.sin(np.pi * (np.arange(Hd) + 0.5) / Hd)                      # row j's centre: v = (j + 1/2) / Hd
    func = np.ascontiguousarray(np.maximum(cells, 0.0) * sin_t[:, None])
    row_sum = func.sum(axis=1)
    total = float(row_sum.sum())
    marg = np.concatenate([[0.0], np.cumsum(row_sum)]) / max(total, 1e-300)
    marg[-1] = 1.0
    cond = np.concatenate([np.zeros((Hd, 1)), np.cumsum(func, axis=1)], axis=1)
    safe = np.where(row_sum > 0, row_sum, 1.0)
    cond = np.where(row_sum[:, None] > 0, cond / safe[:, None], np.linspace(0.0, 1.0, Wd + 1)[None, :])
    cond[:, -1] = 1.0
    par = constant_environment(world.radiance, portals)[4]
    par[E_TEXTURED] = 1.0
    par[E_INTERP] = 0.0 if world.interpolation == "CLOSEST" else 1.0
    par[E_MEAN] = total / (Hd * Wd)
    par[E_NEE_COS] = NEE_COS_FRACTION if total > 0 else 1.0
    par[E_PHOTON_UNIFORM] = PHOTON_UNIFORM_FRACTION if total > 0 else 1.0
    if total > 0:
        par = np.concatenate([par, nee_cos_table(func)])       # kernels.environment.nee_cos
    return (img, func, np.ascontiguousarray(marg), np.ascontiguousarray(cond), par,
            constant_environment(world.radiance, portals)[5])


def camera_environment(world, env: tuple) -> tuple:
    """The ``env`` tuple camera rays read: ``env`` itself, or with ``World.camera_image`` (times colour and
    strength) in place of the image (a Light Path "Is Camera Ray" world: what the camera sees differs
    from what lights the scene; only the look-up reads it, so the distribution stays the image's)."""
    cam = getattr(world, "camera_image", None) if world is not None else None
    if cam is None or world.image is None:
        return env
    tint = (np.asarray(world.color, np.float64) * float(world.strength)).astype(np.float32)
    img = np.ascontiguousarray(np.ascontiguousarray(cam, np.float32) * tint, np.float32)
    return (img,) + tuple(env[1:])


class WorldLight:
    """The world as a light (type ``'WORLD'``), one :class:`LightSet` entry.

    Parameters
    ----------
    radiance : (3,) W/(m^2 sr), > 0 in some channel: the constant radiance, or an image
        world's mean (``World.radiance``).
    center : (3,) scene bounding-sphere centre; radius : its radius (scene units, > 0).
    world : the :class:`~stpm_core.scene.World` (None: constant ``radiance``); an image
        world's mapping becomes ``transform`` and its arrays ``env``.

    Attributes (those every light entry has): ``type = 'WORLD'``, ``color``
    (= radiance), ``power`` (W, mean RGB flux through the scene's sphere),
    ``transform`` (map-to-world rotation; static identity for a constant world),
    ``radius = 0``, ``name``; and ``env`` (the kernels' arrays, ``environment_arrays``),
    ``env_camera`` (what camera rays look up, :func:`camera_environment`).
    """

    type = "WORLD"
    radius = 0.0
    use_soft_falloff = False
    name = "world"

    def __init__(self, radiance, center, radius: float, world=None, portals=None):
        self.color = np.asarray(radiance, np.float64).reshape(3)
        self.portals = portal_rows(portals)
        self.photon_weight = float(getattr(world, "photon_weight", 1.0)) if world is not None else 1.0
        self.center = np.asarray(center, np.float64).reshape(3)
        self.scene_radius = float(radius)
        image_world = world is not None and world.image is not None
        self._world = world if image_world else None
        self.transform = world.mapping if image_world else MotionTransform.static()
        self.power = float(np.mean(self.flux()))

    @property
    def is_image(self) -> bool:
        """Is the radiance an image (direction-dependent)?"""
        return self._world is not None

    @cached_property
    def env(self) -> tuple:
        """The kernels' environment arrays, packed on first use (the effects plan's world light never
        asks: it needs the flux only)."""
        if self._world is not None:
            return environment_arrays(self._world, self.portals)
        return constant_environment(self.color, self.portals)

    @cached_property
    def env_camera(self) -> tuple:
        """What camera rays look up (:func:`camera_environment`)."""
        return camera_environment(self._world, self.env)

    def flux(self) -> np.ndarray:
        """(3,) W through the scene's bounding sphere: 4 pi * pi R^2 * L (L the mean radiance)."""
        return 4.0 * np.pi * np.pi * self.scene_radius ** 2 * self.color
