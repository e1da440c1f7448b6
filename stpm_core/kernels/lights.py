"""Next-event light sampling and light shapes seen along rays, one row at a time (numba).

The one implementation of what :meth:`stpm_core.lights.LightSet.sample_direct` returns, for
every kind of light entry (units and equations: docs/lights-and-materials.md; the numpy
implementation it replaced is the test oracle ``tests/oracles/lights_numpy.py``):

* :func:`sample_light_rows` -- one light sample for each of many shading points: unit direction
  toward the light, distance (inf for SUN / WORLD) and weight, the incident-radiance estimator
  ``L_e G / pdf`` W m^-2 sr^-1 (reflected radiance = f |cos(ns, wi)| weight, times visibility);
  the light type is chosen once per call, outside the loop; the camera-path kernels
  (:mod:`.paths`) call it once per light and bounce;
* :func:`seen_light` -- radiance of the light's shape hit by one ray (AREA lights, one-sided;
  POINT / SPOT of radius > 0: the sphere, or with soft falloff the disc facing the ray's origin;
  a SUN of angle > 0: its cone, seen by rays that escape the scene),
  as ``integrator._seen_lights`` for one light;
* :func:`spherical_rect_sample` -- a point of a rectangle uniform in the solid angle it subtends;
* :func:`light_pdf`, :func:`mesh_light_pdf`, :func:`world_nee_pdf` -- the solid-angle density with
  which :func:`sample_light_rows` draws a direction, for multiple importance sampling against
  camera paths that reach the light through a rough lobe (``paths.mis_weight``);
* :func:`sample_direct_batch`, :func:`sample_pdf_batch`, :func:`light_pdf_batch`, :func:`seen_batch`,
  :func:`spherical_rect_batch` -- the same over
  arrays of rows (``LightSet.sample_direct`` and the tests call these).

Photon emission is :mod:`.emission`; the vector helpers, warps and light shapes (area shape
from a pose, mesh-light points, spot mask, ...) both use are :mod:`.sampling`.

Inputs are data (:func:`.light_params.kernel_light`): a light's parameter row ``prm`` (columns
``P_*``), its object-to-world matrix ``M`` (4, 4) at the row's time (MESH: the instance's matrix,
identity for a static mesh whose corners are packed in world space; WORLD: identity), and for
MESH lights the triangle arrays of ``mesh_arrays`` (empty for the others).  Vectors are 3-tuples
of floats; nothing is allocated per row.

Every row uses the same random numbers and, operation for operation, the same float arithmetic
as the numpy code (divisions where it divides, the same association order, numpy's summation
order of each dot product: ``sampling.dot`` / ``sampling.edot``), so results agree to rounding,
in practice bit for bit (tests/test_kernel_lights.py asks for 1e-9).
"""
from __future__ import annotations

import math

import numpy as np

from ..numba_probe import njit
from .light_params import P_ANGLE, P_COLOR, P_DEAD, P_POWER, P_RADIUS, P_SOFT, P_TYPE, T_AREA, T_MESH, T_POINT, \
    T_SPOT, T_SUN, T_WORLD
from .environment import (E_PORTAL_NEE, nee_cos, E_TEXTURED, PT_E1, PT_E2, PT_N, PT_S, env_pdf, env_radiance,
                          env_sample, portal_cross)
from .sampling import (JIT, TWO_PI, area_point, area_shape, axis_or_z, clip, column, concentric_disk,
                       cosine_hemisphere, cross, dot, edot, intensity, light_axis, load_pose, madd, mesh_choice, mesh_point, mesh_triangle, neg, sun_cone,
                       normalize, one_minus_cos_from_sin2, pose_buffer, row3, scale, sign, spot_attenuation, sub,
                       to_world, uniform_cone, uniform_sphere, unit, vec3)

__all__ = ["sample_light_rows", "world_nee_pdf", "world_nee_pdf_batch", "light_pdf", "mesh_light_pdf", "seen_light", "sample_direct_batch",
           "sample_pdf_batch", "light_pdf_batch", "seen_batch", "spherical_rect_sample",
           "spherical_rect_batch"]


