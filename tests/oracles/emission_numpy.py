"""The numpy photon emission the compiled kernels (:mod:`stpm_core.kernels.emission`) are tested against.

This is the vectorised numpy code that emitted photons before the kernels became the one
implementation (``LightSet.emit``, ``LightSet.emit_toward``, ``LightSet._point_origins``,
``LightSet._sun_photons`` and ``WorldLight.emit`` in stpm_core/lights.py and
stpm_core/world_light.py up to that change), kept verbatim as functions of ``(lights, li, ...)``:
same distributions, same power formulas, same random numbers in the same order.  The light
geometry still comes from the LightSet (``_frame``, ``_area_shape``, ``flux``, ``intensity``,
``_sun_disc_radius``); the numpy helpers that left stpm_core/lights.py (the small private ones,
``LightSet._area_points``, ``MeshLight.sample_points``) are those of the next-event oracle
:mod:`oracles.lights_numpy`, so that neither oracle changes when the product does.
"""
from __future__ import annotations

import numpy as np

from oracles.lights_numpy import (_UNIT_Z, _axis_or_z, _local_to_world, _normalize, _one_minus_cos_from_sin2,
                                  area_points, mesh_sample_points, spot_attenuation)
from stpm_core.sampling import concentric_disk, cosine_hemisphere, orthonormal_basis, uniform_cone, uniform_sphere

__all__ = ["emit", "emit_toward", "world_emit", "point_origins", "sun_photons", "spot_attenuation"]


# ---------------------------------------------------------------------------
# WORLD (WorldLight.emit)
# ---------------------------------------------------------------------------

def world_emit(wl, n: int, rng: np.random.Generator, center=None, radius=None):
    """n photons entering the sphere (center, radius) (default: the scene's) from every direction."""
    c = wl.center if center is None else np.asarray(center, np.float64).reshape(3)
    R = wl.scene_radius if radius is None else float(radius)
    d = uniform_sphere(rng.random((n, 2)))
    t, b = orthonormal_basis(d)
    q = concentric_disk(rng.random((n, 2))) * R
    origins = c + q[:, 0:1] * t + q[:, 1:2] * b - 2.0 * R * d
    power = np.broadcast_to(4.0 * np.pi * np.pi * R * R * wl.color / n, (n, 3)).copy()
    return origins, d, power


# ---------------------------------------------------------------------------
# LightSet.emit and its helpers
# ---------------------------------------------------------------------------

def emit(lights, li: int, n: int, times: np.ndarray, rng: np.random.Generator):
    """Emit n photons from light li over its whole emission: origins, unit dirs, power (n, 3) W."""
    l = lights.lights[li]
    if l.type == "WORLD":
        return world_emit(l, n, rng)                # every direction, through the scene's sphere
    times = np.atleast_1d(np.asarray(times, float))
    u = rng.random((n, 2))
    if l.type == "POINT":
        c, _, _, _ = lights._frame(li, times)
        dirs = uniform_sphere(u)
        power = np.broadcast_to(lights.flux(li) / n, (n, 3)).copy()
        return point_origins(lights, li, c, dirs, rng), dirs, power
    if l.type == "SPOT":
        # Uniform in the spot cone (solid angle Omega_c), power I * att * Omega_c / n
        c, _, _, Z = lights._frame(li, times)
        cos_half = np.cos(0.5 * l.spot_size)
        axis, _ = _axis_or_z(np.broadcast_to(-Z, (n, 3)))     # zero Z scale: att = 0 below
        dirs = _local_to_world(uniform_cone(u, cos_half), axis)
        att = spot_attenuation(l, np.sum(dirs * -Z, axis=-1))
        omega_c = 2.0 * np.pi * (1.0 - cos_half)
        power = lights.intensity(li)[None, :] * (att * omega_c / n)[:, None]
        return point_origins(lights, li, c, dirs, rng), dirs, power
    if l.type == "MESH":
        # Triangle by q_j, uniform point, random side, cosine direction:
        # power = Le cos / (q_j / A * 1/2 * cos / pi) / n = 2 pi Le A / (q_j n)
        q, nrm, A, Le, pq = mesh_sample_points(l, times if times.shape[0] == n else np.broadcast_to(times, (n,)), u)
        side = np.where(rng.random(n) < 0.5, 1.0, -1.0)[:, None]
        dirs = _local_to_world(cosine_hemisphere(rng.random((n, 2))), side * nrm)
        power = Le * (2.0 * np.pi * A / (pq * n))[:, None]
        return q, dirs, power
    if l.type == "AREA":
        # Uniform point, cosine-weighted direction: power = L pi A / n = color P / n
        c, ex, ey, A, n_emit = lights._area_shape(li, times)
        q = area_points(lights, li, ex, ey, c, rng.random((n, 2)))
        axis, ok = _axis_or_z(np.broadcast_to(n_emit, (n, 3)))  # no emitting side: no power
        dirs = _local_to_world(cosine_hemisphere(u), axis)
        power = np.broadcast_to(lights.flux(li) / n, (n, 3)) * ok[:, None]
        return q, dirs, power
    # SUN: a disc perpendicular to the sun covering the scene's bounding sphere
    _, _, _, Z = lights._frame(li, times)
    R = lights._sun_disc_radius(li)
    return sun_photons(lights, li, n, Z, np.broadcast_to(lights._scene_center, (n, 3)),
                       R, 2.0 * lights._scene_radius, u, rng)


