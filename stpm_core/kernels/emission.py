"""Photon emission: n photons of one light, as origins, unit directions and powers (compiled kernels).

The one implementation of ``LightSet.emit`` and ``LightSet.emit_toward`` (the numpy code it
replaced is the test oracle tests/oracles/emission_numpy.py).  Two kernels, one per query, serve
every light type (the row's ``P_TYPE``):

* :func:`emit_photons` -- photons over the light's whole emission (``LightSet.emit``);
* :func:`emit_toward_photons` -- photons aimed at a target sphere (``LightSet.emit_toward``).

The Python wrappers :func:`emit` and :func:`emit_toward` have the signatures of those LightSet
methods (which call them): they draw the uniforms from ``rng`` in the numpy code's order and
shapes, take the light's packed data (:func:`~.light_params.kernel_light`, packed once per
LightSet and shared with next-event estimation) and call the kernels, so that a render keeps its
random stream and its images (tests/test_kernel_emission.py compares them with the oracle).
Next-event sampling is :mod:`.lights`; the warps, frames and light shapes both use (area shape,
mesh-light points, spot mask, ...) are :mod:`.sampling`.

Inputs every kernel takes: ``row`` (N_LIGHT_PARAMS,); ``poses`` (k, 4, 4) object-to-world
matrices, k = 1 (static: every photon reads matrix 0) or n (one per photon); the mesh arrays
``steps`` (K,), ``corners`` (K, F, 3, 3) (in the space the poses map from), ``q``, ``cdf`` (F,),
``Le`` (F, 3) (empty for other lights); ``env`` the world's environment (``kernels.environment``;
black for other lights); ``times`` (1,) or (n,) normalised shutter times.
Outputs, written in place: ``o``, ``d``, ``P`` (n, 3): origins (scene units), unit directions,
power per photon (W); ``s_lit`` (n,): the distance from o below which the photon's first hit
receives nothing (scene units; 0 but for soft-falloff POINT / SPOT lights of radius > 0).

Notation below: c the light's position (pose column 3), Z its unit Z axis (the light shines along
-Z), I = color * power / (4 pi) W/sr its intensity, Phi = ``LightSet.flux`` (``P_FLUX``).

Emission over the whole light (:func:`emit_photons`)
------------------------------------------------------
* POINT: direction uniform on the sphere (``uniform_sphere``); power ``Phi / n``, Phi = color * P.
* SPOT: direction uniform in the cone of half-angle spot_size / 2 about -Z (``uniform_cone``,
  solid angle ``omega_c = 2 pi (1 - cos_half)``); power ``I * att * omega_c / n`` with ``att`` the
  spot mask (``spot_attenuation``: smoothstep over ``P_SMOOTH`` in cosine).  A zero Z scale
  leaves +Z as the cone axis (and the mask then decides).
* POINT / SPOT of radius r > 0: the same direction and power, the origin a uniform point of the
  disc of radius r perpendicular to the direction (``concentric_disk``) through c (soft falloff
  on) or pushed onto the sphere's front (off): :func:`_point_origin`.  Soft falloff also sets
  ``s_lit = b^2 / sqrt(r^2 - b^2)`` (b the origin's distance from c): a first hit nearer than
  that lies outside the disc of radius r facing it, so the tracer drops the photon; the photons
  then give next-event estimation's ``I cos / (r^2 + D^2)``, not the sphere's ``I cos / D^2``.
* AREA: origin uniform on the shape (``area_point``: square / rectangle from 2u - 1, disc /
  ellipse from ``concentric_disk``, times the half-extent vectors ex, ey), direction cosine-weighted
  about the emitting normal (``cosine_hemisphere``); power ``Phi / n`` = color * P / n (0 where
  the light has no emitting side).
* MESH: triangle j with probability q_j, uniform point (``mesh_point``), random side
  (u_side < 1/2: the geometric normal, else its opposite), cosine direction about it; power
  ``Le_j * 2 pi A_j(t) / (q_j n)`` (A_j the triangle's world area at the photon's time).
* SUN: a point q uniform on a disc of radius R = ``P_SUN_R`` perpendicular to Z through the
  centre of the scene's bounding sphere (centre ``P_SCENE_C``, radius R_s = ``P_SCENE_R``);
  direction d = -Z (angle 0) or uniform in the cone of half-angle angle / 2 about -Z; origin
  q - (2 R_s / cos_t) d (2 R_s upstream of the disc, outside the scene); power
  ``color * S * pi R^2 * cos_t / n`` (S = strength W/m^2, cos_t the cosine to -Z):
  :func:`_sun_photon`.
* WORLD (constant; an environment image: :func:`_world_photon`): direction d uniform on the sphere, origin uniform on the disc of radius R_s
  perpendicular to d through the scene centre, moved 2 R_s back along d; power
  ``4 pi * pi R_s^2 * L / n`` (L = ``P_COLOR`` W m^-2 sr^-1): :func:`_world_photon`.

Emission toward a sphere (:func:`emit_toward_photons`, target centres (1 or n, 3), radius rho)
-----------------------------------------------------------------------------------------------
* POINT / SPOT / AREA / MESH: the emission point x as above (c; a uniform point of the AREA
  shape; a MESH point by q_j), then the direction uniform in the cone the sphere of radius
  ``reach`` (rho, + r for a POINT / SPOT of radius r) subtends from x: ``1 - cos_max`` =
  ``sin^2 / (1 + sqrt(1 - sin^2))``, sin^2 = reach^2 / |c_t - x|^2, solid angle
  ``omega = 2 pi (1 - cos_max)``; from inside the sphere (or where the axis does not normalise)
  the whole sphere of directions (omega = 4 pi).  A POINT / SPOT of radius r then moves the
  origin onto its disc / sphere (as above).  Power:
  POINT / SPOT ``I * att * omega / n``;
  AREA ``L * max(cos_l, 0) * A * omega / n`` with L = color * P / (pi A) W m^-2 sr^-1;
  MESH ``Le_j * |cos_l| * A_j / q_j * omega / n`` (cos_l the cosine to the emitting normal).
* SUN: as above, with the disc of radius ``rho + (back + rho) tan(min(angle, 3) / 2)`` about the
  target centre and ``back = |c_t - c_s| + R_s + rho`` upstream of it.
* WORLD: the WORLD photon above with the disc of radius rho about the first centre (power
  ``4 pi * pi rho^2 * L / n``), each origin then shifted by its own centre's offset from the
  first and moved back along -d by ``max(back - 2 rho, 0)`` (so it starts outside the scene).

Float operations follow the numpy code one by one (same order, divisions where it divides, dot
products in numpy's summation order: ``sampling.dot`` / ``sampling.edot``; a static mesh light's
corners packed in world space as ``MeshLight`` computes them, since numpy's ``matmul`` rounds
through BLAS), so that on this platform the results equal the numpy code's to the last bit
(tests/test_kernel_emission.py checks them to 1e-9).
"""
from __future__ import annotations

