"""Photon emission guided by direct visibility (compiled kernels; docs/photon-mapping.md,
"Emission guided by direct visibility").

A light's photon is a function of the uniforms its emission kernel draws (``kernels.emission``,
``emit_photons``): u1 (2) and u2 (2), here the four columns ``(u1_0, u1_1, u2_0, u2_1)`` of a
row ``U`` (n, 4).  The maps from those uniforms to the emission domain are area preserving
(``uniform_sphere``, ``uniform_cone``, ``concentric_disk``, ``cosine_hemisphere`` in projected
solid angle), so a cell of a regular grid over some of the columns is a cell of equal measure of
the light's emission domain (sun: the emission disc; point / spot: the sphere / cone of
directions; area: position x projected solid angle; world: direction x disc).

Two kernels:

* :func:`guide_marks` -- the inverse: for a point p the camera sees (and a time), the uniforms
  of a photon of the light that reaches p straight from the light, and the shadow ray
  (from p back toward where that photon starts) that decides whether it does;
* :func:`guide_warp` -- the mixture: with probability g a listed cell j of one of several
  grids (coarse to fine), drawn with its probability p_j (then uniform inside it), else the uniforms as drawn;
  writes the weight 1 / pdf with ``pdf(u) = (1 - g) + g sum_levels p_cell(u) res^D`` (a density
  on [0, 1)^D), the factor the photon's power is multiplied by.
"""
from __future__ import annotations

import math

import numpy as np

from ..numba_probe import njit
from .light_params import (P_ANGLE, P_COS_HALF, P_SCENE_C, P_SCENE_R, P_SUN_R, P_TYPE, T_AREA, T_POINT, T_SPOT,
                           T_SUN, T_WORLD)
from .sampling import (JIT, TWO_PI, area_point, area_shape, axis_or_z, basis, column, dot, light_axis, load_pose,
                       neg, normalize, pose_buffer, sub, to_world, uniform_cone, uniform_sphere, vec3)

__all__ = ["inverse_concentric", "inverse_sphere", "guide_marks", "guide_warp"]


@njit(**JIT)
def inverse_concentric(x, y):
    """(u0, u1) in [0, 1]^2 with ``concentric_disk(u0, u1) = (x, y)`` for a point of the unit disc."""
    r = math.sqrt(x * x + y * y)
    if r == 0.0:
        return 0.5, 0.5
    if abs(x) >= abs(y):
        a = r if x >= 0.0 else -r
        b = math.atan(y / x) * 4.0 / np.pi * a
    else:
        b = r if y >= 0.0 else -r
        a = math.atan(x / y) * 4.0 / np.pi * b
    return min(max(0.5 * (a + 1.0), 0.0), 1.0), min(max(0.5 * (b + 1.0), 0.0), 1.0)


@njit(**JIT)
def _phi_u(y, x):
    """u in [0, 1) with 2 pi u = atan2(y, x) modulo 2 pi."""
    u = math.atan2(y, x) / TWO_PI
    if u < 0.0:
        u += 1.0
    return min(u, 1.0 - 1e-12)


@njit(**JIT)
def inverse_sphere(d):
    """(u0, u1) with ``uniform_sphere(u0, u1) = d`` (d unit)."""
    return min(max(0.5 * (1.0 - d[2]), 0.0), 1.0), _phi_u(d[1], d[0])


