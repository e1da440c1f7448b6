"""The world's radiance along a direction, and its importance sampling (numba).

Blender's Environment Texture (equirectangular) as Cycles evaluates it, and a 2D
piecewise-constant distribution over the image for next-event estimation and for world photons
(docs/lights-and-materials.md, "World", has the equations with these names).

The world reaches the kernels as one tuple ``env = (img, func, marg, cond, par, portals)``
(:func:`stpm_core.world_light.environment_arrays` packs it); a kernel unpacks it once and hands
the per-direction functions below the arrays they read (taking an array out of a tuple inside a
per-row loop costs two atomic reference-count operations per row, ``sampling.row3``):

* img (H, W, 3) float32: the radiance image (already times colour and strength), row 0 at
  the bottom; (1, 1, 3) for a constant world;
* func (Hd, Wd) float64: the sampling weight of each cell of the distribution grid (the mean
  of the channels' mean over the cell's texels, times sin(theta) at the cell centre), row 0 at
  the bottom; marg (Hd + 1,): the running sum of the rows' totals, normalised (0 .. 1);
  cond (Hd, Wd + 1): per row, the running sum of its cells, normalised;
* par (N_ENV,) float64, for an image with weight (N_ENV + NC_ROWS * NC_COLS,): ``E_TEXTURED`` (0:
  a constant world of radiance ``E_L``), ``E_INTERP`` (0 Closest, 1 Linear), ``E_MEAN`` (the mean
  of func over its cells), ``E_NEE_COS`` (the fraction of next-event samples drawn uniformly
  rather than from the image at a point without a normal; with a normal, the fraction drawn
  about it is the table after ``N_ENV``, one per normal direction: :func:`nee_cos`),
  ``E_PHOTON_UNIFORM`` (the fraction of photon directions drawn uniformly), ``E_L`` (3),
  ``E_PORTAL_NEE`` (the fraction of next-event samples drawn through the portals, where some
  portal faces the point), ``E_PORTAL_PHOTON`` (the fraction of world photons aimed through them);
* portals (K, 12) float64: Blender's light portals (area lights with Cycles' ``is_portal``), one
  rectangle per row: corner s (``PT_S``, 3), full edges e1, e2 (``PT_E1``, ``PT_E2``, orthogonal),
  unit normal n (``PT_N``) pointing into the room (the area light's emitting side).  A portal
  emits nothing and is not seen: it only says where the world's light comes in
  (:func:`portal_cross`; the samplers are ``lights._sample_world_portals`` and
  ``emission._world_photon_portals``).  (0, 12) without portals.

The image's frame is turned by the world's mapping: M (4, 4) is the map-to-world rotation at
the row's time (``WorldLight.transform``), so a world direction d looks up m = M^T d.  With
Cycles' equirectangular coordinates ``u = (pi - atan2(m_y, m_x)) / (2 pi)``,
``v = 1 - acos(m_z) / pi``, a direction's solid-angle density under the image distribution is
``pdf(d) = func[j, i] / (E_MEAN * 2 pi^2 sin(theta))`` (cell j = floor(v Hd), i = floor(u Wd)),
theta = pi (1 - v) the polar angle.
"""
from __future__ import annotations

import math

import numpy as np

from ..numba_probe import njit
from .sampling import JIT, JIT_INLINE, load_pose, pose_buffer, search_right

__all__ = ["N_ENV", "NC_ROWS", "NC_COLS", "E_TEXTURED", "E_INTERP", "E_MEAN", "E_NEE_COS", "nee_cos", "E_PHOTON_UNIFORM", "E_L", "E_PORTAL_NEE",
           "E_PORTAL_PHOTON", "PT_S", "PT_E1", "PT_E2", "PT_N", "N_PORTAL", "portal_cross", "portal_cross_batch",
           "env_radiance", "env_pdf", "env_sample", "env_lookup_batch", "env_pdf_batch", "env_sample_batch"]

E_TEXTURED = 0
E_INTERP = 1
E_MEAN = 2
E_NEE_COS = 3
E_PHOTON_UNIFORM = 4
E_L = 5
E_PORTAL_NEE = 8
E_PORTAL_PHOTON = 9
N_ENV = 10
NC_ROWS, NC_COLS = 8, 16                    # the per-normal cosine fractions after par[N_ENV:] (nee_cos)
PT_S, PT_E1, PT_E2, PT_N = 0, 3, 6, 9       # columns of a portal row
N_PORTAL = 12

_INV_2PI = 1.0 / (2.0 * np.pi)


@njit(**JIT_INLINE)
def _to_map(M, d):
    """m = M^T d: the image-frame direction of world direction d (M's rotation part)."""
    return (M[0, 0] * d[0] + M[1, 0] * d[1] + M[2, 0] * d[2],
            M[0, 1] * d[0] + M[1, 1] * d[1] + M[2, 1] * d[2],
            M[0, 2] * d[0] + M[1, 2] * d[1] + M[2, 2] * d[2])