import math

import numpy as np

from ..numba_probe import njit
from . import kernel_array
from .guide import guide_warp
from .environment import (E_PHOTON_UNIFORM, E_PORTAL_PHOTON, E_TEXTURED, PT_E1, PT_E2, PT_N, PT_S, env_pdf,
                          env_radiance, env_sample, portal_cross)
from .light_params import (P_ANGLE, P_COLOR, P_COS_HALF, P_FLUX, P_POWER, P_RADIUS, P_SCENE_C, P_SCENE_R, P_SOFT,
                           P_SUN_R, P_TYPE, T_AREA, T_MESH, T_POINT, T_SPOT, T_SUN, T_WORLD, kernel_light,
                           light_poses)
from .sampling import (JIT, TWO_PI, add, area_point, area_shape, axis_or_z, basis, column,
                       concentric_disk, cosine_hemisphere, dot, edot, intensity, light_axis, load_pose, madd,
                       mesh_point, neg, normalize, one_minus_cos_from_sin2, plane_point, pose_buffer, row3, scale,
                       spot_attenuation, sub, sun_cone, to_world, uniform_cone, uniform_sphere, vec3)

__all__ = ["emit_photons", "emit_toward_photons", "emit", "emit_toward"]


# ----------------------------------------------------------------------------
# Origins and whole photons of one row
# ----------------------------------------------------------------------------
@njit(**JIT)
def _point_origin(row, c, d, u2, i):
    """Origin of a photon leaving a POINT / SPOT light (centre c) along unit d, and the distance
    ``s_lit`` from it below which its first hit receives nothing.

    A Lambertian sphere of radiance L seen from direction d is a uniformly bright disc of radius
    r perpendicular to d: radius 0, c; radius r > 0, c plus r times a uniform point of the unit
    disc (u2[i]) in the plane perpendicular to d, at distance b from c; without soft falloff moved
    along d onto the sphere's front (s_lit = 0).

    Soft falloff (Cycles' disc of radius r through c facing each receiver): a point p at distance
    s along the photon's line (D^2 = s^2 + b^2 from c) sees this line's radiance only where the
    line crosses the disc facing p, tan(alpha) = b / s <= r / D, i.e. s >= s_lit =
    b^2 / sqrt(r^2 - b^2).  The photon's power holds only for a first hit at s >= s_lit (the
    tracer drops the others), so its lines reproduce that light's radiance I / (pi r^2) in the
    cone of half-angle atan(r / D) about every point -- next-event estimation's
    ``I cos_q / t^2`` over the disc, E = I cos / (r^2 + D^2) on an unshadowed plane -- where
    without the cut they would be the sphere's (asin(r / D), E = I cos / D^2).
    """
    r = row[P_RADIUS]
    if r <= 0.0:
        return c, 0.0
    x, y = concentric_disk(u2[i, 0], u2[i, 1])
    x, y = x * r, y * r
    t, b = basis(d)
    o = plane_point(c, x, t, y, b)
    b2 = x * x + y * y
    if row[P_SOFT] == 0.0:
        return madd(o, math.sqrt(max(r * r - b2, 0.0)), d), 0.0
    rest = r * r - b2
    return o, (b2 / math.sqrt(rest) if rest > 0.0 else np.inf)