# ----------------------------------------------------------------------------
# Spherical rectangle (Urena, Fajardo and King 2013)
# ----------------------------------------------------------------------------
@njit(**JIT)
def spherical_rect_sample(o, s, ex, ey, u0, u1):
    """A point q (3-tuple) on the rectangle (corner s, orthogonal full edges ex, ey) uniform in the
    solid angle S (sr) it subtends from o; returns (q, S).  S = 0 where o lies in its plane.

    Row for row the float operations of the numpy version (``tests/oracles/lights_numpy.py``):
    local frame x = ex / |ex|, y = ey / |ey|, z = x cross y flipped so the rectangle lies at
    z0 <= 0; S from the angles of the four great-circle edges; x by inverting the solid angle's
    cumulative, y uniform in h = y / sqrt(d^2 + y^2).
    """
    x, lx = unit(ex)
    y, ly = unit(ey)
    z = cross(x, y)
    d = sub(s, o)
    z0 = edot(d, z)
    if z0 > 0.0:
        z = neg(z)
        z0 = -z0
    x0 = edot(d, x)
    y0 = edot(d, y)
    x1, y1 = x0 + lx, y0 + ly
    # Inner normals of the four great-circle edges
    n0, _ = unit((0.0, z0, -y0))
    n1, _ = unit((-z0, 0.0, x1))
    n2, _ = unit((0.0, -z0, y1))
    n3, _ = unit((z0, 0.0, -x0))
    g0 = math.acos(clip(-edot(n0, n1), -1.0, 1.0))
    g1 = math.acos(clip(-edot(n1, n2), -1.0, 1.0))
    g2 = math.acos(clip(-edot(n2, n3), -1.0, 1.0))
    g3 = math.acos(clip(-edot(n3, n0), -1.0, 1.0))
    b0, b1 = n0[2], n2[2]
    k = TWO_PI - g2 - g3
    S = max(g0 + g1 - k, 0.0)
    # x by the solid angle's cumulative
    au = u0 * S + k
    sin_au = math.sin(au)
    fu = (math.cos(au) * b0 - b1) / (1e-300 if sin_au == 0.0 else sin_au)
    if fu == 0.0:
        cu = 0.0
    else:
        cu = clip(sign(fu) / math.sqrt(fu * fu + b0 * b0 + 1e-300), -1.0, 1.0)
    xu = clip(-(cu * z0) / math.sqrt(max(1.0 - cu * cu, 1e-300)), x0, x1)
    # y uniform in h = y / sqrt(d^2 + y^2)
    dd = math.sqrt(xu * xu + z0 * z0)
    h0 = y0 / math.sqrt(dd * dd + y0 * y0 + 1e-300)
    h1 = y1 / math.sqrt(dd * dd + y1 * y1 + 1e-300)
    hv = h0 + u1 * (h1 - h0)
    hv2 = hv * hv
    if hv2 < 1.0 - 1e-12:
        yv = hv * dd / math.sqrt(max(1.0 - hv2, 1e-300))
    else:
        yv = y1
    yv = clip(yv, y0, y1)
    q = (o[0] + xu * x[0] + yv * y[0] + z0 * z[0],
         o[1] + xu * x[1] + yv * y[1] + z0 * z[1],
         o[2] + xu * x[2] + yv * y[2] + z0 * z[2])
    return q, S


# ----------------------------------------------------------------------------
# One sample per light type: (wi0, wi1, wi2, dist, w0, w1, w2)
# ----------------------------------------------------------------------------
@njit(**JIT)
def _sample_point_delta(prm, M, p):
    """:func:`_sample_point` of radius 0, a true point: the exact direction, weight I / d^2 (0 at
    the light itself), spot-masked.  No random numbers; small enough to be inlined (the sampling
    loop of such lights contains no call, ``sample_light_rows``)."""
    c = column(M, 3)
    I0, I1, I2 = intensity(prm)
    to_p, d = normalize(sub(p, c))                  # light -> p
    wi = neg(to_p)
    g = 1.0 / max(d * d, 1e-300) if d > 0.0 else 0.0
    w0, w1, w2 = I0 * g, I1 * g, I2 * g
    if int(prm[P_TYPE]) == T_SPOT:
        a = spot_attenuation(prm, dot(wi, light_axis(M)))   # (-wi) . (-Z): the direction leaving the light
        w0, w1, w2 = w0 * a, w1 * a, w2 * a
    return wi[0], wi[1], wi[2], d, w0, w1, w2


@njit(**JIT)
def _sample_point(prm, M, p, u0, u1):
    """POINT / SPOT of intensity I = color P / (4 pi) W/sr at M's translation.

    Radius 0: the exact direction, weight I / d^2 (0 at the light itself).  Radius r > 0 with soft
    falloff: a uniform point of the disc of radius r facing p, weight I cos_q / t^2.  Without: the
    sphere of radius r, directions uniform in the cone it subtends (every direction from inside;
    distance to its far side there), weight I Omega / (pi r^2).  SPOT: times the cone mask of the
    direction the light leaves along (its axis: M's -Z column, normalised).
    """
    r = prm[P_RADIUS]
    if r <= 0.0:
        return _sample_point_delta(prm, M, p)
    c = column(M, 3)
    I0, I1, I2 = intensity(prm)
    to_p, d = normalize(sub(p, c))                  # light -> p
    if prm[P_SOFT] != 0.0:
        # -- soft falloff: disc of radius r through c facing p; pdf_A = 1 / (pi r^2), L = I / (pi r^2)
        dx, dy = concentric_disk(u0, u1)
        wi, dist = normalize(sub(madd(c, r, to_world((dx, dy, 0.0), to_p)), p))
        cos_q = max(-dot(wi, to_p), 0.0)
        g = cos_q / max(dist * dist, 1e-300)
    else:
        # -- sphere of radius r: uniform in its cone (the whole sphere from inside, about +Z)
        inside = d <= r
        if inside:
            one_minus_cos = 2.0
            axis = (0.0, 0.0, 1.0)
        else:
            one_minus_cos = one_minus_cos_from_sin2((r * r) / max(d * d, 1e-300))
            axis = neg(to_p)
        wi = to_world(uniform_cone(u0, u1, 1.0 - one_minus_cos), axis)
        # distance along wi to the sphere: near hit from outside, far hit from inside
        oc = sub(p, c)
        b = edot(oc, wi)
        disc = max(b * b - (edot(oc, oc) - r * r), 0.0)
        sq = math.sqrt(disc)
        dist = -b + sq if inside else max(-b - sq, 0.0)
        omega = TWO_PI * one_minus_cos
        g = omega / (np.pi * r * r)
    w0, w1, w2 = I0 * g, I1 * g, I2 * g
    if int(prm[P_TYPE]) == T_SPOT:
        a = spot_attenuation(prm, dot(wi, light_axis(M)))   # (-wi) . (-Z): the direction leaving the light
        w0, w1, w2 = w0 * a, w1 * a, w2 * a
    return wi[0], wi[1], wi[2], dist, w0, w1, w2


