"""Lights as data for the kernels: one float64 parameter row per light, its pose at any time, and
the emitting triangles of mesh lights, packed once per LightSet.

:func:`kernel_light` packs entry ``li`` of a :class:`~stpm_core.lights.LightSet` on first use and
keeps it on the LightSet (attribute ``_kernel_lights``, by light index): next-event estimation
(``LightSet.sample_direct``), photon emission (``kernels.emission``) and the integrator all read
that one packing, through it or through the three functions below.

:func:`light_params`: the row of ``N_LIGHT_PARAMS`` numbers (columns ``P_*``; type codes ``T_*``;
AREA shapes ``S_*``).  :func:`light_poses`: the object-to-world matrices (k, 4, 4) a kernel reads
per row (k = 1 for a static light: every row reads matrix 0); for a MESH light they are its
instance's matrices, for the WORLD its mapping (the identity for a constant world).
:func:`mesh_arrays`: a mesh light's triangles at each vertex step (empty arrays of the same ranks
for other lights) and the world's environment arrays (black for other lights), so one kernel
signature serves every kind.  A mesh light that neither moves nor deforms is packed with its world corners
(``MeshLight._world_static``, what the numpy code sampled) and the identity as its pose: the
kernels' M x + T is then exact, so its points are those of numpy's matrix product (which BLAS
may round differently, e.g. with FMA).

The packing assumes that a LightSet's lights are not edited after it is made (its ``power`` and
``_dead`` assume it too): change a light before the first query, or make a new LightSet.
"""
from __future__ import annotations

import numpy as np

__all__ = ["N_LIGHT_PARAMS", "kernel_light", "light_params", "light_poses", "mesh_arrays", "TYPE_CODES", "SHAPE_CODES"] + [
    "P_TYPE", "P_COLOR", "P_POWER", "P_RADIUS", "P_SOFT", "P_SPOT_SIZE", "P_SPOT_BLEND", "P_COS_HALF",
    "P_SMOOTH", "P_ANGLE", "P_SHAPE", "P_SIZE", "P_SIZE_Y", "P_FLUX", "P_SUN_R", "P_SCENE_C", "P_SCENE_R",
    "P_DEAD", "T_POINT", "T_SPOT", "T_SUN", "T_AREA", "T_MESH", "T_WORLD",
    "S_SQUARE", "S_RECTANGLE", "S_DISK", "S_ELLIPSE"]

T_POINT, T_SPOT, T_SUN, T_AREA, T_MESH, T_WORLD = range(6)
TYPE_CODES = {"POINT": T_POINT, "SPOT": T_SPOT, "SUN": T_SUN, "AREA": T_AREA, "MESH": T_MESH, "WORLD": T_WORLD}
S_SQUARE, S_RECTANGLE, S_DISK, S_ELLIPSE = range(4)
SHAPE_CODES = {"SQUARE": S_SQUARE, "RECTANGLE": S_RECTANGLE, "DISK": S_DISK, "ELLIPSE": S_ELLIPSE}

P_TYPE = 0            # T_* code
P_COLOR = 1           # 3 columns: light colour (WORLD: its radiance L, W m^-2 sr^-1)
P_POWER = 4           # W (SUN: strength W/m^2; MESH: mean flux at mid-shutter; WORLD: mean flux)
P_RADIUS = 5          # POINT / SPOT radius (m)
P_SOFT = 6            # 1 = use_soft_falloff (a disc facing the receiver), 0 = a sphere
P_SPOT_SIZE = 7       # full cone angle (rad)
P_SPOT_BLEND = 8
P_COS_HALF = 9        # cos(spot_size / 2)
P_SMOOTH = 10         # (1 - cos_half) * spot_blend: width of the smoothstep band in cosine
P_ANGLE = 11          # SUN angular diameter (rad)
P_SHAPE = 12          # AREA shape, S_* code
P_SIZE = 13           # AREA size (local X, m)
P_SIZE_Y = 14         # AREA size_y (RECTANGLE / ELLIPSE; = size for SQUARE / DISK)
P_FLUX = 15           # 3 columns: LightSet.flux(li), W (what emit() photons sum to)
P_SUN_R = 18          # SUN: radius of its emission disc (LightSet._sun_disc_radius)
P_SCENE_C = 19        # 3 columns: scene bounding-sphere centre
P_SCENE_R = 22        # scene bounding-sphere radius
P_DEAD = 23           # 1 = no emitting direction at any key (emits nothing)
N_LIGHT_PARAMS = 24