@njit(**JIT)
def _sun_photon(row, cos_half, Z, ce, R, back, n, u1, u2, i):
    """Sun photon i whose line crosses a disc of radius R perpendicular to Z (unit or zero) through
    ce, starting ``back`` upstream of that disc (along Z).

    The sun's radiance is S norm / Omega in its cone (``sampling.sun_cone``: norm = 2 / (1 +
    cos_half), Cycles' normalisation, 1 at angle 0), so points q uniform on the disc (u2[i], pdf
    1 / (pi R^2)) and directions d = -Z (angle 0) or uniform in the cone of cosine cos_half about
    -Z (u1[i], pdf 1 / Omega) carry color * S * norm * pi R^2 * cos_t / n (0 for a zero Z); the
    photon starts at o = q - (back / cos_t) d.  The disc passes through the scene (not upstream of
    it), so a surface near ce is reached by photons of nearly one patch of the disc whatever the
    direction in the cone: emission guiding (``kernels.guide``) draws that patch sharply.
    Returns origin, direction, power (3-tuples).
    """
    Z, ok = axis_or_z(Z)
    x, y = concentric_disk(u2[i, 0], u2[i, 1])
    q = add(ce, to_world((x * R, y * R, 0.0), Z))
    if row[P_ANGLE] > 0.0:
        local = uniform_cone(u1[i, 0], u1[i, 1], cos_half)
        d = to_world(local, neg(Z))
        cos_t = local[2]
    else:
        d = neg(Z)
        cos_t = 1.0
    o = madd(q, -back / max(cos_t, 1e-6), d)
    g = np.pi * R * R * cos_t * ok / n
    S = row[P_POWER] * sun_cone(row)[2]
    return o, d, (row[P_COLOR] * S * g, row[P_COLOR + 1] * S * g, row[P_COLOR + 2] * S * g)


@njit(**JIT)
def _world_photon(row, img, func, marg, cond, par, M, ce, R, n, u1, u2, i):
    """World photon i through the disc of radius R about ce perpendicular to its direction d (point
    u2[i]), moved 2R back along d.  Returns origin, direction, power (3-tuples).

    A constant world: d uniform (u1[i]), power 4 pi * pi R^2 * L / n.  An environment image
    (``kernels.environment``, M its map-to-world rotation): the direction omega the light comes
    from is drawn from q = a / (4 pi) + (1 - a) p_img (a = ``E_PHOTON_UNIFORM``, u1[i, 0] choosing
    the technique and reused inside it), d = -omega, power L(omega) pi R^2 / (q n).  img, func,
    marg, cond, par: the env arrays."""
    if par[E_TEXTURED] == 0.0:
        d = uniform_sphere(u1[i, 0], u1[i, 1])
        g = 4.0 * np.pi * np.pi * R * R
        P = (g * row[P_COLOR] / n, g * row[P_COLOR + 1] / n, g * row[P_COLOR + 2] / n)
    else:
        a = par[E_PHOTON_UNIFORM]
        u0 = u1[i, 0]
        if u0 < a:
            w = uniform_sphere(u0 / a, u1[i, 1])
        else:
            w0, w1, w2, _ = env_sample(func, marg, cond, par, M, (u0 - a) / (1.0 - a), u1[i, 1])
            w = (w0, w1, w2)
        q = a * 0.25 / np.pi + (1.0 - a) * env_pdf(func, par, M, w)
        L = env_radiance(img, par, M, w)
        g = np.pi * R * R / (q * n) if q > 0.0 else 0.0
        d = neg(w)
        P = (g * L[0], g * L[1], g * L[2])
    t, b = basis(d)
    x, y = concentric_disk(u2[i, 0], u2[i, 1])
    o = sub(plane_point(ce, x * R, t, y * R, b), scale(d, 2.0 * R))
    return o, d, P