@njit(**JIT)
def guide_marks(row, poses, P, R, U, uu, o_sh, d_sh, tmax, ok):
    """For each point P[i] (m, 3) the camera sees: the uniforms uu[i] (4,) = (u1_0, u1_1, u2_0,
    u2_1) of a photon of this light that arrives at P[i] straight from the light, and the shadow
    ray (o_sh[i], unit d_sh[i], length tmax[i]) from P[i] (the caller has moved it off the
    surface, R[i] = P[i]) back to where that photon starts; ok[i] = 0 where no photon of the light
    reaches P[i] (outside a spot's cone, behind an area light, beyond the sun's / world's disc).

    row (N_LIGHT_PARAMS,) the light's packed row; poses (1 or m, 4, 4) its pose at each point's
    time; U (m, 4) uniforms for the parts of the photon the point does not fix (SUN: the
    direction in the cone, u1; WORLD: the direction, u1; AREA: the emission point, u2; POINT /
    SPOT: the point of a radius > 0 light's disc, not guided).  Per type (``emit_photons``):

    * POINT: d = (p - c) / |p - c|, u1 = uniform_sphere^-1(d);
    * SPOT: d's local coordinates about the cone axis, u1 = uniform_cone^-1 (cos_half);
    * SUN: d = -Z (angle 0) or uniform_cone(U[i, :2]) about -Z; the line through p along d
      crosses the emission disc (radius ``P_SUN_R`` about c_s, perpendicular to Z) at q, u2 =
      concentric^-1 of q's disc coordinates / ``P_SUN_R``; the photon starts at
      o = q - (2 R_s / cos_t) d;
    * WORLD: d = uniform_sphere(U[i, :2]); u2 = concentric^-1 of p's coordinates across d about
      the scene centre / R_s; o = that disc point moved 2 R_s back along d;
    * AREA: o = area_point(U[i, 2:]); u1 = cosine_hemisphere^-1 of d about the emitting normal.
    Other types: ok = 0.
    """
    m = P.shape[0]
    typ = int(row[P_TYPE])
    one_pose = poses.shape[0] == 1
    M = pose_buffer(poses)
    ce = vec3(row, P_SCENE_C)
    Rs = row[P_SCENE_R]
    cos_half = row[P_COS_HALF]
    if typ == T_SUN:
        cos_half = math.cos(0.5 * row[P_ANGLE])
    for i in range(m):
        if not one_pose:
            load_pose(poses, i, M)
        p = (P[i, 0], P[i, 1], P[i, 2])
        ok[i] = 0
        uu[i, 0], uu[i, 1], uu[i, 2], uu[i, 3] = U[i, 0], U[i, 1], U[i, 2], U[i, 3]
        o = p
        if typ == T_POINT or typ == T_SPOT:
            # ---- a direction from the light's centre ----
            c = column(M, 3)
            d, dist = normalize(sub(p, c))
            if dist <= 0.0:
                continue
            if typ == T_POINT:
                uu[i, 0], uu[i, 1] = inverse_sphere(d)
            else:
                axis, _ = axis_or_z(neg(light_axis(M)))
                t, b = basis(axis)
                lz = dot(d, axis)
                if lz < cos_half or cos_half >= 1.0:
                    continue
                uu[i, 0] = min(max((1.0 - lz) / (1.0 - cos_half), 0.0), 1.0)
                uu[i, 1] = _phi_u(dot(d, b), dot(d, t))
            o = c
        elif typ == T_SUN:
            # ---- the line through p along the sun's direction: where it crosses the emission disc ----
            Z, good = axis_or_z(light_axis(M))
            if good == 0.0:
                continue
            if row[P_ANGLE] > 0.0:
                d = to_world(uniform_cone(U[i, 0], U[i, 1], cos_half), neg(Z))
            else:
                d = neg(Z)
            dz = dot(d, Z)
            if dz >= 0.0:
                continue
            s = dot(sub(p, ce), Z) / dz                 # p = q + s d, q on the disc through ce
            q = (p[0] - s * d[0], p[1] - s * d[1], p[2] - s * d[2])
            t, b = basis(Z)
            v = sub(q, ce)
            Rd = row[P_SUN_R]
            x, y = dot(v, t) / Rd, dot(v, b) / Rd
            if x * x + y * y > 1.0:
                continue
            uu[i, 2], uu[i, 3] = inverse_concentric(x, y)
            back = 2.0 * Rs / (-dz)                     # the photon starts 2 R_s upstream of the disc
            o = (q[0] - back * d[0], q[1] - back * d[1], q[2] - back * d[2])
        elif typ == T_WORLD:
            # ---- a direction, and where its line through p crosses the disc across it ----
            d = uniform_sphere(U[i, 0], U[i, 1])
            t, b = basis(d)
            v = sub(p, ce)
            x, y = dot(v, t) / Rs, dot(v, b) / Rs
            if x * x + y * y > 1.0:
                continue
            uu[i, 2], uu[i, 3] = inverse_concentric(x, y)
            s = dot(v, d) + 2.0 * Rs
            o = (p[0] - s * d[0], p[1] - s * d[1], p[2] - s * d[2])
        elif typ == T_AREA:
            # ---- a point of the shape, and the direction from it about the emitting normal ----
            c, ex, ey, A, n_emit, disk = area_shape(row, M)
            axis, good = axis_or_z(n_emit)
            if good == 0.0 or A <= 0.0:
                continue
            o = area_point(c, ex, ey, disk, U[i, 2], U[i, 3])
            d, dist = normalize(sub(p, o))
            if dist <= 0.0 or dot(d, axis) <= 0.0:
                continue
            t, b = basis(axis)
            uu[i, 0], uu[i, 1] = inverse_concentric(dot(d, t), dot(d, b))
        else:
            continue
        # ---- the shadow ray: from the point back to where the photon starts ----
        w, dist = normalize(sub(o, (R[i, 0], R[i, 1], R[i, 2])))
        if dist <= 0.0:
            continue
        o_sh[i, 0], o_sh[i, 1], o_sh[i, 2] = R[i, 0], R[i, 1], R[i, 2]
        d_sh[i, 0], d_sh[i, 1], d_sh[i, 2] = w
        tmax[i] = dist
        ok[i] = 1