@njit(**JIT_INLINE)
def _uv(m):
    """Cycles' equirectangular (u, v) of an image-frame direction m (any length > 0): u in [0, 1), v in [0, 1]."""
    s = math.sqrt(m[0] * m[0] + m[1] * m[1] + m[2] * m[2])
    if s == 0.0:
        return 0.0, 0.0
    u = (np.pi - math.atan2(m[1], m[0])) * _INV_2PI
    if u >= 1.0:
        u -= 1.0
    z = min(max(m[2] / s, -1.0), 1.0)
    return u, 1.0 - math.acos(z) / np.pi


@njit(**JIT_INLINE)
def nee_cos(par, M, n):
    """The cosine fraction c of next-event estimation's mixture at a point whose geometric normal
    (turned toward the viewer) is n, for an environment image of map-to-world rotation M:
    ``par[N_ENV + i NC_COLS + j]``, the cell (i, j) of the (u, v) of n in the image frame on an
    NC_ROWS x NC_COLS grid (``world_light.environment_arrays``), where par holds such a table;
    else (or for a zero n) ``par[E_NEE_COS]``.  A function of (n, M) alone: the sampler and the
    density read the same c."""
    if par.shape[0] < N_ENV + NC_ROWS * NC_COLS or (n[0] == 0.0 and n[1] == 0.0 and n[2] == 0.0):
        return par[E_NEE_COS]
    u, v = _uv(_to_map(M, n))
    i = min(int(v * NC_ROWS), NC_ROWS - 1)
    j = min(int(u * NC_COLS), NC_COLS - 1)
    return par[N_ENV + i * NC_COLS + j]


@njit(**JIT_INLINE)
def _texel(img, ix, iy):
    """Texel (ix, iy): columns wrap (Repeat), rows clamp at the poles."""
    H, W = img.shape[0], img.shape[1]
    ix = ix % W
    if ix < 0:
        ix += W
    iy = min(max(iy, 0), H - 1)
    return float(img[iy, ix, 0]), float(img[iy, ix, 1]), float(img[iy, ix, 2])


@njit(**JIT)
def _image(img, interp, u, v):
    """The image at (u, v): Closest (the texel under it) or Linear (bilinear between texel centres)."""
    H, W = img.shape[0], img.shape[1]
    x, y = u * W, v * H
    if interp == 0:
        return _texel(img, int(math.floor(x)), int(math.floor(y)))
    x -= 0.5
    y -= 0.5
    x0, y0 = math.floor(x), math.floor(y)
    fx, fy = x - x0, y - y0
    ix, iy = int(x0), int(y0)
    a = _texel(img, ix, iy)
    b = _texel(img, ix + 1, iy)
    c = _texel(img, ix, iy + 1)
    e = _texel(img, ix + 1, iy + 1)
    w00, w10, w01, w11 = (1.0 - fx) * (1.0 - fy), fx * (1.0 - fy), (1.0 - fx) * fy, fx * fy
    return (w00 * a[0] + w10 * b[0] + w01 * c[0] + w11 * e[0],
            w00 * a[1] + w10 * b[1] + w01 * c[1] + w11 * e[1],
            w00 * a[2] + w10 * b[2] + w01 * c[2] + w11 * e[2])


@njit(**JIT)
def env_radiance(img, par, M, d):
    """Radiance (3-tuple, W m^-2 sr^-1) the world (img, par of ``env``) sends back along world
    direction d (toward -d)."""
    if par[E_TEXTURED] == 0.0:
        return par[E_L], par[E_L + 1], par[E_L + 2]
    u, v = _uv(_to_map(M, d))
    return _image(img, int(par[E_INTERP]), u, v)


@njit(**JIT)
def env_pdf(func, par, M, d):
    """Solid-angle density (1/sr) with which :func:`env_sample` draws world direction d (func, par
    of ``env``)."""
    Hd, Wd = func.shape[0], func.shape[1]
    u, v = _uv(_to_map(M, d))
    sin_t = math.sin(np.pi * v)
    if sin_t <= 0.0 or par[E_MEAN] <= 0.0:
        return 0.0
    j = min(int(v * Hd), Hd - 1)
    i = min(int(u * Wd), Wd - 1)
    return func[j, i] / (par[E_MEAN] * 2.0 * np.pi * np.pi * sin_t)


@njit(**JIT)
def env_sample(func, marg, cond, par, M, u0, u1):
    """A world direction drawn from the image distribution (func, marg, cond, par of ``env``) with
    uniforms u0 (row), u1 (column); returns (d0, d1, d2, pdf) with pdf the solid-angle density
    (0: a pole, nothing drawn)."""
    Hd, Wd = func.shape[0], func.shape[1]
    j = min(max(search_right(marg, u0) - 1, 0), Hd - 1)
    w = marg[j + 1] - marg[j]
    dv = (u0 - marg[j]) / w if w > 0.0 else 0.5
    v = (j + min(max(dv, 0.0), 1.0)) / Hd
    i = min(max(search_right(cond[j], u1) - 1, 0), Wd - 1)
    w = cond[j, i + 1] - cond[j, i]
    du = (u1 - cond[j, i]) / w if w > 0.0 else 0.5
    u = (i + min(max(du, 0.0), 1.0)) / Wd
    theta = np.pi * (1.0 - v)
    phi = np.pi - 2.0 * np.pi * u
    st = math.sin(theta)
    m = (st * math.cos(phi), st * math.sin(phi), math.cos(theta))
    d = (M[0, 0] * m[0] + M[0, 1] * m[1] + M[0, 2] * m[2],
         M[1, 0] * m[0] + M[1, 1] * m[1] + M[1, 2] * m[2],
         M[2, 0] * m[0] + M[2, 1] * m[1] + M[2, 2] * m[2])
    if st <= 0.0 or par[E_MEAN] <= 0.0:
        return d[0], d[1], d[2], 0.0
    return d[0], d[1], d[2], func[j, i] / (par[E_MEAN] * 2.0 * np.pi * np.pi * st)