@njit(**JIT)
def _world_photon_portals(row, img, func, marg, cond, par, portals, M, ce, R, n, u1, u2, i):
    """World photon i with light portals (``env``'s portal rows): a defensive mixture of two ways
    to draw a photon's line (direction d, where it travels, and its crossing of the plane through
    ce perpendicular to d), u1[i, 0] choosing the technique and reused inside it.

    * with probability f = ``par[E_PORTAL_PHOTON]``, through a portal: portal j with probability
      A_j / A_tot (its area), a uniform point x of it (u2[i]), and d (d . n_j > 0: into the room)
      from ``p_d = b (d . n_j) / pi + (1 - b) (p_img(-d) + p_img(-d'))`` (b = 1 for a constant
      world, else 1/2: cosine about the portal's normal, or the image distribution of the
      direction the light comes from, mirrored in the portal's plane (d' = d - 2 (d . n_j) n_j)
      when it would leave through the portal's back);
    * otherwise :func:`_world_photon`'s: omega = -d from q (uniform, or mixed with the image
      distribution), a uniform point of the disc of radius R.

    In the measure of lines (solid angle of d times area across it) the two densities are
    ``q(-d) / (pi R^2)`` (lines through the disc) and
    ``sum_j [the line enters through portal j] p_d(d) / (A_tot (d . n_j))``; the photon carries
    ``L(-d) / (p n)`` with p their mixture (f and 1 - f), so that the photons are unbiased
    whichever technique drew them (docs/photon-mapping.md, "World photons through portals").
    It starts 2R upstream of the plane through ce, as every world photon.
    Returns origin, direction, power (3-tuples)."""
    K = portals.shape[0]
    textured = par[E_TEXTURED] != 0.0
    f = par[E_PORTAL_PHOTON]
    a = par[E_PHOTON_UNIFORM] if textured else 1.0
    b = 0.5 if textured else 1.0
    A_tot = 0.0
    for j in range(K):
        e1 = (portals[j, PT_E1], portals[j, PT_E1 + 1], portals[j, PT_E1 + 2])
        e2 = (portals[j, PT_E2], portals[j, PT_E2 + 1], portals[j, PT_E2 + 2])
        A_tot += math.sqrt(dot(e1, e1) * dot(e2, e2))
    u0 = u1[i, 0]
    if u0 < f and A_tot > 0.0:
        # ---- through a portal: j by area, a uniform point x of it, d from p_d ----
        x_a = u0 / f * A_tot
        acc, pick, before, A_pick = 0.0, 0, 0.0, 1.0
        for j in range(K):
            e1 = (portals[j, PT_E1], portals[j, PT_E1 + 1], portals[j, PT_E1 + 2])
            e2 = (portals[j, PT_E2], portals[j, PT_E2 + 1], portals[j, PT_E2 + 2])
            A_j = math.sqrt(dot(e1, e1) * dot(e2, e2))
            if A_j > 0.0:
                pick, before, A_pick = j, acc, A_j
                acc += A_j
                if x_a < acc:
                    break
        s = min(max((x_a - before) / A_pick, 0.0), 1.0)
        x = (portals[pick, PT_S] + u2[i, 0] * portals[pick, PT_E1] + u2[i, 1] * portals[pick, PT_E2],
             portals[pick, PT_S + 1] + u2[i, 0] * portals[pick, PT_E1 + 1] + u2[i, 1] * portals[pick, PT_E2 + 1],
             portals[pick, PT_S + 2] + u2[i, 0] * portals[pick, PT_E1 + 2] + u2[i, 1] * portals[pick, PT_E2 + 2])
        nj = (portals[pick, PT_N], portals[pick, PT_N + 1], portals[pick, PT_N + 2])
        if s < b:
            d = to_world(cosine_hemisphere(s / b, u1[i, 1]), nj)
        else:
            w0, w1, w2, _ = env_sample(func, marg, cond, par, M, (s - b) / (1.0 - b), u1[i, 1])
            d = (-w0, -w1, -w2)
            dn = dot(d, nj)
            if dn < 0.0:
                d = madd(d, -2.0 * dn, nj)          # mirrored into the room: the line enters through the portal
        # the line's crossing of the plane through ce perpendicular to d
        xp = madd(x, -dot(sub(x, ce), d), d)
    else:
        # ---- over the whole disc ----
        u0 = (u0 - f) / (1.0 - f) if A_tot > 0.0 else u0
        if u0 < a:
            w = uniform_sphere(u0 / a, u1[i, 1])
        else:
            w0, w1, w2, _ = env_sample(func, marg, cond, par, M, (u0 - a) / (1.0 - a), u1[i, 1])
            w = (w0, w1, w2)
        d = neg(w)
        t, bb = basis(d)
        xd, yd = concentric_disk(u2[i, 0], u2[i, 1])
        xp = plane_point(ce, xd * R, t, yd * R, bb)
    # ---- the density of this line under the mixture ----
    w = neg(d)
    p_img = env_pdf(func, par, M, w) if textured else 0.0
    v = sub(xp, ce)
    p_disc = (a * 0.25 / np.pi + (1.0 - a) * p_img) / (np.pi * R * R) if dot(v, v) <= R * R else 0.0
    p_port = 0.0
    if A_tot > 0.0:
        for j in range(K):
            cos_j = d[0] * portals[j, PT_N] + d[1] * portals[j, PT_N + 1] + d[2] * portals[j, PT_N + 2]
            if cos_j > 0.0 and not math.isnan(portal_cross(portals, j, xp, d)):     # enters through portal j
                p_d = b * cos_j / np.pi
                if textured:
                    # the image's direction, or its mirror image in the portal's plane
                    nj = (portals[j, PT_N], portals[j, PT_N + 1], portals[j, PT_N + 2])
                    p_d += (1.0 - b) * (p_img + env_pdf(func, par, M, neg(madd(d, -2.0 * cos_j, nj))))
                p_port += p_d / (A_tot * cos_j)
    pdf = (1.0 - f) * p_disc + f * p_port if A_tot > 0.0 else p_disc
    L = env_radiance(img, par, M, w)
    g = 1.0 / (pdf * n) if pdf > 0.0 else 0.0
    o = sub(xp, scale(d, 2.0 * R))
    return o, d, (g * L[0], g * L[1], g * L[2])


