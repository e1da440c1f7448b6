"""Blender lights in Cycles units: direct-light sampling and photon emission.

Units (``shared/design.md``, "Units: match Cycles"; every formula with its
code name is in docs/lights-and-materials.md):

* POINT / SPOT of power P W: radiant intensity ``I = color * P / (4 pi)`` W/sr
  (the spot cone masks it, never rescales it).  Radius r > 0 makes a soft
  light of the same far-field intensity, emitting radiance
  ``L = I / (pi r^2)``; ``use_soft_falloff`` picks Cycles' two shapes:
  on = a disk of radius r facing the point that looks at it (the shading
  point for next-event estimation, the ray origin for a ray that hits it),
  off = a sphere.
* AREA of power P W: one-sided Lambertian emitter facing local -Z with
  radiance ``L = color * P / (pi A)`` (A in world units, object scale
  included, as Cycles does).  The emitting side follows the transform's -Z
  column, as for SPOT and SUN, even under a mirroring scale
  (:func:`area_light_normal`).
* SUN of strength S: irradiance ``color * S`` W/m^2 on a facing surface;
  ``angle`` > 0 spreads it uniformly over a cone of that angular diameter.
* MESH (:class:`MeshLight`, one per instance with emissive triangles, after
  the scene's lights in :attr:`LightSet.lights`): ``Material.emission`` (or,
  for a node material, what its program emits at each point: a textured
  emitter) is radiance emitted from both sides, flux ``2 pi Le A``; triangles
  sampled by power, points uniform, at each sample's time.

Queries (all vectorised, each sample at its own shutter time; a light's pose
is ``light.transform.at(times)``), all computed by compiled kernels from the
light's data packed once per LightSet (:func:`stpm_core.kernels.light_params.kernel_light`):

* :meth:`LightSet.sample_direct` -- next-event estimation (incident-radiance
  estimator; :mod:`stpm_core.kernels.lights`);
* :meth:`LightSet.emit`, :meth:`LightSet.emit_toward` -- photons, whole or aimed
  (:mod:`stpm_core.kernels.emission`).

Light shapes seen along camera rays and specular chains are the integrator's
(``kernels.lights.seen_light``).  What stays here in numpy: the per-light
constants (:meth:`LightSet.flux`, :meth:`LightSet.intensity`, the sun's disc),
the poses and AREA shapes at given times (``_frame``, ``_area_shape``, which
find lights with no emitting direction), :func:`spot_attenuation`,
:func:`area_light_normal` and the mesh lights' triangles and areas.  The numpy
sampling and emission code the kernels replaced is the test oracles
(tests/oracles/lights_numpy.py, tests/oracles/emission_numpy.py).
"""
from __future__ import annotations

import numpy as np

from .kernels import emission as _emission
from .kernels import kernel_array
from .kernels.light_params import kernel_light, light_poses
from .kernels.lights import sample_direct_batch
from .kernels.sampling import mesh_choices
from .shading import shading_data, surface_emission

__all__ = ["LightSet", "MeshLight", "area_light_normal", "mesh_lights", "spot_attenuation"]

INV_4PI = 1.0 / (4.0 * np.pi)
_NO_NORMALS = np.zeros((1, 3))          # sample_direct without normals (not read)


# ---------------------------------------------------------------------------
# Small geometric helpers
# ---------------------------------------------------------------------------

