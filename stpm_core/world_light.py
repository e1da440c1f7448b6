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

This class holds the world's constants only: radiance, the scene's bounding
sphere and the flux through it.
"""
from __future__ import annotations

import numpy as np

from .motion import MotionTransform

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