@njit(**JIT)
def _store(o_out, d_out, P_out, i, o, d, P):
    """Row i of the three outputs."""
    o_out[i, 0], o_out[i, 1], o_out[i, 2] = o
    d_out[i, 0], d_out[i, 1], d_out[i, 2] = d
    P_out[i, 0], P_out[i, 1], P_out[i, 2] = P


# ----------------------------------------------------------------------------
# Emission over the whole light
# ----------------------------------------------------------------------------
@njit(**JIT)
def emit_photons(row, poses, steps, corners, q, cdf, Le, env, times, u1, u2, u_side, o, d, P, s_lit):
    """n = o.shape[0] photons of one light over its whole emission, as ``LightSet.emit``.

    row, poses, steps, corners, q, cdf, Le, times: see the module docstring.  The uniforms, in
    the order the numpy code draws them: u1 (n, 2) first, then u_side (n,) (MESH only, else
    (0,)), then u2 (n, 2) (every light but a POINT / SPOT of radius 0, for which it may be
    (0, 2)).  Their roles:

    ==========  ==============================  ============================
    type        u1                              u2
    ==========  ==============================  ============================
    POINT/SPOT  direction                       point of the disc (r > 0)
    AREA        direction (cosine)              point of the shape
    MESH        triangle and point              direction (cosine); u_side the side
    SUN         direction in the cone           point of the disc
    WORLD       direction                       point of the disc
    ==========  ==============================  ============================

    Writes o, d, P (n, 3): origins, unit directions, power per photon (W), and s_lit (n,): the
    distance (scene units) from o below which the photon's first hit receives nothing (0 but for
    a POINT / SPOT of radius > 0 with soft falloff, :func:`_point_origin`).
    """
    n = o.shape[0]
    typ = int(row[P_TYPE])
    one_pose = poses.shape[0] == 1
    M = pose_buffer(poses)                   # refilled per photon only when the light moves (no views per photon)
    img, func, marg, cond, par, portals = env
    aim = portals.shape[0] > 0 and par[E_PORTAL_PHOTON] > 0.0       # WORLD photons through light portals
    one_time = times.shape[0] == 1
    cos_half = row[P_COS_HALF]
    omega_c = TWO_PI * (1.0 - cos_half)              # SPOT: the cone's solid angle
    if typ == T_SUN:
        cos_half = math.cos(0.5 * row[P_ANGLE])
    scene_c = vec3(row, P_SCENE_C)
    for i in range(n):
        if not one_pose:
            load_pose(poses, i, M)
        s_lit[i] = 0.0                           # (a soft-falloff POINT / SPOT of radius > 0 sets its own)
        # ---- POINT / SPOT: uniform sphere / cone, origin on the light's disc or sphere ----
        if typ == T_POINT or typ == T_SPOT:
            if typ == T_POINT:
                di = uniform_sphere(u1[i, 0], u1[i, 1])
                Pi = (row[P_FLUX] / n, row[P_FLUX + 1] / n, row[P_FLUX + 2] / n)
            else:
                down = neg(light_axis(M))
                axis, _ = axis_or_z(down)
                di = to_world(uniform_cone(u1[i, 0], u1[i, 1], cos_half), axis)
                Pi = scale(intensity(row), spot_attenuation(row, dot(di, down)) * omega_c / n)
            oi, s_i = _point_origin(row, column(M, 3), di, u2, i)
            s_lit[i] = s_i
        # ---- MESH: triangle by q_j, uniform point, random side, cosine direction ----
        elif typ == T_MESH:
            oi, nrm, A, j, qj = mesh_point(M, steps, corners, q, cdf, times[0 if one_time else i],
                                           u1[i, 0], u1[i, 1])
            side = 1.0 if u_side[i] < 0.5 else -1.0
            di = to_world(cosine_hemisphere(u2[i, 0], u2[i, 1]), scale(nrm, side))
            Pi = scale(row3(Le, j), 2.0 * np.pi * A / (qj * n))
        # ---- AREA: uniform point of the shape, cosine direction about the emitting normal ----
        elif typ == T_AREA:
            c, ex, ey, A, n_emit, disk = area_shape(row, M)
            oi = area_point(c, ex, ey, disk, u2[i, 0], u2[i, 1])
            axis, ok = axis_or_z(n_emit)
            di = to_world(cosine_hemisphere(u1[i, 0], u1[i, 1]), axis)
            Pi = (row[P_FLUX] / n * ok, row[P_FLUX + 1] / n * ok, row[P_FLUX + 2] / n * ok)
        # ---- SUN: lines through a disc across the scene's bounding sphere, starting 2 R_s upstream ----
        elif typ == T_SUN:
            oi, di, Pi = _sun_photon(row, cos_half, light_axis(M), scene_c, row[P_SUN_R], 2.0 * row[P_SCENE_R],
                                     n, u1, u2, i)
        # ---- WORLD: every direction, through the scene's bounding sphere (and the portals) ----
        elif aim:
            oi, di, Pi = _world_photon_portals(row, img, func, marg, cond, par, portals, M, scene_c, row[P_SCENE_R],
                                               n, u1, u2, i)
        else:
            oi, di, Pi = _world_photon(row, img, func, marg, cond, par, M, scene_c, row[P_SCENE_R], n, u1, u2, i)
        _store(o, d, P, i, oi, di, Pi)