def point_origins(lights, li, c, dirs, rng) -> np.ndarray:
    """Where photons leaving along dirs (n, 3) start on a POINT / SPOT light of radius r (its disc / sphere)."""
    l = lights.lights[li]
    r = float(l.radius)
    if r <= 0.0:
        return np.array(c)                   # a writable copy (c may be a broadcast view)
    n = dirs.shape[0]
    d = concentric_disk(rng.random((n, 2))) * r
    t, b = orthonormal_basis(dirs)
    origins = c + d[:, 0:1] * t + d[:, 1:2] * b
    if not l.use_soft_falloff:
        origins = origins + dirs * np.sqrt(np.maximum(r * r - np.sum(d * d, axis=1), 0.0))[:, None]
    return origins


def sun_photons(lights, li, n, Z, center, R, back, u, rng):
    """Sun photons whose lines cross a disc of radius R (scalar or (n,)) perpendicular to Z through
    center, starting ``back`` upstream of it (along Z)."""
    l = lights.lights[li]
    Z, ok = _axis_or_z(np.broadcast_to(Z, (n, 3)))     # zero Z scale: no direction, no power
    R = np.broadcast_to(np.asarray(R, float), (n,))
    disc = concentric_disk(rng.random((n, 2))) * R[:, None]
    q = center + _local_to_world(np.concatenate([disc, np.zeros((n, 1))], axis=1), Z)
    if l.angle > 0.0:
        local = uniform_cone(u, np.cos(0.5 * l.angle))
        dirs = _local_to_world(local, -Z)
        cos_t = local[:, 2]
    else:
        dirs = -Z.copy()
        cos_t = np.ones(n)
    origins = q - (np.broadcast_to(np.asarray(back, float).reshape(-1), (n,)) / np.maximum(cos_t, 1e-6))[:, None] * dirs
    norm = 2.0 / (1.0 + np.cos(0.5 * l.angle))       # radiance S / (pi sin^2(angle / 2)) (Cycles'), 1 at angle 0
    power = (np.asarray(l.color, float) * (float(l.power) * norm))[None, :] * (np.pi * R * R * cos_t * ok / n)[:, None]
    return origins, dirs, power


# ---------------------------------------------------------------------------
# LightSet.emit_toward
# ---------------------------------------------------------------------------

def emit_toward(lights, li: int, n: int, times: np.ndarray, rng: np.random.Generator,
                centers: np.ndarray, radius: float):
    """Emit n photons aimed at a sphere (centers (n, 3) or (3,), radius): origins, unit dirs, power (n, 3)."""
    l = lights.lights[li]
    times = np.atleast_1d(np.asarray(times, float))
    centers = np.broadcast_to(np.asarray(centers, float), (n, 3))
    radius = float(radius)
    if l.type == "WORLD":
        o, d, P = world_emit(l, n, rng, centers[0], radius)
        back = np.linalg.norm(centers - lights._scene_center, axis=-1) + lights._scene_radius + radius
        o = o + (centers - centers[0]) - d * np.maximum(back - 2.0 * radius, 0.0)[:, None]
        return o, d, P
    u = rng.random((n, 2))
    if l.type == "SUN":
        _, _, _, Z = lights._frame(li, times)
        back = (np.linalg.norm(centers - lights._scene_center, axis=-1) + lights._scene_radius + radius)
        R = radius + (back + radius) * np.tan(0.5 * min(l.angle, 3.0))
        return sun_photons(lights, li, n, Z, centers, R, back[:, None], u, rng)
    reach = radius
    if l.type == "AREA":
        c, ex, ey, A, n_emit = lights._area_shape(li, times)
        origins = area_points(lights, li, ex, ey, c, rng.random((n, 2)))
    elif l.type == "MESH":
        origins, n_emit, A, Le_m, pq = mesh_sample_points(
            l, times if times.shape[0] == n else np.broadcast_to(times, (n,)), rng.random((n, 2)))
    else:
        origins, _, _, Z = lights._frame(li, times)
        reach = radius + float(l.radius)
    axis, d = _normalize(centers - origins)
    inside = (d <= reach) | ~(np.abs(np.einsum("ij,ij->i", axis, axis) - 1.0) < 1e-6)
    one_minus_cos = np.where(inside, 2.0, _one_minus_cos_from_sin2((reach * reach) / np.maximum(d * d, 1e-300)))
    dirs = _local_to_world(uniform_cone(u, 1.0 - one_minus_cos), np.where(inside[:, None], _UNIT_Z, axis))
    if l.type not in ("AREA", "MESH"):
        origins = point_origins(lights, li, origins, dirs, rng)
    omega = 2.0 * np.pi * one_minus_cos           # cone solid angle (4 pi inside)
    if l.type == "MESH":
        cos_l = np.abs(np.einsum("ij,ij->i", dirs, n_emit))
        power = Le_m * (cos_l * A / pq * omega / n)[:, None]
    elif l.type == "AREA":
        L = np.asarray(l.color, float)[None, :] * (float(l.power) / (np.pi * np.maximum(A, 1e-300)))[:, None]
        cos_l = np.maximum(np.sum(dirs * n_emit, axis=-1), 0.0)
        power = L * (cos_l * A * omega / n)[:, None]
    else:
        I = lights.intensity(li)
        att = np.ones(n)
        if l.type == "SPOT":
            att = spot_attenuation(l, np.sum(dirs * -Z, axis=-1))
        power = I[None, :] * (att * omega / n)[:, None]
    return origins, dirs, power
