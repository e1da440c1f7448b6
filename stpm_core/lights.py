"""Blender lights in Cycles units: direct-light sampling and photon emission.

Units (``shared/design.md``, "Units: match Cycles"; every formula with its
code name is in docs/lights-and-materials.md):

* POINT / SPOT of power P W: radiant intensity ``I = color * P / (4 pi)`` W/sr
  (the spot cone masks it, never rescales it).  Radius r > 0 makes a soft
  light of the same far-field intensity, emitting radiance
  ``L = I / (pi r^2)``; ``use_soft_falloff`` picks Cycles' two shapes:
  on = a disk of radius r facing the shading point, off = a sphere.
* AREA of power P W: one-sided Lambertian emitter facing local -Z with
  radiance ``L = color * P / (pi A)`` (A in world units, object scale
  included, as Cycles does).  The emitting side follows the transform's -Z
  column, as for SPOT and SUN, even under a mirroring scale
  (:func:`area_light_normal`).
* SUN of strength S: irradiance ``color * S`` W/m^2 on a facing surface;
  ``angle`` > 0 spreads it uniformly over a cone of that angular diameter.
* MESH (:class:`MeshLight`, one per instance with emissive triangles, after
  the scene's lights in :attr:`LightSet.lights`): ``Material.emission`` is
  radiance emitted from both sides, flux ``2 pi Le A``; triangles sampled by
  power, points uniform, at each sample's time.

Queries (all vectorised, each sample at its own shutter time; a light's pose
is ``light.transform.at(times)``):

* :meth:`LightSet.sample_direct` -- next-event estimation (incident-radiance estimator);
* :meth:`LightSet.emit`, :meth:`LightSet.emit_toward` -- photons, whole or aimed;
* :meth:`LightSet.intersect`, :meth:`LightSet.sky_radiance` -- lights seen along
  camera rays and specular chains.
"""
from __future__ import annotations

import numpy as np

from .spherical_rect import spherical_rect_sample
from .sampling import (concentric_disk, cosine_hemisphere, orthonormal_basis, uniform_cone,
                       uniform_sphere)

__all__ = ["LightSet", "MeshLight", "area_light_normal", "mesh_lights", "spot_attenuation"]

INV_4PI = 1.0 / (4.0 * np.pi)
_UNIT_Z = np.array([0.0, 0.0, 1.0])


# ---------------------------------------------------------------------------
# Small geometric helpers
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
    """Unit axes (n, 3), with +Z standing in where ``axis`` is zero, and where it was usable (n,) bool.

    A light whose transform has a zero scale along its Z axis has no direction
    (``_frame`` returns a zero Z); its samples get this stand-in axis, so that
    every direction stays unit length, and zero weight or power.
    """
    ok = np.einsum("ij,ij->i", axis, axis) > 0.5
    return np.where(ok[:, None], axis, _UNIT_Z), ok


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def spot_attenuation(light, cos_axis: np.ndarray) -> np.ndarray:
    """Spot mask in [0, 1] for directions at cos_axis (n,) from the spot axis.

    Zero outside the cone of half-angle ``spot_size / 2``; inside, Cycles'
    smoothstep from the edge inward over ``(1 - cos_half) * spot_blend`` in
    cosine space; 1 in the core.  The mask never rescales the intensity.
    """
    cos_half = np.cos(0.5 * light.spot_size)
    smooth = (1.0 - cos_half) * light.spot_blend
    x = cos_axis - cos_half
    if smooth <= 0.0:
        return (x > 0.0).astype(np.float64)
    return np.where(x > 0.0, _smoothstep(x / smooth), 0.0)


def _spot_solid_angle(light) -> float:
    """Integral of :func:`spot_attenuation` over the sphere (sr): 2 pi (1 - cos_half)(1 - blend / 2).

    The smoothstep over a band of width w = (1 - cos_half) * blend averages 1/2,
    so the blended cone loses w / 2 of its 2 pi (1 - cos_half) extent.
    """
    one_minus = 1.0 - np.cos(0.5 * light.spot_size)
    return 2.0 * np.pi * one_minus * (1.0 - 0.5 * light.spot_blend)