@njit(**JIT)
def _sample_area(prm, M, p, u0, u1):
    """AREA light, one-sided, radiance L = color P / (pi A) toward n_emit.

    SQUARE / RECTANGLE whose edges are orthogonal within |cos| <= 1e-5 (Blender's float32
    matrices; ey then made exactly orthogonal) and whose solid angle S > 1e-7 sr: a point uniform
    in S (:func:`spherical_rect_sample`), weight L S where p is in front, else 0.  Every other
    row (DISK / ELLIPSE, sheared or tiny rectangles): a uniform point of the shape, weight
    L cos_l A / t^2 with cos_l = max(0, -wi . n_emit).

    Returns (wi0, wi1, wi2, dist, w0, w1, w2, pdf): pdf the solid-angle density of wi, the value
    :func:`light_pdf` gives for it (1 / S, or t^2 / (cos_l A) with t the distance along wi to the
    light's plane; inf where wi cannot reach the front), from the same set-up: next-event
    estimation with multiple importance sampling reads it without a second solid angle.
    """
    c, ex, ey, A, n_emit, disk = area_shape(prm, M)
    k = prm[P_POWER] / (np.pi * max(A, 1e-300))
    L0, L1, L2 = prm[P_COLOR] * k, prm[P_COLOR + 1] * k, prm[P_COLOR + 2] * k
    done = False
    wi = (0.0, 0.0, 1.0)
    dist = 0.0
    g = 0.0
    pdf = np.inf
    if not disk:
        exx = edot(ex, ex)
        exy = edot(ex, ey)
        if abs(exy) <= 1e-5 * math.sqrt(exx * edot(ey, ey)):
            eyo = sub(ey, scale(ex, exy / max(exx, 1e-300)))
            qs, S = spherical_rect_sample(p, sub(sub(c, ex), eyo), scale(ex, 2.0), scale(eyo, 2.0), u0, u1)
            if S > 1e-7:
                wi, dist = normalize(sub(qs, p))
                g = S if -dot(wi, n_emit) > 0.0 else 0.0
                pdf = 1.0 / S
                done = True
    if not done:
        wi, dist = normalize(sub(area_point(c, ex, ey, disk, u0, u1), p))
        cos_l = max(-dot(wi, n_emit), 0.0)
        g = cos_l * A / max(dist * dist, 1e-300)
        # light_pdf's expression: t along wi to the plane (cos_l unclamped, as there)
        cos_p = -dot(wi, n_emit)
        if not cos_p > 0.0 or not A > 0.0:
            pdf = np.inf
        else:
            t = dot(sub(c, p), n_emit) / -cos_p
            pdf = t * t / (cos_p * A)
    return wi[0], wi[1], wi[2], dist, L0 * g, L1 * g, L2 * g, pdf


@njit(**JIT)
def _sample_sun(prm, M, u0, u1):
    """SUN of strength S: toward its unit Z axis, uniform in the cone of angular diameter
    ``angle`` (radiance color S norm / Omega = color S / (pi sin^2(angle / 2)), pdf 1 / Omega,
    ``sampling.sun_cone``): weight color S norm, norm = 2 / (1 + cos(angle / 2)) (1 at angle 0:
    the facing irradiance is S, as in Cycles), distance inf.  A zero Z scale has no direction: +Z
    stands in and the weight is 0."""
    Z, ok = axis_or_z(light_axis(M))
    angle = prm[P_ANGLE]
    cos_half, _, norm = sun_cone(prm)
    wi = to_world(uniform_cone(u0, u1, cos_half), Z) if angle > 0.0 else Z
    power = prm[P_POWER] * norm * ok
    return (wi[0], wi[1], wi[2], np.inf, prm[P_COLOR] * power, prm[P_COLOR + 1] * power, prm[P_COLOR + 2] * power)


@njit(**JIT)
def _sample_mesh(M, steps, corners, q, cdf, Le, t, p, u0, u1):
    """MESH: triangle j with probability q_j, a uniform point of it at time t
    (``sampling.mesh_point``); two-sided radiance Le[j]: weight Le |cos_l| A / (q_j t^2)."""
    qp, nrm, A, j, qj = mesh_point(M, steps, corners, q, cdf, t, u0, u1)
    wi, dist = normalize(sub(qp, p))
    g = abs(edot(wi, nrm)) * A / (qj * max(dist * dist, 1e-300))
    return wi[0], wi[1], wi[2], dist, Le[j, 0] * g, Le[j, 1] * g, Le[j, 2] * g


@njit(**JIT)
def _sample_world(prm, n, u0, u1):
    """WORLD of radiance L (the row's colour): cosine-distributed about n (pdf cos / pi), weight
    L pi / cos; a zero n: uniform on the sphere, weight 4 pi L.  Distance inf."""
    L = vec3(prm, P_COLOR)
    if n[0] == 0.0 and n[1] == 0.0 and n[2] == 0.0:
        wi = uniform_sphere(u0, u1)
        c = 4.0 * np.pi
    else:
        local = cosine_hemisphere(u0, u1)
        wi = to_world(local, n)
        c = np.pi / max(local[2], 1e-12)
    return wi[0], wi[1], wi[2], np.inf, c * L[0], c * L[1], c * L[2]