def _normalize(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors (n, 3) and lengths (n,)."""
    length = np.sqrt(np.einsum("ij,ij->i", v, v))
    return v / np.maximum(length, 1e-300)[:, None], length


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
    Le : (F_e, 3) radiance of each (a textured emitter: its mean over the triangle).
    textured : the emission varies over the triangles (a node program computes it, see
        :meth:`point_emission`); the kernels then weigh samples with ``kernel_Le`` = 1 and the
        caller multiplies each sample by the radiance of its point.
    kernel_Le : (F_e, 3) the radiance the kernels weigh samples with (Le, or ones when textured).
    """

    type = "MESH"
    radius = 0.0
    use_soft_falloff = False

    def __init__(self, scene, instance: int, prims: np.ndarray, Le: np.ndarray | None, shading=None):
        inst = scene.instances[instance]
        mesh = scene.meshes[inst.mesh]
        self.instance = int(instance)
        self.name = f"{inst.name} (emission)"
        self.prims = np.asarray(prims, np.int64)
        self.color = np.ones(3)
        self._shading = shading
        self._mat = np.asarray(mesh.material_ids, np.int64)[self.prims].astype(np.int32)
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
        self.textured = False
        if Le is None:
            Le, self.textured = self._mean_emission()
        self.Le = np.asarray(Le, float)
        self.kernel_Le = np.ones_like(self.Le) if self.textured else self.Le
        # Triangle choice: q_j ~ mean(Le_j) * area averaged over three shutter times
        A = np.mean([self._areas_at(t) for t in (0.0, 0.5, 1.0)], axis=0)
        w = np.mean(self.Le, axis=1) * A
        if not np.any(w > 0):
            w = np.ones_like(w)
        # every triangle keeps a chance; a textured one whose stratified mean missed what it
        # emits a fair one (its samples then carry a bounded weight)
        w = np.maximum(w, (1e-3 * w.mean()) if self.textured else (1e-12 * w.max()))
        self.q = w / w.sum()
        self.cdf = np.cumsum(self.q)
        self.cdf[-1] = 1.0
        self.transform = _CentroidMotion(self)
        self.power = float(np.mean(self.flux_at(0.5)))

    # -- emission of node materials ----------------------------------------------------
    def _mean_emission(self) -> tuple:
        """(Le (F_e, 3), textured) of triangles whose node programs may emit: each triangle's mean
        over ``n`` stratified points (Hammersley, uniform by area; n = 4 .. 256, about 2^16 in all)
        at mid-shutter; textured = the samples are not all the same (else Le is that constant)."""
        F = self.prims.shape[0]
        n = int(np.clip(65536 // max(F, 1), 4, 256))
        k = np.arange(n)
        u0 = (k + 0.5) / n
        u1 = np.array([int(f"{i:b}"[::-1], 2) / 2.0 ** len(f"{i:b}") if i else 0.0 for i in k]) + 0.5 / n
        s = np.sqrt(u0)
        b1, b2 = np.tile(s * (1.0 - u1), F), np.tile(s * u1, F)
        tri = np.repeat(np.arange(F), n)
        C = self._all_corners_at(0.5)[tri]                          # (F n, 3, 3)
        P = C[:, 0] + b1[:, None] * (C[:, 1] - C[:, 0]) + b2[:, None] * (C[:, 2] - C[:, 0])
        Ng = np.cross(C[:, 1] - C[:, 0], C[:, 2] - C[:, 0])
        Ng /= np.maximum(np.linalg.norm(Ng, axis=1, keepdims=True), 1e-300)
        E = surface_emission(self._shading, self._mat[tri], np.full(tri.size, self.instance, np.int32),
                             self.prims[tri], b1, b2, P, Ng, -Ng, np.full(tri.size, 0.5), seed=0x5EED)
        E = np.maximum(E, 0.0)
        textured = bool(np.ptp(E, axis=0).max() > 1e-9 * max(float(E.max()), 1e-300)) if E.size else False
        return E.reshape(F, n, 3).mean(axis=1), textured

    def point_emission(self, U: np.ndarray, points: np.ndarray, dirs: np.ndarray, times: np.ndarray) -> np.ndarray:
        """Radiance (n, 3) W m^-2 sr^-1 the node programs emit at the light points that the
        kernels made of uniforms U (n, 2) (``kernels.sampling.mesh_choice``: triangle and
        barycentrics), points (n, 3) world (the same points), dirs (n, 3) unit directions of rays
        arriving at them, times (n,) (or (1,)).  The nodes read -dirs as the normal."""
        n = U.shape[0]
        J, B = np.empty(n, np.int64), np.empty((n, 2))
        mesh_choices(self.q, self.cdf, np.ascontiguousarray(U, np.float64), J, B)
        times = np.broadcast_to(np.asarray(times, np.float64).reshape(-1), (n,))
        return surface_emission(self._shading, self._mat[J], np.full(n, self.instance, np.int32), self.prims[J],
                                B[:, 0], B[:, 1], points, -dirs, dirs, times, seed=0x5EED)

    # -- geometry at times ------------------------------------------------------------
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


def mesh_lights(scene) -> list[MeshLight]:
    """One :class:`MeshLight` per instance with emissive triangles (instance order).

    A material without a node program emits its constant ``Material.emission``; one with a
    program emits what the program computes (``shading.ShadingData.emitting``: programs whose
    emission is not a constant zero): all its triangles are light triangles, sampled by their
    mean emission (:meth:`MeshLight._mean_emission`), each sample weighted by its own point's."""
    E = np.array([np.asarray(m.emission, float) for m in scene.materials]).reshape(-1, 3)
    has_graph = np.array([getattr(m, "graph", None) is not None for m in scene.materials], bool)
    sd = shading_data(scene) if has_graph.any() else None
    programs = np.zeros(len(scene.materials), bool)
    if sd is not None:
        programs[list(sd.emitting)] = True
    out = []
    for i, inst in enumerate(scene.instances):
        mid = np.asarray(scene.meshes[inst.mesh].material_ids, np.int64)
        if mid.size == 0 or E.shape[0] == 0:
            continue
        mid = np.clip(mid, 0, E.shape[0] - 1)
        Le = np.where(has_graph[mid, None], 0.0, E[mid])
        node_emit = programs[mid]
        prims = np.nonzero(np.any(Le > 0, axis=1) | node_emit)[0]
        if not prims.size:
            continue
        if node_emit[prims].any():
            out.append(MeshLight(scene, i, prims, None, shading=sd))
        else:
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
    photon_weight : (L,) float64 >= 0, ``Light.photon_weight`` / ``World.photon_weight`` (1 for
        mesh lights): photons are split in proportion to ``power * photon_weight``.
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
            self.lights.append(WorldLight(scene.world.radiance, self._scene_center, self._scene_radius,
                                              world=scene.world, portals=getattr(scene, "portals", None)))
        # SPOT / SUN / AREA lights with no emitting direction at any key (zero Z scale,
        # zero area): they emit nothing, so flux 0 and no photon budget
        self._dead = [self._no_direction(i) for i in range(len(self.lights))]
        self.power = np.array([float(np.mean(self.flux(i))) for i in range(len(self.lights))])
        # Photon budgets: each light's share relative to the others (mesh lights 1)
        self.photon_weight = np.array([float(getattr(l, "photon_weight", 1.0)) for l in self.lights])

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
        # SUN: irradiance S through the disc (Cycles' normalisation: its radiance S / (pi sin^2(angle / 2))
        # gives a facing surface exactly S, for every angle)
        R = self._sun_disc_radius(li)
        return color * float(l.power) * np.pi * R * R

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

    # -----------------------------------------------------------------------
    # Direct lighting
    # -----------------------------------------------------------------------

    def kernel_light(self, li: int):
        """Light li as kernel data, packed once per LightSet: (prm, static_poses, steps, corners,
        q, cdf, Le, env) (:func:`stpm_core.kernels.light_params.kernel_light`, which next-event
        estimation, photon emission and the integrator share).  Packed on first use: the light's
        attributes are read then (change a light before that, or make a new LightSet).
        """
        return kernel_light(self, li)

    def sample_direct(self, li: int, p: np.ndarray, times: np.ndarray, u: np.ndarray,
                      normals: np.ndarray | None = None):
        """Sample light li as seen from points p at their times (the kernel
        :func:`stpm_core.kernels.lights.sample_light_rows`).

        Parameters
        ----------
        li : light index.
        p : (n, 3) world shading points.
        times : (n,) normalised shutter times (or (1,): one time for every row).
        u : (n, 2) uniform samples in [0, 1).
        normals : (n, 3) unit normals facing the shaded side, or None; used only
            by an entry of type 'WORLD' (cosine-distributed directions about
            them; None: uniform on the sphere); other lights ignore it.

        Returns
        -------
        wi : (n, 3) unit direction from p toward the light sample.
        dist : (n,) distance to the light sample (inf for SUN and WORLD);
            shadow rays test [eps, dist).
        weight : (n, 3) W/(m^2 sr) incident-radiance estimator L_e * G / pdf,
            so reflected radiance = f * |cos(ns, wi)| * weight * visible; 0
            where the light gives nothing (behind an area light, outside a
            spot, a light with no emitting direction).  A textured MESH light's
            weight includes the radiance its node program emits at the sample.
        """
        prm, poses, steps, corners, q, cdf, Le, env = kernel_light(self, li)
        p = kernel_array(np.asarray(p, np.float64).reshape(-1, 3))
        n = p.shape[0]
        times = np.atleast_1d(np.asarray(times, np.float64))
        if poses is None:
            poses = light_poses(self, li, times)     # (1, 4, 4) when every row has the same time
        times = kernel_array(np.broadcast_to(times, (n,)))
        u = kernel_array(np.asarray(u, np.float64).reshape(n, 2))
        use_normals = normals is not None
        normals = kernel_array(np.asarray(normals, np.float64).reshape(n, 3)) if use_normals else _NO_NORMALS
        wi, dist, weight = np.empty((n, 3)), np.empty(n), np.empty((n, 3))
        sample_direct_batch(prm, poses, steps, corners, q, cdf, Le, env, p, times, u, normals, use_normals,
                            wi, dist, weight)
        light = self.lights[li]
        if getattr(light, "textured", False):        # each sample weighed by its own point's radiance
            weight *= light.point_emission(u, p + dist[:, None] * wi, wi, times)
        return wi, dist, weight

    # -----------------------------------------------------------------------
    # Photon emission
    # -----------------------------------------------------------------------

    def emit(self, li: int, n: int, times: np.ndarray, rng: np.random.Generator, *, with_s_lit: bool = False,
             guide=None):
        """Emit n photons from light li over its whole emission (the kernel
        :func:`stpm_core.kernels.emission.emit_photons`).

        times : (n,) normalised shutter times (or (1,) / a scalar: one time for every photon).
        Returns origins (n, 3), unit dirs (n, 3), power (n, 3) W per photon;
        E[sum of power] = :meth:`flux` (exactly, for POINT and AREA).
        Points and spots with a radius emit from their sphere / disc, so
        caustics get the same soft edges as shadows.  ``with_s_lit``: also return s_lit (n,), the
        distance from each origin below which the photon's first hit receives nothing (soft
        falloff; a tracer must drop those photons, :func:`stpm_core.kernels.emission.emit`).
        ``guide``: an ``photons.guide.EmissionGuide`` of this light (guided emission, each power
        divided by the guide's density), or None.
        """
        return _emission.emit(self, li, n, times, rng, with_s_lit=with_s_lit, guide=guide)

    def emit_toward(self, li: int, n: int, times: np.ndarray, rng: np.random.Generator,
                    centers: np.ndarray, radius: float, *, with_s_lit: bool = False):
        """Emit n photons aimed at a sphere (centers (n, 3) or (3,), radius) only (the kernel
        :func:`stpm_core.kernels.emission.emit_toward_photons`).

        Directions are uniform in the cone the sphere subtends from each
        emission point, and power = emitted intensity toward the direction *
        cone solid angle / n, so the expected power reaching anything inside the
        sphere equals that of :meth:`emit` with the same n (no photons wasted
        elsewhere).  Emission points inside the sphere fall back to
        :meth:`emit`'s distribution.  Suns and the world emit from a disc
        covering the sphere, started outside the whole scene.

        Returns origins (n, 3), unit dirs (n, 3), power (n, 3)[, s_lit (n,) as :meth:`emit`].
        """
        return _emission.emit_toward(self, li, n, times, rng, centers, radius, with_s_lit=with_s_lit)