def _pack_row(lights, li: int) -> np.ndarray:
    """Parameter row (N_LIGHT_PARAMS,) float64 of entry li of ``lights`` (a LightSet)."""
    l = lights.lights[li]
    row = np.zeros(N_LIGHT_PARAMS)
    row[P_TYPE] = TYPE_CODES[l.type]
    row[P_COLOR:P_COLOR + 3] = np.asarray(l.color, float).reshape(3)
    row[P_POWER] = float(l.power)
    row[P_RADIUS] = float(getattr(l, "radius", 0.0))
    row[P_SOFT] = 1.0 if getattr(l, "use_soft_falloff", False) else 0.0
    if l.type == "SPOT":
        row[P_SPOT_SIZE] = float(l.spot_size)
        row[P_SPOT_BLEND] = float(l.spot_blend)
        cos_half = float(np.cos(0.5 * l.spot_size))
        row[P_COS_HALF] = cos_half
        row[P_SMOOTH] = (1.0 - cos_half) * float(l.spot_blend)
    if l.type == "SUN":
        row[P_ANGLE] = float(l.angle)
        row[P_SUN_R] = float(lights._sun_disc_radius(li))
    if l.type == "AREA":
        row[P_SHAPE] = SHAPE_CODES[l.shape]
        row[P_SIZE] = float(l.size)
        row[P_SIZE_Y] = float(l.size_y) if l.shape in ("RECTANGLE", "ELLIPSE") else float(l.size)
    row[P_FLUX:P_FLUX + 3] = np.asarray(lights.flux(li), float).reshape(3)
    row[P_SCENE_C:P_SCENE_C + 3] = np.asarray(lights._scene_center, float).reshape(3)
    row[P_SCENE_R] = float(lights._scene_radius)
    row[P_DEAD] = 1.0 if lights._dead[li] else 0.0
    return row


_NO_STEPS = np.zeros(1)
_NO_CORNERS = np.zeros((1, 0, 3, 3))
_NO_F = np.zeros(0)
_NO_LE = np.zeros((0, 3))


def _pose_transform(l):
    """The transform that poses light entry l (MESH: its instance's; WORLD: its mapping, the identity
    for a constant world)."""
    return l._inst_transform if l.type == "MESH" else l.transform


def _no_env():
    """The ``env`` tuple of lights other than the world (a black constant world)."""
    from ..world_light import constant_environment
    return constant_environment(np.zeros(3))


def kernel_light(lights, li: int):
    """Light li of the LightSet ``lights`` as kernel data, packed once: (prm, static_poses, steps,
    corners, q, cdf, Le, env).

    prm (N_LIGHT_PARAMS,); static_poses (1, 4, 4) C-contiguous when the light (for MESH: its
    instance) does not move, else None (:func:`light_poses` per call); steps (K,), corners
    (K, F, 3, 3), q, cdf (F,), Le (F, 3): a MESH light's triangles (Le: ``MeshLight.kernel_Le``,
    ones for a textured emitter, whose callers weigh each sample by its point), K = 1 for a mesh that does
    not deform (steps = [0]; world space with an identity pose for a static mesh, object space
    otherwise), else the mesh's vertex times, corners linear in time between them; triangle j
    is picked with probability q[j] (cdf its running sum, last entry 1).  Other lights: empty
    arrays (F = 0).  env: the WORLD's environment tuple (``world_light.environment_arrays``;
    ``kernels.environment``), a black constant one for every other light.
    """
    cache = lights.__dict__.setdefault("_kernel_lights", {})
    k = cache.get(li)
    if k is None:
        l = lights.lights[li]
        tr = _pose_transform(l)
        world_mesh = l.type == "MESH" and getattr(l, "_world_static", None) is not None
        poses = None
        if world_mesh:
            poses = np.eye(4)[None].copy()
        elif tr.is_static:
            poses = np.ascontiguousarray(tr.at(np.zeros(1)), np.float64)
        if l.type != "MESH":
            mesh = (_NO_STEPS, _NO_CORNERS, _NO_F, _NO_F, _NO_LE)
        else:
            if world_mesh:
                steps, corners = np.zeros(1), l._world_static[None]
            elif l._steps is None:
                steps, corners = np.zeros(1), l._corners[None]
            else:
                steps, corners = l._steps, l._corners
            mesh = tuple(np.ascontiguousarray(a, np.float64) for a in (steps, corners, l.q, l.cdf,
                                                                        getattr(l, "kernel_Le", l.Le)))
        env = l.env if l.type == "WORLD" else _no_env()
        k = cache[li] = (_pack_row(lights, li), poses) + mesh + (env,)
    return k


def light_params(lights, li: int) -> np.ndarray:
    """Parameter row (N_LIGHT_PARAMS,) float64 of entry li of ``lights`` (a LightSet; :func:`kernel_light`)."""
    return kernel_light(lights, li)[0]


def light_poses(lights, li: int, times: np.ndarray) -> np.ndarray:
    """Object-to-world matrices (k, 4, 4) float64 C-contiguous of light li at times (n,): k = 1 when the
    light (for MESH: its instance) does not move (the packed pose; identity for the WORLD and for a
    static mesh light, whose corners are packed in world space), else k = n, one per time."""
    poses = kernel_light(lights, li)[1]
    if poses is not None:
        return poses
    times = np.atleast_1d(np.asarray(times, float))
    return np.ascontiguousarray(_pose_transform(lights.lights[li]).at(times), np.float64)


def mesh_arrays(lights, li: int):
    """A MESH light's (steps (K,), corners (K, F, 3, 3), q (F,), cdf (F,), Le (F, 3)) as packed by
    :func:`kernel_light` (in the space :func:`light_poses` maps from; other lights: empty arrays,
    F = 0), then the light's ``env`` (the WORLD's environment; black for the others): the arrays
    every light kernel takes after the poses."""
    return kernel_light(lights, li)[2:]