@njit(**JIT)
def _sample_env(img, func, marg, cond, par, M, n, u0, u1):
    """WORLD with an environment image (``kernels.environment``'s env arrays, map-to-world rotation
    M): wi from the mixture p = c p_cos + (1 - c) p_img (c = ``environment.nee_cos`` of n; p_cos cosine
    about n, or uniform on the sphere for a zero n), u0 choosing the technique and reused inside
    it; weight L(wi) / p.  Distance inf.  Returns (wi0, wi1, wi2, inf, w0, w1, w2, p): p is
    :func:`world_nee_pdf`'s value for wi without portals (the same expression), so next-event
    estimation reads the density without a second ``env_pdf``."""
    c = nee_cos(par, M, n)
    no_n = n[0] == 0.0 and n[1] == 0.0 and n[2] == 0.0
    if u0 < c:
        u0 = u0 / c
        if no_n:
            wi = uniform_sphere(u0, u1)
        else:
            wi = to_world(cosine_hemisphere(u0, u1), n)
    else:
        d0, d1, d2, _ = env_sample(func, marg, cond, par, M, (u0 - c) / (1.0 - c), u1)
        wi = (d0, d1, d2)
    if no_n:
        p_a = 0.25 / np.pi
    else:
        p_a = max(wi[0] * n[0] + wi[1] * n[1] + wi[2] * n[2], 0.0) / np.pi
    pdf = c * p_a + (1.0 - c) * env_pdf(func, par, M, wi)
    if not pdf > 0.0:
        return wi[0], wi[1], wi[2], np.inf, 0.0, 0.0, 0.0, pdf
    L = env_radiance(img, par, M, wi)
    return wi[0], wi[1], wi[2], np.inf, L[0] / pdf, L[1] / pdf, L[2] / pdf, pdf


@njit(**JIT)
def _portal_solid_angle(portals, j, p):
    """Solid angle (sr) portal j (``kernels.environment``'s rows) subtends from p, where p lies on
    its room side ((p - corner) . n > 0); 0 elsewhere (Cycles samples a portal only from there)."""
    s = (portals[j, PT_S], portals[j, PT_S + 1], portals[j, PT_S + 2])
    nrm = (portals[j, PT_N], portals[j, PT_N + 1], portals[j, PT_N + 2])
    if not (p[0] - s[0]) * nrm[0] + (p[1] - s[1]) * nrm[1] + (p[2] - s[2]) * nrm[2] > 0.0:
        return 0.0
    e1 = (portals[j, PT_E1], portals[j, PT_E1 + 1], portals[j, PT_E1 + 2])
    e2 = (portals[j, PT_E2], portals[j, PT_E2 + 1], portals[j, PT_E2 + 2])
    return spherical_rect_sample(p, s, e1, e2, 0.5, 0.5)[1]


@njit(**JIT)
def world_nee_pdf(func, par, portals, M, p, n, wi):
    """Solid-angle density (1/sr) with which next-event estimation draws wi toward the WORLD from
    the point p whose geometric normal turned toward the viewer is n (zero: no normal): cos / pi
    about n (uniform 1 / (4 pi) without one) for a constant world, the mixture of
    :func:`_sample_env` for an environment image (func, par of its env arrays, M its
    map-to-world rotation); with portals (``env``'s portal rows) facing p, the mixture
    ``g n_cross(wi) / S_tot + (1 - g) p_base(wi)`` of :func:`_sample_world_portals`."""
    no_n = n[0] == 0.0 and n[1] == 0.0 and n[2] == 0.0
    p_a = 0.25 / np.pi if no_n else max(wi[0] * n[0] + wi[1] * n[1] + wi[2] * n[2], 0.0) / np.pi
    if par[E_TEXTURED] == 0.0:
        base = p_a
    else:
        c = nee_cos(par, M, n)
        base = c * p_a + (1.0 - c) * env_pdf(func, par, M, wi)
    if portals.shape[0] == 0 or par[E_PORTAL_NEE] <= 0.0:
        return base
    # Portals facing p: their total solid angle, and how many of them wi passes through
    S_tot = 0.0
    hits = 0
    for j in range(portals.shape[0]):
        S_j = _portal_solid_angle(portals, j, p)
        if S_j > 0.0:
            S_tot += S_j
            if portal_cross(portals, j, p, wi) > 0.0:
                hits += 1
    if not S_tot > 0.0:
        return base
    g = par[E_PORTAL_NEE]
    return g * hits / S_tot + (1.0 - g) * base


@njit(**JIT)
def _sample_world_portals(img, func, marg, cond, par, portals, M, p, n, u0, u1):
    """WORLD (constant or an environment image) with light portals, from p with geometric normal n
    (turned toward the viewer; zero: none).  With probability g = ``par[E_PORTAL_NEE]`` (where
    some portal faces p, else 0) a portal j chosen in proportion to the solid angle S_j it
    subtends from p (:func:`_portal_solid_angle`) and a direction uniform in that solid angle
    (:func:`spherical_rect_sample`); otherwise the sampler without portals (:func:`_sample_world`,
    :func:`_sample_env`), u0 choosing the technique and reused inside it.  The density of the
    mixture, ``g n_cross(wi) / S_tot + (1 - g) p_base(wi)`` (n_cross the facing portals wi passes
    through: overlapping portals add up), is :func:`world_nee_pdf`'s; weight L(wi) / pdf.
    Returns (wi0, wi1, wi2, inf, w0, w1, w2, pdf)."""
    S_tot = 0.0
    for j in range(portals.shape[0]):
        S_tot += _portal_solid_angle(portals, j, p)
    g = par[E_PORTAL_NEE] if S_tot > 0.0 else 0.0
    no_n = n[0] == 0.0 and n[1] == 0.0 and n[2] == 0.0
    if u0 < g:
        # -- through a portal, chosen by solid angle
        x = u0 / g * S_tot
        acc = 0.0
        pick, S_pick, before = -1, 0.0, 0.0
        for j in range(portals.shape[0]):
            S_j = _portal_solid_angle(portals, j, p)
            if S_j > 0.0:
                pick, S_pick, before = j, S_j, acc
                acc += S_j
                if x < acc:
                    break
        u = min(max((x - before) / S_pick, 0.0), 1.0)
        s = (portals[pick, PT_S], portals[pick, PT_S + 1], portals[pick, PT_S + 2])
        e1 = (portals[pick, PT_E1], portals[pick, PT_E1 + 1], portals[pick, PT_E1 + 2])
        e2 = (portals[pick, PT_E2], portals[pick, PT_E2 + 1], portals[pick, PT_E2 + 2])
        q, _ = spherical_rect_sample(p, s, e1, e2, u, u1)
        wi, _ = normalize(sub(q, p))
    else:
        # -- the world's own sampler: cosine (or uniform) and, for an image, its distribution
        u0 = (u0 - g) / (1.0 - g) if g > 0.0 else u0
        c = nee_cos(par, M, n) if par[E_TEXTURED] != 0.0 else 1.0
        if u0 < c:
            u0 = u0 / c
            wi = uniform_sphere(u0, u1) if no_n else to_world(cosine_hemisphere(u0, u1), n)
        else:
            d0, d1, d2, _ = env_sample(func, marg, cond, par, M, (u0 - c) / (1.0 - c), u1)
            wi = (d0, d1, d2)
    pdf = world_nee_pdf(func, par, portals, M, p, n, wi)
    if not pdf > 0.0:
        return wi[0], wi[1], wi[2], np.inf, 0.0, 0.0, 0.0, 0.0
    L = env_radiance(img, par, M, wi)
    return wi[0], wi[1], wi[2], np.inf, L[0] / pdf, L[1] / pdf, L[2] / pdf, pdf