# ----------------------------------------------------------------------------
# Emission toward a sphere
# ----------------------------------------------------------------------------
@njit(**JIT)
def emit_toward_photons(row, poses, steps, corners, q, cdf, Le, env, times, centers, radius, u1, u2, o, d, P,
                        s_lit):
    """n = o.shape[0] photons of one light aimed at spheres (centers (1 or n, 3), radius), as ``LightSet.emit_toward``.

    row, poses, steps, corners, q, cdf, Le, times: see the module docstring.  Uniforms in the
    numpy code's order: u1 (n, 2) (the direction in the cone toward the target; WORLD: the
    direction), then u2 (n, 2) (AREA / MESH: the emission point; POINT / SPOT: the point of the
    disc, (0, 2) allowed for radius 0; SUN / WORLD: the point of the disc).
    Writes o, d, P (n, 3) and s_lit (n,) as :func:`emit_photons`.
    """
    n = o.shape[0]
    typ = int(row[P_TYPE])
    one_pose = poses.shape[0] == 1
    M = pose_buffer(poses)                   # refilled per photon only when the light moves (no views per photon)
    img, func, marg, cond, par = env[0], env[1], env[2], env[3], env[4]     # (aimed at a target: no portals)
    one_time = times.shape[0] == 1
    one_c = centers.shape[0] == 1
    scene_c, scene_r = vec3(row, P_SCENE_C), row[P_SCENE_R]
    first = vec3(centers[0], 0)
    cos_half = row[P_COS_HALF]
    tan_half = 0.0
    if typ == T_SUN:
        cos_half = math.cos(0.5 * row[P_ANGLE])
        tan_half = math.tan(0.5 * min(row[P_ANGLE], 3.0))
    for i in range(n):
        if not one_pose:
            load_pose(poses, i, M)
        s_lit[i] = 0.0                           # (a soft-falloff POINT / SPOT of radius > 0 sets its own)
        x = row3(centers, 0 if one_c else i)
        # ---- SUN / WORLD: a disc upstream, starting outside the whole scene ----
        if typ == T_WORLD or typ == T_SUN:
            v = sub(x, scene_c)
            back = math.sqrt(dot(v, v)) + scene_r + radius
            if typ == T_WORLD:
                # every direction through the target; shifted with its own centre
                oi, di, Pi = _world_photon(row, img, func, marg, cond, par, M, first, radius, n, u1, u2, i)
                oi = sub(add(oi, sub(x, first)), scale(di, max(back - 2.0 * radius, 0.0)))
            else:
                # a disc covering the target sphere
                oi, di, Pi = _sun_photon(row, cos_half, light_axis(M), x, radius + (back + radius) * tan_half,
                                         back, n, u1, u2, i)
            _store(o, d, P, i, oi, di, Pi)
            continue
        # ---- Emission point: AREA shape, MESH triangle, or the POINT / SPOT centre ----
        reach = radius
        down = (0.0, 0.0, 0.0)                      # POINT / SPOT: -Z
        nrm, A, j, qj = (0.0, 0.0, 0.0), 0.0, 0, 1.0   # AREA / MESH: normal, area, triangle
        if typ == T_AREA:
            c, ex, ey, A, nrm, disk = area_shape(row, M)
            oi = area_point(c, ex, ey, disk, u2[i, 0], u2[i, 1])
        elif typ == T_MESH:
            oi, nrm, A, j, qj = mesh_point(M, steps, corners, q, cdf, times[0 if one_time else i],
                                           u2[i, 0], u2[i, 1])
        else:
            oi = column(M, 3)
            down = neg(light_axis(M))
            reach = radius + row[P_RADIUS]
        # ---- Cone toward the sphere (the whole sphere of directions from inside it) ----
        axis, dist = normalize(sub(x, oi))
        if (dist <= reach) or not (abs(edot(axis, axis) - 1.0) < 1e-6):
            one_minus_cos = 2.0
            axis = (0.0, 0.0, 1.0)
        else:
            one_minus_cos = one_minus_cos_from_sin2((reach * reach) / max(dist * dist, 1e-300))
        di = to_world(uniform_cone(u1[i, 0], u1[i, 1], 1.0 - one_minus_cos), axis)
        omega = TWO_PI * one_minus_cos
        # ---- Power: emitted intensity toward d * omega / n ----
        if typ == T_MESH:
            # dPhi = Le |cos_l| dA dw (both sides); point pdf q_j / A, direction pdf 1 / omega
            Pi = scale(row3(Le, j), abs(edot(di, nrm)) * A / qj * omega / n)
        elif typ == T_AREA:
            # dPhi = L cos_l dA dw; point pdf 1 / A, direction pdf 1 / omega
            Lr = row[P_POWER] / (np.pi * max(A, 1e-300))
            g = max(dot(di, nrm), 0.0) * A * omega / n
            Pi = (row[P_COLOR] * Lr * g, row[P_COLOR + 1] * Lr * g, row[P_COLOR + 2] * Lr * g)
        else:
            att = spot_attenuation(row, dot(di, down)) if typ == T_SPOT else 1.0
            Pi = scale(intensity(row), att * omega / n)
            oi, s_i = _point_origin(row, oi, di, u2, i)
            s_lit[i] = s_i
        _store(o, d, P, i, oi, di, Pi)


