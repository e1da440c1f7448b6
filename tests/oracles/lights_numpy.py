"""The numpy light code the compiled kernels (:mod:`stpm_core.kernels.lights`) are tested against.

This is the vectorised numpy code ``LightSet.sample_direct`` ran before the kernels became the one
implementation (``LightSet._sample_point``, ``_sample_area``, ``_sample_sun``, ``_sample_mesh`` in
stpm_core/lights.py, ``WorldLight.sample`` in stpm_core/world_light.py and
``spherical_rect_sample``, all of stpm_core/spherical_rect.py, up to that change), kept verbatim
as functions of ``(lights, li, ...)``: same distributions, same weights, same random numbers.  One
addition: a light with no emitting direction at any key (``LightSet._dead``) gets weight 0
explicitly, as the kernels give it (the old code gave 0 already, except for NaN from inf * 0 when
a zero-area AREA light's radiance overflowed).

The light geometry still comes from the LightSet (``_frame``, ``_area_shape``, ``intensity``);
the numpy helpers that only this code (and ``emission_numpy``) used left stpm_core/lights.py and
live here: the small private helpers, ``LightSet._area_points`` (:func:`area_points`),
``MeshLight.corners`` / ``sample_points`` (:func:`mesh_corners`, :func:`mesh_sample_points`).

:func:`seen_lights_numpy` is ``integrator._seen_lights`` (what camera rays and delta chains see
of light shapes), the reference for ``kernels.lights.seen_light``.  :func:`intersect` (with
:func:`hit_one`) and :func:`sky_radiance` are the former ``LightSet.intersect`` / ``_hit_one`` /
``sky_radiance``: the nearest light surface along rays (soft-falloff discs included) and the sun
cones seen by escaping rays, numpy shading code the renderer does not use (the tests check the
light-sampling estimators against them).
"""
from __future__ import annotations

import math

import numpy as np


def _libm(fn, x: np.ndarray) -> np.ndarray:
    """fn (a ``math`` function) element by element: the C library's result, as the kernels get it.

    numpy dispatches arccos / sin / cos to SIMD implementations chosen by the CPU (SVML on AVX-512)
    that differ from the C library by a few ulp; where the spherical rectangle's angles cancel
    that grew to 8e-8 relative, past the 1e-9 these tests hold the kernels to, on AVX-512 machines only.
    """
    x = np.asarray(x, dtype=np.float64)
    return np.fromiter((fn(v) for v in x.ravel()), dtype=np.float64, count=x.size).reshape(x.shape)

from stpm_core.lights import area_light_normal
from stpm_core.sampling import concentric_disk, cosine_hemisphere, orthonormal_basis, to_world, uniform_cone, uniform_sphere

__all__ = ["sample_direct", "sample_point", "sample_area", "sample_sun", "sample_mesh", "world_sample",
           "spherical_rect_sample", "spot_attenuation", "seen_lights_numpy", "area_points", "mesh_corners",
           "mesh_sample_points", "intersect", "hit_one", "sky_radiance"]

_UNIT_Z = np.array([0.0, 0.0, 1.0])


# ---------------------------------------------------------------------------
# Small helpers (copies of stpm_core/lights.py's)
# ---------------------------------------------------------------------------

def _one_minus_cos_from_sin2(sin2: np.ndarray) -> np.ndarray:
    """1 - sqrt(1 - sin^2) without cancellation for small angles."""
    sin2 = np.clip(sin2, 0.0, 1.0)
    return sin2 / (1.0 + np.sqrt(1.0 - sin2))


