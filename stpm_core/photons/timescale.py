"""Automatic KD4D time scale s (scene units per shutter).

KD4D searches a 4D kd-tree over (x, y, z, s*t).  A 4D ball of radius R then
spans R in space and R/s in (normalised) time, so s converts time into
distance: one unit of shutter time "costs" s scene units.

Rule (docs/photon-mapping.md, "KD4D's time scale"):

    s = sqrt(2) * v_max

where v_max is the fastest speed of anything that moves photons, in scene
units per shutter: every moving instance's vertices (rigid motion and
deformation, sampled densely over the shutter), every moving light's
position and, for a SUN (whose position does not matter), the angular speed of
its direction times the scene's radius (the speed of the shadows it sweeps).  A receiver edge moving at v sweeps R/s * v = R / sqrt(2) during
the ball's half-height, so the ball blurs a moving edge as much in time as
it does in space.  The prototype found this choice best, and the error flat up
to about 3x it.

Static scene (nothing moves, or an instant shutter): time carries no
information, so s falls back to ``1e-3 * scene diagonal``: the ball is long in
time and reaches across the whole shutter as soon as R exceeds half a
millimetre per metre of scene, i.e. KD4D becomes STANDARD (the slab clip keeps
its normalisation exact).  The same floor applies to very slow motion.

Known limits: speeds are measured on the moving objects, not on the light
patterns they throw; a rotating mirror's caustic can move faster than the
mirror (by about twice the angular speed times the throw distance).  And the
fastest mover anywhere sets s, even one far from what the camera sees: a fast
object that throws no light on the visible receivers makes the ball short in
time there, and KD4D noisier (TEMPORAL, the default, has no such scale).  Set
``settings.time_scale`` by hand for such scenes.
"""
from __future__ import annotations

import numpy as np

__all__ = ["auto_time_scale", "max_motion_speed", "STATIC_FRACTION"]

STATIC_FRACTION = 1e-3   # static fallback: s = STATIC_FRACTION * scene diagonal
_TIME_SAMPLES = 33       # shutter samples used to measure speeds
_MAX_VERTICES = 4096     # vertices per mesh used to measure speeds


def _subsample(v: np.ndarray) -> np.ndarray:
    """At most _MAX_VERTICES rows of v (..., V, 3), evenly strided (deterministic)."""
    V = v.shape[-2]
    if V <= _MAX_VERTICES:
        return v
    idx = np.linspace(0, V - 1, _MAX_VERTICES).astype(np.int64)
    return v[..., idx, :]


def max_motion_speed(scene) -> float:
    """Fastest speed (scene units per shutter) of any moving vertex or light, 0 if static."""
    if scene.shutter.is_instant:
        return 0.0
    ts = np.linspace(0.0, 1.0, _TIME_SAMPLES)
    dt = np.diff(ts)
    v_max = 0.0
    # Moving and deforming instances: world-space vertex tracks over the shutter
    for inst in scene.instances:
        mesh = scene.meshes[inst.mesh]
        if inst.transform.is_static and not mesh.is_deforming:
            continue
        M = inst.transform.at(ts)                                  # (T, 4, 4)
        if mesh.is_deforming:
            obj = np.stack([_subsample(np.asarray(mesh.vertices_at(float(t)), float)) for t in ts])
        else:
            v = np.asarray(mesh.vertices, float)
            v = _subsample(v[0] if v.ndim == 3 else v)
            obj = np.broadcast_to(v, (len(ts),) + v.shape)
        if obj.shape[1] == 0:
            continue
        world = np.einsum("tij,tvj->tvi", M[:, :3, :3], obj) + M[:, None, :3, 3]
        speed = np.linalg.norm(np.diff(world, axis=0), axis=-1) / dt[:, None]
        v_max = max(v_max, float(speed.max()))
    # Moving lights: speed of the light's origin; a SUN has no position (only its direction
    # moves photons): the angular speed of its direction times the scene's radius
    radius = None
    for light in scene.lights:
        if light.transform.is_static:
            continue
        M = light.transform.at(ts)
        if light.type == "SUN":
            if radius is None:
                lo, hi = scene.bounds()
                radius = 0.5 * float(np.linalg.norm(hi - lo)) if np.all(np.isfinite([lo, hi])) else 0.0
            zn = np.linalg.norm(M[:, :3, 2], axis=1)
            if not np.all(zn > 0):
                continue                     # no direction at some time: it emits nothing (scene_warnings)
            z = M[:, :3, 2] / zn[:, None]
            angle = np.arccos(np.clip(np.sum(z[1:] * z[:-1], axis=1), -1.0, 1.0))   # rad per step
            speed = angle * radius / dt
        else:
            speed = np.linalg.norm(np.diff(M[:, :3, 3], axis=0), axis=-1) / dt
        v_max = max(v_max, float(speed.max()))
    return v_max


def auto_time_scale(scene) -> float:
    """KD4D's s (scene units per shutter): sqrt(2) * fastest speed, floored for static scenes."""
    lo, hi = scene.bounds()
    diag = float(np.linalg.norm(hi - lo))
    s_floor = STATIC_FRACTION * (diag if diag > 0 else 1.0)
    return max(np.sqrt(2.0) * max_motion_speed(scene), s_floor)
