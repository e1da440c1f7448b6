"""Blender lights -> :class:`stpm_core.scene.Light` in Cycles' units.

Power: ``energy * 2**exposure`` watts (sun: W/m^2), colour times the blackbody
colour when ``use_temperature`` is on.  Area lights fold the object's scale
into their size (as Cycles does); a non-normalised area light's power grows
with its area.

Light portals: an AREA light with Cycles' portal flag (``light.cycles.is_portal``) is not a
light: it becomes one of ``Scene.portals`` (:func:`is_portal`), through which the world's light is
sampled.  Photon budgets: ``light.stpm.photon_weight`` (addon/properties.py) is the light's
``photon_weight``.
"""
from __future__ import annotations

import numpy as np

from .._core import scene_model
from .motion import transform_from_samples, without_scale


def _area(shape: str, sx: float, sy: float) -> float:
    """Area (m^2) of an area light of extents sx, sy."""
    return np.pi / 4 * sx * sy if shape in ("DISK", "ELLIPSE") else sx * sy


def is_portal(light_obj) -> bool:
    """Is this light object a light portal (an AREA light with Cycles' ``is_portal``)?"""
    lamp = light_obj.data
    cyc = getattr(lamp, "cycles", None)
    return lamp.type == "AREA" and bool(getattr(cyc, "is_portal", False))


def export_light(light_obj, times, matrices, warnings: list) -> "scene_model.Light":
    """Light object (evaluated) + sampled light-to-world matrices (K, 4, 4) -> Light."""
    lamp = light_obj.data
    color = np.array(lamp.color[:3], dtype=np.float64)
    if getattr(lamp, "use_temperature", False):
        color = color * np.array(lamp.temperature_color[:3], dtype=np.float64)
    power = float(lamp.energy) * 2.0 ** float(getattr(lamp, "exposure", 0.0))
    if getattr(lamp, "use_nodes", False) and lamp.node_tree is not None:
        warnings.append(f"light {light_obj.name!r}: light node trees are ignored (colour and power only)")
    if power < 0.0 or np.any(color < 0.0):
        warnings.append(f"light {light_obj.name!r}: negative power {power:g} W is not supported (Cycles subtracts "
                        f"light), clamped to 0: the light is off" if power < 0.0 else
                        f"light {light_obj.name!r}: negative colour components clamped to 0")
        color = np.maximum(color, 0.0)
    if not getattr(lamp, "use_shadow", True):
        warnings.append(f"light {light_obj.name!r}: Cast Shadow off is ignored (STPM lights always cast shadows)")
    M = np.asarray(matrices, dtype=np.float64).reshape(-1, 4, 4)
    scale = np.linalg.norm(M[len(M) // 2, :3, :3], axis=0)  # object scale (x, y, z)
    stpm = getattr(lamp, "stpm", None)
    kw = dict(type=lamp.type, color=color, power=max(power, 0.0),
              transform=transform_from_samples(times, without_scale(M)), name=light_obj.name,
              photon_weight=float(getattr(stpm, "photon_weight", 1.0)))
    # Per-type shape parameters
    if lamp.type in ("POINT", "SPOT"):
        kw.update(radius=float(lamp.shadow_soft_size),
                  use_soft_falloff=bool(getattr(lamp, "use_soft_falloff", True)))
        if lamp.type == "SPOT":
            kw.update(spot_size=float(lamp.spot_size), spot_blend=float(lamp.spot_blend))
    elif lamp.type == "AREA":
        sx = float(lamp.size) * scale[0]
        sy = (float(lamp.size_y) if lamp.shape in ("RECTANGLE", "ELLIPSE") else float(lamp.size)) * scale[1]
        if not getattr(lamp, "normalize", True):
            kw["power"] *= _area(lamp.shape, sx, sy)
        kw.update(shape=lamp.shape, size=sx, size_y=sy)
        spread = float(getattr(lamp, "spread", np.pi))
        if spread < np.pi - 1e-6:
            warnings.append(f"light {light_obj.name!r}: area light spread is ignored (full 180 degrees)")
    elif lamp.type == "SUN":
        kw.update(angle=float(lamp.angle))
    else:
        warnings.append(f"light {light_obj.name!r}: type {lamp.type} is not supported, exported as a point light")
        kw["type"] = "POINT"
    return scene_model.Light(**kw)