def _local_to_world(local: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Rotate (n, 3) local directions (z = axis) into the frame about unit axis (n, 3)."""
    t, b = orthonormal_basis(axis)
    return local[:, 0:1] * t + local[:, 1:2] * b + local[:, 2:3] * axis


def _normalize(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors (n, 3) and lengths (n,)."""
    length = np.sqrt(np.einsum("ij,ij->i", v, v))
    return v / np.maximum(length, 1e-300)[:, None], length


def _axis_or_z(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit axes (n, 3), with +Z standing in where ``axis`` is zero, and where it was usable (n,) bool."""
    ok = np.einsum("ij,ij->i", axis, axis) > 0.5
    return np.where(ok[:, None], axis, _UNIT_Z), ok


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def spot_attenuation(light, cos_axis: np.ndarray) -> np.ndarray:
    """Spot mask in [0, 1] for directions at cos_axis (n,) from the spot axis (Cycles' smoothstep)."""
    cos_half = np.cos(0.5 * light.spot_size)
    smooth = (1.0 - cos_half) * light.spot_blend
    x = cos_axis - cos_half
    if smooth <= 0.0:
        return (x > 0.0).astype(np.float64)
    return np.where(x > 0.0, _smoothstep(x / smooth), 0.0)


def _ray_sphere_far(o: np.ndarray, d: np.ndarray, c: np.ndarray, r: float, inside: np.ndarray) -> np.ndarray:
    """Distance along unit d (n, 3) from o to a sphere (c, r): near hit from outside, far hit from inside."""
    oc = o - c
    b = np.einsum("ij,ij->i", oc, d)
    disc = np.maximum(b * b - (np.einsum("ij,ij->i", oc, oc) - r * r), 0.0)
    s = np.sqrt(disc)
    return np.where(inside, -b + s, np.maximum(-b - s, 0.0))


# ---------------------------------------------------------------------------
# Light geometry (formerly LightSet._area_points, MeshLight.corners / sample_points)
# ---------------------------------------------------------------------------

def area_points(lights, li: int, ex, ey, c, u: np.ndarray) -> np.ndarray:
    """Uniform points (n, 3) on the area light's shape from u (n, 2)."""
    l = lights.lights[li]
    if l.shape in ("DISK", "ELLIPSE"):
        d = concentric_disk(u)
    else:
        d = 2.0 * u - 1.0
    return c + d[:, 0:1] * ex + d[:, 1:2] * ey


def mesh_corners(ml, j: np.ndarray, times: np.ndarray) -> np.ndarray:
    """World corners (n, 3, 3) of emitting triangles j (n,) of the MeshLight ml at times (n,)."""
    if ml._world_static is not None:
        return ml._world_static[j]
    if ml._steps is None:
        C = ml._corners[j]
    else:
        K = ml._steps.shape[0]
        i = np.clip(np.searchsorted(ml._steps, times, side="right") - 1, 0, K - 2)
        a = np.clip((times - ml._steps[i]) / (ml._steps[i + 1] - ml._steps[i]), 0.0, 1.0)
        C = (1.0 - a)[:, None, None] * ml._corners[i, j] + a[:, None, None] * ml._corners[i + 1, j]
    M = ml._inst_transform.at(times)
    return np.einsum("nij,nkj->nki", M[:, :3, :3], C) + M[:, None, :3, 3]


def mesh_sample_points(ml, times: np.ndarray, u: np.ndarray):
    """Points on the MeshLight ml at times (n,) from u (n, 2).

    u[:, 0] picks the triangle (by the CDF of q) and is then rescaled to [0, 1) inside the chosen
    interval, so two numbers give both the triangle and the point.  Returns q (n, 3) points,
    nrm (n, 3) unit geometric normals, A (n,) world areas of their triangles, Le (n, 3) radiance,
    pq (n,) = q_j.
    """
    j = np.minimum(np.searchsorted(ml.cdf, u[:, 0], side="right"), ml.q.shape[0] - 1)
    lo = ml.cdf[j] - ml.q[j]
    u0 = np.clip((u[:, 0] - lo) / ml.q[j], 0.0, 1.0 - 1e-12)
    C = mesh_corners(ml, j, times)
    e1, e2 = C[:, 1] - C[:, 0], C[:, 2] - C[:, 0]
    cr = np.cross(e1, e2)
    two_A = np.sqrt(np.einsum("ij,ij->i", cr, cr))
    nrm = cr / np.maximum(two_A, 1e-300)[:, None]
    # Uniform point: barycentrics (1 - s, s (1 - v), s v) with s = sqrt(u0)
    s = np.sqrt(u0)
    b1, b2 = s * (1.0 - u[:, 1]), s * u[:, 1]
    q = C[:, 0] + b1[:, None] * e1 + b2[:, None] * e2
    return q, nrm, 0.5 * two_A, ml.Le[j], ml.q[j]


# ---------------------------------------------------------------------------
# Spherical rectangle (formerly stpm_core/spherical_rect.py)
# ---------------------------------------------------------------------------

def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-300)


def spherical_rect_sample(o: np.ndarray, s: np.ndarray, ex: np.ndarray, ey: np.ndarray, u: np.ndarray):
    """Points on rectangles uniform in the solid angle they subtend from o (Urena, Fajardo and King 2013).

    o : (n, 3) shading points; s : (n, 3) a corner of each rectangle; ex, ey : (n, 3) its two edges
    from that corner (full lengths, orthogonal); u : (n, 2) uniforms in [0, 1).  Returns q (n, 3)
    points on the rectangles and S (n,) the solid angle (sr) each subtends from o (0 where o lies
    in its plane).  Local frame x = ex / |ex|, y = ey / |ey|, z = x cross y flipped so the
    rectangle lies at z0 <= 0; S = g0 + g1 + g2 + g3 - 2 pi from the inner normals' angles;
    x by inverting the solid angle's cumulative, y uniform in h = y / sqrt(d^2 + y^2).
    """
    lx, ly = np.linalg.norm(ex, axis=-1), np.linalg.norm(ey, axis=-1)
    x, y = _unit(ex), _unit(ey)
    z = np.cross(x, y)
    d = s - o
    z0 = np.einsum("ij,ij->i", d, z)
    flip = z0 > 0.0
    z = np.where(flip[:, None], -z, z)
    z0 = np.where(flip, -z0, z0)
    x0 = np.einsum("ij,ij->i", d, x)
    y0 = np.einsum("ij,ij->i", d, y)
    x1, y1 = x0 + lx, y0 + ly
    zero = np.zeros_like(z0)
    # Inner normals of the four great-circle edges of the spherical rectangle
    n0 = _unit(np.stack([zero, z0, -y0], axis=-1))
    n1 = _unit(np.stack([-z0, zero, x1], axis=-1))
    n2 = _unit(np.stack([zero, -z0, y1], axis=-1))
    n3 = _unit(np.stack([z0, zero, -x0], axis=-1))

    def angle(a, b):
        return _libm(math.acos, np.clip(-np.einsum("ij,ij->i", a, b), -1.0, 1.0))

    g0, g1, g2, g3 = angle(n0, n1), angle(n1, n2), angle(n2, n3), angle(n3, n0)
    b0, b1 = n0[:, 2], n2[:, 2]
    k = 2.0 * np.pi - g2 - g3
    S = np.maximum(g0 + g1 - k, 0.0)
    # x by the solid angle's cumulative, then y by h = y / sqrt(d^2 + y^2)
    au = u[:, 0] * S + k
    sin_au = _libm(math.sin, au)
    with np.errstate(divide="ignore", invalid="ignore"):
        fu = (_libm(math.cos, au) * b0 - b1) / np.where(sin_au == 0.0, 1e-300, sin_au)
        cu = np.clip(np.sign(fu) / np.sqrt(fu * fu + b0 * b0 + 1e-300), -1.0, 1.0)
    cu = np.where(fu == 0.0, 0.0, cu)
    xu = np.clip(-(cu * z0) / np.sqrt(np.maximum(1.0 - cu * cu, 1e-300)), x0, x1)
    dd = np.sqrt(xu * xu + z0 * z0)
    h0 = y0 / np.sqrt(dd * dd + y0 * y0 + 1e-300)
    h1 = y1 / np.sqrt(dd * dd + y1 * y1 + 1e-300)
    hv = h0 + u[:, 1] * (h1 - h0)
    hv2 = hv * hv
    yv = np.where(hv2 < 1.0 - 1e-12, hv * dd / np.sqrt(np.maximum(1.0 - hv2, 1e-300)), y1)
    yv = np.clip(yv, y0, y1)
    q = o + xu[:, None] * x + yv[:, None] * y + z0[:, None] * z
    return q, S


# ---------------------------------------------------------------------------
# The world (formerly WorldLight.sample)
# ---------------------------------------------------------------------------

def world_sample(world, p: np.ndarray, u: np.ndarray, normals: np.ndarray | None = None):
    """Directions toward the world (a WorldLight) from points p (n, 3) with uniforms u (n, 2).

    normals: (n, 3) unit normals facing the side being shaded (cosine sampling about them),
    or None (uniform sphere).  Returns wi (n, 3) unit, dist (n,) = inf, weight (n, 3) = L / pdf.
    """
    n = p.shape[0]
    if normals is None:
        wi = uniform_sphere(u)
        return wi, np.full(n, np.inf), np.broadcast_to(4.0 * np.pi * world.color, (n, 3)).copy()
    local = cosine_hemisphere(u)                                   # (n, 3), z = cos
    wi = to_world(local, normals)
    cos = np.maximum(local[:, 2], 1e-12)
    return wi, np.full(n, np.inf), (np.pi / cos)[:, None] * world.color[None, :]


# ---------------------------------------------------------------------------
# Next-event estimation per light type
# ---------------------------------------------------------------------------

def sample_direct(lights, li: int, p: np.ndarray, times: np.ndarray, u: np.ndarray, normals: np.ndarray | None = None):
    """``LightSet.sample_direct`` in numpy: (wi (n, 3), dist (n,), weight (n, 3)) for light li."""
    l = lights.lights[li]
    p = np.asarray(p, float)
    times = np.atleast_1d(np.asarray(times, float))
    u = np.asarray(u, float)
    if l.type in ("POINT", "SPOT"):
        wi, dist, weight = sample_point(lights, li, p, times, u)
    elif l.type == "AREA":
        wi, dist, weight = sample_area(lights, li, p, times, u)
    elif l.type == "MESH":
        wi, dist, weight = sample_mesh(lights, li, p, times, u)
    elif l.type == "WORLD":
        wi, dist, weight = world_sample(l, p, u, normals)
    else:
        wi, dist, weight = sample_sun(lights, li, p, times, u)
    if lights._dead[li]:
        weight = np.zeros_like(weight)
    return wi, dist, weight


def sample_mesh(lights, li, p, times, u):
    """MESH: triangle by power, uniform point; weight = Le |cos_l| A / (q_j t^2) (two-sided)."""
    q, nrm, A, Le, pq = mesh_sample_points(lights.lights[li], np.broadcast_to(times, (p.shape[0],)), u)
    wi, dist = _normalize(q - p)
    cos_l = np.abs(np.einsum("ij,ij->i", wi, nrm))
    g = cos_l * A / (pq * np.maximum(dist * dist, 1e-300))
    return wi, dist, Le * g[:, None]


def sample_point(lights, li, p, times, u):
    """POINT / SPOT: true point (r = 0), disk facing p (soft falloff) or sphere."""
    l = lights.lights[li]
    c, _, _, Z = lights._frame(li, times)
    I = lights.intensity(li)
    r = float(l.radius)
    to_p, d = _normalize(p - c)              # light -> p, unit
    n = p.shape[0]
    if r <= 0.0:
        # Point: E-estimator I / d^2 along the exact direction
        wi, dist = -to_p, d
        g = np.where(d > 0.0, 1.0 / np.maximum(d * d, 1e-300), 0.0)   # nothing at the light itself
    elif l.use_soft_falloff:
        # Disk of radius r centred on the light, facing p (Cycles' soft falloff).
        # Radiance L = I / (pi r^2); pdf_A = 1 / (pi r^2) -> weight = I cos_q / t^2
        q = c + r * _local_to_world(np.concatenate([concentric_disk(u), np.zeros((n, 1))], axis=1), to_p)
        wi, dist = _normalize(q - p)
        cos_q = np.maximum(-np.sum(wi * to_p, axis=-1), 0.0)
        g = cos_q / np.maximum(dist * dist, 1e-300)
    else:
        # Sphere of radius r: uniform in the cone it subtends (or the whole
        # sphere from inside).  Radiance L = I / (pi r^2); weight = L / pdf.
        inside = d <= r
        one_minus_cos = np.where(inside, 2.0, _one_minus_cos_from_sin2((r * r) / np.maximum(d * d, 1e-300)))
        # (cos_max = -1 is the uniform sphere; it needs no axis, and p at the
        # very centre has none: +Z stands in)
        local = uniform_cone(u, 1.0 - one_minus_cos)
        wi = _local_to_world(local, np.where(inside[:, None], _UNIT_Z, -to_p))
        dist = _ray_sphere_far(p, wi, c, r, inside)
        omega = 2.0 * np.pi * one_minus_cos
        g = omega / (np.pi * r * r)
    weight = I[None, :] * g[:, None]
    if l.type == "SPOT":
        # Spot mask on the direction the light leaves along (toward p)
        weight = weight * spot_attenuation(l, np.sum(-wi * -Z, axis=-1))[:, None]
    return wi, dist, weight


def sample_area(lights, li, p, times, u):
    """AREA (one-sided, faces local -Z).  SQUARE / RECTANGLE: uniform in the solid angle S the
    rectangle subtends (:func:`spherical_rect_sample`), weight = L S where the point is in front;
    the other rows (disc, ellipse, sheared transform: |cos(ex, ey)| above 1e-5, S below 1e-7 sr)
    uniform by area, weight = L cos_l A / t^2.  Both use the same two uniforms per sample; each
    row is computed by one of them only."""
    l = lights.lights[li]
    c, ex, ey, A, n_emit = lights._area_shape(li, times)
    n = p.shape[0]
    L = np.asarray(l.color, float)[None, :] * (float(l.power) / (np.pi * np.maximum(A, 1e-300)))[:, None]
    wi, dist, g = np.empty((n, 3)), np.empty(n), np.empty(n)
    rest = np.ones(n, bool)
    if l.shape in ("SQUARE", "RECTANGLE"):
        exb, eyb = np.broadcast_to(ex, (n, 3)), np.broadcast_to(ey, (n, 3))
        # Blender's float32 matrices leave |cos(ex, ey)| ~ 1e-8 on rotated lights: treat up to 1e-5
        # as orthogonal (ey made exactly so: the rectangle moves by < 1e-5 of its size); real
        # shear stays with area sampling
        exx = np.einsum("ij,ij->i", exb, exb)
        dot = np.einsum("ij,ij->i", exb, eyb)
        ortho = np.abs(dot) <= 1e-5 * np.sqrt(exx * np.einsum("ij,ij->i", eyb, eyb))
        if np.any(ortho):
            eyo = eyb - (dot / np.maximum(exx, 1e-300))[:, None] * exb
            corner = np.broadcast_to(c, (n, 3)) - exb - eyo
            qs, S = spherical_rect_sample(p, corner, 2.0 * exb, 2.0 * eyo, u)
            use = ortho & (S > 1e-7)
            wi[use], dist[use] = _normalize(qs[use] - p[use])
            front = -np.sum(wi[use] * np.broadcast_to(n_emit, (n, 3))[use], axis=-1) > 0.0
            g[use] = np.where(front, S[use], 0.0)
            rest = ~use
    if np.any(rest):
        def rows(a):
            """The fallback rows of a per-sample (or broadcast) array."""
            return np.broadcast_to(a, (n,) + np.shape(a)[1:])[rest]

        q = area_points(lights, li, rows(ex), rows(ey), rows(c), u[rest])
        wi[rest], dist[rest] = _normalize(q - p[rest])
        cos_l = np.maximum(-np.sum(wi[rest] * rows(n_emit), axis=-1), 0.0)
        g[rest] = cos_l * rows(A) / np.maximum(dist[rest] * dist[rest], 1e-300)
    return wi, dist, L * g[:, None]


def sample_sun(lights, li, p, times, u):
    """SUN: direction +Z of the light (toward the sun); cone of angular diameter ``angle``.

    Radiance S / (pi sin^2(angle / 2)) uniform in the cone (Cycles' normalisation: a facing surface
    receives S), pdf 1 / Omega -> weight = color * S * 2 / (1 + cos(angle / 2)).
    """
    l = lights.lights[li]
    _, _, _, Z = lights._frame(li, times)
    Z, ok = _axis_or_z(Z)                    # zero Z scale: no direction, no light
    n = p.shape[0]
    if l.angle > 0.0:
        wi = _local_to_world(uniform_cone(u, np.cos(0.5 * l.angle)), np.broadcast_to(Z, (n, 3)))
    else:
        wi = np.broadcast_to(Z, (n, 3)).copy()
    norm = 2.0 / (1.0 + np.cos(0.5 * l.angle))       # Omega / (pi sin^2(angle / 2)); 1 at angle 0
    weight = np.broadcast_to(np.asarray(l.color, float) * (float(l.power) * norm), (n, 3)) * ok[:, None]
    return wi, np.full(n, np.inf), weight


# ---------------------------------------------------------------------------
# Light shapes seen along rays (integrator._seen_lights)
# ---------------------------------------------------------------------------

def seen_lights_numpy(lights, o: np.ndarray, d: np.ndarray, t: np.ndarray, t_scene: np.ndarray,
                      camera_ray: bool = False, visible_camera=None, only: int | None = None) -> np.ndarray:
    """Radiance (n, 3) of light shapes hit by rays o + s d (unit d) before t_scene (n,), at times t (n,).

    Camera rays see light i only if ``visible_camera[i]``.  AREA lights are one-sided emitters
    facing their local -Z with radiance ``color P / (pi A)``; POINT / SPOT lights of radius r > 0
    have radiance ``I / (pi r^2)`` (spots masked by their cone along -d): with ``use_soft_falloff``
    on the disc of radius r through their centre facing the ray's origin (Cycles), else on the sphere.  A SUN of
    angle > 0 has radiance ``color S / (pi sin^2(angle / 2))`` (Cycles') along rays that escape
    (t_scene = inf) within its cone (:func:`sky_radiance`).  Radius-0 lights and suns of
    angle 0 are not visible; meshes (their triangles are geometry) and the world neither.  only:
    the one light to look at (None: all).
    """
    n = o.shape[0]
    L = np.zeros((n, 3))
    for li, light in enumerate(lights.lights):
        if only is not None and li != only:
            continue
        if light.type in ("MESH", "WORLD"):
            continue                          # emissive triangles: the caster hits them (Emit); world: misses
        color = np.asarray(light.color, float)
        if light.power <= 0 or not np.any(color > 0):
            continue
        if camera_ray and not (visible_camera is not None and li < len(visible_camera) and visible_camera[li]):
            continue
        if light.type == "SUN":
            escaped = ~(np.asarray(t_scene, float) < np.inf)
            L[escaped] += _sun_seen(lights, li, d[escaped], t[escaped])
        elif light.type == "AREA":
            # Plane of the light at each ray's time; local coordinates of the crossing
            M = light.transform.at(t)
            sy = light.size_y if light.shape in ("RECTANGLE", "ELLIPSE") else light.size
            ex, ey = 0.5 * light.size * M[:, :3, 0], 0.5 * sy * M[:, :3, 1]
            c = M[:, :3, 3]
            n_emit, A4 = area_light_normal(ex, ey, M[:, :3, 2])   # -Z side, as LightSet (Cycles' rule)
            cos_d = np.sum(d * n_emit, axis=1)
            with np.errstate(divide="ignore", invalid="ignore"):
                s_hit = np.sum((c - o) * n_emit, axis=1) / cos_d
            q = o + np.nan_to_num(s_hit, nan=0.0, posinf=0.0, neginf=0.0)[:, None] * d - c
            a = np.sum(q * ex, axis=1) / np.maximum(np.sum(ex * ex, axis=1), 1e-300)
            b = np.sum(q * ey, axis=1) / np.maximum(np.sum(ey * ey, axis=1), 1e-300)
            disk = light.shape in ("DISK", "ELLIPSE")
            inside = (a * a + b * b <= 1.0) if disk else ((np.abs(a) <= 1.0) & (np.abs(b) <= 1.0))
            area = (np.pi if disk else 4.0) * A4
            seen = inside & (cos_d < 0) & (s_hit > 0) & (s_hit < t_scene) & (area > 0)
            L[seen] += color * light.power / (np.pi * area[seen, None])
        elif light.type in ("POINT", "SPOT") and light.radius > 0:
            M = light.transform.at(t)
            oc = o - M[:, :3, 3]
            r = float(light.radius)
            if light.use_soft_falloff:
                # Disc of radius r through the light's position, its normal toward the ray origin:
                # the plane {x : (x - c) . oc = 0}, crossed at s = |oc|^2 / (-d . oc)
                oo = np.sum(oc * oc, axis=1)
                den = -np.sum(d * oc, axis=1)
                with np.errstate(divide="ignore", invalid="ignore"):
                    s_hit = oo / den
                    x = oc + s_hit[:, None] * d
                    seen = ((oo > 0) & (den > 0) & (np.sum(x * x, axis=1) <= r * r) & (s_hit < t_scene))
            else:
                # Sphere of radius r around the light's position at each ray's time
                bq = np.sum(oc * d, axis=1)
                disc = bq * bq - (np.sum(oc * oc, axis=1) - r * r)
                s_hit = -bq - np.sqrt(np.maximum(disc, 0.0))
                seen = (disc > 0) & (s_hit > 0) & (s_hit < t_scene)
            radiance = np.broadcast_to(color * light.power / (4 * np.pi) / (np.pi * r * r), (n, 3))
            if light.type == "SPOT":
                with np.errstate(divide="ignore", invalid="ignore"):
                    axis = -M[:, :3, 2] / np.linalg.norm(M[:, :3, 2], axis=1, keepdims=True)
                radiance = radiance * spot_attenuation(light, np.sum(-d * axis, axis=1))[:, None]
            L[seen] += radiance[seen]
    return L


# ---------------------------------------------------------------------------
# Lights seen along rays (formerly LightSet.intersect, _hit_one, sky_radiance)
# ---------------------------------------------------------------------------

def intersect(lights, o: np.ndarray, d: np.ndarray, times: np.ndarray, tmax: np.ndarray | None = None):
    """Nearest light surface along rays and the radiance it sends back along them.

    AREA lights (one-sided), and POINT / SPOT lights with radius > 0 (the sphere, or with
    ``use_soft_falloff`` the disc of radius r facing the ray origin, as in ``sample_direct``) are
    visible; true points and suns are not (see :func:`sky_radiance` for suns with an angle).
    o, d : (n, 3) ray origins and unit directions; times : (n,); tmax : (n,) or None: only hits
    closer than tmax count.  Returns t (n,) the distance to the nearest light hit (inf: none) and
    L (n, 3) the radiance W/(m^2 sr) arriving at o along -d from that light.
    """
    o = np.asarray(o, float)
    d = np.asarray(d, float)
    n = o.shape[0]
    times = np.broadcast_to(np.atleast_1d(np.asarray(times, float)), (n,))
    t_best = np.full(n, np.inf) if tmax is None else np.asarray(tmax, float).copy()
    L = np.zeros((n, 3))
    found = np.zeros(n, bool)
    for li, l in enumerate(lights.lights):
        if l.type in ("SUN", "MESH", "WORLD") or (l.type in ("POINT", "SPOT") and l.radius <= 0.0):
            continue          # MESH: the caster hits the triangles themselves; WORLD: escaping rays
        t, Le = hit_one(lights, li, o, d, times)
        closer = (t > 0) & (t < t_best)
        t_best = np.where(closer, t, t_best)
        L[closer] = Le[closer]
        found |= closer
    return np.where(found, t_best, np.inf), L


def hit_one(lights, li, o, d, times):
    """Hit distance (n,) (inf: miss) and radiance (n, 3) of light li along rays."""
    l = lights.lights[li]
    n = o.shape[0]
    if l.type == "AREA":
        # Plane of the light, inside the shape, seen from its emitting side
        c, ex, ey, A, n_emit = lights._area_shape(li, times)
        dn = np.sum(d * n_emit, axis=-1)
        t = np.sum((c - o) * n_emit, axis=-1) / np.where(dn == 0, np.inf, dn)
        q = o + t[:, None] * d - c
        a = np.sum(q * ex, axis=-1) / np.maximum(np.sum(ex * ex, axis=-1), 1e-300)
        b = np.sum(q * ey, axis=-1) / np.maximum(np.sum(ey * ey, axis=-1), 1e-300)
        if l.shape in ("DISK", "ELLIPSE"):
            inside = a * a + b * b <= 1.0
        else:
            inside = (np.abs(a) <= 1.0) & (np.abs(b) <= 1.0)
        ok = inside & (dn < 0) & (t > 0)
        Le = np.asarray(l.color, float)[None, :] * (float(l.power) / (np.pi * np.maximum(A, 1e-300)))[:, None]
        return np.where(ok, t, np.inf), np.where(ok[:, None], Le, 0.0)
    # POINT / SPOT with radius: sphere, or the disc facing the ray origin
    c, _, _, Z = lights._frame(li, times)
    r = float(l.radius)
    oc = o - c
    if l.use_soft_falloff:
        nd, dist_c = _normalize(oc)
        dn = np.sum(d * nd, axis=-1)
        t = -np.sum(oc * nd, axis=-1) / np.where(dn == 0, np.inf, dn)
        q = o + t[:, None] * d - c
        ok = (np.sum(q * q, axis=-1) <= r * r) & (t > 0) & (dist_c > 0)
    else:
        b = np.sum(oc * d, axis=-1)
        disc = b * b - (np.sum(oc * oc, axis=-1) - r * r)
        s = np.sqrt(np.maximum(disc, 0.0))
        t0, t1 = -b - s, -b + s
        t = np.where(t0 > 0, t0, t1)
        ok = (disc >= 0) & (t > 0)
    Le = np.broadcast_to(lights.intensity(li) / (np.pi * r * r), (n, 3))
    if l.type == "SPOT":
        Le = Le * spot_attenuation(l, np.sum(-d * -Z, axis=-1))[:, None]
    return np.where(ok, t, np.inf), np.where(ok[:, None], Le, 0.0)


def sky_radiance(lights, d: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Radiance (n, 3) of suns with angle > 0 seen along escaping rays d (n, 3): color S / (pi sin^2(angle / 2))
    inside their cone."""
    d = np.asarray(d, float)
    n = d.shape[0]
    times = np.broadcast_to(np.atleast_1d(np.asarray(times, float)), (n,))
    L = np.zeros((n, 3))
    for li, l in enumerate(lights.lights):
        if l.type == "SUN":
            L += _sun_seen(lights, li, d, times)
    return L


def _sun_seen(lights, li: int, d: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Radiance (n, 3) of SUN li along the unit directions d (n, 3) of escaping rays at times (n,):
    color S / (pi sin^2(angle / 2)) (Cycles' normalisation) where d . Z >= cos(angle / 2) (Z its
    unit axis toward the sun; none for a zero Z scale); 0 for angle 0, no power or black colour."""
    l = lights.lights[li]
    n = d.shape[0]
    color = np.asarray(l.color, float)
    if l.angle <= 0.0 or l.power <= 0 or not np.any(color > 0) or n == 0:
        return np.zeros((n, 3))
    Z, ok = _axis_or_z(lights._frame(li, np.broadcast_to(np.atleast_1d(np.asarray(times, float)), (n,)))[3])
    inside = (np.sum(d * Z, axis=-1) >= np.cos(0.5 * l.angle)) & (ok > 0)
    return inside[:, None] * (color * float(l.power) / (np.pi * np.sin(0.5 * l.angle) ** 2))[None, :]


# ---------------------------------------------------------------------------
# Densities of next-event estimation's samples (multiple importance sampling)
# ---------------------------------------------------------------------------
def _triangle_solid_angle(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Solid angle (n,) of the triangles with corners a, b, c (n, 3) seen from the origin (Van
    Oosterom and Strackee 1983: tan(Omega / 2) = |a . (b x c)| / (|a||b||c| + (a.b)|c| + (a.c)|b|
    + (b.c)|a|))."""
    la, lb, lc = (np.linalg.norm(v, axis=1) for v in (a, b, c))
    num = np.abs(np.einsum("ij,ij->i", a, np.cross(b, c)))
    den = (la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", a, c) * lb
           + np.einsum("ij,ij->i", b, c) * la)
    return 2.0 * np.arctan2(num, den)


def nee_pdf(lights, li: int, p: np.ndarray, wi: np.ndarray, times: np.ndarray, x: np.ndarray | None = None,
            j: np.ndarray | None = None) -> np.ndarray:
    """Solid-angle density (n,) with which :func:`sample_direct` draws the unit direction wi (n, 3)
    from p (n, 3) at times (n,), written from the geometry (not from the samplers' weights):

    AREA rectangle (edges orthogonal within 1e-5, solid angle S > 1e-7 sr: the two triangles'
    solid angles): 1 / S; other AREA shapes: t^2 / (cos_l A), t the distance to the light's plane
    along wi (inf where wi meets its back); POINT / SPOT with soft falloff: t^2 / (cos pi r^2) where
    wi crosses the disc of radius r through the centre facing p, else 0; sphere: 1 / (2 pi (1 -
    cos theta_max)) (1 / (4 pi) from inside); MESH: q_j |x - p|^2 / (A_j |cos_l|) for the point x
    (n, 3) of its triangles j (n,); SUN of angle > 0: 1 / Omega inside its cone (wi . Z >=
    cos(angle / 2)), 0 outside; delta lights and suns of angle 0: inf.
    """
    l = lights.lights[li]
    n = p.shape[0]
    times = np.broadcast_to(np.atleast_1d(np.asarray(times, float)), (n,))
    out = np.full(n, np.inf)
    if l.type == "AREA":
        c, ex, ey, A, n_emit = lights._area_shape(li, np.ascontiguousarray(times))
        done = np.zeros(n, bool)
        if l.shape in ("SQUARE", "RECTANGLE"):
            dot = np.einsum("ij,ij->i", ex, ey)
            exx = np.einsum("ij,ij->i", ex, ex)
            ortho = np.abs(dot) <= 1e-5 * np.sqrt(exx * np.einsum("ij,ij->i", ey, ey))
            eyo = ey - (dot / np.maximum(exx, 1e-300))[:, None] * ex
            k00, k10, k11, k01 = (c + sx * ex + sy * eyo - p for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1)))
            S = _triangle_solid_angle(k00, k10, k11) + _triangle_solid_angle(k00, k11, k01)
            done = ortho & (S > 1e-7)
            out[done] = 1.0 / S[done]
        cos_l = -np.einsum("ij,ij->i", wi, n_emit)
        rest = ~done & (cos_l > 0) & (A > 0)
        t = np.einsum("ij,ij->i", c - p, n_emit)[rest] / -cos_l[rest]
        out[rest] = t * t / (cos_l[rest] * A[rest])
    elif l.type in ("POINT", "SPOT") and l.radius > 0:
        r = float(l.radius)
        c = lights._frame(li, times)[0]
        v = p - c
        d = np.linalg.norm(v, axis=1)
        if l.use_soft_falloff:
            cos_q = -np.einsum("ij,ij->i", wi, v / d[:, None])
            with np.errstate(divide="ignore", invalid="ignore"):
                t = d / cos_q
                hit = p + t[:, None] * wi - c
                ok = (cos_q > 0) & (np.einsum("ij,ij->i", hit, hit) <= r * r)
                out = np.where(ok, t * t / (cos_q * np.pi * r * r), 0.0)
        else:
            sin2 = (r / np.maximum(d, r)) ** 2
            one_minus_cos = sin2 / (1.0 + np.sqrt(1.0 - sin2))       # 1 - cos theta_max, without cancellation
            out = np.where(d <= r, 1.0 / (4.0 * np.pi), 1.0 / (2.0 * np.pi * one_minus_cos))
    elif l.type == "SUN" and l.angle > 0:
        Z, _ = _axis_or_z(lights._frame(li, np.ascontiguousarray(times))[3])
        cos_half = np.cos(0.5 * l.angle)
        inside = np.einsum("ij,ij->i", wi, Z) >= cos_half
        out = np.where(inside, 1.0 / (2.0 * np.pi * (1.0 - cos_half)), 0.0)
    elif l.type == "MESH":
        C = mesh_corners(l, j, times)
        cr = np.cross(C[:, 1] - C[:, 0], C[:, 2] - C[:, 0])
        A = 0.5 * np.linalg.norm(cr, axis=1)
        w, dist = _normalize(x - p)
        cos_l = np.abs(np.einsum("ij,ij->i", w, cr)) / np.maximum(2.0 * A, 1e-300)
        ok = A * cos_l > 0
        out[ok] = l.q[j[ok]] * dist[ok] ** 2 / (A[ok] * cos_l[ok])
    return out


def mesh_triangle_of_sample(lights, li: int, u: np.ndarray) -> np.ndarray:
    """The emitting triangle j (n,) a MESH light's sample from uniforms u (n, 2) lies on."""
    ml = lights.lights[li]
    return np.minimum(np.searchsorted(ml.cdf, u[:, 0], side="right"), ml.q.shape[0] - 1)
