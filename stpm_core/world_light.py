"""The world as a light: a constant environment of radiance ``L = color * strength``.

Blender's world lights the scene in Cycles; here it does too, for a constant
colour (textured worlds export their mean colour, see docs/blender.md).  One
:class:`WorldLight` entry joins the :class:`~stpm_core.lights.LightSet` (after
the scene's lights and the mesh lights) when L > 0, with the same interface as
the other entries.  Units and equations (docs/lights-and-materials.md, "World"):

* Radiance ``L`` (3,) W/(m^2 sr) from every direction.  Irradiance on an
  unoccluded surface: ``E = pi L``.
* Next-event estimation at a point with (face-forwarded) normal n: direction
  wi cosine-distributed about n, ``pdf = cos / pi``, so ``weight = L pi / cos``
  and the integrator's ``f |cos| weight`` is ``f pi L`` times visibility (a
  shadow ray to infinity).  Without a normal: uniform on the sphere,
  ``weight = 4 pi L``.
* Photons: the flux crossing a disc of radius R (the scene's bounding sphere)
  from every direction is ``Phi = 4 pi * pi R^2 * L``.  A photon picks a
  uniform direction d (where it travels), a uniform point on the disc of
  radius R perpendicular to d through the scene centre, starts 2R upstream,
  and carries ``Phi / n``: any point inside the sphere then receives, from a
  solid angle dw around d, the power per area ``L dw``, i.e. radiance L.
  Aimed at a specular object (bounding sphere c, r): the same with the disc
  of radius r about c, power ``4 pi * pi r^2 * L / n``.
"""
from __future__ import annotations

import numpy as np

from .motion import MotionTransform
from .sampling import concentric_disk, cosine_hemisphere, orthonormal_basis, to_world, uniform_sphere

__all__ = ["WorldLight"]


class WorldLight:
    """A constant environment light (type ``'WORLD'``), one :class:`LightSet` entry.

    Parameters
    ----------
    radiance : (3,) W/(m^2 sr), > 0 in some channel.
    center : (3,) scene bounding-sphere centre; radius : its radius (scene units, > 0).

    Attributes (those every light entry has): ``type = 'WORLD'``, ``color``
    (= radiance), ``power`` (W, mean RGB flux through the scene's sphere),
    ``transform`` (static), ``radius = 0``, ``name``.
    """

    type = "WORLD"
    radius = 0.0
    use_soft_falloff = False
    name = "world"

    def __init__(self, radiance, center, radius: float):
        self.color = np.asarray(radiance, np.float64).reshape(3)
        self.center = np.asarray(center, np.float64).reshape(3)
        self.scene_radius = float(radius)
        self.transform = MotionTransform.static()
        self.power = float(np.mean(self.flux()))

    def flux(self) -> np.ndarray:
        """(3,) W through the scene's bounding sphere: 4 pi * pi R^2 * L."""
        return 4.0 * np.pi * np.pi * self.scene_radius ** 2 * self.color

    def sample(self, p: np.ndarray, u: np.ndarray, normals: np.ndarray | None = None):
        """Directions toward the world from points p (n, 3) with uniforms u (n, 2).

        normals: (n, 3) unit normals facing the side being shaded (cosine sampling about them),
        or None (uniform sphere).  Returns wi (n, 3) unit, dist (n,) = inf, weight (n, 3) =
        L / pdf (W m^-2 per unit f |cos|).
        """
        n = p.shape[0]
        if normals is None:
            wi = uniform_sphere(u)
            return wi, np.full(n, np.inf), np.broadcast_to(4.0 * np.pi * self.color, (n, 3)).copy()
        local = cosine_hemisphere(u)                                   # (n, 3), z = cos
        wi = to_world(local, normals)
        cos = np.maximum(local[:, 2], 1e-12)
        return wi, np.full(n, np.inf), (np.pi / cos)[:, None] * self.color[None, :]

    def emit(self, n: int, rng: np.random.Generator, center=None, radius=None):
        """n photons entering the sphere (center, radius) (default: the scene's) from every direction.

        Returns origins (n, 3), unit directions (n, 3), power (n, 3) W per photon.
        """
        c = self.center if center is None else np.asarray(center, np.float64).reshape(3)
        R = self.scene_radius if radius is None else float(radius)
        d = uniform_sphere(rng.random((n, 2)))
        t, b = orthonormal_basis(d)
        q = concentric_disk(rng.random((n, 2))) * R
        origins = c + q[:, 0:1] * t + q[:, 1:2] * b - 2.0 * R * d
        power = np.broadcast_to(4.0 * np.pi * np.pi * R * R * self.color / n, (n, 3)).copy()
        return origins, d, power