def area_light_normal(ex: np.ndarray, ey: np.ndarray, z_col: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Emitting normal of an AREA light and its |ex x ey|, from its half-extent vectors and -Z.

    ex, ey : (n, 3) half-extent vectors (the transform's X and Y columns times
        half the size); z_col : (n, 3) the transform's Z column.
    Returns n_emit (n, 3): the unit normal of the light's plane on the side of
    the -Z column (Cycles takes every light's direction from -Z, so a mirrored
    transform turns an AREA light exactly as it turns a SPOT or SUN: scale
    (1, 1, -1) faces it away, (-1, 1, 1) does not); zero when -Z lies in the
    plane or is zero (the light then emits nothing).  And A4 (n,) = |ex x ey|
    = area / 4 for a rectangle (m^2).
    """
    cross = np.cross(ex, ey)
    A4 = np.sqrt(np.einsum("ij,ij->i", cross, cross))
    g = cross / np.maximum(A4, 1e-300)[:, None]               # unit plane normal (+Z for a plain transform)
    side = np.sign(-np.einsum("ij,ij->i", g, z_col))           # +1 where g points along -Z
    return g * side[:, None], A4


def _ray_sphere_far(o: np.ndarray, d: np.ndarray, c: np.ndarray, r: float, inside: np.ndarray) -> np.ndarray:
    """Distance along unit d (n, 3) from o to a sphere (c, r): near hit from outside, far hit from inside."""
    oc = o - c
    b = np.einsum("ij,ij->i", oc, d)
    disc = np.maximum(b * b - (np.einsum("ij,ij->i", oc, oc) - r * r), 0.0)
    s = np.sqrt(disc)
    return np.where(inside, -b + s, np.maximum(-b - s, 0.0))


# ---------------------------------------------------------------------------
# Emissive meshes as lights
# ---------------------------------------------------------------------------

class _CentroidMotion:
    """Pose of a mesh light for code that treats lights as posed objects.

    ``at(t)`` gives identity rotation and, as translation, the area-weighted
    centroid of the emitting triangles at time t (what a caller asking "where
    is this light" wants, e.g. to aim caustic photons).
    """

    def __init__(self, mesh_light: "MeshLight"):
        self._ml = mesh_light
        self.is_static = mesh_light.is_static

    def at(self, t):
        scalar = np.ndim(t) == 0
        t = np.atleast_1d(np.asarray(t, float))
        out = np.broadcast_to(np.eye(4), (t.shape[0], 4, 4)).copy()
        out[:, :3, 3] = self._ml.centroid(t)
        return out[0] if scalar else out


class MeshLight:
    """The emitting triangles of one scene instance, as one light entry.

    Surface emission is radiance ``Le`` W/(m^2 sr) (``Material.emission``),
    emitted from both sides of every triangle, as Cycles' Emission shader on a
    mesh.  A triangle of world area A (at the time asked for) emits
    ``Phi = 2 pi Le A`` W.

    Sampling: triangle j with the fixed probability ``q_j`` proportional to
    ``Le_j A_j`` (mean RGB radiance times the area averaged over shutter times
    0, 1/2, 1), then a uniform point of that triangle at the sample's own time
    (pdf ``q_j / A_j(t)`` per unit area).  Any q_j > 0 keeps the estimators
    unbiased; proportional to power keeps their variance low.

    Attributes (besides the ones every light entry has: ``type = 'MESH'``,
    ``color``, ``power`` (W, mean RGB flux at mid-shutter), ``transform``
    (:class:`_CentroidMotion`), ``radius = 0``, ``name``):
    instance : index into ``scene.instances``.
    prims : (F_e,) triangle indices (within the mesh) that emit.
    Le : (F_e, 3) radiance of each.
    """

    type = "MESH"
    radius = 0.0
    use_soft_falloff = False

    def __init__(self, scene, instance: int, prims: np.ndarray, Le: np.ndarray):
        inst = scene.instances[instance]
        mesh = scene.meshes[inst.mesh]
        self.instance = int(instance)
        self.name = f"{inst.name} (emission)"
        self.prims = np.asarray(prims, np.int64)
        self.Le = np.asarray(Le, float)
        self.color = np.ones(3)
        self._inst_transform = inst.transform
        tri = np.asarray(mesh.triangles, np.int64)[self.prims]
        V = np.asarray(mesh.vertices, np.float64)
        if mesh.is_deforming:
            # (K, F_e, 3, 3) object-space corners at each vertex step
            self._steps = np.asarray(mesh.vertex_times, float)
            self._corners = V[:, tri]
        else:
            self._steps = None
            self._corners = (V[0] if V.ndim == 3 else V)[tri]
        self.is_static = inst.transform.is_static and self._steps is None
        self._world_static = None
        if self.is_static:
            M = inst.transform.matrices[0]
            self._world_static = self._corners @ M[:3, :3].T + M[:3, 3]
        # Triangle choice: q_j ~ mean(Le_j) * area averaged over three shutter times
        A = np.mean([self._areas_at(t) for t in (0.0, 0.5, 1.0)], axis=0)
        w = np.mean(self.Le, axis=1) * A
        if not np.any(w > 0):
            w = np.ones_like(w)
        w = np.maximum(w, 1e-12 * w.max())      # every triangle keeps a chance
        self.q = w / w.sum()
        self.cdf = np.cumsum(self.q)
        self.cdf[-1] = 1.0
        self.transform = _CentroidMotion(self)
        self.power = float(np.mean(self.flux_at(0.5)))

    # -- geometry at times ------------------------------------------------------------
    def corners(self, j: np.ndarray, times: np.ndarray) -> np.ndarray:
        """World corners (n, 3, 3) of emitting triangles j (n,) at times (n,)."""
        if self._world_static is not None:
            return self._world_static[j]
        if self._steps is None:
            C = self._corners[j]
        else:
            K = self._steps.shape[0]
            i = np.clip(np.searchsorted(self._steps, times, side="right") - 1, 0, K - 2)
            a = np.clip((times - self._steps[i]) / (self._steps[i + 1] - self._steps[i]), 0.0, 1.0)
            C = (1.0 - a)[:, None, None] * self._corners[i, j] + a[:, None, None] * self._corners[i + 1, j]
        M = self._inst_transform.at(times)
        return np.einsum("nij,nkj->nki", M[:, :3, :3], C) + M[:, None, :3, 3]

    def _all_corners_at(self, t: float) -> np.ndarray:
        """World corners (F_e, 3, 3) of every emitting triangle at one time t (one matrix)."""
        if self._world_static is not None:
            return self._world_static
        if self._steps is None:
            C = self._corners
        else:
            K = self._steps.shape[0]
            i = int(np.clip(np.searchsorted(self._steps, t, side="right") - 1, 0, K - 2))
            a = float(np.clip((t - self._steps[i]) / (self._steps[i + 1] - self._steps[i]), 0.0, 1.0))
            C = (1.0 - a) * self._corners[i] + a * self._corners[i + 1]
        M = self._inst_transform.at(float(t))
        return C @ M[:3, :3].T + M[:3, 3]

    def _areas_at(self, t: float) -> np.ndarray:
        C = self._all_corners_at(t)
        return 0.5 * np.linalg.norm(np.cross(C[:, 1] - C[:, 0], C[:, 2] - C[:, 0]), axis=-1)

    def flux_at(self, t: float) -> np.ndarray:
        """Total emitted flux (3,) W at time t: 2 pi sum_j Le_j A_j(t) (both sides)."""
        return 2.0 * np.pi * np.sum(self.Le * self._areas_at(t)[:, None], axis=0)

    def centroid(self, times: np.ndarray) -> np.ndarray:
        """Area-weighted centroid (n, 3) of the emitting triangles at times (n,)."""
        out = np.empty((times.shape[0], 3))
        for k, t in enumerate(times):
            C = self._all_corners_at(t)
            A = 0.5 * np.linalg.norm(np.cross(C[:, 1] - C[:, 0], C[:, 2] - C[:, 0]), axis=-1)
            out[k] = np.sum(C.mean(axis=1) * A[:, None], axis=0) / max(A.sum(), 1e-300)
        return out

    def sample_points(self, times: np.ndarray, u: np.ndarray):
        """Points on the emitter at times (n,) from u (n, 2).

        u[:, 0] picks the triangle (by the CDF of q) and is then rescaled to
        [0, 1) inside the chosen interval, so two numbers give both the
        triangle and the point.

        Returns q (n, 3) points, nrm (n, 3) unit geometric normals, A (n,)
        world areas of their triangles, Le (n, 3) radiance, pq (n,) = q_j.
        """
        j = np.minimum(np.searchsorted(self.cdf, u[:, 0], side="right"), self.q.shape[0] - 1)
        lo = self.cdf[j] - self.q[j]
        u0 = np.clip((u[:, 0] - lo) / self.q[j], 0.0, 1.0 - 1e-12)
        C = self.corners(j, times)
        e1, e2 = C[:, 1] - C[:, 0], C[:, 2] - C[:, 0]
        cr = np.cross(e1, e2)
        two_A = np.sqrt(np.einsum("ij,ij->i", cr, cr))
        nrm = cr / np.maximum(two_A, 1e-300)[:, None]
        # Uniform point: barycentrics (1 - s, s (1 - v), s v) with s = sqrt(u0)
        s = np.sqrt(u0)
        b1, b2 = s * (1.0 - u[:, 1]), s * u[:, 1]
        q = C[:, 0] + b1[:, None] * e1 + b2[:, None] * e2
        return q, nrm, 0.5 * two_A, self.Le[j], self.q[j]


def mesh_lights(scene) -> list[MeshLight]:
    """One :class:`MeshLight` per instance with emissive triangles (instance order)."""
    E = np.array([np.asarray(m.emission, float) for m in scene.materials]).reshape(-1, 3)
    out = []
    for i, inst in enumerate(scene.instances):
        mid = np.asarray(scene.meshes[inst.mesh].material_ids, np.int64)
        if mid.size == 0 or E.shape[0] == 0:
            continue
        Le = E[np.clip(mid, 0, E.shape[0] - 1)]
        prims = np.nonzero(np.any(Le > 0, axis=1))[0]
        if prims.size:
            out.append(MeshLight(scene, i, prims, Le[prims]))
    return out


class LightSet:
    """The scene's lights, ready for direct sampling and photon emission.

    Attributes
    ----------
    lights : list: the scene's lights (``scene.Light``, same indices as
        ``scene.lights``) followed by one :class:`MeshLight` (``type == 'MESH'``)
        per instance with emissive triangles, then, when the world's radiance
        ``color * strength`` is > 0 in some channel, one
        :class:`~stpm_core.world_light.WorldLight` (``type == 'WORLD'``) around
        the scene's bounding sphere.  Every query below takes an index into
        this list and treats all kinds alike.
    n_scene_lights : how many of them are ``scene.lights``.
    power : (L,) float64 total emitted flux per light in W (mean over RGB), for
        splitting photons in proportion to power.
    scene_bounds : ((3,), (3,)) world bounds over the shutter (suns aim their
        photons at the sphere around it).
    """

    def __init__(self, scene):
        self.lights = list(scene.lights) + mesh_lights(scene)
        self.n_scene_lights = len(scene.lights)
        lo, hi = scene.bounds()
        self.scene_bounds = (np.asarray(lo, float), np.asarray(hi, float))
        # Bounding sphere of the scene (suns and the world emit from a disc covering it)
        self._scene_center, self._scene_radius = scene.bounding_sphere()
        # The world, when it shines: a light entry like the others (stpm_core/world_light.py)
        if scene.world.shines:
            from .world_light import WorldLight
            self.lights.append(WorldLight(scene.world.radiance, self._scene_center, self._scene_radius))
        # SPOT / SUN / AREA lights with no emitting direction at any key (zero Z scale,
        # zero area): they emit nothing, so flux 0 and no photon budget
        self._dead = [self._no_direction(i) for i in range(len(self.lights))]
        self.power = np.array([float(np.mean(self.flux(i))) for i in range(len(self.lights))])

    def __len__(self) -> int:
        return len(self.lights)

    # -----------------------------------------------------------------------
    # Per-light constants
    # -----------------------------------------------------------------------

    def intensity(self, li: int) -> np.ndarray:
        """POINT / SPOT radiant intensity I = color * P / (4 pi) (3,) W/sr."""
        l = self.lights[li]
        return np.asarray(l.color, float) * float(l.power) * INV_4PI

    def _sun_disc_radius(self, li: int) -> float:
        """Radius of the sun's emission disc: scene sphere grown by the cone's drift across it."""
        l = self.lights[li]
        R = self._scene_radius
        return R * (1.0 + 3.0 * np.tan(0.5 * min(l.angle, 3.0)))

    def _no_direction(self, li: int) -> bool:
        """Does SPOT / SUN / AREA light li lack an emitting direction at every key of its motion?"""
        l = self.lights[li]
        if l.type not in ("SPOT", "SUN", "AREA"):
            return False
        t = np.asarray(l.transform.times, float)
        if l.type == "AREA":
            axis = self._area_shape(li, t)[4]
        else:
            axis = self._frame(li, t)[3]
        return not bool(np.any(np.einsum("ij,ij->i", axis, axis) > 0.5))

    def flux(self, li: int) -> np.ndarray:
        """Total emitted flux (3,) W of light li (what :meth:`emit` photons sum to).

        0 for a SPOT / SUN / AREA light with no emitting direction (zero Z scale
        or zero area at every key of its motion: ``scene_warnings`` names it).
        """
        l = self.lights[li]
        if getattr(self, "_dead", None) is not None and self._dead[li]:
            return np.zeros(3)
        if l.type == "MESH":
            return l.flux_at(0.5)
        if l.type == "WORLD":
            return l.flux()
        color = np.asarray(l.color, float)
        if l.type == "POINT":
            return color * float(l.power)
        if l.type == "SPOT":
            return self.intensity(li) * _spot_solid_angle(l)
        if l.type == "AREA":
            return color * float(l.power)
        # SUN: irradiance S through the disc (mean cos over the cone for angle > 0)
        R = self._sun_disc_radius(li)
        return color * float(l.power) * np.pi * R * R * self._sun_mean_cos(li)

    def _sun_mean_cos(self, li: int) -> float:
        """Mean cosine to the axis over the sun's cone: (1 + cos_half) / 2."""
        return 0.5 * (1.0 + np.cos(0.5 * self.lights[li].angle))

    def _frame(self, li: int, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Light pose at times (n,): position (n, 3), unit X, Y, Z axes (n, 3) each (scale removed).

        A static light computes its pose once and returns read-only broadcast views.
        """
        times = np.atleast_1d(np.asarray(times, float))
        if self.lights[li].transform.is_static and times.shape[0] > 1:
            n = times.shape[0]
            return tuple(np.broadcast_to(a, (n, 3)) for a in self._frame(li, times[:1]))
        M = self.lights[li].transform.at(times)
        R = M[:, :3, :3]
        X, _ = _normalize(R[:, :, 0])
        Y, _ = _normalize(R[:, :, 1])
        Z, _ = _normalize(R[:, :, 2])
        return M[:, :3, 3], X, Y, Z

    def _area_shape(self, li: int, times: np.ndarray):
        """AREA light at times: centre (n, 3), half-extent vectors ex, ey (n, 3), area A (n,), emitting normal (n, 3)."""
        l = self.lights[li]
        times = np.atleast_1d(np.asarray(times, float))
        if l.transform.is_static and times.shape[0] > 1:
            # One pose: compute once, broadcast (read-only views)
            n = times.shape[0]
            c, ex, ey, A, n_emit = self._area_shape(li, times[:1])
            return (np.broadcast_to(c, (n, 3)), np.broadcast_to(ex, (n, 3)), np.broadcast_to(ey, (n, 3)),
                    np.broadcast_to(A, (n,)), np.broadcast_to(n_emit, (n, 3)))
        M = l.transform.at(times)
        sx = float(l.size)
        sy = float(l.size_y) if l.shape in ("RECTANGLE", "ELLIPSE") else sx
        ex = 0.5 * sx * M[:, :3, 0]
        ey = 0.5 * sy * M[:, :3, 1]
        n_emit, A4 = area_light_normal(ex, ey, M[:, :3, 2])   # A4 = |ex x ey| = A_rect / 4
        if l.shape in ("DISK", "ELLIPSE"):
            A = np.pi * A4
        else:
            A = 4.0 * A4
        return M[:, :3, 3], ex, ey, A, n_emit

    def _area_points(self, li: int, ex, ey, c, u: np.ndarray) -> np.ndarray:
        """Uniform points (n, 3) on the area light's shape from u (n, 2)."""
        l = self.lights[li]
        if l.shape in ("DISK", "ELLIPSE"):
            d = concentric_disk(u)
        else:
            d = 2.0 * u - 1.0
        return c + d[:, 0:1] * ex + d[:, 1:2] * ey

    # -----------------------------------------------------------------------
    # Direct lighting
    # -----------------------------------------------------------------------

    def sample_direct(self, li: int, p: np.ndarray, times: np.ndarray, u: np.ndarray,
                      normals: np.ndarray | None = None):
        """Sample light li as seen from points p at their times.

        Parameters
        ----------
        li : light index.
        p : (n, 3) world shading points.
        times : (n,) normalised shutter times.
        u : (n, 2) uniform samples in [0, 1).
        normals : (n, 3) unit normals facing the shaded side, or None; used only
            by an entry of type 'WORLD' (``world_light.WorldLight.sample``, which
            samples cosine-distributed directions about them); other lights
            ignore it.

        Returns
        -------
        wi : (n, 3) unit direction from p toward the light sample.
        dist : (n,) distance to the light sample (inf for SUN); shadow rays
            test [eps, dist).
        weight : (n, 3) W/(m^2 sr) incident-radiance estimator L_e * G / pdf,
            so reflected radiance = f * |cos(ns, wi)| * weight * visible; 0
            where the light gives nothing (behind an area light, outside a spot).
        """
        l = self.lights[li]
        p = np.asarray(p, float)
        times = np.atleast_1d(np.asarray(times, float))
        u = np.asarray(u, float)
        if l.type in ("POINT", "SPOT"):
            return self._sample_point(li, p, times, u)
        if l.type == "AREA":
            return self._sample_area(li, p, times, u)
        if l.type == "MESH":
            return self._sample_mesh(li, p, times, u)
        if l.type == "WORLD":
            return l.sample(p, u, normals)
        return self._sample_sun(li, p, times, u)

    def _sample_mesh(self, li, p, times, u):
        """MESH: triangle by power, uniform point; weight = Le |cos_l| A / (q_j t^2) (two-sided)."""
        q, nrm, A, Le, pq = self.lights[li].sample_points(np.broadcast_to(times, (p.shape[0],)), u)
        wi, dist = _normalize(q - p)
        cos_l = np.abs(np.einsum("ij,ij->i", wi, nrm))
        g = cos_l * A / (pq * np.maximum(dist * dist, 1e-300))
        return wi, dist, Le * g[:, None]

    def _sample_point(self, li, p, times, u):
        """POINT / SPOT: true point (r = 0), disk facing p (soft falloff) or sphere."""
        l = self.lights[li]
        c, _, _, Z = self._frame(li, times)
        I = self.intensity(li)
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

    def _sample_area(self, li, p, times, u):
        """AREA (one-sided, faces local -Z).  SQUARE / RECTANGLE: uniform in the solid angle S the
        rectangle subtends (:func:`~stpm_core.spherical_rect.spherical_rect_sample`), weight = L S
        where the point is in front; the other rows (disc, ellipse, sheared transform: |cos(ex, ey)|
        above 1e-5, S below 1e-7 sr) uniform by area, weight = L cos_l A / t^2.  Both use the same
        two uniforms per sample; each row is computed by one of them only."""
        l = self.lights[li]
        c, ex, ey, A, n_emit = self._area_shape(li, times)
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

            q = self._area_points(li, rows(ex), rows(ey), rows(c), u[rest])
            wi[rest], dist[rest] = _normalize(q - p[rest])
            cos_l = np.maximum(-np.sum(wi[rest] * rows(n_emit), axis=-1), 0.0)
            g[rest] = cos_l * rows(A) / np.maximum(dist[rest] * dist[rest], 1e-300)
        return wi, dist, L * g[:, None]

    def _sample_sun(self, li, p, times, u):
        """SUN: direction +Z of the light (toward the sun); cone of angular diameter ``angle``.

        Radiance S / Omega uniform in the cone, pdf 1 / Omega -> weight = color * S.
        """
        l = self.lights[li]
        _, _, _, Z = self._frame(li, times)
        Z, ok = _axis_or_z(Z)                    # zero Z scale: no direction, no light
        n = p.shape[0]
        if l.angle > 0.0:
            wi = _local_to_world(uniform_cone(u, np.cos(0.5 * l.angle)), Z)
        else:
            wi = Z.copy()
        weight = np.broadcast_to(np.asarray(l.color, float) * float(l.power), (n, 3)) * ok[:, None]
        return wi, np.full(n, np.inf), weight

    # -----------------------------------------------------------------------
    # Lights seen along rays (camera rays and specular chains)
    # -----------------------------------------------------------------------

    def intersect(self, o: np.ndarray, d: np.ndarray, times: np.ndarray, tmax: np.ndarray | None = None):
        """Nearest light surface along rays and the radiance it sends back along them.

        Lights are not scene geometry; a path that can only reach them by
        chance (a camera ray, a chain of delta bounces) asks here.  AREA lights
        (one-sided), and POINT / SPOT lights with radius > 0 (the sphere, or with
        ``use_soft_falloff`` the disc of radius r facing the ray origin, as in
        :meth:`sample_direct`) are visible; true points and suns are not (see
        :meth:`sky_radiance` for suns with an angle).

        Parameters
        ----------
        o, d : (n, 3) ray origins and unit directions; times : (n,).
        tmax : (n,) or None: only hits closer than tmax count (e.g. the geometry hit).

        Returns
        -------
        t : (n,) distance to the nearest light hit (inf: none).
        L : (n, 3) radiance W/(m^2 sr) arriving at o along -d from that light.
        """
        o = np.asarray(o, float)
        d = np.asarray(d, float)
        n = o.shape[0]
        times = np.broadcast_to(np.atleast_1d(np.asarray(times, float)), (n,))
        t_best = np.full(n, np.inf) if tmax is None else np.asarray(tmax, float).copy()
        L = np.zeros((n, 3))
        found = np.zeros(n, bool)
        for li, l in enumerate(self.lights):
            if l.type in ("SUN", "MESH", "WORLD") or (l.type in ("POINT", "SPOT") and l.radius <= 0.0):
                continue          # MESH: the caster hits the triangles themselves; WORLD: escaping rays
            t, Le = self._hit_one(li, o, d, times)
            closer = (t > 0) & (t < t_best)
            t_best = np.where(closer, t, t_best)
            L[closer] = Le[closer]
            found |= closer
        return np.where(found, t_best, np.inf), L

    def _hit_one(self, li, o, d, times):
        """Hit distance (n,) (inf: miss) and radiance (n, 3) of light li along rays."""
        l = self.lights[li]
        n = o.shape[0]
        if l.type == "AREA":
            # Plane of the light, inside the shape, seen from its emitting side
            c, ex, ey, A, n_emit = self._area_shape(li, times)
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
        c, _, _, Z = self._frame(li, times)
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
        Le = np.broadcast_to(self.intensity(li) / (np.pi * r * r), (n, 3))
        if l.type == "SPOT":
            Le = Le * spot_attenuation(l, np.sum(-d * -Z, axis=-1))[:, None]
        return np.where(ok, t, np.inf), np.where(ok[:, None], Le, 0.0)

    def sky_radiance(self, d: np.ndarray, times: np.ndarray) -> np.ndarray:
        """Radiance (n, 3) of suns with angle > 0 seen along escaping rays d (n, 3): color S / Omega inside their cone."""
        d = np.asarray(d, float)
        n = d.shape[0]
        times = np.broadcast_to(np.atleast_1d(np.asarray(times, float)), (n,))
        L = np.zeros((n, 3))
        for li, l in enumerate(self.lights):
            if l.type != "SUN" or l.angle <= 0.0:
                continue
            _, _, _, Z = self._frame(li, times)
            cos_half = np.cos(0.5 * l.angle)
            omega = 2.0 * np.pi * (1.0 - cos_half)
            inside = np.sum(d * Z, axis=-1) >= cos_half
            L += inside[:, None] * (np.asarray(l.color, float) * float(l.power) / omega)[None, :]
        return L

    # -----------------------------------------------------------------------
    # Photon emission
    # -----------------------------------------------------------------------

    def emit(self, li: int, n: int, times: np.ndarray, rng: np.random.Generator):
        """Emit n photons from light li over its whole emission.

        Returns origins (n, 3), unit dirs (n, 3), power (n, 3) W per photon;
        E[sum of power] = :meth:`flux` (exactly, for POINT and AREA).
        Points and spots with a radius emit from their sphere / disc
        (:meth:`_point_origins`), so caustics get the same soft edges as shadows.
        """
        l = self.lights[li]
        if l.type == "WORLD":
            return l.emit(n, rng)                # every direction, through the scene's sphere
        times = np.atleast_1d(np.asarray(times, float))
        u = rng.random((n, 2))
        if l.type == "POINT":
            c, _, _, _ = self._frame(li, times)
            dirs = uniform_sphere(u)
            power = np.broadcast_to(self.flux(li) / n, (n, 3)).copy()
            return self._point_origins(li, c, dirs, rng), dirs, power
        if l.type == "SPOT":
            # Uniform in the spot cone (solid angle Omega_c), power I * att * Omega_c / n
            c, _, _, Z = self._frame(li, times)
            cos_half = np.cos(0.5 * l.spot_size)
            axis, _ = _axis_or_z(np.broadcast_to(-Z, (n, 3)))     # zero Z scale: att = 0 below
            dirs = _local_to_world(uniform_cone(u, cos_half), axis)
            att = spot_attenuation(l, np.sum(dirs * -Z, axis=-1))
            omega_c = 2.0 * np.pi * (1.0 - cos_half)
            power = self.intensity(li)[None, :] * (att * omega_c / n)[:, None]
            return self._point_origins(li, c, dirs, rng), dirs, power
        if l.type == "MESH":
            # Triangle by q_j, uniform point, random side, cosine direction:
            # power = Le cos / (q_j / A * 1/2 * cos / pi) / n = 2 pi Le A / (q_j n)
            q, nrm, A, Le, pq = l.sample_points(times if times.shape[0] == n else np.broadcast_to(times, (n,)), u)
            side = np.where(rng.random(n) < 0.5, 1.0, -1.0)[:, None]
            dirs = _local_to_world(cosine_hemisphere(rng.random((n, 2))), side * nrm)
            power = Le * (2.0 * np.pi * A / (pq * n))[:, None]
            return q, dirs, power
        if l.type == "AREA":
            # Uniform point, cosine-weighted direction: power = L pi A / n = color P / n
            c, ex, ey, A, n_emit = self._area_shape(li, times)
            q = self._area_points(li, ex, ey, c, rng.random((n, 2)))
            axis, ok = _axis_or_z(np.broadcast_to(n_emit, (n, 3)))  # no emitting side: no power
            dirs = _local_to_world(cosine_hemisphere(u), axis)
            power = np.broadcast_to(self.flux(li) / n, (n, 3)) * ok[:, None]
            return q, dirs, power
        # SUN: a disc perpendicular to the sun covering the scene's bounding sphere
        _, _, _, Z = self._frame(li, times)
        R = self._sun_disc_radius(li)
        return self._sun_photons(li, n, Z, np.broadcast_to(self._scene_center, (n, 3)),
                                 R, 2.0 * self._scene_radius, u, rng)

    def _point_origins(self, li, c, dirs, rng) -> np.ndarray:
        """Where photons leaving along dirs (n, 3) start on a POINT / SPOT light of radius r.

        A Lambertian sphere of radiance L seen from direction w is a uniformly
        bright disc of radius r perpendicular to w, so photons along w start at a
        uniform point of that disc: on the sphere's front (``use_soft_falloff``
        off) or in the disc through the centre (on: Cycles' disc facing the
        receiver).  Direction and power are those of the point light.  r = 0:
        the centre.
        """
        l = self.lights[li]
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

    def _sun_photons(self, li, n, Z, center, R, back, u, rng):
        """Sun photons through a disc of radius R (scalar or (n,)) perpendicular to Z, ``back`` upstream of center.

        The sun's radiance is S / Omega in its cone, so the flux through the
        disc is dPhi = (S / Omega) cos(theta) dA dw.  Points uniform on the disc
        (pdf 1 / (pi R^2)) and directions uniform in the cone (pdf 1 / Omega)
        give power = color * S * pi R^2 * cos(theta) / n per photon.
        """
        l = self.lights[li]
        Z, ok = _axis_or_z(np.broadcast_to(Z, (n, 3)))     # zero Z scale: no direction, no power
        R = np.broadcast_to(np.asarray(R, float), (n,))
        disc = concentric_disk(rng.random((n, 2))) * R[:, None]
        origins = center + back * Z + _local_to_world(np.concatenate([disc, np.zeros((n, 1))], axis=1), Z)
        if l.angle > 0.0:
            local = uniform_cone(u, np.cos(0.5 * l.angle))
            dirs = _local_to_world(local, -Z)
            cos_t = local[:, 2]
        else:
            dirs = -Z.copy()
            cos_t = np.ones(n)
        power = (np.asarray(l.color, float) * float(l.power))[None, :] * (np.pi * R * R * cos_t * ok / n)[:, None]
        return origins, dirs, power

    def emit_toward(self, li: int, n: int, times: np.ndarray, rng: np.random.Generator,
                    centers: np.ndarray, radius: float):
        """Emit n photons aimed at a sphere (centers (n, 3) or (3,), radius) only.

        Directions are uniform in the cone the sphere subtends from each
        emission point, and power = emitted intensity toward the direction *
        cone solid angle / n, so the expected power reaching anything inside the
        sphere equals that of :meth:`emit` with the same n (no photons wasted
        elsewhere).  Emission points inside the sphere fall back to
        :meth:`emit`'s distribution.

        Returns origins (n, 3), unit dirs (n, 3), power (n, 3).
        """
        l = self.lights[li]
        times = np.atleast_1d(np.asarray(times, float))
        centers = np.broadcast_to(np.asarray(centers, float), (n, 3))
        radius = float(radius)
        if l.type == "WORLD":
            # Every direction through the target sphere (power 4 pi * pi r^2 * L / n), each
            # photon started outside the whole scene on its own line (as the sun's), so that
            # occluders anywhere are traced; per-photon centres shift the lines with them.
            o, d, P = l.emit(n, rng, centers[0], radius)
            back = np.linalg.norm(centers - self._scene_center, axis=-1) + self._scene_radius + radius
            o = o + (centers - centers[0]) - d * np.maximum(back - 2.0 * radius, 0.0)[:, None]
            return o, d, P
        u = rng.random((n, 2))
        if l.type == "SUN":
            # Disc perpendicular to the sun covering the target sphere, upstream of the
            # whole scene so that occluders anywhere are still traced.
            _, _, _, Z = self._frame(li, times)
            back = (np.linalg.norm(centers - self._scene_center, axis=-1) + self._scene_radius + radius)
            R = radius + (back + radius) * np.tan(0.5 * min(l.angle, 3.0))
            return self._sun_photons(li, n, Z, centers, R, back[:, None], u, rng)
        # Emission point (and, for area lights, its emitting normal and radiance).
        # A point / spot of radius r aims from its centre at the sphere grown by r,
        # then starts each photon on its disc (every ray from the light that can
        # reach the target lies in that wider cone).
        reach = radius
        if l.type == "AREA":
            c, ex, ey, A, n_emit = self._area_shape(li, times)
            origins = self._area_points(li, ex, ey, c, rng.random((n, 2)))
        elif l.type == "MESH":
            origins, n_emit, A, Le_m, pq = l.sample_points(
                times if times.shape[0] == n else np.broadcast_to(times, (n,)), rng.random((n, 2)))
        else:
            origins, _, _, Z = self._frame(li, times)
            reach = radius + float(l.radius)
        # Cone toward the sphere: cos_max from sin = reach / d.  Inside the sphere
        # (d <= reach, which includes an emission point at the very centre, where
        # the axis is undefined) every direction reaches it: the whole sphere of
        # directions (Omega = 4 pi), as :meth:`emit` for a point light.  An axis
        # that does not normalise (d too small for its direction to be resolved)
        # is treated the same way.
        axis, d = _normalize(centers - origins)
        inside = (d <= reach) | ~(np.abs(np.einsum("ij,ij->i", axis, axis) - 1.0) < 1e-6)
        one_minus_cos = np.where(inside, 2.0, _one_minus_cos_from_sin2((reach * reach) / np.maximum(d * d, 1e-300)))
        # (a cone with cos_max = -1 is the uniform sphere; it needs no axis, so +Z stands in)
        dirs = _local_to_world(uniform_cone(u, 1.0 - one_minus_cos), np.where(inside[:, None], _UNIT_Z, axis))
        if l.type not in ("AREA", "MESH"):
            origins = self._point_origins(li, origins, dirs, rng)
        omega = 2.0 * np.pi * one_minus_cos           # cone solid angle (4 pi inside)
        if l.type == "MESH":
            # dPhi = Le |cos_l| dA dw (both sides); point pdf q_j / A, direction pdf 1 / omega
            cos_l = np.abs(np.einsum("ij,ij->i", dirs, n_emit))
            power = Le_m * (cos_l * A / pq * omega / n)[:, None]
        elif l.type == "AREA":
            # dPhi = L cos_l dA dw; point pdf 1 / A, direction pdf 1 / omega
            L = np.asarray(l.color, float)[None, :] * (float(l.power) / (np.pi * np.maximum(A, 1e-300)))[:, None]
            cos_l = np.maximum(np.sum(dirs * n_emit, axis=-1), 0.0)
            power = L * (cos_l * A * omega / n)[:, None]
        else:
            I = self.intensity(li)
            att = np.ones(n)
            if l.type == "SPOT":
                att = spot_attenuation(l, np.sum(dirs * -Z, axis=-1))
            power = I[None, :] * (att * omega / n)[:, None]
        return origins, dirs, power