# ----------------------------------------------------------------------------
# Python wrappers: the LightSet methods' signatures and random streams
# ----------------------------------------------------------------------------
_EMPTY1 = np.zeros(0)
_EMPTY2 = np.zeros((0, 2))


def _prepare(lights, li: int, n: int, times, rng: np.random.Generator, side: bool):
    """The uniforms u1, u_side, u2 drawn from rng in the numpy code's order and shapes (u_side only
    when ``side`` and the light is a MESH; no u2 for a POINT / SPOT of radius 0), and the kernel
    inputs of light li: row, poses (1 or n, 4, 4), mesh arrays, contiguous times (1 or n,)."""
    l = lights.lights[li]
    u1 = rng.random((n, 2))
    u_side = rng.random(n) if (side and l.type == "MESH") else _EMPTY1
    u2 = _EMPTY2 if (l.type in ("POINT", "SPOT") and float(l.radius) <= 0.0) else rng.random((n, 2))
    row, poses, steps, corners, q, cdf, Le, env = kernel_light(lights, li)
    still = l.type == "WORLD" and l.transform.is_static          # (the world's time matters only to its mapping)
    times = np.ascontiguousarray(np.atleast_1d(np.asarray(0.0 if still else times, np.float64)))
    if poses is None:
        poses = light_poses(lights, li, times)
    return (u1, u_side, u2), (row, poses, steps, corners, q, cdf, Le, env, times)


