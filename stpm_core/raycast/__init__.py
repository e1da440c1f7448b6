"""Time-aware ray casting: every ray carries its own shutter time.

Public API (implemented by the backends in this package; one interface):

    caster = make_caster(scene, backend="auto")   # 'embree' | 'numba' | 'numpy' | 'auto'
    hits = caster.intersect(origins, dirs, times, tmax=None, guard=None)
    blocked = caster.occluded(origins, dirs, times, tmax, guard=None)

Arrays
------
origins : (n, 3) float64 world-space ray origins.
dirs    : (n, 3) float64 world-space directions (need not be unit length;
          ``t`` is measured in units of ``|dir|``).
times   : (n,) float64 normalised shutter times in [0, 1].
tmax    : (n,) float64 or None (= inf): hits at t >= tmax are ignored.

A ray never reports a hit with ``t * |dir| <= TMIN_REL * scale`` (a distance;
``scale`` = diagonal of the scene bounds over the shutter; self-intersection
guard, callers also offset origins along the normal); ``guard`` (n,) gives
rays their own, smaller guards (``geometry.ray_guard``).  See docs/raycast.md.

:class:`Hits` fields (n rows; misses have ``t = inf`` and ``instance = -1``):
t (n,) float64; instance (n,) int32 index into ``scene.instances``;
prim (n,) int32 triangle index within that instance's mesh; u, v (n,)
float64 barycentrics (point = (1-u-v) * v0 + u * v1 + v * v2);
position (n, 3) world hit point; ng (n, 3) unit geometric normal in world
space (orientation from the triangle winding); ns (n, 3) unit shading
normal (smooth normals interpolated, else ng); material (n,) int32 index
into ``scene.materials`` (-1 for misses).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Hits", "make_caster", "set_persistent_static", "TMIN_REL"]


@dataclass
class Hits:
    t: np.ndarray
    instance: np.ndarray
    prim: np.ndarray
    u: np.ndarray
    v: np.ndarray
    position: np.ndarray
    ng: np.ndarray
    ns: np.ndarray
    material: np.ndarray

    @classmethod
    def empty(cls, n: int) -> "Hits":
        """Uninitialised arrays for n rays (dtypes as above), for the caster to fill."""
        return cls(t=np.empty(n), instance=np.empty(n, np.int32), prim=np.empty(n, np.int32), u=np.empty(n),
                   v=np.empty(n), position=np.empty((n, 3)), ng=np.empty((n, 3)), ns=np.empty((n, 3)),
                   material=np.empty(n, np.int32))

    @property
    def hit(self) -> np.ndarray:
        """(n,) bool: did the ray hit anything?"""
        return np.isfinite(self.t)


from .geometry import TMIN_REL  # noqa: E402  (self-intersection guard, see above)


def make_caster(scene, backend: str = "auto"):
    """Build a ray caster for ``scene`` ('auto': $STPM_RAYCAST_BACKEND, else embree, numba or numpy)."""
    from .build import make_caster as _make
    return _make(scene, backend=backend)


def set_persistent_static(on: bool) -> None:
    """Keep the baked static geometry between renders while nothing static changes (embree backend).

    Blender's "Persistent Data" (``scene.render.use_persistent_data``) and the
    CLI's frame ranges turn it on; off frees what is kept.  See docs/raycast.md.
    """
    from .build import embree_available
    if embree_available():
        from .embree_backend import set_persistent_static as _set
        _set(on)
