"""Blender world -> :class:`stpm_core.scene.World` (a constant environment: background and light)."""
from __future__ import annotations

import numpy as np

from .._core import scene_model


def _uses_nodes(idblock) -> bool:
    """Blender < 5 has a use_nodes switch; 5.0 always uses the node tree (and deprecates the flag)."""
    import bpy
    if bpy.app.version >= (5, 0, 0):
        return idblock.node_tree is not None
    return bool(idblock.use_nodes)


def _output_node(tree):
    """The active World Output node of a node tree, or None."""
    outs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputWorld"]
    active = [n for n in outs if getattr(n, "is_active_output", False)]
    return (active or outs or [None])[0]


def export_world(world, warnings: list) -> "scene_model.World":
    """Background colour * strength from the Background node (or ``world.color``).

    The core lights the scene with it as a constant environment (stpm_core/world_light.py), as
    Cycles does; a textured background lights and shows as its default colour (warned).
    """
    return _export_world(world, warnings)


def _export_world(world, warnings: list) -> "scene_model.World":
    if world is None:
        return scene_model.World(color=np.zeros(3), strength=1.0)
    tree = world.node_tree if _uses_nodes(world) else None
    if tree is None:
        return scene_model.World(color=np.array(world.color[:3], dtype=np.float64), strength=1.0)
    out = _output_node(tree)
    sock = out.inputs.get("Surface") if out is not None else None
    if sock is None or not sock.is_linked:
        return scene_model.World(color=np.zeros(3), strength=1.0)
    node = sock.links[0].from_node
    if node.bl_idname != "ShaderNodeBackground":
        warnings.append(f"world {world.name!r}: {node.bl_idname} is not supported, using black")
        return scene_model.World(color=np.zeros(3), strength=1.0)
    color_in, strength_in = node.inputs["Color"], node.inputs["Strength"]
    if color_in.is_linked:
        warnings.append(f"world {world.name!r}: textured background is not supported, using its default colour")
    if strength_in.is_linked:
        warnings.append(f"world {world.name!r}: linked background strength is not supported, using its default value")
    color = np.maximum(np.array(color_in.default_value[:3], dtype=np.float64), 0.0)
    return scene_model.World(color=color, strength=max(float(strength_in.default_value), 0.0))