def _textured(light, U, o, d, times, P) -> None:
    """A textured MESH light (``MeshLight.textured``; the kernels weighed its photons with radiance
    1): P (n, 3) *= what each photon's emission point emits, U the uniforms that chose it."""
    if getattr(light, "textured", False):
        P *= light.point_emission(U, o, -d, times)


def emit(lights, li: int, n: int, times: np.ndarray, rng: np.random.Generator, *, with_s_lit: bool = False,
         guide=None):
    """n photons of light li of the LightSet ``lights`` over its whole emission (``LightSet.emit``).

    times : (n,) (or (1,) / scalar: one time for all) normalised shutter times.
    rng : draws exactly the numbers the numpy code drew, in its order and shapes.
    with_s_lit : also return s_lit (n,), the distance from each origin below which the photon's
        first hit receives nothing (soft falloff, :func:`_point_origin`; 0 elsewhere).  A tracer
        must drop those photons: with them a soft-falloff light's photons carry its sphere's near
        field, up to 1 + r^2 / D^2 times next-event estimation's at distance D.
    guide : ``photons.guide.EmissionGuide`` of this light, or None (uniform emission): its columns
        of (u1_0, u1_1, u2_0, u2_1) are redrawn from the guide's mixture (one more uniform per
        photon from rng, after the others, picks the technique; ``kernels.guide.guide_warp``) and
        each power is divided by the mixture's density there.  None leaves the stream unchanged.
    Returns origins (n, 3), unit directions (n, 3), power (n, 3) W per photon[, s_lit (n,)].
    """
    n = int(n)
    o, d, P, s_lit = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3)), np.empty(n)
    if n > 0:
        (u1, u_side, u2), inputs = _prepare(lights, li, n, times, rng, side=True)
        w = None
        if guide is not None:
            w = np.empty(n)
            U = (u1, u2)
            V = np.ascontiguousarray(np.stack([U[c // 2][:, c % 2] for c in guide.cols], axis=1))
            guide_warp(V, guide.res, guide.start, guide.cells, guide.cdf, guide.dens, float(guide.g), rng.random(n), w)
            for k, c in enumerate(guide.cols):
                U[c // 2][:, c % 2] = V[:, k]
        emit_photons(*inputs, u1, u2, u_side, o, d, P, s_lit)
        _textured(lights.lights[li], u1, o, d, inputs[-1], P)
        if w is not None:
            P *= w[:, None]
    return (o, d, P, s_lit) if with_s_lit else (o, d, P)


def emit_toward(lights, li: int, n: int, times: np.ndarray, rng: np.random.Generator,
                centers: np.ndarray, radius: float, *, with_s_lit: bool = False):
    """n photons of light li aimed at a sphere (centers (n, 3) or (3,), radius) (``LightSet.emit_toward``).

    times : (n,) (or (1,) / scalar) normalised shutter times.
    rng : draws exactly the numbers the numpy code drew, in its order and shapes.
    with_s_lit : also return s_lit (n,) as :func:`emit`.
    Returns origins (n, 3), unit directions (n, 3), power (n, 3) W per photon[, s_lit (n,)].
    """
    n = int(n)
    o, d, P, s_lit = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3)), np.empty(n)
    if n > 0:
        centers = np.asarray(centers, np.float64)
        centers = kernel_array(centers.reshape(1, 3) if centers.ndim == 1 else np.broadcast_to(centers, (n, 3)))
        (u1, _, u2), inputs = _prepare(lights, li, n, times, rng, side=False)
        emit_toward_photons(*inputs, centers, float(radius), u1, u2, o, d, P, s_lit)
        _textured(lights.lights[li], u2, o, d, inputs[-1], P)
    return (o, d, P, s_lit) if with_s_lit else (o, d, P)