@njit(**JIT)
def portal_cross(portals, j, o, d):
    """Where the line o + s d (3-tuples, d not zero) crosses portal j's rectangle (``portals`` rows
    of the module docstring): s (any sign; a ray from o crosses it where s > 0), or nan where the
    line misses it (a line in the portal's plane misses it)."""
    n = (portals[j, PT_N], portals[j, PT_N + 1], portals[j, PT_N + 2])
    dn = d[0] * n[0] + d[1] * n[1] + d[2] * n[2]
    if dn == 0.0:
        return np.nan
    w0, w1, w2 = portals[j, PT_S] - o[0], portals[j, PT_S + 1] - o[1], portals[j, PT_S + 2] - o[2]
    s = (w0 * n[0] + w1 * n[1] + w2 * n[2]) / dn
    # the crossing minus the corner, in the edges' coordinates (a, b in [0, 1] inside)
    x0, x1, x2 = s * d[0] - w0, s * d[1] - w1, s * d[2] - w2
    e1 = (portals[j, PT_E1], portals[j, PT_E1 + 1], portals[j, PT_E1 + 2])
    e2 = (portals[j, PT_E2], portals[j, PT_E2 + 1], portals[j, PT_E2 + 2])
    l1 = e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2]
    l2 = e2[0] * e2[0] + e2[1] * e2[1] + e2[2] * e2[2]
    if not (l1 > 0.0 and l2 > 0.0):
        return np.nan
    a = (x0 * e1[0] + x1 * e1[1] + x2 * e1[2]) / l1
    b = (x0 * e2[0] + x1 * e2[1] + x2 * e2[2]) / l2
    if 0.0 <= a <= 1.0 and 0.0 <= b <= 1.0:
        return s
    return np.nan


# ----------------------------------------------------------------------------
# Batch kernels (the integrator's misses, tests)
# ----------------------------------------------------------------------------
@njit(**JIT)
def env_lookup_batch(env, poses, d, out):
    """out[i] = :func:`env_radiance` along d[i] (n, 3); poses (k, 4, 4), k = 1 or one per row."""
    img, par = env[0], env[4]
    one = poses.shape[0] == 1
    M = pose_buffer(poses)
    for i in range(d.shape[0]):
        if not one:
            load_pose(poses, i, M)
        L = env_radiance(img, par, M, (d[i, 0], d[i, 1], d[i, 2]))
        out[i, 0], out[i, 1], out[i, 2] = L[0], L[1], L[2]


@njit(**JIT)
def env_pdf_batch(env, poses, d, out):
    """out[i] = :func:`env_pdf` of direction d[i] (n, 3); poses (k, 4, 4), k = 1 or one per row (tests)."""
    func, par = env[1], env[4]
    one = poses.shape[0] == 1
    M = pose_buffer(poses)
    for i in range(d.shape[0]):
        if not one:
            load_pose(poses, i, M)
        out[i] = env_pdf(func, par, M, (d[i, 0], d[i, 1], d[i, 2]))


@njit(**JIT)
def env_sample_batch(env, poses, u, d_out, pdf_out, pdf_again):
    """:func:`env_sample` per row of u (n, 2) into d_out (n, 3), pdf_out (n,); pdf_again (n,) is
    :func:`env_pdf` of the drawn direction (tests: the two must agree)."""
    func, marg, cond, par = env[1], env[2], env[3], env[4]
    one = poses.shape[0] == 1
    M = pose_buffer(poses)
    for i in range(u.shape[0]):
        if not one:
            load_pose(poses, i, M)
        d0, d1, d2, p = env_sample(func, marg, cond, par, M, u[i, 0], u[i, 1])
        d_out[i, 0], d_out[i, 1], d_out[i, 2] = d0, d1, d2
        pdf_out[i] = p
        pdf_again[i] = env_pdf(func, par, M, (d0, d1, d2))


@njit(**JIT)
def portal_cross_batch(portals, j, o, d, out):
    """out[i] = :func:`portal_cross` of portal j for the lines o[i] + s d[i] (n, 3) (tests)."""
    for i in range(o.shape[0]):
        out[i] = portal_cross(portals, j, (o[i, 0], o[i, 1], o[i, 2]), (d[i, 0], d[i, 1], d[i, 2]))