@njit(**JIT)
def light_pdf(prm, M, p, wi):
    """Solid-angle density (1/sr) with which :func:`sample_light_rows` draws the direction wi (unit)
    from p toward an AREA light or a POINT / SPOT of radius > 0 at pose M, for multiple
    importance sampling against camera paths that reach the light through a rough lobe
    (docs/rendering.md, "Multiple importance sampling").  The same cases as the samplers:

    * AREA rectangle sampled by solid angle (:func:`_sample_area`'s test): 1 / S;
    * AREA otherwise: t^2 / (cos_l A), t the distance along wi to the light's plane;
    * POINT / SPOT with soft falloff (a disc of radius r through the centre c facing p):
      t^2 / (cos_q pi r^2) where wi crosses the disc at distance t, else 0;
    * POINT / SPOT sphere: 1 / Omega, Omega = 2 pi (1 - cos theta_max) the cone it subtends from
      outside (1 / (4 pi) from inside).

    * SUN of angle > 0: 1 / Omega inside its cone (``wi . Z >= cos(angle / 2)``, the cone
      :func:`seen_light` shows), 0 outside (``sampling.sun_cone``).

    inf for every other light (delta lights and suns of angle 0: next-event estimation alone
    counts them) and where wi cannot reach the light's front (the sample then weighs nothing)."""
    typ = int(prm[P_TYPE])
    if typ == T_SUN:
        if not prm[P_ANGLE] > 0.0:
            return np.inf
        cos_half, omega, _ = sun_cone(prm)
        Z, _ = axis_or_z(light_axis(M))
        return 1.0 / omega if dot(wi, Z) >= cos_half else 0.0
    if typ == T_AREA:
        c, ex, ey, A, n_emit, disk = area_shape(prm, M)
        if not disk:
            exx = edot(ex, ex)
            exy = edot(ex, ey)
            if abs(exy) <= 1e-5 * math.sqrt(exx * edot(ey, ey)):
                eyo = sub(ey, scale(ex, exy / max(exx, 1e-300)))
                _, S = spherical_rect_sample(p, sub(sub(c, ex), eyo), scale(ex, 2.0), scale(eyo, 2.0), 0.5, 0.5)
                if S > 1e-7:
                    return 1.0 / S
        cos_l = -dot(wi, n_emit)
        if not cos_l > 0.0 or not A > 0.0:
            return np.inf
        t = dot(sub(c, p), n_emit) / -cos_l
        return t * t / (cos_l * A)
    if (typ == T_POINT or typ == T_SPOT) and prm[P_RADIUS] > 0.0:
        r = prm[P_RADIUS]
        to_p, d = normalize(sub(p, column(M, 3)))          # light -> p
        if prm[P_SOFT] != 0.0:
            cos_q = -dot(wi, to_p)
            if not cos_q > 0.0:
                return 0.0
            t = d / cos_q                                   # to the disc through c facing p
            x = madd(sub(p, column(M, 3)), t, wi)
            if edot(x, x) > r * r:
                return 0.0
            return t * t / (cos_q * np.pi * r * r)
        if d <= r:
            return 0.25 / np.pi
        return 1.0 / (TWO_PI * one_minus_cos_from_sin2((r * r) / max(d * d, 1e-300)))
    return np.inf


@njit(**JIT)
def mesh_light_pdf(M, steps, corners, q, j, t, p, x):
    """Solid-angle density (1/sr) with which :func:`sample_light_rows` draws the point x of emitting
    triangle j of a MESH light (pose M, arrays of ``light_params.mesh_arrays``) from p at
    normalised time t: q_j dist^2 / (A_j(t) |cos_l|) (inf where the triangle is seen edge-on)."""
    C0, e1, e2 = mesh_triangle(M, steps, corners, j, t)
    nrm, two_A = normalize(cross(e1, e2))
    wi, dist = normalize(sub(x, p))
    den = 0.5 * two_A * abs(edot(wi, nrm))
    if not den > 0.0:
        return np.inf
    return q[j] * dist * dist / den


# ----------------------------------------------------------------------------
# Light samples for many shading points
# ----------------------------------------------------------------------------
@njit(**JIT)
def _put(S, k, r):
    """S[k, :7] := r, a sampler's 7-tuple (wi, dist, w)."""
    for j in range(7):
        S[k, j] = r[j]


@njit(**JIT)
def _put8(S, k, r):
    """S[k, :8] := r, a sampler's 8-tuple (wi, dist, w, density): its own function, so that neither
    compiles a second signature for the other's tuple length."""
    for j in range(8):
        S[k, j] = r[j]


