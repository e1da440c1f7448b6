"""Blender lights -> :class:`stpm_core.scene.Light` in Cycles' units.

Power: ``energy * 2**exposure`` watts (sun: W/m^2), colour times the blackbody
colour when ``use_temperature`` is on.  Area lights fold the object's scale
into their size (as Cycles does); a non-normalised area light's power grows
with its area.

Light node trees: a constant Emission node at the Light Output (its Color possibly from a constant
Blackbody) multiplies colour and power, as in Cycles (:func:`light_node_emission`); other trees are
warned and ignored.

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


def _linked_node(socket):
    """The node feeding ``socket`` through reroutes, or None when unlinked (or a muted link)."""
    while socket.is_linked:
        link = socket.links[0]
        if getattr(link, "is_muted", False) or not getattr(link, "is_valid", True):
            return None
        node = link.from_node
        if node.type != "REROUTE":
            return node
        socket = node.inputs[0]
    return None


def light_node_emission(node_tree, name: str, warnings: list) -> tuple:
    """(colour (3,), strength) a light's node tree multiplies the light's own colour and power by.

    Cycles multiplies the light's colour x power by the emission its Light Output receives.  A
    tree whose output is fed by an Emission node with constant Color and Strength (the default
    tree: white, 1; or an artist's constant edits) is that constant; a Blackbody node of constant
    temperature on Color gives Blender's blackbody colour (:mod:`.blackbody`).  Anything else
    linked (an IES Texture, textures, Light Falloff) is not evaluated: read as 1, warned; so is a
    tree with no Emission node at its output.
    """
    outputs = [n for n in node_tree.nodes if n.type == "OUTPUT_LIGHT"
               and getattr(n, "target", "ALL") in ("ALL", "CYCLES")]
    out = next((n for n in outputs if getattr(n, "is_active_output", False)), outputs[0] if outputs else None)
    node = _linked_node(out.inputs[0]) if out is not None else None
    if node is not None and node.type == "EMISSION" and not node.mute:
        col, strength = node.inputs["Color"], node.inputs["Strength"]
        c = np.ones(3) if col.is_linked else np.array(col.default_value[:3], dtype=np.float64)
        k = 1.0 if strength.is_linked else float(strength.default_value)
        bb = _linked_node(col) if col.is_linked else None
        if bb is not None and bb.type == "BLACKBODY" and not bb.mute and not bb.inputs[0].is_linked:
            # Blackbody (constant temperature) -> Color: the colour Cycles computes (blackbody.py)
            from .blackbody import blackbody
            from .nodes import working_space
            c = blackbody(float(bb.inputs[0].default_value), working_space())
            col = None
        fed = [f"{sock.name} <- {getattr(_linked_node(sock), 'name', '?')!r}" for sock in (col, strength)
               if sock is not None and sock.is_linked]
        if fed:
            warnings.append(f"light {name!r}: its node tree's Emission {', '.join(fed)} is not evaluated "
                            f"(constant Emission Color and Strength and a constant Blackbody are): read as 1")
        return c, k
    else:
        what = f"node {node.name!r} ({node.bl_idname})" if node is not None else "no Emission node"
        warnings.append(f"light {name!r}: light node tree with {what} at its Light Output is not evaluated: "
                        f"the light's colour and power only")
    return np.ones(3, dtype=np.float64), 1.0


def export_light(light_obj, times, matrices, warnings: list) -> "scene_model.Light":
    """Light object (evaluated) + sampled light-to-world matrices (K, 4, 4) -> Light."""
    lamp = light_obj.data
    color = np.array(lamp.color[:3], dtype=np.float64)
    if getattr(lamp, "use_temperature", False):
        color = color * np.array(lamp.temperature_color[:3], dtype=np.float64)
    power = float(lamp.energy) * 2.0 ** float(getattr(lamp, "exposure", 0.0))
    if getattr(lamp, "use_nodes", False) and lamp.node_tree is not None:
        node_color, node_strength = light_node_emission(lamp.node_tree, light_obj.name, warnings)
        color, power = color * node_color, power * node_strength
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