@njit(**JIT)
def _find(cells, lo, hi, c):
    """Index j in [lo, hi) with cells[j] == c (cells[lo:hi] sorted), or -1."""
    a, b = lo, hi
    while a < b:
        mid = (a + b) // 2
        if cells[mid] < c:
            a = mid + 1
        else:
            b = mid
    if a < hi and cells[a] == c:
        return a
    return -1


@njit(**JIT)
def _cell(V, i, res):
    """Flat cell of row V[i] (D,) on a res^D grid: sum_k floor(V_k res) res^(D - 1 - k)."""
    c = 0
    for k in range(V.shape[1]):
        c = c * res + min(int(V[i, k] * res), res - 1)
    return c


@njit(**JIT)
def guide_warp(V, res, start, cells, cdf, dens, g, u_pick, w):
    """Draw the guided columns V (n, D) in place from the mixture and write the weights w (n,).

    The guide lists cells of L grids: level l has res[l] cells per column and its cells are
    cells[start[l]:start[l + 1]] (sorted flat indices sum_k floor(V_k res) res^(D - 1 - k));
    res (L,) int64, start (L + 1,) int64.  Cell j is drawn with probability cdf[j] - cdf[j - 1]
    (cdf (M,) cumulative, last 1) and adds dens[j] = g p_j res^D (its level's res) to the density
    wherever it lies.  V: the uniforms as drawn (uniform on [0, 1)^D); u_pick (n,) uniforms
    choosing the technique (u_pick < g: cell j with cdf[j - 1] <= u_pick / g < cdf[j], V then
    placed uniformly inside it; else V as drawn).
    w[i] = 1 / pdf(V[i]), pdf = (1 - g) + sum over levels of dens[the level's cell of V[i]] (0 for
    a cell not listed): a density on [0, 1)^D that integrates to 1.
    """
    n, D = V.shape
    M = cells.shape[0]
    L = res.shape[0]
    for i in range(n):
        if u_pick[i] < g:
            # ---- the guided technique: a listed cell by its probability, uniform inside it ----
            x = u_pick[i] / g
            a, b = 0, M - 1
            while a < b:
                mid = (a + b) // 2
                if cdf[mid] <= x:
                    a = mid + 1
                else:
                    b = mid
            lev = 0
            while start[lev + 1] <= a:
                lev += 1
            r = res[lev]
            c = cells[a]
            for k in range(D - 1, -1, -1):
                V[i, k] = min((c % r + V[i, k]) / r, 1.0 - 1e-12)
                c //= r
        # ---- the mixture's density where V[i] lies, summed over the levels ----
        pdf = 1.0 - g
        for lev in range(L):
            if start[lev + 1] > start[lev]:
                j = _find(cells, start[lev], start[lev + 1], _cell(V, i, res[lev]))
                if j >= 0:
                    pdf += dens[j]
        w[i] = 1.0 / pdf