@njit(**JIT)
def _toward(NG, D, r):
    """Row r's geometric normal turned toward wo = -D[r] (the WORLD's cosine-sampling axis)."""
    g0, g1, g2 = NG[r, 0], NG[r, 1], NG[r, 2]
    if -D[r, 0] * g0 - D[r, 1] * g1 - D[r, 2] * g2 < 0.0:
        return -g0, -g1, -g2
    return g0, g1, g2


@njit(**JIT)
def sample_light_rows(prm, poses, steps, corners, q, cdf, Le, env, rows, P, NG, D, T, U, S, want_pdf):
    """One sample of light ``prm`` for each shading row k, the point p = P[rows[k]] (world) at
    normalised time T[k] with uniforms U[k] (2,); writes S[k] = (wi0, wi1, wi2, dist, w0, w1, w2).

    prm (N_LIGHT_PARAMS,): the light's parameter row; poses (K, 4, 4): its object-to-world
    matrices, row k reads poses[0] when K = 1 else poses[k] (MESH: its instance's, identity for a
    static one; WORLD: identity); steps (K,), corners (K, F, 3, 3), q, cdf (F,), Le (F, 3): a MESH
    light's triangles (``light_params.mesh_arrays``; empty for other lights); env: the WORLD's
    environment (``kernels.environment``; an image world samples it, :func:`_sample_env`, with
    poses its mapping; with light portals :func:`_sample_world_portals`).  NG, D (m, 3): the rows' geometric normals and ray directions, read by
    WORLD only (cosine sampling about ng turned toward wo = -d; a zero ng: uniform sphere).  rows (n,) into P, NG, D; T (n,), U (n, 2), S (n, 8).

    wi: unit direction from p toward the light sample; dist: its distance (inf for SUN / WORLD;
    shadow rays test [eps, dist)); w: the weight W m^-2 sr^-1, 0 where the light gives nothing
    (behind an area light, outside a spot, a dead light).  S[k, 7]: the density with which wi was
    drawn, for multiple importance sampling, written in the same loop: the WORLD's
    (:func:`world_nee_pdf`) always; with want_pdf also an AREA's, a POINT / SPOT sphere's
    (:func:`light_pdf`), a MESH light's (:func:`mesh_light_pdf`) and a SUN's of angle > 0 (1 / Omega,
    ``sampling.sun_cone``); inf otherwise (delta lights and suns of angle 0 always).  The light type is chosen once, outside the loops: each loop body is one
    sampler, with no branch or call it does not need (a POINT / SPOT of radius 0 has a loop of
    its own, :func:`_sample_point_delta`, which LLVM inlines: a loop with a call in it saves and
    reloads its floating-point values around the call on every row).  The loops
    make no array views (the pose M is one buffer, refilled per row only when the light moves; the
    env arrays are taken out of their tuple once): a view per row would cost two atomic
    reference-count operations per row (``sampling.row3``).
    """
    typ = int(prm[P_TYPE])
    one = poses.shape[0] == 1
    n = rows.shape[0]
    M = pose_buffer(poses)
    img, func, marg, cond, par, portals = env
    # Column 7 (written in the same loop): the density the samples were drawn with (multiple
    # importance sampling against camera paths that go on through rough lobes); inf for delta
    # lights, which next-event estimation handles alone
    if (typ == T_POINT or typ == T_SPOT) and prm[P_RADIUS] <= 0.0:
        for k in range(n):
            if not one:
                load_pose(poses, k, M)
            _put(S, k, _sample_point_delta(prm, M, row3(P, rows[k])))
            S[k, 7] = np.inf
    elif typ == T_POINT or typ == T_SPOT:
        for k in range(n):
            if not one:
                load_pose(poses, k, M)
            p = row3(P, rows[k])
            _put(S, k, _sample_point(prm, M, p, U[k, 0], U[k, 1]))
            S[k, 7] = light_pdf(prm, M, p, (S[k, 0], S[k, 1], S[k, 2])) if want_pdf else np.inf
    elif typ == T_AREA:
        for k in range(n):
            if not one:
                load_pose(poses, k, M)
            _put8(S, k, _sample_area(prm, M, row3(P, rows[k]), U[k, 0], U[k, 1]))   # with light_pdf's density
            if not want_pdf:
                S[k, 7] = np.inf
    elif typ == T_SUN:
        # a sun of angle > 0 is seen by rays that escape within its cone (seen_light): density
        # 1 / Omega for multiple importance sampling; a sun of angle 0 is a direction only (inf)
        p_sun = 1.0 / sun_cone(prm)[1] if want_pdf and prm[P_ANGLE] > 0.0 else np.inf
        for k in range(n):
            if not one:
                load_pose(poses, k, M)
            _put(S, k, _sample_sun(prm, M, U[k, 0], U[k, 1]))
            S[k, 7] = p_sun
    elif typ == T_MESH:
        for k in range(n):
            if not one:
                load_pose(poses, k, M)
            p = row3(P, rows[k])
            _put(S, k, _sample_mesh(M, steps, corners, q, cdf, Le, T[k], p, U[k, 0], U[k, 1]))
            if want_pdf:
                j = mesh_choice(q, cdf, U[k, 0], U[k, 1])[0]
                x = (p[0] + S[k, 3] * S[k, 0], p[1] + S[k, 3] * S[k, 1], p[2] + S[k, 3] * S[k, 2])
                S[k, 7] = mesh_light_pdf(M, steps, corners, q, j, T[k], p, x)
            else:
                S[k, 7] = np.inf
    elif typ == T_WORLD and portals.shape[0] > 0:
        for k in range(n):
            if not one:
                load_pose(poses, k, M)
            nk = _toward(NG, D, rows[k])
            r = _sample_world_portals(img, func, marg, cond, par, portals, M, row3(P, rows[k]), nk, U[k, 0], U[k, 1])
            S[k, 0], S[k, 1], S[k, 2], S[k, 3] = r[0], r[1], r[2], r[3]
            S[k, 4], S[k, 5], S[k, 6], S[k, 7] = r[4], r[5], r[6], r[7]
    elif typ == T_WORLD and par[E_TEXTURED] != 0.0:
        for k in range(n):
            if not one:
                load_pose(poses, k, M)
            nk = _toward(NG, D, rows[k])
            _put8(S, k, _sample_env(img, func, marg, cond, par, M, nk, U[k, 0], U[k, 1]))  # world_nee_pdf's density (no portals here)
    elif typ == T_WORLD:
        for k in range(n):
            if not one:
                load_pose(poses, k, M)
            nk = _toward(NG, D, rows[k])
            _put(S, k, _sample_world(prm, nk, U[k, 0], U[k, 1]))
            S[k, 7] = world_nee_pdf(func, par, portals, M, row3(P, rows[k]), nk, (S[k, 0], S[k, 1], S[k, 2]))
    else:
        for k in range(n):
            _put(S, k, (0.0, 0.0, 1.0, np.inf, 0.0, 0.0, 0.0))     # (no other type codes)
            S[k, 7] = np.inf
    if prm[P_DEAD] != 0.0:
        # no emitting direction at any key (zero Z scale, zero area): nothing
        for k in range(n):
            S[k, 4] = S[k, 5] = S[k, 6] = 0.0


# ----------------------------------------------------------------------------
# Light shapes seen along one ray
# ----------------------------------------------------------------------------
@njit(**JIT)
def seen_light(prm, M, o, d, t_scene, camera_ray):
    """Radiance (L0, L1, L2) W m^-2 sr^-1 of this light's shape hit by the ray o + s d (unit d,
    3-tuples) at 0 < s < t_scene, as ``integrator._seen_lights`` for one light; M its matrix at
    the ray's time (scale kept).

    AREA: one-sided (seen where d . n_emit < 0), radiance color P / (pi A).  POINT / SPOT of
    radius r > 0, radiance I / (pi r^2), spots masked by the cone about M's -Z (normalised) along
    -d: with soft falloff the disc of radius r through the centre facing o (the disc
    :func:`_sample_point` draws from o, so that hits, samples and :func:`light_pdf` describe one
    light, as Cycles' ``point_light_intersect``), without it the sphere, seen from outside only.  Radius-0 lights,
    suns of angle 0, meshes (the caster hits their triangles) and the world: 0; lights of power <= 0 or black
    colour: 0.  ``camera_ray`` is accepted for symmetry: Blender's camera-visibility flag is the
    caller's test.

    SUN of angle > 0 (Cycles' ``distant_light_intersect``): seen by a ray that escapes the scene
    (t_scene = inf) within its cone, ``d . Z >= cos(angle / 2)`` (Z: M's unit Z axis, toward the
    sun), with radiance color S norm / Omega = color S / (pi sin^2(angle / 2)) (Cycles'; ``sampling.sun_cone``):
    next-event estimation's weight color S norm times its density 1 / Omega.
    """
    typ = int(prm[P_TYPE])
    power = prm[P_POWER]
    c0, c1, c2 = vec3(prm, P_COLOR)
    if power <= 0.0 or not (c0 > 0.0 or c1 > 0.0 or c2 > 0.0):
        return 0.0, 0.0, 0.0
    if typ == T_SUN:
        # -- a disc at infinity: rays that escape inside its cone
        if not prm[P_ANGLE] > 0.0 or t_scene < np.inf:
            return 0.0, 0.0, 0.0
        Z, ok = axis_or_z(light_axis(M))
        cos_half, omega, norm = sun_cone(prm)
        if ok == 0.0 or dot(d, Z) < cos_half:
            return 0.0, 0.0, 0.0
        k = power * norm / omega
        return c0 * k, c1 * k, c2 * k
    if typ == T_AREA:
        # -- the light's plane; local coordinates of the crossing
        c, ex, ey, area, n_emit, disk = area_shape(prm, M)
        cos_d = dot(d, n_emit)
        s_hit = dot(sub(c, o), n_emit) / cos_d
        qv = sub(madd(o, s_hit if np.isfinite(s_hit) else 0.0, d), c)
        a = dot(qv, ex) / max(dot(ex, ex), 1e-300)
        b = dot(qv, ey) / max(dot(ey, ey), 1e-300)
        inside = (a * a + b * b <= 1.0) if disk else (abs(a) <= 1.0 and abs(b) <= 1.0)
        if inside and cos_d < 0.0 and s_hit > 0.0 and s_hit < t_scene and area > 0.0:
            den = np.pi * area
            return c0 * power / den, c1 * power / den, c2 * power / den
        return 0.0, 0.0, 0.0
    if (typ == T_POINT or typ == T_SPOT) and prm[P_RADIUS] > 0.0:
        r = prm[P_RADIUS]
        oc = sub(o, column(M, 3))
        if prm[P_SOFT] != 0.0:
            # -- soft falloff: the disc of radius r through the centre c facing the ray's origin o,
            # the disc next-event estimation samples from o (Cycles' point_light_intersect)
            to_o, d_c = normalize(oc)                       # light -> o
            cos_q = -dot(d, to_o)
            if not (d_c > 0.0 and cos_q > 0.0):
                return 0.0, 0.0, 0.0
            s_hit = d_c / cos_q
            x = madd(oc, s_hit, d)                          # the crossing, from c
            if not (edot(x, x) <= r * r and s_hit < t_scene):
                return 0.0, 0.0, 0.0
        else:
            # -- sphere of radius r about M's translation
            bq = dot(oc, d)
            disc = bq * bq - (dot(oc, oc) - r * r)
            s_hit = -bq - math.sqrt(max(disc, 0.0))
            if not (disc > 0.0 and s_hit > 0.0 and s_hit < t_scene):
                return 0.0, 0.0, 0.0
        den = np.pi * r * r
        L0 = c0 * power / (4.0 * np.pi) / den
        L1 = c1 * power / (4.0 * np.pi) / den
        L2 = c2 * power / (4.0 * np.pi) / den
        if typ == T_SPOT:
            Z = column(M, 2)
            nz = math.sqrt(dot(Z, Z))                # (no 1e-300 guard, as the numpy code)
            att = spot_attenuation(prm, dot(neg(d), (-Z[0] / nz, -Z[1] / nz, -Z[2] / nz)))
            L0, L1, L2 = L0 * att, L1 * att, L2 * att
        return L0, L1, L2
    return 0.0, 0.0, 0.0


# ----------------------------------------------------------------------------
# Batch kernels (LightSet.sample_direct, tests)
# ----------------------------------------------------------------------------
@njit(**JIT)
def sample_direct_batch(prm, poses, steps, corners, q, cdf, Le, env, p, times, u, normals, use_normals,
                        wi_out, dist_out, weight_out):
    """:func:`sample_light_rows` for every row i of p (n, 3) at times (n,) with uniforms u (n, 2).

    poses (k, 4, 4): the light's matrices, row i reads poses[0] when k = 1 else poses[i].
    normals (n, 3): read when use_normals (WORLD cosine sampling about them), else every row gets
    (0, 0, 0) (WORLD: uniform sphere).  Writes wi_out (n, 3), dist_out (n,), weight_out (n, 3).
    """
    n = p.shape[0]
    ng = normals if use_normals else np.zeros((n, 3))
    S = np.empty((n, 8))
    no_pdf = n < 0            # False as a run-time bool: a literal False would compile sample_light_rows twice
    sample_light_rows(prm, poses, steps, corners, q, cdf, Le, env, np.arange(n), p, ng, -ng, times, u, S, no_pdf)
    for i in range(n):
        wi_out[i, 0], wi_out[i, 1], wi_out[i, 2] = S[i, 0], S[i, 1], S[i, 2]
        dist_out[i] = S[i, 3]
        weight_out[i, 0], weight_out[i, 1], weight_out[i, 2] = S[i, 4], S[i, 5], S[i, 6]


@njit(**JIT)
def sample_pdf_batch(prm, poses, steps, corners, q, cdf, Le, env, p, times, u, normals, S_out):
    """:func:`sample_light_rows` with want_pdf for every row i of p (n, 3) at times (n,) with uniforms
    u (n, 2) and WORLD normals (n, 3): writes S_out (n, 8), the samples and their densities (tests)."""
    want_pdf = p.shape[0] >= 0    # True as a run-time bool (one compiled sample_light_rows)
    sample_light_rows(prm, poses, steps, corners, q, cdf, Le, env, np.arange(p.shape[0]), p, normals, -normals,
                      times, u, S_out, want_pdf)


@njit(**JIT)
def world_nee_pdf_batch(env, poses, p, n, wi, out):
    """out[i] = :func:`world_nee_pdf` from points p[i] with normals n[i] (zero: none) toward unit
    directions wi[i] (n, 3 each) for the world's env tuple; poses (k, 4, 4) its mapping, k = 1 or
    one per row (tests)."""
    func, par, portals = env[1], env[4], env[5]
    one = poses.shape[0] == 1
    M = pose_buffer(poses)
    for i in range(p.shape[0]):
        if not one:
            load_pose(poses, i, M)
        out[i] = world_nee_pdf(func, par, portals, M, row3(p, i), row3(n, i), row3(wi, i))


@njit(**JIT)
def light_pdf_batch(prm, poses, p, wi, pdf_out):
    """:func:`light_pdf` from points p toward unit directions wi (n, 3): writes pdf_out (n,); poses
    (k, 4, 4), k = 1 or one per row (tests)."""
    one = poses.shape[0] == 1
    M = pose_buffer(poses)
    for i in range(p.shape[0]):
        if not one:
            load_pose(poses, i, M)
        pdf_out[i] = light_pdf(prm, M, row3(p, i), row3(wi, i))


@njit(**JIT)
def seen_batch(prm, poses, o, d, t_scene, camera_ray, L_out):
    """:func:`seen_light` for rays o + s d (n, 3) before t_scene (n,): writes L_out (n, 3)
    (overwrites; sum over lights in the caller).  poses (k, 4, 4): k = 1 or one per ray."""
    one = poses.shape[0] == 1
    M = pose_buffer(poses)
    for i in range(o.shape[0]):
        if not one:
            load_pose(poses, i, M)
        L = seen_light(prm, M, row3(o, i), row3(d, i), t_scene[i], camera_ray)
        L_out[i, 0], L_out[i, 1], L_out[i, 2] = L[0], L[1], L[2]


@njit(**JIT)
def spherical_rect_batch(o, s, ex, ey, u, q_out, S_out):
    """:func:`spherical_rect_sample` per row of (n, 3) arrays o, s, ex, ey and u (n, 2): writes
    q_out (n, 3), S_out (n,) (tests)."""
    for i in range(o.shape[0]):
        qv, S = spherical_rect_sample(vec3(o[i], 0), vec3(s[i], 0), vec3(ex[i], 0), vec3(ey[i], 0), u[i, 0], u[i, 1])
        q_out[i, 0], q_out[i, 1], q_out[i, 2] = qv[0], qv[1], qv[2]
        S_out[i] = S
